//! The multigrid path against the direct path: every per-step norm to 1e-9 relative, on the
//! paper rectangles (smoothed aggregation when small, geometric levels from halving the
//! grid), a polygon and an imported mesh as given (aggregation) and refined (geometric
//! levels), the Kuhn box (both ways) and an imported tetrahedral mesh; damage on. Scenes that
//! slip take the semismooth Newton method on all DOFs on the multigrid path and the dense
//! reduced problem on the direct one: partial and full slip in 2D and 3D, slip-weakening
//! inside (2.31), a curved Γ3, an imported cylinder as given and refined.

use contact_core::linalg::LinearPath;
use contact_core::problem::{Precision, Problem};
use contact_core::scene::{self, presets};
use contact_core::solve::invariants;
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

fn run<const D: usize>(p: Problem) -> (Vec<StepReport>, String, &'static str) {
    let (reports, sim) = simulate::<D>(p);
    (reports, sim.linear_solver(), sim.slip_solver().describe())
}

/// Every step, with the invariants (friction law, w·n = 0 on Γ3, 0 ≤ ζ ≤ 1) checked.
fn simulate<const D: usize>(p: Problem) -> (Vec<StepReport>, Simulation<D>) {
    let mut sim = Simulation::<D>::new(p, SolverSettings::default()).expect("set-up");
    let mut reports = Vec::new();
    while !sim.finished() {
        let r = sim.step().expect("step");
        invariants::check_step(&sim, &r).unwrap_or_else(|e| panic!("{e}"));
        reports.push(r);
    }
    (reports, sim)
}

fn close(a: f64, b: f64, what: &str) {
    let scale = a.abs().max(b.abs()).max(1e-300);
    assert!(
        (a - b).abs() <= 1e-9 * scale,
        "{what}: direct {a} vs multigrid {b}"
    );
}

fn compare<const D: usize>(preset: &str, mesh: Value, steps: usize, expect: &str) {
    compare_with::<D>(preset, mesh, steps, expect, &[]);
}

/// As [`compare`], with scene edits (JSON pointer, value); returns the steps that slipped.
fn compare_with<const D: usize>(
    preset: &str,
    mesh: Value,
    steps: usize,
    expect: &str,
    edits: &[(&str, Value)],
) -> usize {
    let edit = |mut p: Problem, path: &str| {
        let mut doc = presets::get(preset).expect("preset");
        doc["mesh"] = mesh.clone();
        doc["time"] = json!({"T": doc["time"].get("T").or(doc["time"].get("t_end")).cloned().unwrap_or(json!(1)), "N": steps});
        doc["solver"] = json!({"linear": path});
        for (pointer, value) in edits {
            match pointer.strip_prefix("/solver/") {
                Some(key) => doc["solver"][key] = value.clone(),
                None => *doc.pointer_mut(pointer).expect("pointer") = value.clone(),
            }
        }
        if !edits.is_empty() {
            p = scene::validate(&doc).unwrap_or_else(|e| panic!("{preset}: {e}"));
        }
        p
    };
    let (direct, d_name, d_slip) = run::<D>(edit(
        problem(preset, mesh.clone(), steps, "direct"),
        "direct",
    ));
    let (multi, m_name, m_slip) = run::<D>(edit(
        problem(preset, mesh.clone(), steps, "multigrid"),
        "multigrid",
    ));
    assert_eq!(d_name, "direct (Cholesky)");
    // `expect`: the description's start, then (after each `*`) pieces that follow in order.
    assert!(
        m_name.starts_with(expect.split('*').next().unwrap_or(""))
            && expect
                .split('*')
                .try_fold(m_name.as_str(), |rest, piece| {
                    rest.find(piece).map(|i| &rest[i + piece.len()..])
                })
                .is_some(),
        "{preset}: {m_name}"
    );
    assert_eq!(direct.len(), multi.len());
    for (a, b) in direct.iter().zip(&multi) {
        let at = format!("{preset} step {}", a.n);
        close(a.w_v, b.w_v, &format!("{at} |w|_V"));
        close(a.u_v, b.u_v, &format!("{at} |u|_V"));
        close(a.zeta_l2, b.zeta_l2, &format!("{at} |ζ|"));
        close(a.zeta_min, b.zeta_min, &format!("{at} min ζ"));
        assert_eq!(a.slip_nodes, b.slip_nodes, "{at}: slip nodes");
        assert!(b.velocity.residual <= 1e-10 && b.damage.is_none_or(|d| d.residual <= 1e-10));
    }
    // A step may need no iteration at all: its starting guess, the projection onto the
    // earlier solutions, can already meet the tolerance (step 2 of a load that grows in
    // proportion).
    assert!(
        multi
            .iter()
            .map(|r| r.velocity.krylov_iterations)
            .sum::<usize>()
            > 0,
        "{preset}: the multigrid path was taken"
    );
    let slipped = multi.iter().filter(|r| r.slip_nodes > 0).count();
    if slipped > 0 {
        assert!(d_slip.starts_with("dense Schur complement"), "{d_slip}");
        assert_eq!(m_slip, "semismooth Newton on all DOFs (multigrid)");
        let newton = multi.iter().filter(|r| r.slip_nodes > 0);
        let most = newton.map(|r| r.velocity.iterations).max().unwrap_or(0);
        eprintln!("{preset} {edits:?}: {slipped} slipping steps, at most {most} Newton iterations");
    }
    slipped
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
        "multigrid (geometric, 2 levels, mixed precision)",
    );
    compare::<3>(
        "standing-cylinder",
        json!({"refine": 0}),
        3,
        "multigrid (smoothed aggregation",
    );
}

