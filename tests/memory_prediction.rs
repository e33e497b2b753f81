//! The memory prediction a run is admitted on ([`contact_core::memory`]) against the peak the
//! run then measures (VmHWM), each run in its own process (`contact-sim run`): generated
//! boxes of three sizes and imported meshes as given (smoothed aggregation) and refined
//! (geometric levels down to the given mesh), sticking and slipping, all on the multigrid
//! path whose prediction comes from counts alone. The promise is ±25 %.

use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;

const MESHES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/crates/contact-core");

/// A scene from a preset with `changes` merged into its top level.
fn scene(preset: &str, changes: Value) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_contact-sim"))
        .args(["preset", preset])
        .output()
        .unwrap();
    assert!(out.status.success());
    let mut s: Value = serde_json::from_slice(&out.stdout).unwrap();
    for (k, v) in changes.as_object().unwrap() {
        s[k] = v.clone();
    }
    s
}

/// Runs `scene` (its mesh file copied from `mesh`, if any) on the multigrid path with one
/// thread; returns predicted ÷ peak bytes.
fn ratio(dir: &Path, name: &str, scene: &Value, mesh: Option<PathBuf>) -> f64 {
    if let Some(mesh) = mesh {
        std::fs::copy(&mesh, dir.join(mesh.file_name().unwrap())).unwrap();
    }
    let file = dir.join(format!("{name}.json"));
    std::fs::write(&file, scene.to_string()).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_contact-sim"))
        .args(["run", "--linear-solver", "multigrid", "--threads", "1"])
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(s["mesh"]["linear_solver"]
        .as_str()
        .unwrap()
        .starts_with("multigrid"));
    let predicted = s["memory"]["predicted_bytes"].as_f64().unwrap();
    let peak = s["memory"]["peak_bytes"].as_f64().unwrap();
    predicted / peak
}

#[test]
#[cfg(target_os = "linux")]
fn the_prediction_is_within_a_quarter_of_the_peak() {
    let dir = std::env::temp_dir().join(format!("contact-sim-memory-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let short = json!({"t_end": 0.25, "k": 0.125});
    let preset_mesh = |f: &str| Some(Path::new(MESHES).join("preset-meshes").join(f));
    let test_mesh = |f: &str| Some(Path::new(MESHES).join("tests/meshes").join(f));
    let mut cases: Vec<(String, Value, Option<PathBuf>)> = [12, 16, 20]
        .into_iter()
        .map(|n| {
            let s = scene(
                "box-exp3",
                json!({"time": short, "mesh": {"h": 1.0 / n as f64}}),
            );
            (format!("box-exp3 1/{n}"), s, None)
        })
        .collect();
    // The standing cylinder slips (g = 1); with g = 100 it sticks.
    for (label, refine, g) in [
        ("as given", 0, 1.0),
        ("refined once", 1, 1.0),
        ("refined once, sticking", 1, 100.0),
    ] {
        let s = scene(
            "standing-cylinder",
            json!({"time": short, "mesh": {"refine": refine},
                   "friction": {"law": "tresca", "g": g}}),
        );
        let name = format!("standing-cylinder {label}");
        cases.push((name, s, preset_mesh("standing-cylinder.msh")));
    }
    let s = scene(
        "standing-cylinder",
        json!({"time": short, "domain": {"mesh": "cylinder.msh"}, "mesh": {"refine": 2}}),
    );
    cases.push((
        "cylinder.msh refined twice".into(),
        s,
        test_mesh("cylinder.msh"),
    ));
    let ratios: Vec<(String, f64)> = cases
        .iter()
        .enumerate()
        .map(|(i, (name, s, mesh))| {
            (
                name.clone(),
                ratio(&dir, &format!("case{i}"), s, mesh.clone()),
            )
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!("predicted ÷ peak: {ratios:?}");
    let outside: Vec<_> = ratios
        .iter()
        .filter(|(_, r)| !(0.75..=1.25).contains(r))
        .collect();
    assert!(
        outside.is_empty(),
        "predicted ÷ peak outside ±25 %: {outside:?} (all: {ratios:?})"
    );
}
