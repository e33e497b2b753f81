//! The multigrid path against the direct path: every per-step norm to 1e-9 relative, on the
//! paper rectangles (smoothed aggregation when small, geometric levels from halving the
//! grid), a polygon and an imported mesh as given (aggregation) and refined (geometric
//! levels), the Kuhn box (both ways) and an imported tetrahedral mesh; damage on. Friction cases that slip on the multigrid path form the Schur
//! complement by solves (until the full-space Newton method lands).

use contact_core::linalg::LinearPath;
use contact_core::problem::Problem;
use contact_core::scene::{self, presets};
use contact_core::solve::stepper::{Simulation, StepReport};
use contact_core::solve::SolverSettings;
use serde_json::{json, Value};

/// A preset with the given mesh and time edits and linear path.
fn problem(preset: &str, mesh: Value, steps: usize, path: &str) -> Problem {
    let mut doc = presets::get(preset).expect("preset");
    doc["mesh"] = mesh;
    doc["time"] = json!({"T": doc["time"].get("T").or(doc["time"].get("t_end")).cloned().unwrap_or(json!(1)), "N": steps});
    doc["solver"] = json!({"linear": path});
    scene::validate(&doc).unwrap_or_else(|e| panic!("{preset}: {e}"))
}

fn run<const D: usize>(p: Problem) -> (Vec<StepReport>, String) {
    let mut sim = Simulation::<D>::new(p, SolverSettings::default()).expect("set-up");
    let mut reports = Vec::new();
    while !sim.finished() {
        reports.push(sim.step().expect("step"));
    }
    (reports, sim.linear_solver())
}

fn close(a: f64, b: f64, what: &str) {
    let scale = a.abs().max(b.abs()).max(1e-300);
    assert!(
        (a - b).abs() <= 1e-9 * scale,
        "{what}: direct {a} vs multigrid {b}"
    );
}

fn compare<const D: usize>(preset: &str, mesh: Value, steps: usize, expect: &str) {
    let (direct, d_name) = run::<D>(problem(preset, mesh.clone(), steps, "direct"));
    let (multi, m_name) = run::<D>(problem(preset, mesh, steps, "multigrid"));
    assert_eq!(d_name, "direct (Cholesky)");
    assert!(m_name.starts_with(expect), "{preset}: {m_name}");
    assert_eq!(direct.len(), multi.len());
    for (a, b) in direct.iter().zip(&multi) {
        let at = format!("{preset} step {}", a.n);
        close(a.w_v, b.w_v, &format!("{at} |w|_V"));
        close(a.u_v, b.u_v, &format!("{at} |u|_V"));
        close(a.zeta_l2, b.zeta_l2, &format!("{at} |ζ|"));
        close(a.zeta_min, b.zeta_min, &format!("{at} min ζ"));
        assert_eq!(a.slip_nodes, b.slip_nodes, "{at}: slip nodes");
        assert!(b.velocity.residual <= 1e-10 && b.damage.is_none_or(|d| d.residual <= 1e-10));
        assert!(
            b.velocity.krylov_iterations > 0,
            "{at}: the multigrid path was taken"
        );
    }
}

#[test]
fn paper_rectangles_agree() {
    compare::<2>(
        "paper-exp3",
        json!({"h": "1/16"}),
        8,
        "multigrid (smoothed aggregation",
    );
    compare::<2>(
        "paper-convergence",
        json!({"h": "1/16"}),
        8,
        "multigrid (smoothed aggregation",
    );
    // 1089 nodes: the grid is halved once (33² → 17² nodes), the coarse level factored.
    compare::<2>(
        "paper-convergence",
        json!({"h": "1/32"}),
        8,
        "multigrid (geometric, 2 levels)",
    );
}

#[test]
fn polygon_and_imported_meshes_agree_as_given_and_refined() {
    compare::<2>(
        "l-bracket",
        json!({"h": "1/8", "refine": 0}),
        4,
        "multigrid (smoothed aggregation",
    );
    compare::<2>(
        "plate-with-hole",
        json!({"refine": 0}),
        4,
        "multigrid (smoothed aggregation",
    );
    compare::<2>(
        "plate-with-hole",
        json!({"refine": 1}),
        4,
        "multigrid (geometric, 2 levels)",
    );
}

#[test]
fn boxes_and_tetrahedral_meshes_agree() {
    compare::<3>(
        "box-exp3",
        json!({"h": "1/6"}),
        4,
        "multigrid (smoothed aggregation",
    );
    // 16 × 8 × 8 cubes: halved once to 8 × 4 × 4 (Kuhn boxes of h and 2h are nested).
    compare::<3>(
        "box-exp3",
        json!({"h": "1/8"}),
        4,
        "multigrid (geometric, 2 levels)",
    );
    compare::<3>(
        "standing-cylinder",
        json!({"refine": 0}),
        3,
        "multigrid (smoothed aggregation",
    );
}

#[test]
fn the_scene_field_is_validated_and_hashed() {
    let mut doc = presets::get("paper-exp1").unwrap();
    doc["solver"] = json!({"linear": "gmres"});
    let e = scene::validate(&doc).unwrap_err().to_string();
    assert!(e.contains("/solver/linear"), "{e}");
    doc["solver"] = json!({"linear": "multigrid"});
    let p = scene::validate(&doc).unwrap();
    assert_eq!(p.linear, LinearPath::Multigrid);
    let plain = presets::get("paper-exp1").unwrap();
    assert_ne!(scene::content_hash(&doc), scene::content_hash(&plain));
}
