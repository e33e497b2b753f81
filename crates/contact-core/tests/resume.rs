//! Resuming from a checkpoint repeats an uninterrupted run bit for bit: the checkpoint
//! carries (u, ζ, step) and the warm starts of both sub-problem solvers (the tangential
//! velocities on Γ3 and the damage active set), through the binary checkpoint format.

mod common;
use common::*;
use contact_core::output::stored::{decode_state, encode_state};
use contact_core::solve::stepper::Simulation;
use contact_core::solve::SolverSettings;
use serde_json::json;

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Runs `p` straight through, and again stopped after `stop` steps, checkpointed, restored
/// into a fresh simulation and continued; compares every value of u, ζ and w at T.
fn assert_bit_for_bit(p: contact_core::problem::Problem, stop: usize) -> usize {
    let mut straight = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
    let mut slipping_steps = 0;
    while !straight.finished() {
        slipping_steps += usize::from(straight.step().unwrap().slip_nodes > 0);
    }
    let mut first = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
    for _ in 0..stop {
        first.step().unwrap();
    }
    let bytes = encode_state(&first.checkpoint_state());
    drop(first);
    let mut resumed = Simulation::<2>::new(p, SolverSettings::default()).unwrap();
    resumed.restore(decode_state(&bytes).unwrap());
    while !resumed.finished() {
        resumed.step().unwrap();
    }
    assert_eq!(bits(&resumed.state.u), bits(&straight.state.u), "u");
    assert_eq!(
        bits(&resumed.state.zeta),
        bits(&straight.state.zeta),
        "zeta"
    );
    assert_eq!(bits(&resumed.w), bits(&straight.w), "w");
    slipping_steps
}

#[test]
fn slipping_contact_with_damage_resumes_bit_for_bit() {
    let p = problem(
        "paper-exp3",
        16,
        32,
        &[("/friction", json!({"law": "tresca", "g": 1}))],
    );
    let slipping = assert_bit_for_bit(p, 13);
    assert!(
        slipping > 20,
        "the scene must exercise the friction solver ({slipping} steps slip)"
    );
}

#[test]
fn non_convex_friction_resumes_bit_for_bit() {
    let law = json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": 2});
    let p = problem("paper-exp3", 16, 32, &[("/friction", law)]);
    assert_bit_for_bit(p, 7);
}

#[test]
fn damage_down_to_zero_resumes_bit_for_bit() {
    // Weak friction on the contact half: slip and damage evolve together.
    let p = problem(
        "paper-exp2",
        8,
        32,
        &[("/friction", json!({"law": "tresca", "g": 0.5}))],
    );
    assert_bit_for_bit(p, 16);
}

/// On the multigrid path the conjugate-gradient starting guesses (the span of the earlier
/// velocity solutions) are not checkpointed: a resumed run agrees with an uninterrupted one to
/// the solver tolerance, not bit for bit.
#[test]
fn a_multigrid_run_resumes_to_the_solver_tolerance() {
    let mut doc = contact_core::scene::presets::get("box-exp3").unwrap();
    doc["mesh"] = json!({"h": "1/8"});
    doc["time"] = json!({"T": 1, "N": 20});
    doc["solver"] = json!({"linear": "multigrid"});
    let p = contact_core::scene::validate(&doc).unwrap();
    let run = |stop: Option<usize>| {
        let mut sim = Simulation::<3>::new(p.clone(), SolverSettings::default()).unwrap();
        if let Some(stop) = stop {
            for _ in 0..stop {
                sim.step().unwrap();
            }
            let bytes = encode_state(&sim.checkpoint_state());
            sim = Simulation::<3>::new(p.clone(), SolverSettings::default()).unwrap();
            sim.restore(decode_state(&bytes).unwrap());
        }
        let mut last = None;
        while !sim.finished() {
            last = Some(sim.step().unwrap());
        }
        (sim.state.u.clone(), last.unwrap())
    };
    let (u, straight) = run(None);
    let (u_resumed, resumed) = run(Some(14));
    let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let du: Vec<f64> = u.iter().zip(&u_resumed).map(|(a, b)| a - b).collect();
    assert!(max(&du) <= 1e-9 * max(&u), "u differs by {}", max(&du));
    for (a, b) in [
        (straight.w_v, resumed.w_v),
        (straight.u_v, resumed.u_v),
        (straight.zeta_l2, resumed.zeta_l2),
    ] {
        assert!((a - b).abs() <= 1e-9 * a.abs(), "{a} vs {b}");
    }
}
