//! Adaptive studies on whole runs ([`contact_core::study::adapt`]): on the l-bracket, whose
//! re-entrant corner at (1, 0.5) costs uniform refinement its order, the cycles reach the
//! uniform line's true error with at most a third of its unknowns and recover the order
//! N^(−1/2) of a smooth solution. Runs on the meshes the cycles make, in 2D and 3D, keep every
//! invariant of a step, and the multigrid path on them matches the direct path to 1e-9.

use contact_core::admission::Limits;
use contact_core::linalg::LinearPath;
use contact_core::mesh::AnyMesh;
use contact_core::problem::{Body, Problem};
use contact_core::scene::{self, presets};
use contact_core::solve::invariants;
use contact_core::solve::stepper::{Simulation, StepReport};
use contact_core::solve::SolverSettings;
use contact_core::study::adapt::{self, AdaptResult, Row};
use contact_core::study::target::Discard;
use contact_core::study::Execution;
use serde_json::json;
use std::ops::ControlFlow;
use std::sync::Arc;

fn study(doc: serde_json::Value) -> AdaptResult {
    let (spec, _) = adapt::parse_with(&doc, "/study", &scene::Bundled).unwrap();
    let exec = Execution {
        threads: 2,
        settings: Default::default(),
    };
    let r = adapt::run(
        &spec,
        exec,
        Limits::default(),
        &|_, _| ControlFlow::Continue(()),
        &mut Discard,
    )
    .unwrap();
    eprintln!("{}", r.text_table());
    r
}

/// Least-squares slope of log(error) against log(unknowns).
fn slope(rows: &[&Row]) -> f64 {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| ((r.unknowns as f64).ln(), r.error.unwrap().ln()))
        .collect();
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

#[test]
fn adaptivity_pays_on_the_l_bracket() {
    let mut scene = presets::get("l-bracket").unwrap();
    scene["mesh"]["h"] = json!("1/2");
    scene["time"] = json!({"t_end": 0.25, "k": "1/64"});
    scene["output"] = json!({"every": 0, "last": true, "fields": []});
    let r = study(json!({
        "scene": scene,
        "adapt": {"target": 1e-4, "theta": 0.5, "max_nodes": 12000, "max_cycles": 30},
        "reference": {"refine": 7}
    }));
    // The finest point of the uniform line whose true error a cycle nested in the reference
    // reaches (h/16 or finer), and the first cycle as accurate.
    let (uniform, cycle) = r
        .uniform
        .iter()
        .rev()
        .find_map(|u| {
            let e = u.error?;
            let c = r.cycles.iter().find(|c| c.error.is_some_and(|x| x <= e))?;
            Some((u, c))
        })
        .unwrap();
    assert!(uniform.generation >= 8, "{uniform:?}");
    assert!(
        3 * cycle.unknowns <= uniform.unknowns,
        "the cycles reach {:.3e} with {} unknowns, uniform refinement with {}",
        uniform.error.unwrap(),
        cycle.unknowns,
        uniform.unknowns
    );
    // Orders in N over the last four points with a true error of each: the cycles' near the
    // smooth solution's 1/2, uniform refinement's clearly below.
    let cycles: Vec<&Row> = r.cycles.iter().filter(|c| c.error.is_some()).collect();
    let uniform: Vec<&Row> = r.uniform.iter().filter(|u| u.error.is_some()).collect();
    let (adaptive, plain) = (
        -slope(&cycles[cycles.len() - 6..]),
        -slope(&uniform[uniform.len() - 3..]),
    );
    eprintln!("orders in N: adaptive {adaptive:.3}, uniform {plain:.3}");
    assert!(
        adaptive > 0.45 && adaptive > plain + 0.05,
        "{adaptive} against {plain}"
    );
    // The efficiency index (relative estimate ÷ relative true error) over the cycles stays
    // in the band of the uniform ladders (crates/contact-core/tests/a_posteriori.rs).
    check_band("l-bracket cycles", &cycles);
}

/// Every index estimate ÷ true error of `rows` in [1, 10], the largest at most 3× the
/// smallest.
fn check_band(what: &str, rows: &[&Row]) {
    let index: Vec<f64> = rows.iter().map(|r| r.estimate / r.error.unwrap()).collect();
    let (lo, hi) = index.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &i| {
        (lo.min(i), hi.max(i))
    });
    eprintln!("{what}: indices {index:.2?}");
    assert!(
        lo >= 1.0 && hi <= 10.0 && hi <= 3.0 * lo,
        "{what}: {index:?}"
    );
}

/// The plate with a hole (an imported mesh, a curved hole, Γ1 meeting Γ3): the efficiency
/// index of the uniform line against the mesh bisected 6 times (h/8), 8× and 4× finer than
/// its first two points.
#[test]
fn the_efficiency_index_stays_in_its_band_on_the_plate_with_a_hole() {
    let mut scene = presets::get("plate-with-hole").unwrap();
    scene["time"] = json!({"t_end": 0.25, "k": "1/32"});
    scene["output"] = json!({"every": 0, "last": true, "fields": []});
    let r = study(
        json!({"scene": scene, "adapt": {"target": 1e-6, "max_cycles": 1, "max_nodes": 3000},
                         "reference": {"refine": 3}}),
    );
    let rows: Vec<&Row> = r.uniform.iter().take(2).collect();
    assert_eq!(rows.len(), 2);
    check_band("plate with a hole", &rows);
}

