//! Sparse Cholesky LLᵀ with faer's low-level API, in two steps as faer makes it:
//! - [`CholeskyPlan`], the symbolic analysis of a pattern (AMD ordering, or the lesser fill
//!   of AMD and nested dissection, [`super::nested_dissection`]; supernodal structure): it
//!   knows the factor's entries nnz(L) and the bytes the numeric factor will hold before any
//!   numeric work, which is what the direct path's memory prediction needs
//!   ([`crate::memory`]);
//! - [`Cholesky`], the numeric factor of values on that pattern ([`Cholesky::from_plan`]),
//!   in our own buffer, recomputed for new values on the same pattern; solves reuse one
//!   scratch buffer.
//!
//! faer's automatic simplicial/supernodal switch picks the slower variant for P1 meshes of
//! these sizes (measured here: 2–5× slower), so the supernodal path is forced. Parallelism is `Seq`:
//! jobs and the two sub-problems of a step are parallel instead.

use super::nested_dissection;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::SparseColMatRef;
use faer::{Conj, MatMut, Par, Side};
use std::sync::Arc;

#[derive(Debug, thiserror::Error)]
pub enum FactorError {
    #[error("symbolic Cholesky analysis failed: {0:?}")]
    Symbolic(faer::sparse::FaerError),
    #[error("matrix is not numerically positive definite (Cholesky broke down)")]
    NotPositiveDefinite,
}

/// A factorised SPD matrix A = P Lᵀ L Pᵀ (faer's convention), n × n.
///
/// Clones share the symbolic analysis and the factor values (runs of one study on one mesh
/// factor their velocity operator once); each clone has its own scratch, and `refactor` on
/// a shared factor copies the values first (copy on write).
pub struct Cholesky {
    symbolic: Arc<SymbolicCholesky<usize>>,
    l_values: Arc<Vec<f64>>,
    factor_scratch: MemBuffer,
    /// Scratch for single right-hand-side solves.
    solve_scratch: MemBuffer,
    ordering: Ordering,
}

/// The symbolic analysis of an SPD pattern: ordering P and the supernodal structure of L in
/// P A Pᵀ = L Lᵀ, no values. Clones share the analysis.
#[derive(Clone)]
pub struct CholeskyPlan {
    symbolic: Arc<SymbolicCholesky<usize>>,
    ordering: Ordering,
}

/// How the rows of a factor were ordered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ordering {
    /// Approximate minimum degree (faer's).
    Amd,
    /// [`super::nested_dissection`].
    NestedDissection,
    /// An ordering the caller gave.
    Given,
}

/// The supernodal symbolic analysis of `a_lower` with the ordering `forward`, else AMD.
fn analyse(
    a_lower: SparseColMatRef<'_, usize, f64>,
    forward: Option<&[usize]>,
) -> Result<SymbolicCholesky<usize>, FactorError> {
    let params = CholeskySymbolicParams {
        supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
        ..Default::default()
    };
    let inverse = forward.map(|f| {
        let mut inv = vec![0; f.len()];
        for (i, &p) in f.iter().enumerate() {
            inv[p] = i;
        }
        inv
    });
    let ordering = match (forward, &inverse) {
        (Some(f), Some(inv)) => SymmetricOrdering::Custom(PermRef::new_checked(f, inv, f.len())),
        _ => SymmetricOrdering::Amd,
    };
    factorize_symbolic_cholesky(a_lower.symbolic(), Side::Lower, ordering, params)
        .map_err(FactorError::Symbolic)
}

impl Clone for Cholesky {
    fn clone(&self) -> Self {
        Cholesky {
            symbolic: self.symbolic.clone(),
            l_values: self.l_values.clone(),
            factor_scratch: factor_scratch(&self.symbolic),
            solve_scratch: MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(1, Par::Seq)),
            ordering: self.ordering,
        }
    }
}

fn factor_scratch(symbolic: &SymbolicCholesky<usize>) -> MemBuffer {
    MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()))
}

impl std::fmt::Debug for Cholesky {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Cholesky")
            .field("n", &self.n())
            .field("nnz_l", &self.l_values.len())
            .finish()
    }
}

impl CholeskyPlan {
    /// The analysis of the lower triangle `a_lower`'s pattern with AMD ordering.
    pub fn amd(a_lower: SparseColMatRef<'_, usize, f64>) -> Result<Self, FactorError> {
        Self::with_ordering(a_lower, None)
    }

    /// The analysis with the ordering of smaller fill of AMD and nested dissection (both
    /// analyses are made, a small cost next to the numeric factorisation; AMD on a tie).
    pub fn least_fill(a_lower: SparseColMatRef<'_, usize, f64>) -> Result<Self, FactorError> {
        let amd = analyse(a_lower, None)?;
        let nd_order = nested_dissection::order(a_lower.symbolic());
        let nd = analyse(a_lower, Some(&nd_order))?;
        let (symbolic, ordering) = if nd.len_val() < amd.len_val() {
            (nd, Ordering::NestedDissection)
        } else {
            (amd, Ordering::Amd)
        };
        Ok(Self::new(symbolic, ordering))
    }

