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
//! Both need λ_min(W^{-½} S W^{-½}) of a Schur complement S onto Γ3. The direct path forms S
//! (the trailing block of the factor). The multigrid path never forms it: λ_min is 1/λ_max of
//! T = W^{½} S⁻¹ W^{½}, and S⁻¹ = (A⁻¹)_CC, so each product with T is one multigrid-CG solve
//! with A on all free DOFs (load on Γ3 only); λ_max(T) by Lanczos with full
//! reorthogonalisation ([`min_eig_by_lanczos`]).

use super::velocity::VelocityStep;
use super::SolveError;
use crate::fem::{assembly, multilevel, DofMap, Geometry};
use crate::linalg::dense::{min_eig_scaled, tridiagonal_max_eig};
use crate::linalg::multigrid::{Hierarchy, Params};
use crate::linalg::schur::{schur_by_solves, SCHUR_COLUMN_TOLERANCE};
use crate::linalg::Csr;
use crate::linalg::{schur_complement, Cholesky, SchurPath};
use crate::linalg::{LinearPath, LinearSolver};
use crate::mesh::Mesh;
use crate::problem::Problem;
use std::sync::Arc;

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
    let d: Vec<f64> = velocity.weights().iter().map(|w| 1.0 / w.sqrt()).collect();
    // The multigrid path is the one for large meshes: no element triplets (24 (D(D+1))²
    // bytes per cell, 11 GB at the 1/64 box).
    let gram = match velocity.linear_solver() {
        LinearSolver::Direct(_) => assembly::viscous_stiffness(mesh, geo, dofs, 0.5, 0.0),
        _ => assembly::viscous_stiffness_in_pattern(mesh, geo, dofs, 0.5, 0.0),
    };
    let n_i = dofs.n_interior;
    let factor_error = |source| SolveError::Factor {
        what: "strain Gram",
        source,
    };
    let s_g = match velocity.linear_solver() {
        LinearSolver::Direct(_) => {
            let g_ii = Cholesky::new(gram.block(0..n_i, 0..n_i).lower_csc().as_ref())
                .map_err(factor_error)?;
            schur_complement(&gram, n_i, &g_ii, SchurPath::TrailingBlock).0
        }
        LinearSolver::LeadingBlock(_) => {
            return lanczos_report(mesh, dofs, velocity, gram, c2, m_a);
        }
        LinearSolver::Multigrid(_) => {
            let mut g_ii = multilevel::velocity_solver(
                mesh,
                dofs,
                gram.block(0..n_i, 0..n_i),
                n_i,
                LinearPath::Multigrid,
            )
            .map_err(factor_error)?;
            schur_by_solves(&gram, n_i, &mut g_ii).map_err(|e| SolveError::NotConverged {
                what: "strain Gram Schur complement (multigrid)",
                step: 0,
                iterations: e.iterations,
                residual: e.residual,
                tolerance: SCHUR_COLUMN_TOLERANCE,
            })?
        }
    };
    let lambda_g = min_eig_scaled(&s_g, &d);
    let lambda_a = min_eig_scaled(velocity.schur()?, &d);
    Ok(SmallnessReport::from_eigenvalues(
        c2, m_a, lambda_g, lambda_a,
    ))
}

/// The report on the multigrid path: both λ_min by Lanczos, no S formed.
fn lanczos_report<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    velocity: &VelocityStep,
    gram: Csr,
    c2: f64,
    m_a: f64,
) -> Result<SmallnessReport, SolveError> {
    let w_sqrt: Vec<f64> = velocity.weights().iter().map(|w| w.sqrt()).collect();
    let (_, n_i) = velocity.operator();
    let k_hierarchy = velocity
        .linear_solver()
        .hierarchy()
        .expect("the multigrid path's")
        .clone();
    let mut k_solver = LinearSolver::with_hierarchy(k_hierarchy, velocity.shared_operator());
    let gram = Arc::new(gram);
    let (blocks, levels) = multilevel::velocity_levels(mesh, dofs, dofs.n_free());
    let g_hierarchy =
        Hierarchy::new(gram.clone(), blocks, levels, Params::default()).map_err(|source| {
            SolveError::Factor {
                what: "strain Gram",
                source,
            }
        })?;
    let mut g_solver = LinearSolver::with_hierarchy(Arc::new(g_hierarchy), gram);
    let lambda_g = min_eig_by_lanczos(&mut g_solver, n_i, &w_sqrt)?;
    let lambda_a = min_eig_by_lanczos(&mut k_solver, n_i, &w_sqrt)?;
    Ok(SmallnessReport::from_eigenvalues(
        c2, m_a, lambda_g, lambda_a,
    ))
}

