//! The direct family: sparse Cholesky factors, computed once per run.
//! - K_II: factored once on the ordering of least fill ([`plan`]); S = K_CC − K_CI K_II⁻¹ K_IC
//!   formed on a slipping step's first need, for the dense reduced problem on Γ3
//!   ([`super::super::reduced`]).
//! - H: factored on a fixed pattern, refactored with the active rows and columns replaced
//!   by the identity when the damage step's active set changes ([`Masked`]).
//! - The smallness estimate: both Schur complements formed, their λ_min dense.
//!
//! Every operator is assembled from element triplets, in the order of summation the direct
//! path has always had (bit for bit the same numbers run after run).

use super::Backend;
use crate::fem::{assembly, DofMap, Geometry};
use crate::linalg::cholesky::FactorError;
use crate::linalg::dense::min_eig_scaled;
use crate::linalg::solver::NotConverged;
use crate::linalg::SchurPath;
use crate::linalg::{schur_complement, Cholesky, CholeskyPlan, Csr, LinearPath, LinearSolver};
use crate::mesh::Mesh;
use crate::problem::{FrictionLaw, Problem};
use crate::solve::damage::{Bound, DamageStep, MaskedSolver};
use crate::solve::velocity::VelocityStep;
use crate::solve::SolveError;
use faer::sparse::{SparseColMat, SparseColMatRef};
use std::sync::Arc;

/// The symbolic analysis of a run's operator on a D-dimensional mesh: in 3D the ordering of
/// less fill of AMD and nested dissection (nested dissection wins on the boxes from a few
/// thousand unknowns on, docs/src/speed/speed.md); in 2D AMD.
pub fn plan<const D: usize>(
    a_lower: SparseColMatRef<'_, usize, f64>,
) -> Result<CholeskyPlan, FactorError> {
    if D == 3 {
        CholeskyPlan::least_fill(a_lower)
    } else {
        CholeskyPlan::amd(a_lower)
    }
}

/// The symbolic analysis of H's factor from any matrix with H's pattern (the mass matrix:
/// H = M/k + κL is assembled into M's pattern). AMD: the scalar operator's factor is small
/// beside K_II's.
pub fn damage_plan(pattern: &Csr) -> Result<CholeskyPlan, SolveError> {
    CholeskyPlan::amd(pattern.lower_csc().as_ref()).map_err(|source| SolveError::Factor {
        what: "damage",
        source,
    })
}

/// The analyses of a run's factors, made on the operators' patterns before any is
/// assembled: what the exact prediction of the direct path needs ([`crate::memory::refine`]).
#[derive(Clone)]
pub struct Plans {
    k_ii: CholeskyPlan,
    /// H's, with damage.
    h: Option<CholeskyPlan>,
}

impl Plans {
    pub fn analyse<const D: usize>(
        problem: &Problem,
        mesh: &Mesh<D>,
        dofs: &DofMap<D>,
    ) -> Result<Plans, SolveError> {
        let n_i = dofs.n_interior;
        let pattern = assembly::free_pattern(mesh, dofs);
        let lower = pattern.block(0..n_i, 0..n_i).lower_csc();
        drop(pattern);
        let k_ii = plan::<D>(lower.as_ref()).map_err(|source| SolveError::Factor {
            what: "velocity",
            source,
        })?;
        let h = match problem.damage {
            Some(_) => Some(damage_plan(&assembly::node_pattern(mesh))?),
            None => None,
        };
        Ok(Plans { k_ii, h })
    }

    /// K_II's, then H's.
    pub fn all(&self) -> Vec<&CholeskyPlan> {
        std::iter::once(&self.k_ii).chain(&self.h).collect()
    }
}

/// The direct family, with the analyses its choice was made on.
pub struct Direct {
    plans: Plans,
    predicted_bytes: u64,
}

impl Direct {
    pub fn new(plans: Plans, predicted_bytes: u64) -> Direct {
        Direct {
            plans,
            predicted_bytes,
        }
    }
}

impl<const D: usize> Backend<D> for Direct {
    fn path(&self) -> LinearPath {
        LinearPath::Direct
    }

    fn predicted_bytes(&self) -> u64 {
        self.predicted_bytes
    }

    fn stiffness(
        &self,
        mesh: &Mesh<D>,
        geo: &Geometry<D>,
        dofs: &DofMap<D>,
        eta: f64,
        xi: f64,
    ) -> Csr {
        assembly::viscous_stiffness(mesh, geo, dofs, eta, xi)
    }

    fn mass(&self, mesh: &Mesh<D>, geo: &Geometry<D>) -> Csr {
        assembly::mass(mesh, geo)
    }

