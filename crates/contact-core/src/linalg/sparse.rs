//! A symmetric sparse operator in the storage its path reads: scalar CSR ([`Csr`]: the direct
//! path, which factors it, and the other operators), or f64 node blocks ([`BlockCsr`]: K on
//! the multigrid path, where after set-up it is only multiplied and read row by row on Γ3).
//! Shared, not copied: a clone is another handle on the same storage.
//!
//! What the velocity step reads of K after set-up is all here: products (residuals, CG,
//! the projection's K-images), rows of few DOFs (the Γ3 rows of the semismooth Newton
//! method and of the truncated cycle's Galerkin update) and single entries (node blocks).

use super::block_csr::BlockCsr;
use super::{Csr, LinearOperator};
use std::borrow::Cow;
use std::sync::Arc;

/// A square symmetric operator, shared.
#[derive(Debug, Clone)]
pub enum Sparse {
    Scalar(Arc<Csr>),
    Blocks(Arc<BlockCsr<f64>>),
}

impl From<Arc<Csr>> for Sparse {
    fn from(a: Arc<Csr>) -> Sparse {
        Sparse::Scalar(a)
    }
}

impl From<Csr> for Sparse {
    fn from(a: Csr) -> Sparse {
        Sparse::Scalar(Arc::new(a))
    }
}

impl Sparse {
    /// `a` in the node blocks of consecutive DOFs ptr[b]..ptr[b + 1] (see [`BlockCsr::new`]).
    pub fn in_blocks(a: &Csr, ptr: &[usize]) -> Sparse {
        Sparse::Blocks(Arc::new(BlockCsr::new(a, ptr)))
    }

    pub fn nrows(&self) -> usize {
        match self {
            Sparse::Scalar(a) => a.nrows,
            Sparse::Blocks(a) => a.dim(),
        }
    }

    /// y ← A x.
    pub fn mul_vec(&self, x: &[f64], y: &mut [f64]) {
        match self {
            Sparse::Scalar(a) => a.mul_vec(x, y),
            Sparse::Blocks(a) => a.mul_vec(x, y),
        }
    }

    /// f(j, a_ij) for the entries of row i, in increasing j (in node blocks, the nonzero
    /// ones).
    pub fn for_each_in_row(&self, i: usize, mut f: impl FnMut(usize, f64)) {
        match self {
            Sparse::Scalar(a) => {
                let row = a.indptr[i]..a.indptr[i + 1];
                for (&j, &v) in a.indices[row.clone()].iter().zip(&a.values[row]) {
                    f(j as usize, v);
                }
            }
            Sparse::Blocks(a) => a.for_each_in_row(i, f),
        }
    }

    /// Entry (i, j), 0 when absent.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        match self {
            Sparse::Scalar(a) => a.get(i, j),
            Sparse::Blocks(a) => a.get(i, j),
        }
    }

    /// y ← y − A[:, F] x_F for the DOFs F in `cols` (from A's rows: A is symmetric).
    pub fn sub_columns(&self, cols: &[usize], x: &[f64], y: &mut [f64]) {
        match self {
            Sparse::Scalar(_) => {
                for &c in cols {
                    if x[c] != 0.0 {
                        self.for_each_in_row(c, |j, v| y[j] -= v * x[c]);
                    }
                }
            }
            Sparse::Blocks(a) => a.sub_columns(cols, x, y),
        }
    }

    /// The rows flagged in `keep` (the others empty), same shape, in scalar CSR.
    pub fn rows_of(&self, keep: &[bool]) -> Csr {
        let n = self.nrows();
        Csr::from_rows(n, n, keep, |i, f| self.for_each_in_row(i, f))
    }

    /// The block rows `rows`, columns `cols` (half-open ranges), in scalar CSR.
    pub fn block(&self, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>) -> Csr {
        match self {
            Sparse::Scalar(a) => a.block(rows, cols),
            Sparse::Blocks(_) => {
                let mut t = Vec::new();
                for i in rows.clone() {
                    self.for_each_in_row(i, |j, v| {
                        if cols.contains(&j) {
                            t.push((i - rows.start, j - cols.start, v));
                        }
                    });
                }
                Csr::from_triplets(rows.len(), cols.len(), t)
            }
        }
    }

    /// The operator in scalar CSR: itself, or a copy of the node blocks' nonzero entries.
    pub fn to_csr(&self) -> Cow<'_, Csr> {
        match self {
            Sparse::Scalar(a) => Cow::Borrowed(a.as_ref()),
            Sparse::Blocks(_) => {
                let n = self.nrows();
                Cow::Owned(self.rows_of(&vec![true; n]))
            }
        }
    }

    /// The scalar CSR storage, when this is it.
    pub fn scalar(&self) -> Option<&Arc<Csr>> {
        match self {
            Sparse::Scalar(a) => Some(a),
            Sparse::Blocks(_) => None,
        }
    }

    /// max_i Σ_j |a_ij w_j|: the size of the terms whose rounding the residual K w − f
    /// carries.
    pub fn max_abs_row_product(&self, w: &[f64]) -> f64 {
        (0..self.nrows()).fold(0.0f64, |m, i| {
            let mut s = 0.0;
            self.for_each_in_row(i, |j, v| s += (v * w[j]).abs());
            m.max(s)
        })
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match self {
            Sparse::Scalar(a) => 12 * a.nnz() + 8 * (a.nrows + 1),
            Sparse::Blocks(a) => a.bytes(),
        }
    }
}

impl LinearOperator for Sparse {
    fn dim(&self) -> usize {
        self.nrows()
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        self.mul_vec(x, y);
    }
}

#[cfg(test)]
mod tests;