/// Most Lanczos steps.
const LANCZOS_STEPS: usize = 300;
/// Each solve of the Lanczos iteration stops at this max-norm residual relative to its load.
const SOLVE_TOLERANCE: f64 = 1e-11;
/// Lanczos stops when the largest Ritz value moves by less than this, relative.
const LANCZOS_TOLERANCE: f64 = 1e-10;

/// λ_min(W^{-½} S W^{-½}) for S the Schur complement of the solver's operator A (n × n) onto
/// its DOFs from `lead` on, W = diag(w_sqrt²): 1/λ_max of T = W^{½} (A⁻¹)_CC W^{½} by Lanczos
/// with full reorthogonalisation from a fixed start vector (deterministic); each product with
/// T is one solve A z = [0; W^{½} v] to [`SOLVE_TOLERANCE`].
pub fn min_eig_by_lanczos(
    a: &mut LinearSolver,
    lead: usize,
    w_sqrt: &[f64],
) -> Result<f64, SolveError> {
    let n = a.n();
    let m = n - lead;
    if m == 0 {
        return Ok(f64::INFINITY);
    }
    let mut apply = |v: &[f64], out: &mut [f64], z: &mut Vec<f64>| -> Result<(), SolveError> {
        let mut b = vec![0.0; n];
        for i in 0..m {
            b[lead + i] = w_sqrt[i] * v[i];
        }
        let scale = b.iter().fold(f64::MIN_POSITIVE, |s, x| s.max(x.abs()));
        z.iter_mut().for_each(|x| *x = 0.0);
        a.solve(&b, z, SOLVE_TOLERANCE * scale)
            .map_err(|e| SolveError::NotConverged {
                what: "smallness check (multigrid solve of the Lanczos iteration)",
                step: 0,
                iterations: e.iterations,
                residual: e.residual / scale,
                tolerance: SOLVE_TOLERANCE,
            })?;
        for i in 0..m {
            out[i] = w_sqrt[i] * z[lead + i];
        }
        Ok(())
    };
    let mut z = vec![0.0; n];
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut v: Vec<f64> = (0..m)
        .map(|i| 1.0 + 0.5 * ((i as f64) * 0.618_033_988_7).fract())
        .collect();
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let s = norm(&v);
    v.iter_mut().for_each(|x| *x /= s);
    let (mut alphas, mut betas) = (Vec::new(), Vec::new());
    let mut w = vec![0.0; m];
    let mut last = 0.0;
    for step in 0..LANCZOS_STEPS.min(m) {
        apply(&v, &mut w, &mut z)?;
        let alpha: f64 = w.iter().zip(&v).map(|(a, b)| a * b).sum();
        basis.push(v.clone());
        // Full reorthogonalisation (twice) against every basis vector.
        for _ in 0..2 {
            for q in &basis {
                let c: f64 = w.iter().zip(q).map(|(a, b)| a * b).sum();
                w.iter_mut().zip(q).for_each(|(a, b)| *a -= c * b);
            }
        }
        alphas.push(alpha);
        let beta = norm(&w);
        let top = tridiagonal_max_eig(&alphas, &betas);
        if step > 0 && (top - last).abs() <= LANCZOS_TOLERANCE * top || beta <= 1e-14 * top {
            return Ok(1.0 / top);
        }
        last = top;
        betas.push(beta);
        v.iter_mut().zip(&w).for_each(|(v, w)| *v = w / beta);
    }
    Ok(1.0 / last)
}