/// `solver.precision`: 3D takes single-precision level operators by default (the cases
/// above), 2D double; either precision on either dimension agrees with the direct path.
#[test]
fn both_precisions_agree_in_both_dimensions() {
    let precision = |p: &str| ("/solver/precision", json!(p));
    let tresca = |g: f64| ("/friction", json!({"law": "tresca", "g": g}));
    let slipped = compare_with::<2>(
        "paper-convergence",
        json!({"h": "1/32"}),
        4,
        "multigrid (geometric*, mixed precision)",
        &[precision("mixed"), tresca(0.5)],
    );
    assert!(slipped > 0);
    compare_with::<2>(
        "paper-exp3",
        json!({"h": "1/16"}),
        4,
        "multigrid (smoothed aggregation*, mixed precision)",
        &[precision("mixed")],
    );
    compare_with::<3>(
        "box-exp3",
        json!({"h": "1/8"}),
        4,
        "multigrid (geometric, 2 levels)",
        &[precision("double")],
    );
    compare_with::<3>(
        "box-exp3",
        json!({"h": "1/8"}),
        4,
        "multigrid (geometric, 2 levels, mixed precision)",
        &[],
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
    doc["solver"] = json!({"precision": "half"});
    let e = scene::validate(&doc).unwrap_err().to_string();
    assert!(e.contains("/solver/precision"), "{e}");
    doc["solver"] = json!({"precision": "double"});
    assert_eq!(scene::validate(&doc).unwrap().precision, Precision::Double);
    assert!(!Precision::Auto.mixed(2) && Precision::Auto.mixed(3));
}

/// A preset, its mesh, the expected hierarchy and scene edits.
type Case = (
    &'static str,
    Value,
    &'static str,
    Vec<(&'static str, Value)>,
);

/// Friction that slips, on the semismooth Newton path against the dense reduced problem.
#[test]
fn slipping_friction_agrees_on_the_newton_path() {
    let tresca = |g: f64| ("/friction", json!({"law": "tresca", "g": g}));
    // 2D: partial slip on a rectangle (aggregation, then a halved grid), full slip (g = 0).
    let cases2: Vec<Case> = vec![
        (
            "paper-exp3",
            json!({"h": "1/16"}),
            "multigrid (smoothed aggregation",
            vec![tresca(0.05)],
        ),
        (
            "paper-convergence",
            json!({"h": "1/32"}),
            "multigrid (geometric",
            vec![tresca(0.5)],
        ),
        (
            "paper-convergence",
            json!({"h": "1/16"}),
            "multigrid (smoothed aggregation",
            vec![tresca(0.0)],
        ),
        (
            "plate-with-hole",
            json!({"refine": 1}),
            "multigrid (geometric",
            vec![],
        ),
        (
            "arch-on-support",
            json!({"refine": 0}),
            "multigrid (smoothed aggregation",
            vec![],
        ),
        (
            "paper-exp3",
            json!({"h": "1/16"}),
            "multigrid (smoothed aggregation",
            vec![(
                "/friction",
                json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": 2}),
            )],
        ),
    ];
    for (preset, mesh, expect, edits) in cases2 {
        let slipped = compare_with::<2>(preset, mesh, 4, expect, &edits);
        assert!(slipped > 0, "{preset} {edits:?}: no step slipped");
    }
    // 3D: oblique partial slip on the box (aggregation and halved), the imported cylinder in
    // full slip as given (aggregation) and refined (geometric).
    let cases3: Vec<Case> = vec![
        (
            "box-exp3",
            json!({"h": "1/6"}),
            "multigrid (smoothed aggregation",
            vec![tresca(2.0)],
        ),
        (
            "box-exp3",
            json!({"h": "1/8"}),
            "multigrid (geometric",
            vec![tresca(2.0)],
        ),
        (
            "standing-cylinder",
            json!({"refine": 0}),
            "multigrid (smoothed aggregation",
            vec![tresca(0.0)],
        ),
        (
            "standing-cylinder",
            json!({"refine": 1}),
            "multigrid (geometric",
            vec![tresca(0.0)],
        ),
    ];
    for (preset, mesh, expect, edits) in cases3 {
        let slipped = compare_with::<3>(preset, mesh, 3, expect, &edits);
        assert!(slipped > 0, "{preset} {edits:?}: no step slipped");
    }
}

/// 24 steps on the geometric path: the space of earlier solutions whose projection starts
/// each K_II solve fills (12 vectors) and is compressed twice; the norms still agree with the
/// direct path, and the starting guesses pay: once the space has a few vectors, the solves
/// take well under half the iterations of the first step's (which starts from zero).
#[test]
fn a_long_run_agrees_through_the_compressions_of_its_starting_guesses() {
    compare::<3>(
        "box-exp3",
        json!({"h": "1/8"}),
        24,
        "multigrid (geometric, 2 levels, mixed precision)",
    );
    let (reports, _) = simulate::<3>(problem("box-exp3", json!({"h": "1/8"}), 24, "multigrid"));
    let its: Vec<usize> = reports
        .iter()
        .map(|r| r.velocity.krylov_iterations)
        .collect();
    let late = its[8..].iter().max().unwrap();
    assert!(
        2 * late < its[0],
        "Krylov iterations a step: {its:?} (the late ones at most {late})"
    );
}

/// 16 steps that all slip on the geometric path: each step after the first starts from the
/// minimiser of the energy over the span of the earlier velocities, the norms agree with the
/// direct path, and the starting points pay: the late steps take one Newton iteration and
/// under half the first slipping step's Krylov iterations (which starts from the stick
/// solution).
#[test]
fn a_slipping_run_starts_its_steps_from_the_earlier_velocities() {
    let g2 = ("/friction", json!({"law": "tresca", "g": 2.0}));
    let slipped = compare_with::<3>(
        "box-exp3",
        json!({"h": "1/8"}),
        16,
        "multigrid (geometric, 2 levels, mixed precision)",
        std::slice::from_ref(&g2),
    );
    assert_eq!(slipped, 16, "every step slips with g = 2");
    let mut doc = presets::get("box-exp3").expect("preset");
    doc["time"] = json!({"T": 1, "N": 16});
    doc["solver"] = json!({"linear": "multigrid"});
    doc["friction"] = g2.1;
    let p = scene::validate(&doc).expect("scene");
    let (reports, _) = simulate::<3>(p);
    let newton: Vec<usize> = reports.iter().map(|r| r.velocity.iterations).collect();
    let krylov: Vec<usize> = reports
        .iter()
        .map(|r| r.velocity.krylov_iterations)
        .collect();
    assert!(
        newton[8..].iter().all(|&n| n <= 1),
        "Newton iterations a step: {newton:?}"
    );
    let late = krylov[8..].iter().max().unwrap();
    assert!(
        2 * late < krylov[0],
        "Krylov iterations a step: {krylov:?} (the late ones at most {late})"
    );
}
