//! Invariants every step of Problem 3.1 must keep, checked on a [`Simulation`] after a step:
//! - both sub-problem residuals at the simulation's tolerance;
//! - 0 ≤ ζ ≤ 1 at every node;
//! - zero normal velocity on Γ3 (every node of a contact edge, normal of that edge), exactly;
//! - the discrete friction law at every Γ3 DOF: stick |σ_τ| ≤ μ(0); slip
//!   σ_τ = μ(|w_τ|) w_τ/|w_τ| (the friction force on the body opposing the slip).
//!
//! Used by the whole-run tests and by the stability suite ([`crate::stress`]).

use super::stepper::{Simulation, StepReport};

/// Relative tolerance of the friction-law checks (times the largest traction of the step).
pub const FRICTION_LAW_TOL: f64 = 1e-8;

/// Checks every invariant after the step `r` of `sim`; the first violation is described.
pub fn check_step(sim: &Simulation, r: &StepReport) -> Result<(), String> {
    let tol = sim.settings.tolerance;
    let n = r.n;
    if !at_most(r.velocity.residual, tol) {
        return Err(format!(
            "velocity residual {:.3e} > tolerance {tol:.1e} at step {n}",
            r.velocity.residual
        ));
    }
    if let Some(d) = r.damage {
        if !at_most(d.residual, tol) {
            return Err(format!(
                "damage residual {:.3e} > tolerance {tol:.1e} at step {n}",
                d.residual
            ));
        }
    }
    if let Some((i, z)) = sim
        .state
        .zeta
        .iter()
        .enumerate()
        .find(|(_, z)| !(0.0..=1.0).contains(*z))
    {
        return Err(format!("ζ = {z} out of [0, 1] at node {i}, step {n}"));
    }
    // w_i · n_i = 0 at every unclamped Γ3 node: exactly where n_i is a coordinate axis (the
    // normal component is not a DOF), to round-off where the frame is rotated.
    for &(i, n_i) in &sim.dofs.normals {
        let w = [sim.w[2 * i], sim.w[2 * i + 1]];
        let wn = w[0] * n_i[0] + w[1] * n_i[1];
        let tol = NORMAL_TOL * w[0].hypot(w[1]);
        if !at_most(wn.abs(), tol) {
            return Err(format!(
                "normal velocity {wn:e} on Γ3 at node {i}, step {n}"
            ));
        }
    }
    let law = &sim.problem.friction;
    let nodes = sim.contact_state();
    // The floor covers frictionless (μ ≡ 0) runs.
    let scale = nodes.iter().fold(law.mu(0.0).max(1.0), |s, c| {
        s.max(c.friction_traction.abs())
    });
    for c in &nodes {
        if c.slipping {
            let expect = law.mu(c.slip_velocity.abs()) * c.slip_velocity.signum();
            if !at_most(
                (c.friction_traction - expect).abs(),
                FRICTION_LAW_TOL * scale,
            ) {
                return Err(format!(
                    "slip law at node {}, step {n}: traction {} vs μ(|w_τ|) sign(w_τ) = {expect}",
                    c.node, c.friction_traction
                ));
            }
        } else if !at_most(
            c.friction_traction.abs(),
            law.mu(0.0) + FRICTION_LAW_TOL * scale,
        ) {
            return Err(format!(
                "stick bound at node {}, step {n}: |traction| {} > μ(0) = {}",
                c.node,
                c.friction_traction.abs(),
                law.mu(0.0)
            ));
        }
    }
    Ok(())
}

/// |w_i · n_i| / |w_i| allowed at a rotated Γ3 node (a few ulps of the rotation).
const NORMAL_TOL: f64 = 1e-14;

/// a ≤ b, false when either is NaN.
fn at_most(a: f64, b: f64) -> bool {
    a <= b
}
