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
use super::{Csr, Sparse};
use std::sync::Arc;

/// Most conjugate-gradient iterations of one solve.
pub const MAX_KRYLOV_ITERATIONS: usize = 1000;

/// Conjugate gradients with a multigrid V-cycle on a shared hierarchy.
#[derive(Clone)]
pub struct Krylov {
    a: Sparse,
    vcycle: VCycle,
    work: PcgWork,
}

/// CG on the leading block of an operator with the truncated V-cycle of its hierarchy.
#[derive(Clone)]
pub struct LeadingBlock {
    hierarchy: Arc<Hierarchy>,
    a: Sparse,
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
        Ok(Self::with_hierarchy(hierarchy, a.into()))
    }

    /// Multigrid-preconditioned CG for the operator `a` of `hierarchy` (shared; in any
    /// storage, whether or not the hierarchy kept its own).
    pub fn with_hierarchy(hierarchy: Arc<Hierarchy>, a: Sparse) -> LinearSolver {
        let n = a.nrows();
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
        a: Sparse,
        lead: usize,
    ) -> Result<LinearSolver, FactorError> {
        let n = a.nrows();
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
            LinearSolver::Multigrid(k) => k.a.nrows(),
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
                let rep = pcg::solve(&*a, vcycle, b, x, atol, MAX_KRYLOV_ITERATIONS, work);
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

    /// Nonzeros of the direct factor's L (0 on the iterative paths).
    pub fn factor_nnz(&self) -> usize {
        self.factor().map_or(0, |c| c.nnz_l())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::{assembly, multilevel, Geometry};
    use crate::mesh::Mesh;
    use crate::problem::MeshPattern;

    fn max_abs(v: &[f64]) -> f64 {
        v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
    }

    /// ‖b − A x‖∞.
    fn residual(a: &Csr, b: &[f64], x: &[f64]) -> f64 {
        let mut ax = vec![0.0; b.len()];
        a.mul_vec(x, &mut ax);
        ax.iter()
            .zip(b)
            .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()))
    }

    /// The three solvers of one SPD operator (H = 64 M + L on a halved grid) solve to what
    /// they promise: the factor to round-off, CG to the residual asked for with that
    /// residual reported as b − A x of the answer; CG on a leading block with the other DOFs
    /// held at zero solves the block itself.
    #[test]
    fn every_solver_meets_its_residual() {
        let mesh = Mesh::rectangle(1.0, 1.0, 32, 32, MeshPattern::Diagonal);
        let geo = Geometry::new(&mesh);
        let m = assembly::mass_in_pattern(&mesh, &geo);
        let l = assembly::laplacian_in_pattern_of(&mesh, &geo, &m);
        let a = Arc::new(assembly::combine(64.0, &m, 1.0, &l));
        let n = a.nrows;
        let b: Vec<f64> = (0..n).map(|i| (0.91 * i as f64).sin()).collect();
        let mut direct = LinearSolver::direct(&a).unwrap();
        let mut x_direct = vec![0.0; n];
        assert_eq!(direct.solve(&b, &mut x_direct, 0.0), Ok(0));
        assert!(residual(&a, &b, &x_direct) <= 1e-12 * max_abs(&b));
        assert!(direct.last_residual().is_none() && !direct.is_iterative());

        let (blocks, levels) = multilevel::scalar_levels(&mesh, n);
        let hierarchy =
            Arc::new(Hierarchy::new(a.clone(), blocks, levels, Params::default()).unwrap());
        let mut cg = LinearSolver::with_hierarchy(hierarchy.clone(), a.clone().into());
        let atol = 1e-8 * max_abs(&b);
        let mut x = vec![0.0; n];
        assert!(cg.solve(&b, &mut x, atol).unwrap() > 0);
        let r = residual(&a, &b, &x);
        assert!(r <= atol, "{r} > {atol}");
        let reported = max_abs(cg.last_residual().unwrap());
        assert!(
            (reported - r).abs() <= 1e-3 * r.max(1e-300),
            "{reported} vs {r}"
        );

        // The leading block: all nodes but the top row (the last 33), as Γ3 is held at zero
        // for K_II.
        let lead = n - 33;
        let block = a.block(0..lead, 0..lead);
        let mut leading = LinearSolver::leading_block(hierarchy, a.clone().into(), lead).unwrap();
        let mut y = vec![0.0; lead];
        leading.solve(&b[..lead], &mut y, atol).unwrap();
        assert_eq!(leading.n(), lead);
        assert!(residual(&block, &b[..lead], &y) <= atol);
        let mut y_direct = vec![0.0; lead];
        LinearSolver::direct(&block)
            .unwrap()
            .solve(&b[..lead], &mut y_direct, 0.0)
            .unwrap();
        let scale = max_abs(&y_direct);
        assert!(y
            .iter()
            .zip(&y_direct)
            .all(|(p, q)| (p - q).abs() <= 1e-6 * scale));
    }
}
