//! The direct family: sparse Cholesky factors, computed once per run.
//! - K_II: factored once on the ordering of least fill ([`plan`]); S = K_CC − K_CI K_II⁻¹ K_IC
//!   formed on a slipping step's first need, for the dense reduced problem on Γ3: the slip
//!   solver [`DenseReduced`], which keeps S for the run.
//! - H: factored on a fixed pattern, refactored with the active rows and columns replaced
//!   by the identity when the damage step's active set changes ([`Masked`]).
//! - The smallness estimate: both Schur complements formed (S_A the slip solver's), their
//!   λ_min dense.
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
use crate::solve::velocity::{ContactSolver, SlipSolver, StepState, VelocityStep};
use crate::solve::{friction_isotropic, friction_reduced, SolveError, SolverSettings};
use faer::sparse::{SparseColMat, SparseColMatRef};
use nalgebra::DMatrix;
use std::any::Any;
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
            k.into(),
            dofs,
            law,
            LinearSolver::Direct(factor),
            Box::new(DenseReduced::default()),
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
        // S_A is the slip solver's: formed here once, reused by the slipping steps.
        let (state, slip) = velocity.parts_mut();
        let dense = slip
            .as_any_mut()
            .downcast_mut::<DenseReduced>()
            .expect("the direct family's slip solver");
        let lambda_a = min_eig_scaled(dense.schur(state), &w_inv_sqrt);
        Ok((lambda_g, lambda_a))
    }
}

/// The dense reduced problem on Γ3: S = K_CC − K_CI K_II⁻¹ K_IC formed on first need as
/// the trailing block of a factor of K with the contact DOFs last
/// ([`crate::linalg::schur`]; blocked solves with the factor of K_II should the analysis not
/// keep them last), the reduced problem solved ([`friction_reduced`] in 2D,
/// [`friction_isotropic`] in 3D) from the last step's x, and w_I recovered by one more
/// solve. S is kept for the run (and the smallness estimate's λ_min,
/// [`Backend::trace_eigenvalues`]).
#[derive(Clone, Default)]
pub struct DenseReduced {
    /// How S is formed; after forming it, the path taken.
    path: SchurPath,
    s: Option<DMatrix<f64>>,
}

impl DenseReduced {
    /// S of the velocity step of `state` (its solver of K_II a factor), formed on first use.
    pub fn schur(&mut self, state: &StepState) -> &DMatrix<f64> {
        if self.s.is_none() {
            let factor = state
                .k_ii
                .factor()
                .expect("the direct family's factor of K_II");
            let (s, path) = schur_complement(
                state
                    .k
                    .scalar()
                    .expect("the direct path keeps K in scalar CSR"),
                state.n_i,
                factor,
                self.path,
            );
            self.path = path;
            self.s = Some(s);
        }
        self.s.as_ref().unwrap()
    }
}

impl SlipSolver for DenseReduced {
    fn report(&self) -> ContactSolver {
        ContactSolver::DenseSchur(self.path)
    }

    fn solve(
        &mut self,
        state: &mut StepState,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<usize, SolveError> {
        let n_i = state.n_i;
        // Same force scale as the step's full residual, and half its tolerance: the
        // recovery of the interior adds rounding only.
        let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
        let inner = SolverSettings {
            tolerance: 0.5 * settings.tolerance,
            ..*settings
        };
        let s = self.schur(state);
        let mut x = std::mem::take(&mut state.x);
        let rep = match state.block {
            1 => friction_reduced::solve(
                &friction_reduced::Reduced {
                    s,
                    b: &state.b,
                    weights: &state.weights,
                    law: &state.law,
                    scale: Some(scale),
                },
                &mut x,
                &inner,
                step,
            ),
            _ => friction_isotropic::solve(
                &friction_isotropic::Reduced {
                    s,
                    b: &state.b,
                    weights: &state.node_weights,
                    law: &state.law,
                    scale: Some(scale),
                },
                &mut x,
                &inner,
                step,
            ),
        };
        state.x = x;
        let iterations = rep?.iterations;
        // w_I = K_II⁻¹ (f_I − K_IC x).
        let mut rhs = f[..n_i].to_vec();
        let mut kic_x = vec![0.0; n_i];
        state.k_ci.tmul_vec_add(&state.x, &mut kic_x);
        rhs.iter_mut().zip(&kic_x).for_each(|(a, v)| *a -= v);
        let wi = &mut w[..n_i];
        wi.copy_from_slice(&state.y);
        state.solve_interior(&rhs, wi, scale, settings, step)?;
        Ok(iterations)
    }

    fn boxed_clone(&self) -> Box<dyn SlipSolver> {
        Box::new(self.clone())
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
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
