//! The linear-solver layer: one interface over the two ways the scheme solves its SPD
//! systems (K_II y = f_I of the velocity step, the masked H of the damage QP):
//! - [`LinearSolver::Direct`]: the cached sparse Cholesky factor ([`super::Cholesky`]);
//! - [`LinearSolver::Multigrid`]: conjugate gradients ([`super::pcg`]) preconditioned by a
//!   multigrid V-cycle ([`super::multigrid`]), warm-started from the caller's guess and
//!   stopped on the max-norm residual the caller asks for;
//! - [`LinearSolver::LeadingBlock`]: the same for the leading block A_II of an operator A
//!   whose hierarchy is built on all its DOFs, with the trailing DOFs held at zero by the
//!   truncated V-cycle ([`super::multigrid::truncated`]); A_II is never copied (the velocity
//!   step's K_II when K's hierarchy also serves the slipping steps).
//!
//! Both solve A x = b to the requested residual; the direct one reaches round-off in one
//! substitution pair, the iterative one in O(N) work per iteration with a memory of a small
//! multiple of A.

use super::cholesky::{Cholesky, FactorError};
use super::multigrid::truncated::{Jacobian, Truncated};
use super::multigrid::{Blocks, Coarsening, Hierarchy, Params, VCycle};
use super::pcg::{self, PcgWork};
use super::Csr;
use std::sync::Arc;

/// Most conjugate-gradient iterations of one solve.
pub const MAX_KRYLOV_ITERATIONS: usize = 1000;

/// Conjugate gradients with a multigrid V-cycle on a shared hierarchy.
#[derive(Clone)]
pub struct Krylov {
    a: Arc<Csr>,
    vcycle: VCycle,
    work: PcgWork,
}

impl Krylov {
    /// The operator and its V-cycle (for a caller that runs CG on a related operator
    /// itself, sharing the operator's storage).
    pub fn into_parts(self) -> (Arc<Csr>, VCycle) {
        (self.a, self.vcycle)
    }
}

/// CG on the leading block of an operator with the truncated V-cycle of its hierarchy.
#[derive(Clone)]
pub struct LeadingBlock {
    hierarchy: Arc<Hierarchy>,
    a: Arc<Csr>,
    lead: usize,
    /// The trailing DOFs, as a list and a flag per DOF.
    fixed: Vec<usize>,
    is_fixed: Vec<bool>,
    truncated: Truncated,
    work: PcgWork,
    /// b and x padded with the trailing zeros.
    b: Vec<f64>,
    x: Vec<f64>,
}

/// A solver of A x = b for one SPD matrix A, fixed for a run.
#[derive(Clone)]
pub enum LinearSolver {
    Direct(Cholesky),
    Multigrid(Box<Krylov>),
    LeadingBlock(Box<LeadingBlock>),
}

/// The iterations, or the failure, of a CG solve.
fn outcome(rep: pcg::PcgReport) -> Result<usize, NotConverged> {
    if rep.converged {
        Ok(rep.iterations)
    } else {
        Err(NotConverged {
            iterations: rep.iterations,
            residual: rep.residual,
        })
    }
}

/// A solve that did not reach its residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotConverged {
    pub iterations: usize,
    pub residual: f64,
}

impl LinearSolver {
    /// The direct factor of A.
    pub fn direct(a: &Csr) -> Result<LinearSolver, FactorError> {
        Ok(LinearSolver::Direct(Cholesky::new(a.lower_csc().as_ref())?))
    }

    /// Multigrid-preconditioned CG for A with node `blocks` and the given coarsening.
    pub fn multigrid(
        a: Arc<Csr>,
        blocks: Blocks,
        coarsening: Coarsening,
    ) -> Result<LinearSolver, FactorError> {
        let hierarchy = Arc::new(Hierarchy::new(
            a.clone(),
            blocks,
            coarsening,
            Params::default(),
        )?);
        Ok(Self::with_hierarchy(hierarchy, a))
    }

    /// Multigrid-preconditioned CG for the operator `a` of `hierarchy` (shared).
    pub fn with_hierarchy(hierarchy: Arc<Hierarchy>, a: Arc<Csr>) -> LinearSolver {
        let n = a.nrows;
        LinearSolver::Multigrid(Box::new(Krylov {
            vcycle: hierarchy.vcycle(),
            a,
            work: PcgWork::new(n),
        }))
    }