/// The scene of `doc` on `mesh`, on the linear path `path`.
fn on(doc: &serde_json::Value, mesh: &AnyMesh, path: LinearPath) -> Problem {
    let mut p = scene::validate(doc).unwrap();
    p.body = Some(Arc::new(Body::new("adaptive".into(), mesh.clone(), 0)));
    p.linear = path;
    p
}

/// Every step with the invariants checked (KKT of each sub-problem at tolerance,
/// 0 ≤ ζ ≤ 1, w·n = 0 on Γ3, the friction law at every Γ3 node).
fn checked<const D: usize>(p: Problem) -> (Vec<StepReport>, String) {
    let mut sim = Simulation::<D>::new(p, SolverSettings::default()).unwrap();
    let mut reports = Vec::new();
    while !sim.finished() {
        let r = sim.step().unwrap();
        invariants::check_step(&sim, &r).unwrap_or_else(|e| panic!("{e}"));
        reports.push(r);
    }
    (reports, sim.linear_solver())
}

/// The final mesh of a few cycles on `scene`, then the scene on it by both linear paths.
fn multigrid_matches_direct<const D: usize>(scene: serde_json::Value, cycles: usize) -> usize {
    let r = study(
        json!({"scene": scene, "adapt": {"target": 1e-6, "max_cycles": cycles, "uniform": false}}),
    );
    assert_eq!(r.cycles.len(), cycles);
    let (direct, d) = checked::<D>(on(&scene, &r.final_mesh, LinearPath::Direct));
    let (multigrid, m) = checked::<D>(on(&scene, &r.final_mesh, LinearPath::Multigrid));
    assert!(
        d.starts_with("direct") && m.starts_with("multigrid"),
        "{d}, {m}"
    );
    // The cycles' meshes are nested: the multigrid takes its levels from earlier cycles.
    assert!(m.contains("geometric"), "{m}");
    let close = |a: f64, b: f64, what: &str| {
        let scale = a.abs().max(b.abs()).max(1e-300);
        assert!(
            (a - b).abs() <= 1e-9 * scale,
            "{what}: direct {a}, multigrid {b}"
        );
    };
    for (a, b) in direct.iter().zip(&multigrid) {
        close(a.w_v, b.w_v, "|w|_V");
        close(a.u_v, b.u_v, "|u|_V");
        close(a.zeta_l2, b.zeta_l2, "|ζ|");
        assert_eq!(a.slip_nodes, b.slip_nodes);
    }
    direct.iter().map(|r| r.slip_nodes).max().unwrap()
}

#[test]
fn runs_on_adaptive_plane_meshes_keep_the_invariants_and_multigrid_matches_direct() {
    let mut scene = presets::get("l-bracket").unwrap();
    scene["mesh"]["h"] = json!("1/4");
    scene["time"] = json!({"t_end": 0.25, "k": "1/16"});
    scene["output"] = json!({"every": 0, "last": true, "fields": []});
    let slipping = multigrid_matches_direct::<2>(scene, 10);
    assert!(slipping > 0, "part of the bracket's Γ3 slips");
}

#[test]
fn runs_on_adaptive_tetrahedral_meshes_keep_the_invariants_and_multigrid_matches_direct() {
    let mut scene = presets::get("box-exp3").unwrap();
    scene["mesh"]["h"] = json!("1/2");
    scene["time"] = json!({"t_end": 0.25, "k": "1/8"});
    scene["friction"] = json!({"law": "tresca", "g": 0.5});
    scene["output"] = json!({"every": 0, "last": true, "fields": []});
    let slipping = multigrid_matches_direct::<3>(scene, 10);
    assert!(slipping > 0, "Tresca g = 0.5 makes Γ3 slip");
}

/// In 3D the cycles' meshes nest in the reference (the initial mesh bisected 3r times), so
/// each has a true error, and the estimate and the error fall together.
#[test]
fn a_tetrahedral_adaptive_study_has_true_errors() {
    let mut scene = presets::get("box-exp3").unwrap();
    scene["mesh"]["h"] = json!("1/2");
    scene["time"] = json!({"t_end": 0.25, "k": "1/8"});
    scene["output"] = json!({"every": 0, "last": true, "fields": []});
    let r = study(
        json!({"scene": scene, "adapt": {"target": 1e-6, "max_cycles": 3},
                         "reference": {"refine": 1}}),
    );
    let errors: Vec<f64> = r.cycles.iter().map(|c| c.error.unwrap()).collect();
    assert!(errors.windows(2).all(|w| w[1] < w[0]), "{errors:?}");
    assert!(r.cycles.windows(2).all(|w| w[1].estimate < w[0].estimate));
}
