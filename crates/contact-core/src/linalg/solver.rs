//! The linear-solver layer: one interface over the two ways the scheme solves its SPD
//! systems (K_II y = f_I of the velocity step, the masked H of the damage QP):
//! - [`LinearSolver::Direct`]: the cached sparse Cholesky factor ([`super::Cholesky`]);
//! - [`LinearSolver::Multigrid`]: conjugate gradients ([`super::pcg`]) preconditioned by a
//!   multigrid V-cycle ([`super::multigrid`]), warm-started from the caller's guess and
//!   stopped on the max-norm residual the caller asks for.
//!
//! Both solve A x = b to the requested residual; the direct one reaches round-off in one
//! substitution pair, the iterative one in O(N) work per iteration with a memory of a small
//! multiple of A.

use super::cholesky::{Cholesky, FactorError};
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
    /// The V-cycle (for a caller that runs CG on a related operator itself).
    pub fn into_vcycle(self) -> VCycle {
        self.vcycle
    }
}

/// A solver of A x = b for one SPD matrix A, fixed for a run.
#[derive(Clone)]
pub enum LinearSolver {
    Direct(Cholesky),
    Multigrid(Box<Krylov>),
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
        let n = a.nrows;
        Ok(LinearSolver::Multigrid(Box::new(Krylov {
            vcycle: hierarchy.vcycle(),
            a,
            work: PcgWork::new(n),
        })))
    }

    pub fn n(&self) -> usize {
        match self {
            LinearSolver::Direct(c) => c.n(),
            LinearSolver::Multigrid(k) => k.a.nrows,
        }
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
                if rep.converged {
                    Ok(rep.iterations)
                } else {
                    Err(NotConverged {
                        iterations: rep.iterations,
                        residual: rep.residual,
                    })
                }
            }
        }
    }

    /// The direct factor, when this is the direct path.
    pub fn factor(&self) -> Option<&Cholesky> {
        match self {
            LinearSolver::Direct(c) => Some(c),
            LinearSolver::Multigrid(_) => None,
        }
    }

    /// What the summary says: "direct (Cholesky)", "multigrid (geometric, 5 levels)", ….
    pub fn describe(&self) -> String {
        match self {
            LinearSolver::Direct(_) => "direct (Cholesky)".to_string(),
            LinearSolver::Multigrid(k) => k.vcycle.hierarchy().describe(),
        }
    }
}