    /// Multigrid-preconditioned CG for the leading `lead` × `lead` block of the operator of
    /// `hierarchy` (the other DOFs held at zero).
    pub fn leading_block(
        hierarchy: Arc<Hierarchy>,
        a: Arc<Csr>,
        lead: usize,
    ) -> Result<LinearSolver, FactorError> {
        let n = a.nrows;
        let fixed: Vec<usize> = (lead..n).collect();
        let is_fixed = (0..n).map(|i| i >= lead).collect();
        let truncated = Truncated::with_operator(&hierarchy, a.clone(), fixed.clone(), &[])?;
        Ok(LinearSolver::LeadingBlock(Box::new(LeadingBlock {
            hierarchy,
            a,
            lead,
            fixed,
            is_fixed,
            truncated,
            work: PcgWork::new(n),
            b: vec![0.0; n],
            x: vec![0.0; n],
        })))
    }

    pub fn n(&self) -> usize {
        match self {
            LinearSolver::Direct(c) => c.n(),
            LinearSolver::Multigrid(k) => k.a.nrows,
            LinearSolver::LeadingBlock(l) => l.lead,
        }
    }

    /// True on the iterative paths.
    pub fn is_iterative(&self) -> bool {
        !matches!(self, LinearSolver::Direct(_))
    }

    /// x ← A⁻¹ b with ‖b − A x‖∞ ≤ `atol` (the direct path: one substitution pair, whatever
    /// `atol`; the iterative one starts from x as given). Returns the Krylov iterations (0
    /// for the direct path).
    pub fn solve(&mut self, b: &[f64], x: &mut [f64], atol: f64) -> Result<usize, NotConverged> {
        match self {
            LinearSolver::Direct(c) => {
                x.copy_from_slice(b);
                c.solve_in_place(x);
                Ok(0)
            }
            LinearSolver::Multigrid(k) => {
                let Krylov { a, vcycle, work } = &mut **k;
                let rep = pcg::solve(&**a, vcycle, b, x, atol, MAX_KRYLOV_ITERATIONS, work);
                outcome(rep)
            }
            LinearSolver::LeadingBlock(l) => {
                let LeadingBlock {
                    a,
                    lead,
                    fixed,
                    is_fixed,
                    truncated,
                    work,
                    b: bp,
                    x: xp,
                    ..
                } = &mut **l;
                bp[..*lead].copy_from_slice(b);
                xp[..*lead].copy_from_slice(x);
                xp[*lead..].iter_mut().for_each(|v| *v = 0.0);
                let jacobian = Jacobian {
                    a,
                    fixed,
                    is_fixed,
                    blocks: &[],
                };
                let rep = pcg::solve(
                    &jacobian,
                    truncated,
                    bp,
                    xp,
                    atol,
                    MAX_KRYLOV_ITERATIONS,
                    work,
                );
                x.copy_from_slice(&xp[..*lead]);
                outcome(rep)
            }
        }
    }

    /// b − A x of the last solve on the iterative paths (the true residual its stopping test
    /// was passed on); None on the direct path, which does not form it.
    pub fn last_residual(&self) -> Option<&[f64]> {
        match self {
            LinearSolver::Direct(_) => None,
            LinearSolver::Multigrid(k) => Some(k.work.residual()),
            LinearSolver::LeadingBlock(l) => Some(&l.work.residual()[..l.lead]),
        }
    }

    /// The direct factor, when this is the direct path.
    pub fn factor(&self) -> Option<&Cholesky> {
        match self {
            LinearSolver::Direct(c) => Some(c),
            _ => None,
        }
    }

    /// The multigrid hierarchy (iterative paths).
    pub fn hierarchy(&self) -> Option<&Arc<Hierarchy>> {
        match self {
            LinearSolver::Direct(_) => None,
            LinearSolver::Multigrid(k) => Some(k.vcycle.hierarchy()),
            LinearSolver::LeadingBlock(l) => Some(&l.hierarchy),
        }
    }

    /// What the summary says: "direct (Cholesky)", "multigrid (geometric, 5 levels)", ….
    pub fn describe(&self) -> String {
        match self {
            LinearSolver::Direct(_) => "direct (Cholesky)".to_string(),
            LinearSolver::Multigrid(k) => k.vcycle.hierarchy().describe(),
            LinearSolver::LeadingBlock(l) => l.hierarchy.describe(),
        }
    }
}