    fn laplacian(&self, mesh: &Mesh<D>, geo: &Geometry<D>, _mass: &Csr) -> Csr {
        assembly::laplacian(mesh, geo)
    }

    fn velocity(
        &self,
        k: Arc<Csr>,
        _mesh: &Mesh<D>,
        dofs: &DofMap<D>,
        law: FrictionLaw,
    ) -> Result<VelocityStep, SolveError> {
        let n_i = dofs.n_interior;
        let lower = k.block(0..n_i, 0..n_i).lower_csc();
        let factor =
            Cholesky::from_plan(self.plans.k_ii.clone(), lower.as_ref()).map_err(|source| {
                SolveError::Factor {
                    what: "velocity",
                    source,
                }
            })?;
        drop(lower);
        Ok(VelocityStep::with_solver(
            k,
            dofs,
            law,
            SchurPath::default(),
            LinearSolver::Direct(factor),
        ))
    }

    fn damage(&self, _mesh: &Mesh<D>, h: Csr) -> Result<DamageStep, SolveError> {
        let plan = match &self.plans.h {
            Some(plan) => plan.clone(),
            None => damage_plan(&h)?,
        };
        damage_step(h, plan)
    }

    fn trace_eigenvalues(
        &self,
        _mesh: &Mesh<D>,
        dofs: &DofMap<D>,
        gram: Csr,
        velocity: &mut VelocityStep,
    ) -> Result<(f64, f64), SolveError> {
        let w_inv_sqrt: Vec<f64> = velocity.weights().iter().map(|w| 1.0 / w.sqrt()).collect();
        let n_i = dofs.n_interior;
        let g_ii =
            Cholesky::new(gram.block(0..n_i, 0..n_i).lower_csc().as_ref()).map_err(|source| {
                SolveError::Factor {
                    what: "strain Gram",
                    source,
                }
            })?;
        let s_g = schur_complement(&gram, n_i, &g_ii, SchurPath::TrailingBlock).0;
        let lambda_g = min_eig_scaled(&s_g, &w_inv_sqrt);
        let lambda_a = min_eig_scaled(velocity.schur()?, &w_inv_sqrt);
        Ok((lambda_g, lambda_a))
    }
}

/// The damage step on H's factor made from the analysis `plan` of H's pattern.
pub fn damage_step(h: Csr, plan: CholeskyPlan) -> Result<DamageStep, SolveError> {
    let lower = h.lower_csc();
    let (sym, vals) = lower.as_ref().parts();
    let mut entries = Vec::with_capacity(vals.len());
    for c in 0..sym.ncols() {
        for &r in sym.row_idx_of_col_raw(c) {
            entries.push((r, c));
        }
    }
    let lower_values = vals.to_vec();
    let chol = Cholesky::from_plan(plan, lower.as_ref()).map_err(|source| SolveError::Factor {
        what: "damage",
        source,
    })?;
    let masked = Masked {
        lower,
        entries,
        lower_values,
        chol,
        factorizations: 1,
    };
    Ok(DamageStep::new(Arc::new(h), Box::new(masked)))
}

/// H's factor on a fixed pattern, refactored with the active rows and columns replaced by
/// the identity (faer has no rank update; the symbolic analysis is kept).
struct Masked {
    /// Lower triangle of H in faer's CSC form; its values are refilled with the masked H.
    lower: SparseColMat<usize, f64>,
    /// (row, col) of each stored entry of `lower`.
    entries: Vec<(usize, usize)>,
    lower_values: Vec<f64>,
    chol: Cholesky,
    factorizations: usize,
}

impl MaskedSolver for Masked {
    fn set_active(&mut self, _h: &Csr, active: &[Bound]) -> Result<(), FactorError> {
        {
            let vals = self.lower.val_mut();
            for (k, &(r, c)) in self.entries.iter().enumerate() {
                vals[k] = if active[r] != Bound::Free || active[c] != Bound::Free {
                    if r == c {
                        1.0
                    } else {
                        0.0
                    }
                } else {
                    self.lower_values[k]
                };
            }
        }
        self.chol.refactor(self.lower.as_ref())?;
        self.factorizations += 1;
        Ok(())
    }

    fn solve(
        &mut self,
        _h: &Csr,
        _active: &[Bound],
        rhs: &[f64],
        zeta: &mut [f64],
        _atol: f64,
    ) -> Result<usize, NotConverged> {
        zeta.copy_from_slice(rhs);
        self.chol.solve_in_place(zeta);
        Ok(0)
    }

    fn hysteresis(&self, _tolerance: f64) -> f64 {
        1e-13
    }

    fn factorizations(&self) -> usize {
        self.factorizations
    }
}
