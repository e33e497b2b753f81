//! The command-line contract: `run` prints the summary JSON with the documented keys and
//! writes summary.json, mesh.json and the selected fields with --out; bad input exits with 2
//! and names the offending field.

use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_contact-sim"))
}

#[test]
fn run_preset_prints_summary_and_writes_fields() {
    let dir = std::env::temp_dir().join(format!("contact-sim-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = bin()
        .args([
            "run",
            "--preset",
            "paper-exp2",
            "--h",
            "1/4",
            "--k",
            "1/8",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(s["mesh"]["nodes"], 9 * 5);
    assert_eq!(s["mesh"]["triangles"], 2 * 8 * 4);
    assert_eq!(s["time"]["steps"], 8);
    for key in ["t", "w_V", "u_V", "zeta_L2", "zeta_min"] {
        assert!(s["final"][key].is_f64(), "final.{key}");
    }
    let steps = s["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 8);
    for st in steps {
        assert!(
            st["velocity"]["iterations"].is_u64()
                && st["velocity"]["residual"].as_f64().unwrap() <= 1e-10
        );
        assert!(
            st["damage"]["iterations"].is_u64()
                && st["damage"]["residual"].as_f64().unwrap() <= 1e-10
        );
    }
    assert!(s["timing"]["setup_s"].is_f64() && s["timing"]["solve_s"].is_f64());
    assert_eq!(s["final"]["t"], 1.0);
    // Files: summary, mesh, one field document per step (every = 1).
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["final"], s["final"]);
    let mesh: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("mesh.json")).unwrap()).unwrap();
    assert_eq!(mesh["nodes"].as_array().unwrap().len(), 45);
    let last: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fields/step_00008.json")).unwrap())
            .unwrap();
    assert_eq!(last["zeta"].as_array().unwrap().len(), 45);
    assert_eq!(last["u"].as_array().unwrap().len(), 90);
    assert_eq!(last["sigma"].as_array().unwrap().len(), 64);
    // Γ3 = [0, 1] × {0} at h = 1/4: nodes x = 0.25, 0.5, 0.75, 1 (x = 0 is clamped).
    let contact = last["contact"].as_array().unwrap();
    assert_eq!(contact.len(), 4);
    assert!(contact.iter().all(|c| c["slipping"] == false));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn invalid_scene_exits_2_with_pointer() {
    let dir = std::env::temp_dir().join(format!("contact-sim-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bad.json");
    let mut doc: Value = serde_json::from_slice(
        &bin()
            .args(["preset", "paper-exp1"])
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap();
    doc["material"]["viscosity"]["eta"] = Value::from(-1.0);
    std::fs::write(&path, doc.to_string()).unwrap();
    let out = bin().arg("run").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/material/viscosity/eta"), "{err}");
    // A key repeated in one object: refused as the service refuses it, at its pointer.
    doc["material"]["viscosity"]["eta"] = Value::from(1.0);
    let text = doc.to_string();
    let twice = text.replacen("\"damage\":{", "\"damage\":{\"kappa\":1,\"kappa\":2,", 1);
    assert_ne!(twice, text);
    std::fs::write(&path, twice).unwrap();
    let out = bin().arg("run").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("\"/damage/kappa\"") && err.contains("more than once"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn presets_are_listed_and_round_trip() {
    let out = bin().arg("presets").output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    for name in [
        "paper-exp1",
        "paper-exp2",
        "paper-exp3",
        "paper-convergence",
    ] {
        assert!(text.contains(name));
        let doc = bin().args(["preset", name]).output().unwrap();
        let v: Value = serde_json::from_slice(&doc.stdout).unwrap();
        assert!(contact_core::scene::validate(&v).is_ok(), "{name}");
    }
}

/// The example scene of the guide's scene format stays valid.
#[test]
fn guide_example_scene_validates() {
    let readme = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/docs/src/reference/scene-format.md"
    ))
    .unwrap();
    let start = readme.find("```json\n").expect("json block") + 8;
    let end = start + readme[start..].find("```").unwrap();
    let doc: Value = serde_json::from_str(&readme[start..end]).unwrap();
    let p = contact_core::scene::validate(&doc).unwrap();
    assert_eq!((p.cells_per_unit, p.steps, p.boundary.len()), (32, 32, 4));
}

/// `contact-sim study FILE` with a target: the choice as JSON, the report files; a target
/// out of reach of the budget is exit code 1 with the reason.
#[test]
fn a_target_study_file_prints_the_choice_or_the_reason() {
    let dir = std::env::temp_dir().join(format!("contact-sim-cli-target-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("target.json");
    std::fs::write(
        &file,
        r#"{"study": {"name": "t", "scene": "paper-convergence", "target": {"error": 0.2}}}"#,
    )
    .unwrap();
    let reports = dir.join("reports");
    let out = bin()
        .args(["study", "--report-dir"])
        .arg(&reports)
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["kind"], "target");
    assert!(
        v["chosen"]["estimated_error"].as_f64().unwrap() <= 0.2,
        "{v}"
    );
    let svg = std::fs::read_to_string(reports.join("t.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("target"));
    assert!(std::fs::read_to_string(reports.join("t.txt"))
        .unwrap()
        .contains("chosen h ="));
    std::fs::write(
        &file,
        r#"{"study": {"scene": "paper-convergence", "target": {"error": 0.05}, "budget_s": 0.001}}"#,
    )
    .unwrap();
    let out = bin().arg("study").arg(&file).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot be reached"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `contact-sim study` of an adaptive study file: the cycles as JSON, and with --report-dir
/// its report, table and final mesh, which imports as a mesh with the last cycle's nodes.
#[test]
fn an_adaptive_study_file_writes_its_final_mesh() {
    let dir = std::env::temp_dir().join(format!("contact-sim-cli-adapt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("adapt.json");
    let mut scene = contact_core::scene::presets::get("l-bracket").unwrap();
    scene["mesh"]["h"] = serde_json::json!("1/4");
    scene["time"] = serde_json::json!({"t_end": 0.25, "k": "1/16"});
    let doc = serde_json::json!({"study": {"name": "a", "scene": scene,
        "adapt": {"target": 0.01, "max_cycles": 3, "uniform": false}}});
    std::fs::write(&file, doc.to_string()).unwrap();
    let reports = dir.join("reports");
    let out = bin()
        .args(["study", "--threads", "1", "--report-dir"])
        .arg(&reports)
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["kind"].as_str(), v["stopped"].as_str()),
        (Some("adapt"), Some("max_cycles")),
        "{v}"
    );
    let nodes = v["cycles"][2]["nodes"].as_u64().unwrap() as usize;
    let msh = std::fs::read(reports.join("a.msh")).unwrap();
    let mesh = contact_core::mesh::import::import_any(&msh).unwrap();
    assert_eq!(mesh.n_nodes(), nodes);
    assert!(std::fs::read_to_string(reports.join("a.txt"))
        .unwrap()
        .contains("cycle 2"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `contact-sim study --max-nodes N --max-job-memory B`: a target out of reach of the limits
/// is refused after the cheap pilot runs and before the expensive run (exit code 1, naming
/// the limit, the run it would need with its predicted time, and the best error reachable
/// with its cost): the command takes far less than that run's predicted time. Pilots beyond
/// the node limit, or a ladder study's reference, are exit code 2 before any run.
#[test]
fn a_target_out_of_reach_of_the_limits_is_refused_before_the_expensive_run() {
    let dir = std::env::temp_dir().join(format!("contact-sim-cli-limits-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("target.json");
    std::fs::write(
        &file,
        r#"{"study": {"name": "tight", "scene": "paper-convergence", "target": {"error": 0.005}}}"#,
    )
    .unwrap();
    // The number after `label` in `text`.
    let figure = |text: &str, label: &str| -> f64 {
        let at = text
            .find(label)
            .unwrap_or_else(|| panic!("no {label:?} in {text}"))
            + label.len();
        let num: String = text[at..]
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == 'e' || *c == '-')
            .collect();
        num.trim_end_matches('.')
            .parse()
            .unwrap_or_else(|_| panic!("{label:?} in {text}"))
    };
    // `contact-sim study FLAGS… FILE`: its exit code and stderr.
    let study = |flags: &[&str]| {
        let out = bin().arg("study").args(flags).arg(&file).output().unwrap();
        assert!(
            out.status.code() == Some(0) || out.stdout.is_empty(),
            "a refused study prints no result"
        );
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    for (flag, value, limit) in [
        (
            "--max-nodes",
            "1100",
            "nodes, more than the node limit of 1100",
        ),
        (
            "--max-job-memory",
            "24M",
            "of memory (predicted), more than the per-job memory limit of 24 MiB",
        ),
    ] {
        let started = std::time::Instant::now();
        let (code, err) = study(&[flag, value]);
        let took = started.elapsed().as_secs_f64();
        eprintln!("{flag} {value}: {took:.2} s: {err}");
        assert_eq!(code, Some(1), "{flag}: {err}");
        assert!(
            err.contains("tight: the target error 0.005 in w cannot be reached within the limits"),
            "{err}"
        );
        assert!(err.contains(limit), "{flag}: {err}");
        let best = figure(&err, "the best reachable is a predicted error of ");
        assert!(best > 0.005 && best < 1.0, "{err}");
        assert!(figure(&err, " in about ") > 0.0, "{err}");
        // The run the target needs, with its predicted time: the refusal came well before it.
        let needed = figure(&err, ", about ");
        assert!(
            took < needed / 4.0 && took < 120.0,
            "{flag}: refused after {took:.1} s, the needed run alone is predicted at {needed} s: {err}"
        );
    }
    // Pilot levels beyond the node limit (h = 1/8: 81 nodes): nothing to plan with.
    let (code, err) = study(&["--max-nodes", "50"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("even the pilot runs of this scene do not fit: the mesh has 81 nodes, more than the per-job limit of 50 (--max-nodes)"),
        "{err}"
    );
    // A ladder study whose reference (h = 1/16: 289 nodes) is beyond the limits.
    std::fs::write(
        &file,
        r#"{"study": {"name": "ladder", "scene": "paper-convergence", "h": ["1/2", "1/4"], "k": "1/4",
            "reference": {"h": "1/16", "k": "1/4"}}}"#,
    )
    .unwrap();
    let (code, err) = study(&["--max-nodes", "288"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("ladder: the reference (h = 1/16, k = 1/4): the mesh has 289 nodes, more than the per-job limit of 288 (--max-nodes)"),
        "{err}"
    );
    let (code, err) = study(&["--max-job-memory", "10K"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("ladder: the reference (h = 1/16, k = 1/4): this run needs about")
            && err.contains(
                "of memory (predicted, on the multigrid path), more than this node's per-job limit"
            ),
        "{err}"
    );
    // Within the limits the same study runs.
    let (code, err) = study(&["--max-nodes", "289", "--max-job-memory", "1G"]);
    assert_eq!(code, Some(0), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn study_file_prints_the_table_as_json_or_text() {
    let dir = std::env::temp_dir().join(format!("contact-sim-cli-study-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("study.json");
    std::fs::write(
        &file,
        r#"{"study": {"scene": "paper-convergence", "h": ["1/2", "1/4"], "k": "1/8",
            "reference": {"h": "1/8", "k": "1/8"}}}"#,
    )
    .unwrap();
    let out = bin().arg("study").arg(&file).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["reference"]["h"], 0.125);
    assert_eq!(v["rows"].as_array().unwrap().len(), 2);
    assert!(v["rows"][0]["order_w"].is_null() && v["rows"][1]["order_w"].is_number());
    let reports = dir.join("reports");
    let out = bin()
        .args(["study", "--format", "text", "--report-dir"])
        .arg(&reports)
        .arg(&file)
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("err_w") && text.contains("1/4"), "{text}");
    let svg = std::fs::read_dir(&reports)
        .unwrap()
        .filter_map(|e| e.ok())
        .find(|e| e.path().extension().is_some_and(|x| x == "svg"));
    assert!(svg.is_some(), "the report directory holds the SVG");
    std::fs::write(
        &file,
        r#"{"scene": "paper-convergence", "h": ["1/3"], "k": "1/8", "reference": {"h": "1/8", "k": "1/8"}}"#,
    )
    .unwrap();
    let out = bin().arg("study").arg(&file).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/h/0") && err.contains("not nested"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The summary's `initial` is step 0, the state at t = 0 the norms over time start from:
/// w_0 = 0, and for u_0 = (a x, 0) on the 2 × 1 plate with ζ_0 = 1, ε(u_0) = diag(a, 0), so
/// |u_0|_V = a √2, |ζ_0|_Z0 = (∫ 1)^½ = √2 and min ζ_0 = 1.
#[test]
fn the_summary_starts_at_the_initial_state() {
    let dir = std::env::temp_dir().join(format!("contact-sim-initial-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut doc: Value = serde_json::from_slice(
        &bin()
            .args(["preset", "paper-exp2"])
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap();
    assert_eq!(
        (
            doc["domain"]["width"].as_f64(),
            doc["domain"]["height"].as_f64()
        ),
        (Some(2.0), Some(1.0))
    );
    let a = 0.01;
    doc["initial"] = serde_json::json!({"u0": [format!("{a}*x"), 0]});
    doc["mesh"]["h"] = Value::from("1/4");
    doc["time"] = serde_json::json!({"t_end": 1, "k": "1/4"});
    let path = dir.join("scene.json");
    std::fs::write(&path, doc.to_string()).unwrap();
    let out = bin().arg("run").arg(&path).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s: Value = serde_json::from_slice(&out.stdout).unwrap();
    let initial = &s["initial"];
    let close = |key: &str, want: f64| {
        let got = initial[key].as_f64().unwrap();
        assert!(
            (got - want).abs() <= 1e-12,
            "initial.{key}: {got} vs {want}"
        );
    };
    close("t", 0.0);
    close("w_V", 0.0);
    close("u_V", a * 2f64.sqrt());
    close("zeta_L2", 2f64.sqrt());
    close("zeta_min", 1.0);
    // steps[] holds the solved steps 1 to N, from t = k.
    assert_eq!(s["steps"][0]["n"], 1);
    assert_eq!(s["steps"].as_array().unwrap().len(), 4);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Scripts read stdout and may log stderr: piped, the long commands draw no progress bar
/// (no escape sequences, no carriage returns).
#[test]
fn piped_stderr_carries_no_progress_bar() {
    let out = bin()
        .args([
            "run",
            "--preset",
            "paper-convergence",
            "--h",
            "1/4",
            "--k",
            "1/16",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains(['\x1b', '\r']) && err.is_empty(), "{err:?}");
    let out = bin()
        .args(["stress", "--quick", "--format", "json"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains(['\x1b', '\r']), "{err:?}");
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(report["cases"].as_array().is_some_and(|c| !c.is_empty()));
}

/// `contact-sim … | head`: a reader that takes what it wants and closes the pipe ends the
/// writer quietly (status 0, nothing on stderr), not with a panic. Two readers: one that reads
/// one line of a summary larger than a pipe's buffer (so the rest is written after it has
/// gone), one that has gone before the run prints anything.
#[test]
fn a_closed_pipe_on_stdout_ends_the_command_quietly() {
    use std::io::BufRead;
    use std::process::Stdio;
    let run = |k: &str| {
        let mut cmd = bin();
        cmd.args([
            "run",
            "--preset",
            "paper-convergence",
            "--h",
            "1/4",
            "--k",
            k,
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
        cmd
    };
    // Linux pipes hold 64 KiB: a summary of 512 steps is larger.
    let mut child = run("1/512").spawn().unwrap();
    let mut first = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert_eq!(first, "{\n", "the summary JSON begins");
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && err.is_empty(),
        "{:?}: {err}",
        out.status
    );
    let whole = run("1/512").output().unwrap();
    assert!(
        whole.stdout.len() > 1 << 16,
        "the summary ({} bytes) outgrows the pipe's buffer",
        whole.stdout.len()
    );

    let mut child = run("1/16").spawn().unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && !err.contains("panicked"),
        "{:?}: {err}",
        out.status
    );
}

/// On a terminal `run` draws its bar (steps and ETA) on stderr. The terminal is the
/// pseudo-terminal of util-linux's `script`; without it the test has nothing to run.
#[test]
fn a_terminal_gets_a_progress_bar() {
    let exe = env!("CARGO_BIN_EXE_contact-sim");
    let command = format!("'{exe}' run --preset paper-convergence --h 1/4 --k 1/16 >/dev/null");
    // indicatif draws nothing on a terminal whose TERM is unset or `dumb` (as under CI).
    let Ok(out) = Command::new("script")
        .args(["-qec", &command, "/dev/null"])
        .env("TERM", "xterm")
        .stdin(std::process::Stdio::null())
        .output()
    else {
        eprintln!("no `script` (util-linux): the terminal case is not checked");
        return;
    };
    assert!(out.status.success(), "{out:?}");
    let tty = String::from_utf8_lossy(&out.stdout);
    assert!(tty.contains("/16 steps") && tty.contains("ETA"), "{tty:?}");
}

#[test]
fn a_mesh_file_is_read_next_to_the_scene() {
    let dir = std::env::temp_dir().join(format!("contact-sim-msh-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/crates/contact-core/tests/meshes/plate-with-hole-binary.msh"
        ),
        dir.join("meshes/plate.msh"),
    )
    .unwrap();
    let preset = |name: &str| -> Value {
        serde_json::from_slice(&bin().args(["preset", name]).output().unwrap().stdout).unwrap()
    };
    let mut doc = preset("plate-with-hole");
    doc["domain"]["mesh"] = Value::from("meshes/plate.msh");
    doc["time"]["k"] = Value::from("1/4");
    let path = dir.join("scene.json");
    std::fs::write(&path, doc.to_string()).unwrap();
    // Run from another working directory: the path is relative to the scene file.
    let out = bin()
        .arg("run")
        .arg(&path)
        .arg("--out")
        .arg(dir.join("out"))
        .current_dir(std::env::temp_dir())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s: Value = serde_json::from_slice(&out.stdout).unwrap();
    // The binary copy of the bundled ASCII mesh: the same mesh.
    let bundled: Value = serde_json::from_slice(
        &bin()
            .args(["run", "--preset", "plate-with-hole", "--k", "1/4"])
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap();
    assert_eq!(s["mesh"]["nodes"], bundled["mesh"]["nodes"]);
    // gmsh writes ASCII coordinates with 16 digits, so the copies differ in the last bit.
    let (a, b) = (
        s["final"]["w_V"].as_f64().unwrap(),
        bundled["final"]["w_V"].as_f64().unwrap(),
    );
    assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
    assert_eq!(s["mesh"]["source"], "mesh meshes/plate.msh");
    // A given mesh has no n = 1/h: its summary gives the cells' diameters (longest edges),
    // here recomputed from the mesh the run wrote.
    assert!(s["mesh"].get("cells_per_unit").is_none() && s["mesh"].get("h").is_none());
    let mesh: Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/mesh.json")).unwrap()).unwrap();
    let point = |i: &Value| -> Vec<f64> {
        mesh["nodes"][i.as_u64().unwrap() as usize]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let diameters: Vec<f64> = mesh["triangles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            let p: Vec<Vec<f64>> = t.as_array().unwrap().iter().map(point).collect();
            [(0, 1), (1, 2), (0, 2)]
                .iter()
                .map(|&(a, b)| ((p[a][0] - p[b][0]).powi(2) + (p[a][1] - p[b][1]).powi(2)).sqrt())
                .fold(0.0, f64::max)
        })
        .collect();
    let size = &s["mesh"]["cell_size"];
    let close = |key: &str, v: f64| {
        let got = size[key].as_f64().unwrap();
        assert!(
            (got - v).abs() <= 1e-12 * v,
            "cell_size.{key}: {got} vs {v}"
        );
    };
    close(
        "min",
        diameters.iter().copied().fold(f64::INFINITY, f64::min),
    );
    close("max", diameters.iter().copied().fold(0.0, f64::max));
    close(
        "mean",
        diameters.iter().sum::<f64>() / diameters.len() as f64,
    );
    assert!(size["min"].as_f64() < size["mean"].as_f64());

    doc["domain"]["mesh"] = Value::from("meshes/missing.msh");
    std::fs::write(&path, doc.to_string()).unwrap();
    let out = bin().arg("run").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/domain/mesh") && err.contains("missing.msh"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A run over `--max-job-memory` is refused before any numeric work, naming the field and
/// both figures; `auto` under a limit that only multigrid meets takes multigrid.
#[test]
fn a_run_over_the_memory_limit_is_refused_and_auto_takes_what_fits() {
    let out = bin()
        .args(["run", "--preset", "box-exp3", "--h", "1/8", "--k", "1/2"])
        .args(["--linear-solver", "direct", "--max-job-memory", "1M"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/solver/linear") && err.contains("per-job limit of 1 MiB"),
        "{err}"
    );
    let out = bin()
        .args([
            "run",
            "--preset",
            "box-exp3",
            "--h",
            "1/8",
            "--k",
            "1/2",
            "--max-job-memory",
            "1M",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("\"/mesh\""));
    // Between the two predictions: auto takes multigrid (a 3D box above the direct size).
    let problem = {
        let mut doc = contact_core::scene::presets::get("box-exp3").unwrap();
        doc["mesh"]["h"] = Value::from("1/24");
        contact_core::scene::validate(&doc).unwrap()
    };
    let p = contact_core::memory::predict(&problem);
    assert!(p.multigrid < p.direct, "{p:?}");
    let (path, _) = contact_core::memory::choose(&problem, Some(p.multigrid)).unwrap();
    assert_eq!(path, contact_core::linalg::LinearPath::Multigrid);
    let out = bin()
        .args([
            "run",
            "--preset",
            "box-exp3",
            "--h",
            "1/4",
            "--k",
            "1/2",
            "--linear-solver",
            "multigrid",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(summary["mesh"]["linear_solver"]
        .as_str()
        .unwrap()
        .starts_with("multigrid"));
    assert!(summary["memory"]["predicted_bytes"].as_u64().unwrap() > 0);
    assert!(
        summary["stats"]["velocity_max_krylov_iterations"]
            .as_u64()
            .unwrap()
            > 0
    );
}

/// `run --continue DIR --t-end T2` goes on from the last state a finished run's --out kept: the
/// same steps as one run to T2 — bit for bit on the direct path (every field of the last step
/// and every step's report), to the solver tolerance on the multigrid path, whose CG starting
/// guesses are not kept — in 2D and 3D, with slip. Its summary numbers the steps from the
/// parent's start and names the parent.
#[test]
fn a_continued_run_is_one_long_run() {
    let dir = std::env::temp_dir().join(format!("contact-sim-continue-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let preset = |name: &str| -> Value {
        serde_json::from_slice(&bin().args(["preset", name]).output().unwrap().stdout).unwrap()
    };
    let mut plane = preset("paper-exp3");
    plane["friction"] =
        serde_json::json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": 2});
    plane["mesh"]["h"] = Value::from("1/8");
    plane["time"] = serde_json::json!({"t_end": 0.25, "k": "1/16"});
    let mut solid = preset("box-exp3");
    solid["friction"] = serde_json::json!({"law": "tresca", "g": 2});
    solid["mesh"]["h"] = Value::from("1/4");
    solid["time"] = serde_json::json!({"t_end": 0.25, "N": 2});
    let run = |args: &[&str], out: &Path| -> Value {
        let o = bin().args(args).arg("--out").arg(out).output().unwrap();
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let last = |out: &Path, n: usize| -> Value {
        serde_json::from_slice(
            &std::fs::read(out.join(format!("fields/step_{n:05}.json"))).unwrap(),
        )
        .unwrap()
    };
    // The box's scene gives N: its continuation keeps k = T/N, not N.
    for (name, scene, path, k, steps) in [
        ("plane", &plane, "direct", "1/16", 8),
        ("solid", &solid, "direct", "1/8", 4),
        ("solid-mg", &solid, "multigrid", "1/8", 4),
    ] {
        let file = dir.join(format!("{name}.json"));
        std::fs::write(&file, scene.to_string()).unwrap();
        let file = file.to_str().unwrap();
        let (first, rest, long) = (
            dir.join(format!("{name}-1")),
            dir.join(format!("{name}-2")),
            dir.join(format!("{name}-long")),
        );
        run(&["run", file, "--linear-solver", path], &first);
        let continued = run(
            &[
                "run",
                "--continue",
                first.to_str().unwrap(),
                "--t-end",
                "0.5",
                "--linear-solver",
                path,
            ],
            &rest,
        );
        let straight = run(
            &[
                "run",
                file,
                "--t-end",
                "0.5",
                "--k",
                k,
                "--linear-solver",
                path,
            ],
            &long,
        );
        assert_eq!(continued["continued_from"]["step"], steps / 2, "{name}");
        assert_eq!(
            continued["steps"].as_array().unwrap().len(),
            steps,
            "{name}"
        );
        assert!(
            continued["stats"]["steps_with_slip"].as_u64().unwrap() > 0,
            "{name} slips"
        );
        assert!(
            !rest
                .join(format!("fields/step_{:05}.json", steps / 2))
                .exists(),
            "{name}: the parent's steps are the parent's"
        );
        let (a, b) = (last(&rest, steps), last(&long, steps));
        assert_eq!(a["t"], b["t"]);
        if path == "direct" {
            assert_eq!(a, b, "{name}: the last step, bit for bit");
            assert_eq!(
                continued["steps"], straight["steps"],
                "{name}: every step's norms and solver reports"
            );
        } else {
            let u = |f: &Value| -> Vec<f64> {
                f["u"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            };
            let (ua, ub) = (u(&a), u(&b));
            let max = ub.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let diff = ua
                .iter()
                .zip(&ub)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            assert!(
                max > 0.0 && diff <= 1e-9 * max,
                "{name}: u differs by {diff} of {max}"
            );
        }
    }
    // Refused: a final time before the parent's, or between two of its steps.
    let first = dir.join("plane-1");
    for t in ["0.125", "0.3"] {
        let o = bin()
            .args(["run", "--continue", first.to_str().unwrap(), "--t-end", t])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "--t-end {t}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `contact-sim sweep FILE`: the table of a 2 × 2 sweep as JSON (the same numbers as single
/// runs of its members), as CSV, and its plot; a bad pointer exits 2 naming it.
#[test]
fn a_sweep_file_prints_its_table_and_plots_it() {
    let dir = std::env::temp_dir().join(format!("contact-sim-cli-sweep-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut scene = contact_core::scene::presets::get("paper-convergence").unwrap();
    scene["mesh"]["h"] = serde_json::json!("1/4");
    scene["time"] = serde_json::json!({"t_end": "1/2", "k": "1/4"});
    scene["friction"] = serde_json::json!({"law": "tresca", "g": 1});
    let file = dir.join("sweep.json");
    let sweep = serde_json::json!({"sweep": {"scene": scene,
        "vary": {"/friction/g": [0.05, 2], "/damage/kappa": [0.1, 0.5]}}});
    std::fs::write(&file, sweep.to_string()).unwrap();
    let plot = dir.join("plot.svg");
    let out = bin()
        .args(["sweep", "--plot"])
        .arg(&plot)
        .args(["--quantity", "slip_nodes", "--against", "/damage/kappa"])
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["kind"], "sweep");
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 4);
    // The third member (g = 2, κ = 0.1) as a single run: the same final norms.
    let mut single = scene.clone();
    single["friction"]["g"] = serde_json::json!(2);
    single["damage"]["kappa"] = serde_json::json!(0.1);
    let scene_file = dir.join("single.json");
    std::fs::write(&scene_file, single.to_string()).unwrap();
    let one = bin().arg("run").arg(&scene_file).output().unwrap();
    let one: serde_json::Value = serde_json::from_slice(&one.stdout).unwrap();
    assert_eq!(rows[2]["values"]["/friction/g"], 2);
    assert_eq!(rows[2]["w_V"], one["final"]["w_V"]);
    assert_eq!(rows[2]["zeta_L2"], one["final"]["zeta_L2"]);
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert_eq!(svg.matches("<g class=\"line\">").count(), 2, "a line per g");
    let csv = bin()
        .args(["sweep", "--format", "csv"])
        .arg(&file)
        .output()
        .unwrap();
    let csv = String::from_utf8(csv.stdout).unwrap();
    assert!(
        csv.starts_with("member,/friction/g,/damage/kappa,w_V"),
        "{csv}"
    );
    assert_eq!(csv.lines().count(), 5);
    std::fs::write(
        &file,
        serde_json::json!({"sweep": {"scene": "paper-convergence", "vary": {"/friction/gg": [1]}}})
            .to_string(),
    )
    .unwrap();
    let out = bin().arg("sweep").arg(&file).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/sweep/vary/~1friction~1gg"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
