//! Invariants of whole runs on the paper's scenes and on scenes that make Γ3 slip (with the
//! paper's g = 20 every contact node sticks, so the non-smooth solver is never exercised):
//! 0 ≤ ζ ≤ 1; zero normal velocity on Γ3; the discrete friction law at every Γ3 node
//! (stick: |σ_τ| ≤ μ(0); slip: σ_τ = μ(|w_τ|) w_τ/|w_τ|, the friction force on the body
//! opposing the slip); sub-problem residuals at tolerance. The checks themselves are
//! `contact_core::solve::invariants` (shared with the stability suite, tests/stability.rs).

mod common;
use common::*;
use contact_core::problem::Problem;
use contact_core::solve::invariants;
use contact_core::solve::stepper::Simulation;
use contact_core::solve::SolverSettings;
use serde_json::json;

struct Outcome {
    steps_with_slip: usize,
    max_velocity_iterations: usize,
}

fn check_run(p: Problem) -> Outcome {
    let mut out = Outcome {
        steps_with_slip: 0,
        max_velocity_iterations: 0,
    };
    run_checked(p, |sim: &Simulation, r| {
        if let Err(e) = invariants::check_step(sim, r) {
            panic!("{e}");
        }
        out.steps_with_slip += (r.slip_nodes > 0) as usize;
        out.max_velocity_iterations = out.max_velocity_iterations.max(r.velocity.iterations);
    });
    out
}

#[test]
fn paper_experiments_stick_everywhere_and_keep_invariants() {
    for preset in [
        "paper-exp1",
        "paper-exp2",
        "paper-exp3",
        "paper-convergence",
    ] {
        let o = check_run(problem(preset, 8, 16, &[]));
        assert_eq!(
            o.steps_with_slip, 0,
            "{preset}: g = 20 should stick everywhere"
        );
    }
}

#[test]
fn tresca_with_low_bound_slips_and_satisfies_the_friction_law() {
    let o = check_run(problem(
        "paper-exp3",
        8,
        16,
        &[("/friction", json!({"law": "tresca", "g": 1}))],
    ));
    assert!(o.steps_with_slip > 0 && o.max_velocity_iterations > 0);
    let o = check_run(problem(
        "paper-convergence",
        16,
        16,
        &[("/friction", json!({"law": "tresca", "g": 1}))],
    ));
    assert!(o.steps_with_slip > 0);
}

#[test]
fn slip_weakening_is_solved_as_a_true_hvi() {
    let law = json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": 3});
    let mild = json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": 2});
    // On the 2 × 1 body of experiment 3, α = 3 (c2τ = 2.4) is beyond the smallness
    // condition: (2.31) fails (cτ ≈ 1.55: c2τ·cτ² ≈ 5.8 > m_A = 4) and so does the discrete
    // strong convexity of the velocity step, so the scene is refused by default.
    let p = problem("paper-exp3", 8, 16, &[("/friction", law.clone())]);
    let err = Simulation::<2>::new(p, SolverSettings::default())
        .err()
        .expect("refused by (2.31)");
    assert!(
        err.to_string().contains("2.31") && err.to_string().contains("not strongly convex"),
        "{err}"
    );
    // α = 2 (c2τ = 1.6) on experiment 3 and α = 3 on the unit square satisfy (2.31).
    for (preset, law, c2) in [("paper-exp3", &mild, 1.6), ("paper-convergence", &law, 2.4)] {
        let p = problem(preset, 8, 16, &[("/friction", law.clone())]);
        let sim = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
        assert!((sim.smallness.c2 - c2).abs() < 1e-12);
        assert!(
            sim.smallness.holds && sim.smallness.discrete_margin.unwrap() > 0.0,
            "{preset}: {:?}",
            sim.smallness
        );
        let o = check_run(p);
        assert!(o.steps_with_slip > 0, "{preset}");
    }
}

#[test]
fn piecewise_linear_friction_slips() {
    // Slope −1 then +0.1: c2τ = 1, within (2.31) for experiment 3 (cτ² ≈ 2.4 < 4).
    let law = json!({"law": "piecewise_linear", "points": [[0, 1.0], [0.5, 0.5], [1, 0.55]]});
    let p = problem("paper-exp3", 8, 16, &[("/friction", law)]);
    let sim = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
    assert!(sim.smallness.holds && sim.smallness.c2 == 1.0);
    let o = check_run(p);
    assert!(o.steps_with_slip > 0);
}

#[test]
fn von_mises_elasticity_and_full_stick_limits() {
    let vm = json!({"type": "von_mises", "eta_b": 8, "sigma_y": 0.05});
    check_run(problem("paper-exp2", 8, 8, &[("/material/elasticity", vm)]));
    // g = 0: frictionless (every Γ3 node slides freely); g = 1e4: full stick.
    let o = check_run(problem(
        "paper-exp3",
        8,
        8,
        &[("/friction", json!({"law": "tresca", "g": 0}))],
    ));
    assert!(o.steps_with_slip > 0);
    let o = check_run(problem(
        "paper-exp3",
        8,
        8,
        &[("/friction", json!({"law": "tresca", "g": 1e4}))],
    ));
    assert_eq!(o.steps_with_slip, 0);
}

#[test]
fn smallness_violation_is_refused_or_warned() {
    let law = json!({"law": "slip_weakening", "mu0": 50, "mu1": 0, "alpha": 100});
    let p = problem("paper-exp3", 8, 8, &[("/friction", law.clone())]);
    let err = Simulation::<2>::new(p, SolverSettings::default())
        .err()
        .expect("refused");
    assert!(err.to_string().contains("smallness"), "{err}");
    let p = problem(
        "paper-exp3",
        8,
        8,
        &[("/friction", law), ("/smallness", json!("warn"))],
    );
    let sim = Simulation::<2>::new(p, SolverSettings::default()).expect("warn runs");
    assert!(!sim.smallness.holds);
}

#[test]
fn no_damage_block_means_no_damage_solve() {
    let mut doc_edits = Vec::new();
    doc_edits.push(("/friction", json!({"law": "tresca", "g": 20})));
    let mut p = problem("paper-exp3", 8, 8, &doc_edits);
    p.damage = None;
    run_checked(p, |sim, r| {
        assert!(r.damage.is_none());
        assert!(sim.state.zeta.iter().all(|&z| z == 1.0));
    });
}

/// Regression: the reduced friction solver measured its residual relative to ‖b‖ while the
/// velocity step checks the full residual relative to ‖f‖; at h = k = 1/64 the last step
/// stopped at 1.16e-10 of the full scale and the run failed. Both now use the same scale.
#[test]
fn reduced_and_full_residuals_use_one_scale() {
    let law = json!({"law": "piecewise_linear", "points": [[0, 1.0], [0.5, 0.5], [1, 0.55]]});
    let o = check_run(problem("paper-exp3", 64, 64, &[("/friction", law)]));
    assert!(o.steps_with_slip > 0);
}
