//! Invariants every step of Problem 3.1 must keep, checked on a [`Simulation`] after a step:
//! - both sub-problem residuals at the simulation's tolerance;
//! - 0 ≤ ζ ≤ 1 at every node;
//! - zero normal velocity on Γ3 (every node of a contact edge, normal of that edge), exactly;
//! - the discrete friction law at every Γ3 node: stick |σ_τ| ≤ μ(0); slip
//!   σ_τ = μ(|w_τ|) w_τ/|w_τ| (the friction force on the body opposing the slip; in 3D with
//!   the tangential 2-vectors and the Euclidean norm).
//!
//! Used by the whole-run tests and by the stability suite ([`crate::harness::stress`]).

use super::stepper::{Simulation, StepReport};

/// Relative tolerance of the friction-law checks (times the largest traction of the step).
pub const FRICTION_LAW_TOL: f64 = 1e-8;

/// Checks every invariant after the step `r` of `sim`; the first violation is described.
pub fn check_step<const D: usize>(sim: &Simulation<D>, r: &StepReport) -> Result<(), String> {
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
        let w = &sim.w[D * i..D * i + D];
        let wn: f64 = (0..D).map(|c| w[c] * n_i[c]).sum();
        let tol = NORMAL_TOL
            * match D {
                2 => w[0].hypot(w[1]),
                _ => w.iter().map(|v| v * v).sum::<f64>().sqrt(),
            };
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
        if let (Some(v), Some(f)) = (c.tangential_velocity, c.traction) {
            // 3D, as vectors and with the sign of the 2D check below: the reported traction
            // is −σ_τ ∈ ∂j(w_τ), so μ(|w_τ|) w_τ/|w_τ| at slip and |·| ≤ μ(0) at stick.
            let speed = v.iter().map(|a| a * a).sum::<f64>().sqrt();
            let size = f.iter().map(|a| a * a).sum::<f64>().sqrt();
            if c.slipping {
                let mu = law.mu(speed);
                let gap = (0..3)
                    .map(|k| (f[k] - mu * v[k] / speed).powi(2))
                    .sum::<f64>()
                    .sqrt();
                if !at_most(gap, FRICTION_LAW_TOL * scale) {
                    return Err(format!(
                        "slip law at node {}, step {n}: traction {f:?} vs μ(|w_τ|) w_τ/|w_τ| \
                         with w_τ = {v:?}",
                        c.node
                    ));
                }
            } else if !at_most(size, law.mu(0.0) + FRICTION_LAW_TOL * scale) {
                return Err(format!(
                    "stick bound at node {}, step {n}: |traction| {size} > μ(0) = {}",
                    c.node,
                    law.mu(0.0)
                ));
            }
            continue;
        }
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
