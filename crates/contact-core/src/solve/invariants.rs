//! Invariants every step of Problem 3.1 must keep, checked on a [`Simulation`] after a step:
//! - both sub-problem residuals at the simulation's tolerance;
//! - 0 ≤ ζ ≤ 1 at every node;
//! - zero normal velocity on Γ3 (every node of a contact edge, normal of that edge), exactly;
//! - the discrete friction law at every Γ3 DOF: stick |σ_τ| ≤ μ(0); slip
//!   σ_τ = μ(|w_τ|) w_τ/|w_τ| (the friction force on the body opposing the slip).
//!
//! Used by the whole-run tests and by the stability suite ([`crate::stress`]).

use super::stepper::{Simulation, StepReport};
use crate::problem::BoundaryKind;

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
    let contact = |part: Option<usize>| {
        part.is_some_and(|p| matches!(sim.problem.boundary[p].kind, BoundaryKind::Contact))
    };
    for e in sim.mesh.boundary_edges.iter().filter(|e| contact(e.part)) {
        for &i in &e.nodes {
            let wn = sim.w[2 * i] * e.normal[0] + sim.w[2 * i + 1] * e.normal[1];
            if wn != 0.0 {
                return Err(format!(
                    "normal velocity {wn:e} on Γ3 at node {i}, step {n}"
                ));
            }
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

/// a ≤ b, false when either is NaN.
fn at_most(a: f64, b: f64) -> bool {
    a <= b
}
