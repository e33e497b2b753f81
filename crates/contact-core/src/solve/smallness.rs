//! The smallness condition (2.31), c2τ · cτ² < m_A, for a scene, in two forms:
//! - the paper's estimate: m_A = 2η (monotonicity of A in (4.1), ξ ≥ 0), c2τ the
//!   relaxed-monotonicity constant of ∂j (in 3D of ξ ↦ μ(|ξ|) ξ/|ξ| on R², the same
//!   sup(−μ'), since the tangential curvature μ(r)/r is non-negative), and cτ the discrete
//!   trace constant
//!   ‖v_τ‖_{L2(Γ3)} ≤ cτ ‖ε(v)‖_{L2(Ω)} on V^h with the nodal quadrature of the friction term,
//!   i.e. cτ² = 1 / λ_min(W^{-½} S_G W^{-½}) with S_G the Schur complement onto the Γ3
//!   tangential DOFs of the Gram matrix of ‖ε(·)‖ and W = diag(ω_i);
//! - the discrete condition that the time step actually needs: the reduced energy is strongly
//!   convex iff λ_min(W^{-½} S_A W^{-½}) > c2τ (S_A: Schur complement of the velocity
//!   operator). Since S_A ⪰ 2η S_G, the paper's estimate implies the discrete one.
//!
//! Both need λ_min(W^{-½} S W^{-½}) of a Schur complement S onto Γ3, which the run's
//! backend computes ([`Backend::trace_eigenvalues`]: S formed as the trailing block of a
//! factor, or never formed and λ_min found by Lanczos on S⁻¹ with multigrid solves).

use super::backend::Backend;
use super::velocity::VelocityStep;
use super::SolveError;
use crate::fem::{DofMap, Geometry};
use crate::mesh::Mesh;
use crate::problem::Problem;

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SmallnessReport {
    /// c2τ of (2.31).
    pub c2: f64,
    /// m_A = 2η.
    pub m_a: f64,
    /// Discrete trace constant cτ (computed only when c2τ > 0 and Γ3 has free DOFs).
    pub c_tau: Option<f64>,
    /// c2τ · cτ² (0 when c2τ = 0).
    pub lhs: f64,
    /// Does (2.31) hold?
    pub holds: bool,
    /// λ_min(W^{-½} S_A W^{-½}) − c2τ: positive means each velocity step is strongly convex.
    pub discrete_margin: Option<f64>,
}

impl SmallnessReport {
    /// Both forms from λ_G = λ_min(W^{-½} S_G W^{-½}) (so cτ² = 1/λ_G) and
    /// λ_A = λ_min(W^{-½} S_A W^{-½}).
    fn from_eigenvalues(c2: f64, m_a: f64, lambda_g: f64, lambda_a: f64) -> SmallnessReport {
        let c_tau = (1.0 / lambda_g).sqrt();
        let lhs = c2 * c_tau * c_tau;
        SmallnessReport {
            c2,
            m_a,
            c_tau: Some(c_tau),
            lhs,
            holds: lhs < m_a,
            discrete_margin: Some(lambda_a - c2),
        }
    }
}

/// Evaluates both forms; forms the Schur complements only for non-convex laws.
pub fn check<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    dofs: &DofMap<D>,
    velocity: &mut VelocityStep,
    backend: &dyn Backend<D>,
) -> Result<SmallnessReport, SolveError> {
    let m_a = 2.0 * problem.material.viscosity.eta;
    let c2 = if dofs.n_contact() > 0 {
        problem.friction.relaxed_monotonicity()
    } else {
        0.0
    };
    if c2 == 0.0 {
        return Ok(SmallnessReport {
            c2,
            m_a,
            c_tau: None,
            lhs: 0.0,
            holds: true,
            discrete_margin: None,
        });
    }
    let gram = backend.stiffness(mesh, geo, dofs, 0.5, 0.0);
    let (lambda_g, lambda_a) = backend.trace_eigenvalues(mesh, dofs, gram, velocity)?;
    Ok(SmallnessReport::from_eigenvalues(
        c2, m_a, lambda_g, lambda_a,
    ))
}

#[cfg(test)]
mod tests {
    use crate::fem::assembly;
    use crate::scene::{self, presets};
    use crate::solve::stepper::Simulation;
    use crate::solve::SolverSettings;
    use nalgebra::DMatrix;
    use serde_json::json;

    /// λ_min(W^{-½} S W^{-½}), S the Schur complement of `a` onto its DOFs from `n_i` on,
    /// formed densely (the reference the backends are checked against).
    fn dense_lambda(a: &crate::linalg::Csr, n_i: usize, w: &[f64]) -> f64 {
        let n = a.nrows;
        let dense = DMatrix::from_fn(n, n, |i, j| a.get(i, j));
        let m = n - n_i;
        let a_ii = dense.view((0, 0), (n_i, n_i)).into_owned();
        let a_ic = dense.view((0, n_i), (n_i, m)).into_owned();
        let a_cc = dense.view((n_i, n_i), (m, m)).into_owned();
        let x = a_ii.cholesky().unwrap().solve(&a_ic);
        let s = a_cc - a_ic.transpose() * x;
        let scaled = DMatrix::from_fn(m, m, |i, j| s[(i, j)] / (w[i] * w[j]).sqrt());
        scaled.symmetric_eigen().eigenvalues.min()
    }

    /// Both backends' estimates agree with the dense eigenvalues of the Schur complements of
    /// the Gram matrix (cτ² = 1/λ_G) and of K (the discrete margin λ_A − c2τ), for a
    /// slip-weakening law (c2τ = (μ0 − μ1) α = 1.6).
    #[test]
    fn both_backends_match_the_dense_schur_eigenvalues() {
        for linear in ["direct", "multigrid"] {
            let mut doc = presets::get("paper-exp3").unwrap();
            doc["mesh"]["h"] = json!("1/8");
            doc["time"] = json!({"T": 1, "N": 1});
            doc["friction"] = json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": 2});
            doc["solver"] = json!({"linear": linear});
            let p = scene::validate(&doc).unwrap();
            let sim = Simulation::<2>::new(p, SolverSettings::default()).unwrap();
            let (mesh, geo, dofs) = (&sim.mesh, &sim.geo, &sim.dofs);
            let w: Vec<f64> = dofs.contact.iter().map(|c| c.weight).collect();
            let n_i = dofs.n_interior;
            let gram = assembly::viscous_stiffness(mesh, geo, dofs, 0.5, 0.0);
            let visc = sim.problem.material.viscosity;
            let k = assembly::viscous_stiffness(mesh, geo, dofs, visc.eta, visc.xi);
            let (lambda_g, lambda_a) = (dense_lambda(&gram, n_i, &w), dense_lambda(&k, n_i, &w));
            let r = &sim.smallness;
            assert!((r.c2 - 1.6).abs() < 1e-12);
            let c_tau = r.c_tau.unwrap();
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-8 * a.abs().max(b.abs());
            assert!(
                close(c_tau * c_tau, 1.0 / lambda_g),
                "{linear}: cτ = {c_tau}, λ_G = {lambda_g}"
            );
            let margin = r.discrete_margin.unwrap();
            assert!(
                close(margin, lambda_a - r.c2),
                "{linear}: margin {margin}, λ_A = {lambda_a}"
            );
            assert!(close(r.lhs, r.c2 * c_tau * c_tau) && r.holds == (r.lhs < r.m_a));
        }
    }
}