    /// The analysis with the given ordering method (for comparisons).
    pub fn by(
        a_lower: SparseColMatRef<'_, usize, f64>,
        ordering: Ordering,
    ) -> Result<Self, FactorError> {
        match ordering {
            Ordering::Amd | Ordering::Given => Self::amd(a_lower),
            Ordering::NestedDissection => {
                let order = nested_dissection::order(a_lower.symbolic());
                Ok(Self::new(analyse(a_lower, Some(&order))?, ordering))
            }
        }
    }

    /// The analysis with the symmetric ordering `forward` (row i of the factored P A Pᵀ is
    /// row `forward[i]` of A) instead of AMD; it may still reorder within it (postordering),
    /// which [`Cholesky::forward`] reports.
    pub fn with_ordering(
        a_lower: SparseColMatRef<'_, usize, f64>,
        forward: Option<&[usize]>,
    ) -> Result<Self, FactorError> {
        let ordering = match forward {
            Some(_) => Ordering::Given,
            None => Ordering::Amd,
        };
        Ok(Self::new(analyse(a_lower, forward)?, ordering))
    }

    fn new(symbolic: SymbolicCholesky<usize>, ordering: Ordering) -> Self {
        CholeskyPlan {
            symbolic: Arc::new(symbolic),
            ordering,
        }
    }

    /// The ordering method of the analysis.
    pub fn ordering(&self) -> Ordering {
        self.ordering
    }

    pub fn n(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Number of stored entries of the factor L (supernodal: the dense blocks' entries,
    /// explicit zeros included).
    pub fn nnz_l(&self) -> usize {
        self.symbolic.len_val()
    }

    /// Bytes a [`Cholesky`] made from this plan holds: L's values (8 nnz(L)), faer's scratch
    /// of the numeric factorisation and of a one-column solve, and the analysis's own index
    /// arrays: the supernodes' row indices, as much again as a bound of faer's row-major
    /// supernode structure, the supernode pointers and the permutation.
    pub fn factor_bytes(&self) -> u64 {
        let s = &self.symbolic;
        let scratch = s
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .size_bytes()
            + s.solve_in_place_scratch::<f64>(1, Par::Seq).size_bytes();
        let word = std::mem::size_of::<usize>();
        let structure = match s.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) => {
                word * (2 * sn.row_idx().len() + 4 * (sn.n_supernodes() + 1))
            }
            SymbolicCholeskyRaw::Simplicial(sm) => word * (sm.row_idx().len() + s.nrows() + 1),
        };
        let permutation = if s.perm().is_some() {
            2 * word * s.nrows()
        } else {
            0
        };
        (8 * self.nnz_l() + scratch + structure + permutation) as u64
    }
}

impl Cholesky {
    /// Symbolic analysis (AMD) and first numeric factorisation of the lower triangle
    /// `a_lower`.
    pub fn new(a_lower: SparseColMatRef<'_, usize, f64>) -> Result<Self, FactorError> {
        Self::from_plan(CholeskyPlan::amd(a_lower)?, a_lower)
    }

    /// [`Cholesky::new`] with [`CholeskyPlan::least_fill`].
    pub fn least_fill(a_lower: SparseColMatRef<'_, usize, f64>) -> Result<Self, FactorError> {
        Self::from_plan(CholeskyPlan::least_fill(a_lower)?, a_lower)
    }

    /// [`Cholesky::new`] with [`CholeskyPlan::by`] (for comparisons).
    pub fn by(
        a_lower: SparseColMatRef<'_, usize, f64>,
        ordering: Ordering,
    ) -> Result<Self, FactorError> {
        Self::from_plan(CholeskyPlan::by(a_lower, ordering)?, a_lower)
    }

    /// [`Cholesky::new`] with [`CholeskyPlan::with_ordering`].
    pub fn with_ordering(
        a_lower: SparseColMatRef<'_, usize, f64>,
        forward: Option<&[usize]>,
    ) -> Result<Self, FactorError> {
        Self::from_plan(CholeskyPlan::with_ordering(a_lower, forward)?, a_lower)
    }

    /// The numeric factorisation of `a_lower`, whose pattern is the one `plan` analysed.
    pub fn from_plan(
        plan: CholeskyPlan,
        a_lower: SparseColMatRef<'_, usize, f64>,
    ) -> Result<Self, FactorError> {
        let CholeskyPlan { symbolic, ordering } = plan;
        assert_eq!(
            a_lower.nrows(),
            symbolic.nrows(),
            "a pattern of another size"
        );
        let solve_scratch = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        let mut this = Cholesky {
            l_values: Arc::new(vec![0.0; symbolic.len_val()]),
            factor_scratch: factor_scratch(&symbolic),
            symbolic,
            solve_scratch,
            ordering,
        };
        this.refactor(a_lower)?;
        Ok(this)
    }

    /// The ordering method of the factor.
    pub fn ordering(&self) -> Ordering {
        self.ordering
    }

