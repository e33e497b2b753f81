//! A level's prolongator P (fine × coarse DOFs) and the restriction Pᵀ of the V-cycle.
//!
//! Geometric levels interpolate (at most two nodes a row): P in scalar CSR with Pᵀ stored.
//! Smoothed aggregation's P is wide (a fine node couples to every aggregate next to its own)
//! and as large as half of A: Pᵀ is applied by pieces, never stored, and with mixed precision
//! P is held in f32 node blocks (a fine node's DOFs × an aggregate's coarse DOFs, one index
//! per block: 3D elasticity 3 × 6, 76 bytes against 216 in scalar CSR). Its entries are
//! rounded before the Galerkin product A_c = PᵀAP is formed, so the hierarchy stays Galerkin
//! for the P it applies: the rounding perturbs the preconditioner only, as the f32 level
//! operators do (docs/src/speed/speed.md#mixed-precision-levels).

use crate::linalg::block_csr::BlockCsr32;
use crate::linalg::csr::TRANSPOSE_PIECES;
use crate::linalg::galerkin::{add, product_with_rows, transpose};
use crate::linalg::Csr;
use std::borrow::Cow;

/// P, and how Pᵀ is applied.
#[derive(Debug, Clone)]
pub enum Prolongator {
    /// Scalar CSR, with Pᵀ stored (a sparse P) or applied by pieces (`pt` None).
    Scalar { p: Csr, pt: Option<Csr> },
    /// f32 node blocks, Pᵀ by pieces.
    Blocks(BlockCsr32),
}

impl Prolongator {
    pub fn nrows(&self) -> usize {
        match self {
            Prolongator::Scalar { p, .. } => p.nrows,
            Prolongator::Blocks(p) => p.nrows(),
        }
    }

    pub fn ncols(&self) -> usize {
        match self {
            Prolongator::Scalar { p, .. } => p.ncols,
            Prolongator::Blocks(p) => p.ncols(),
        }
    }

    /// y ← P x.
    pub fn mul_vec(&self, x: &[f64], y: &mut [f64]) {
        match self {
            Prolongator::Scalar { p, .. } => p.mul_vec(x, y),
            Prolongator::Blocks(p) => p.mul_vec(x, y),
        }
    }

    /// y ← Pᵀ x, with `scratch` of [`Prolongator::scratch_len`].
    pub fn restrict(&self, x: &[f64], y: &mut [f64], scratch: &mut [f64]) {
        match self {
            Prolongator::Scalar { pt: Some(pt), .. } => pt.mul_vec(x, y),
            Prolongator::Scalar { p, pt: None } => p.tmul_vec_by_pieces(x, y, scratch),
            Prolongator::Blocks(p) => p.tmul_vec_by_pieces(x, y, scratch),
        }
    }

    /// The scratch entries of [`Prolongator::restrict`].
    pub fn scratch_len(&self) -> usize {
        match self {
            Prolongator::Scalar { pt: Some(_), .. } => 0,
            _ => TRANSPOSE_PIECES * self.ncols(),
        }
    }

    /// f(j, p_ij) for the entries of row i (in node blocks, the nonzero ones).
    fn for_each_in_row(&self, i: usize, f: &mut dyn FnMut(usize, f64)) {
        match self {
            Prolongator::Scalar { p, .. } => {
                for k in p.indptr[i]..p.indptr[i + 1] {
                    f(p.indices[k] as usize, p.values[k]);
                }
            }
            Prolongator::Blocks(p) => p.for_each_in_row(i, f),
        }
    }

    /// The rows flagged in `keep` (the others empty), same shape, in scalar CSR.
    pub fn rows_of(&self, keep: &[bool]) -> Csr {
        Csr::from_rows(self.nrows(), self.ncols(), keep, |i, f| {
            self.for_each_in_row(i, f)
        })
    }

    /// A·P for A with P's rows as columns.
    pub fn left_product(&self, a: &Csr) -> Csr {
        assert_eq!(a.ncols, self.nrows(), "inner dimensions differ");
        product_with_rows(a, self.ncols(), |k, f| self.for_each_in_row(k, f))
    }

    /// PᵀΔP for a symmetric Δ on P's rows, made exactly symmetric: (Δ P)ᵀ P from P's rows
    /// that meet Δ's, so the work is on Δ's rows only.
    pub fn galerkin_of(&self, delta: &Csr) -> Csr {
        let dp = self.left_product(delta);
        let c = self.left_product(&transpose(&dp));
        add(0.5, &c, 0.5, &transpose(&c))
    }

    /// P in scalar CSR: itself, or a copy of the node blocks' nonzero entries.
    pub fn to_csr(&self) -> Cow<'_, Csr> {
        match self {
            Prolongator::Scalar { p, .. } => Cow::Borrowed(p),
            Prolongator::Blocks(_) => Cow::Owned(self.rows_of(&vec![true; self.nrows()])),
        }
    }
}