    pub fn n(&self) -> usize {
        self.symbolic.nrows()
    }

    /// The ordering of the factor: row i of P A Pᵀ = L Lᵀ is row `forward()[i]` of A.
    pub fn forward(&self) -> Vec<usize> {
        match self.symbolic.perm() {
            Some(p) => p.arrays().0.to_vec(),
            None => (0..self.n()).collect(),
        }
    }

    /// The supernodal factor L of P A Pᵀ (always supernodal, see the module doc).
    pub(crate) fn supernodal(&self) -> SupernodalLltRef<'_, usize, f64> {
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => SupernodalLltRef::new(s, &self.l_values),
            SymbolicCholeskyRaw::Simplicial(_) => unreachable!("supernodal forced"),
        }
    }

    /// Number of stored entries of the factor L.
    pub fn nnz_l(&self) -> usize {
        self.l_values.len()
    }

    /// Numeric factorisation of new values on the pattern given to [`Cholesky::new`].
    pub fn refactor(
        &mut self,
        a_lower: SparseColMatRef<'_, usize, f64>,
    ) -> Result<(), FactorError> {
        self.symbolic
            .factorize_numeric_llt::<f64>(
                Arc::make_mut(&mut self.l_values).as_mut_slice(),
                a_lower,
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut self.factor_scratch),
                Default::default(),
            )
            .map_err(|_| FactorError::NotPositiveDefinite)?;
        Ok(())
    }

    /// x ← A⁻¹ x (one forward and one backward substitution).
    pub fn solve_in_place(&mut self, x: &mut [f64]) {
        let n = self.n();
        assert_eq!(x.len(), n);
        let rhs = MatMut::from_column_major_slice_mut(x, n, 1);
        LltRef::new(&self.symbolic, &self.l_values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut self.solve_scratch),
        );
    }

    /// X ← A⁻¹ X for a block of right-hand sides (column-major, n × ncols); the supernodal
    /// kernels work on the whole block at once, which is what makes a Schur complement cheap.
    pub fn solve_block_in_place(&self, x: &mut [f64], ncols: usize) {
        let n = self.n();
        assert_eq!(x.len(), n * ncols);
        let mut scratch =
            MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, Par::Seq));
        let rhs = MatMut::from_column_major_slice_mut(x, n, ncols);
        LltRef::new(&self.symbolic, &self.l_values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut scratch),
        );
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::linalg::Csr;

    /// 1D Laplacian with Dirichlet ends: tridiag(-1, 2, -1).
    pub(crate) fn laplace_1d(n: usize) -> Csr {
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 2.0));
            if i + 1 < n {
                t.push((i, i + 1, -1.0));
                t.push((i + 1, i, -1.0));
            }
        }
        Csr::from_triplets(n, n, t)
    }

    #[test]
    fn solves_and_refactors_on_same_pattern() {
        let a = laplace_1d(50);
        let mut chol = Cholesky::new(a.lower_csc().as_ref()).unwrap();
        let xs: Vec<f64> = (0..50).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut b = vec![0.0; 50];
        a.mul_vec(&xs, &mut b);
        chol.solve_in_place(&mut b);
        for (u, v) in b.iter().zip(&xs) {
            assert!((u - v).abs() < 1e-12);
        }
        // Scale the matrix by 3: same pattern, new values.
        let mut a3 = a.clone();
        a3.values.iter_mut().for_each(|v| *v *= 3.0);
        chol.refactor(a3.lower_csc().as_ref()).unwrap();
        let mut b = vec![0.0; 50];
        a3.mul_vec(&xs, &mut b);
        let mut blk = [b.clone(), b].concat();
        chol.solve_block_in_place(&mut blk, 2);
        for i in 0..50 {
            assert!((blk[i] - xs[i]).abs() < 1e-12 && (blk[50 + i] - xs[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn clones_share_the_factor_until_one_refactors() {
        let a = laplace_1d(20);
        let mut first = Cholesky::new(a.lower_csc().as_ref()).unwrap();
        let mut second = first.clone();
        assert!(Arc::ptr_eq(&first.l_values, &second.l_values));
        let mut a2 = a.clone();
        a2.values.iter_mut().for_each(|v| *v *= 2.0);
        second.refactor(a2.lower_csc().as_ref()).unwrap();
        assert!(!Arc::ptr_eq(&first.l_values, &second.l_values));
        let (mut x1, mut x2) = (vec![1.0; 20], vec![1.0; 20]);
        first.solve_in_place(&mut x1);
        second.solve_in_place(&mut x2);
        for (u, v) in x1.iter().zip(&x2) {
            assert!(
                (u - 2.0 * v).abs() < 1e-12,
                "the original factor is untouched"
            );
        }
    }

    #[test]
    fn indefinite_matrix_is_an_error() {
        let mut a = laplace_1d(5);
        a.values.iter_mut().for_each(|v| *v = -*v);
        assert!(Cholesky::new(a.lower_csc().as_ref()).is_err());
    }
}
