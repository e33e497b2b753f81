//! Truncated multigrid (Kornhuber; Gräser & Kornhuber, "Multigrid methods for obstacle
//! problems", J. Comput. Math. 27 (2009)) for an operator that differs from one with a
//! [`Hierarchy`] on a few node blocks only: the generalized Jacobian of a semismooth Newton
//! step of the velocity HVI,
//!
//!   M = (A + E)_{RR} ⊕ I_{FF},
//!
//! with F the fixed DOFs (sticking Γ3 nodes, held at zero), R the rest and E block diagonal on
//! a few node blocks (the curvature of the friction potential at slipping Γ3 nodes). M is
//! applied from A's storage ([`Jacobian`]), never copied.
//!
//! The preconditioner is a V-cycle for M⁺ (E replaced by its positive semidefinite part E⁺):
//! - the finest level smooths M⁺ with A's Chebyshev polynomial over M⁺'s block diagonal. For
//!   E⁺ ⪰ 0, λ_max(D_M⁻¹ M⁺) ≤ max(λ_max(D_A⁻¹ A), 1) (mediant inequality, block by block), so
//!   A's interval still covers the spectrum and no new estimate is needed;
//! - the prolongator is truncated, P̃ = P with the rows of F zeroed, so coarse corrections never
//!   move a fixed DOF, and the first coarse operator is Galerkin for M⁺:
//!   A₁' = P̃ᵀ M⁺ P̃ = A₁ − X − Xᵀ + P_Fᵀ A P_F + P̃ᵀ E⁺ P̃,   X = P_Fᵀ A P,
//!   (P_F: the rows of F of P), an update of A₁ = Pᵀ A P that costs work on the rows of F and
//!   of E only;
//! - the levels below are updated with A's prolongators by the Galerkin products of A₁' − A₁
//!   ([`Hierarchy::changes_below`]), whose work is on the coarse rows that F and E reach.
//!
//! A Newton iteration whose stick set or blocks moved updates the cycle it has
//! ([`Truncated::updated`]): M⁺'s change is on the rows and columns of the nodes that changed
//! only, and so is the work of carrying it to the coarse levels.
//!
//! With every Γ3 node fixed this is multigrid for K_II with contact-free coarse spaces below
//! the first level; with none fixed and E = 0 it is A's own V-cycle.

use super::prolongator::Prolongator;
use super::smoother::{BlockJacobi, Chebyshev};
use super::{Hierarchy, VCycle};
use crate::linalg::block_csr::BlockCsr32;
use crate::linalg::cholesky::{Cholesky, FactorError};
use crate::linalg::galerkin::{add, product, transpose};
use crate::linalg::par;
use crate::linalg::pcg::Preconditioner;
use crate::linalg::{Csr, LinearOperator, Sparse};
use nalgebra::DMatrix;
use std::sync::Arc;

/// A symmetric s × s block (s ≤ 2) on the consecutive DOFs start..start + s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeBlock {
    pub start: usize,
    pub size: usize,
    /// Row-major, the first size² entries used.
    pub m: [f64; 4],
}

impl NodeBlock {
    /// The positive semidefinite part (negative eigenvalues set to zero).
    pub fn positive_part(&self) -> NodeBlock {
        let mut out = *self;
        match self.size {
            1 => out.m[0] = self.m[0].max(0.0),
            _ => {
                let e = nalgebra::SymmetricEigen::new(nalgebra::Matrix2::new(
                    self.m[0], self.m[1], self.m[2], self.m[3],
                ));
                let l = e.eigenvalues.map(|v| v.max(0.0));
                let q = e.eigenvectors;
                let p = q * nalgebra::Matrix2::from_diagonal(&l) * q.transpose();
                out.m = [p[(0, 0)], p[(0, 1)], p[(1, 0)], p[(1, 1)]];
            }
        }
        out
    }

    fn value(&self, i: usize, j: usize) -> f64 {
        self.m[(i - self.start) * self.size + (j - self.start)]
    }

    fn contains(&self, i: usize) -> bool {
        (self.start..self.start + self.size).contains(&i)
    }
}

/// M = (A + E)_{RR} ⊕ I_{FF} applied from A's storage.
pub struct Jacobian<'a> {
    pub a: &'a Sparse,
    /// The fixed DOFs F, and a flag per DOF.
    pub fixed: &'a [usize],
    pub is_fixed: &'a [bool],
    /// E's blocks (on DOFs of R).
    pub blocks: &'a [NodeBlock],
}

impl LinearOperator for Jacobian<'_> {
    fn dim(&self) -> usize {
        self.a.nrows()
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        self.a.mul_vec(x, y);
        // Remove A's columns of F, then make the rows of F the identity's.
        self.a.sub_columns(self.fixed, x, y);
        for &s in self.fixed {
            y[s] = x[s];
        }
        add_blocks(self.blocks, x, y);
    }
}

/// M⁺ from A's single-precision copy, for the smoother of the finest level in mixed
/// precision: as [`Jacobian`], with A's columns of F removed with the same rounded entries
/// as the product's ([`BlockCsr32::sub_columns`]), so M⁺ stays symmetric.
struct MixedJacobian<'a> {
    a32: &'a BlockCsr32,
    fixed: &'a [usize],
    blocks: &'a [NodeBlock],
}

impl LinearOperator for MixedJacobian<'_> {
    fn dim(&self) -> usize {
        self.a32.dim()
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        self.a32.mul_vec(x, y);
        self.a32.sub_columns(self.fixed, x, y);
        for &s in self.fixed {
            y[s] = x[s];
        }
        add_blocks(self.blocks, x, y);
    }
}

/// y += E x for E's node blocks.
fn add_blocks(blocks: &[NodeBlock], x: &[f64], y: &mut [f64]) {
    for b in blocks {
        for i in 0..b.size {
            let mut v = 0.0;
            for j in 0..b.size {
                v += b.m[i * b.size + j] * x[b.start + j];
            }
            y[b.start + i] += v;
        }
    }
}

/// The block-diagonal n × n matrix of `blocks`.
fn block_matrix(n: usize, blocks: &[NodeBlock]) -> Csr {
    let t = blocks
        .iter()
        .flat_map(|b| {
            (0..b.size * b.size).map(move |k| (b.start + k / b.size, b.start + k % b.size, b.m[k]))
        })
        .collect();
    Csr::from_triplets(n, n, t)
}

/// Δ₁ = −X − Xᵀ + P_Fᵀ A P_F + P̃ᵀ E⁺ P̃, the change from A₁ to the first coarse operator of
/// the truncated cycle A₁' = A₁ + Δ₁: Galerkin for M⁺ with P̃ = P with F's rows zeroed
/// (X = P_Fᵀ A P). E⁺ P̃ has rows only on E's DOFs of R, so P̃ᵀ E⁺ P̃ = P_Eᵀ E⁺ P_E with P_E
/// those rows of P: the same terms in the same order as with all of P̃, without a copy and a
/// transpose of P. Δ₁ has rows only where P's columns meet F or E, so the levels below are
/// updated by its Galerkin products ([`Hierarchy::updated`]), not formed again. Its own
/// function so that the products are freed before they are.
fn first_coarse_change(
    p: &Prolongator,
    a: &Sparse,
    is_fixed: &[bool],
    positive: &[NodeBlock],
) -> Csr {
    let n = a.nrows();
    let mut in_e = vec![false; n];
    for b in positive {
        for i in b.start..b.start + b.size {
            in_e[i] = !is_fixed[i];
        }
    }
    let p_e = p.rows_of(&in_e);
    let p_f = p.rows_of(is_fixed);
    let a_f = a.rows_of(is_fixed);
    let p_ft = transpose(&p_f);
    let x = product(&p_ft, &p.left_product(&a_f));
    let y = product(&p_ft, &product(&a_f, &p_f));
    let z = product(&transpose(&p_e), &product(&block_matrix(n, positive), &p_e));
    let delta = add(1.0, &add(1.0, &y, 1.0, &z), -1.0, &x);
    let delta = add(1.0, &delta, -1.0, &transpose(&x));
    add(0.5, &delta, 0.5, &transpose(&delta))
}

/// The truncated V-cycle's finest level and the hierarchy below it.
#[derive(Clone)]
struct Levels {
    smoother: Chebyshev,
    /// A's hierarchy, whose first prolongator P (and Pᵀ) is applied with F's rows masked:
    /// P̃ x = mask(P x), P̃ᵀ t = Pᵀ mask(t), without a copy of P.
    fine: Arc<Hierarchy>,
    coarse: VCycle,
    work: [Vec<f64>; 8],
}

#[derive(Clone)]
enum Cycle {
    /// A's hierarchy has levels: the truncated V-cycle.
    Levels(Box<Levels>),
    /// A is factored directly (a small problem): M⁺ is too.
    Direct(Cholesky),
}

/// The truncated V-cycle for M⁺ (an SPD preconditioner for M).
#[derive(Clone)]
pub struct Truncated {
    a: Sparse,
    fixed: Vec<usize>,
    is_fixed: Vec<bool>,
    /// E⁺'s blocks, in increasing DOFs.
    positive: Vec<NodeBlock>,
    cycle: Cycle,
}

/// M⁺'s entry (i, j): the identity's on F, A's plus E⁺'s elsewhere. `positive` in
/// increasing DOFs.
fn entry(a: &Sparse, is_fixed: &[bool], positive: &[NodeBlock], i: usize, j: usize) -> f64 {
    if is_fixed[i] || is_fixed[j] {
        return if i == j { 1.0 } else { 0.0 };
    }
    a.get(i, j) + block_entry(positive, i, j)
}

/// E⁺'s entry (i, j), `positive` in increasing DOFs.
fn block_entry(positive: &[NodeBlock], i: usize, j: usize) -> f64 {
    let k = positive.partition_point(|b| b.start + b.size <= i);
    positive
        .get(k)
        .filter(|b| b.contains(i) && b.contains(j))
        .map_or(0.0, |b| b.value(i, j))
}

/// E⁺'s blocks in increasing DOFs.
fn positive_parts(blocks: &[NodeBlock]) -> Vec<NodeBlock> {
    let mut positive: Vec<NodeBlock> = blocks.iter().map(NodeBlock::positive_part).collect();
    positive.sort_by_key(|b| b.start);
    positive
}

/// Remakes the smoother blocks that hold any of `dofs` from M⁺.
fn remake_blocks(
    jacobi: &mut BlockJacobi,
    a: &Sparse,
    is_fixed: &[bool],
    positive: &[NodeBlock],
    dofs: impl Iterator<Item = usize>,
) {
    let block_of = jacobi.blocks().block_of(a.nrows());
    let mut touched: Vec<u32> = dofs.map(|i| block_of[i]).collect();
    touched.sort_unstable();
    touched.dedup();
    for b in touched {
        let dofs = jacobi.blocks().dofs(b as usize).to_vec();
        let m = DMatrix::from_fn(dofs.len(), dofs.len(), |i, j| {
            entry(a, is_fixed, positive, dofs[i], dofs[j])
        });
        jacobi.set_block(b as usize, &m);
    }
}

/// The change of M⁺'s part on R, D_R (A + E⁺) D_R (D_R zeroing F), from (`old_fixed`,
/// `old`) to (`new_fixed`, `new`): the rows and columns of the DOFs that became fixed or
/// free, and the blocks of E⁺ that changed on the others. Its Galerkin product with P is
/// the change of A₁'. Block lists in increasing DOFs.
fn fine_change(
    a: &Sparse,
    (old_fixed, old): (&[bool], &[NodeBlock]),
    (new_fixed, new): (&[bool], &[NodeBlock]),
) -> Csr {
    let n = a.nrows();
    let part = |fixed: &[bool], blocks: &[NodeBlock], i: usize, j: usize, aij: f64| {
        if fixed[i] || fixed[j] {
            0.0
        } else {
            aij + block_entry(blocks, i, j)
        }
    };
    let flipped = |i: usize| old_fixed[i] != new_fixed[i];
    let mut t = Vec::new();
    for i in (0..n).filter(|&i| flipped(i)) {
        a.for_each_in_row(i, |j, aij| {
            let g = part(new_fixed, new, i, j, aij) - part(old_fixed, old, i, j, aij);
            if g != 0.0 {
                t.push((i, j, g));
                if !flipped(j) {
                    t.push((j, i, g));
                }
            }
        });
    }
    // Blocks on DOFs that stayed free and changed (or came or went): E⁺'s difference only.
    let mut changed: Vec<&NodeBlock> = Vec::new();
    let (mut p, mut q) = (0, 0);
    while p < old.len() || q < new.len() {
        match (old.get(p), new.get(q)) {
            (Some(o), Some(m)) if o.start == m.start => {
                if o != m {
                    changed.extend([o, m]);
                }
                p += 1;
                q += 1;
            }
            (Some(o), Some(m)) if o.start < m.start => {
                changed.push(o);
                p += 1;
            }
            (Some(o), None) => {
                changed.push(o);
                p += 1;
            }
            (_, Some(m)) => {
                changed.push(m);
                q += 1;
            }
            (None, None) => unreachable!(),
        }
    }
    let mut seen = vec![false; n];
    for b in changed {
        if seen[b.start] || flipped(b.start) || new_fixed[b.start] {
            continue;
        }
        seen[b.start] = true;
        for i in b.start..b.start + b.size {
            for j in b.start..b.start + b.size {
                let g = block_entry(new, i, j) - block_entry(old, i, j);
                if g != 0.0 {
                    t.push((i, j, g));
                }
            }
        }
    }
    Csr::from_triplets(n, n, t)
}

impl Truncated {
    /// The preconditioner for M with fixed DOFs `fixed` and blocks `blocks`, from A's
    /// hierarchy `h`.
    pub fn new(
        h: &Arc<Hierarchy>,
        fixed: Vec<usize>,
        blocks: &[NodeBlock],
    ) -> Result<Truncated, FactorError> {
        let a = Sparse::from(h.operator().clone());
        Self::with_operator(h, a, fixed, blocks)
    }

    /// As [`Truncated::new`], with A given (shared with the caller, which holds it anyway;
    /// the hierarchy may have shed its own).
    pub fn with_operator(
        h: &Arc<Hierarchy>,
        a: Sparse,
        fixed: Vec<usize>,
        blocks: &[NodeBlock],
    ) -> Result<Truncated, FactorError> {
        let n = a.nrows();
        let is_fixed = flags(n, &fixed);
        let positive = positive_parts(blocks);
        let cycle = match h.level(0) {
            None => {
                let pattern = a.to_csr();
                let t = (0..n)
                    .flat_map(|i| {
                        let row = pattern.indptr[i]..pattern.indptr[i + 1];
                        pattern.indices[row].iter().map(move |&j| (i, j as usize))
                    })
                    .map(|(i, j)| (i, j, entry(&a, &is_fixed, &positive, i, j)))
                    .collect();
                let m = Csr::from_triplets(n, n, t);
                Cycle::Direct(Cholesky::new(m.lower_csc().as_ref())?)
            }
            Some((smoother, p)) => {
                // The block diagonal of M⁺: A's, with the blocks touching F or E remade.
                let mut jacobi = smoother.jacobi.patched();
                let touched = fixed
                    .iter()
                    .copied()
                    .chain(positive.iter().map(|b| b.start));
                remake_blocks(&mut jacobi, &a, &is_fixed, &positive, touched);
                let smoother = smoother.with_jacobi(jacobi);
                let delta = first_coarse_change(p, &a, &is_fixed, &positive);
                let coarse = coarse_levels(h, delta)?;
                Cycle::Levels(Box::new(Levels {
                    smoother,
                    fine: h.clone(),
                    coarse,
                    work: work_vectors(h),
                }))
            }
        };
        Ok(Truncated {
            a,
            fixed,
            is_fixed,
            positive,
            cycle,
        })
    }

    /// This preconditioner for new fixed DOFs and blocks, the same operator as
    /// [`Truncated::with_operator`] makes for less work: M⁺ changes on the rows and columns
    /// of the nodes that changed only, so A₁' changes by the Galerkin product of that change
    /// ([`fine_change`]), carried down the levels as at set-up. The finest smoother's blocks
    /// on those nodes are remade; the levels' smoothers and the coarsest factor are made
    /// afresh from the updated operators. `h` is the hierarchy it was made from.
    ///
    /// The levels are updated from their own operators, so where those are kept in f32 each
    /// update rounds them again (2⁻²⁴ relative an update, a preconditioner's rounding);
    /// where they are kept in f64 the result is the fresh one to rounding.
    pub fn updated(
        self,
        h: &Arc<Hierarchy>,
        fixed: Vec<usize>,
        blocks: &[NodeBlock],
    ) -> Result<Truncated, FactorError> {
        let Truncated {
            a,
            is_fixed: old_fixed,
            positive: old,
            cycle,
            ..
        } = self;
        let Cycle::Levels(levels) = cycle else {
            return Self::with_operator(h, a, fixed, blocks);
        };
        let n = a.nrows();
        let is_fixed = flags(n, &fixed);
        let positive = positive_parts(blocks);
        let change = fine_change(&a, (&old_fixed, &old), (&is_fixed, &positive));
        let Levels {
            mut smoother,
            fine,
            mut coarse,
            mut work,
        } = *levels;
        if change.nnz() > 0 {
            let p = h.prolongator(0).expect("A's hierarchy has a first level");
            let first = p.galerkin_of(&change);
            // The levels are changed in place, the work vectors freed meanwhile: the
            // update holds no more than a new cycle would.
            drop(work);
            let below = coarse.into_hierarchy();
            let changes = below.changes_below(0, first);
            let below = match Arc::try_unwrap(below) {
                Ok(own) => own.with_changes(&changes)?,
                // A clone of this cycle shares the levels: they are copied with the change.
                Err(shared) => {
                    let mut copy = shared.updated(0, &changes)?;
                    copy.shed_operators(&[]);
                    copy
                }
            };
            coarse = Arc::new(below).vcycle();
            work = work_vectors(h);
            let rows = (0..n).filter(|&i| change.indptr[i] < change.indptr[i + 1]);
            remake_blocks(&mut smoother.jacobi, &a, &is_fixed, &positive, rows);
        }
        let levels = Box::new(Levels {
            smoother,
            fine,
            coarse,
            work,
        });
        Ok(Truncated {
            a,
            fixed,
            is_fixed,
            positive,
            cycle: Cycle::Levels(levels),
        })
    }
}

/// A flag per DOF, set on `dofs`.
fn flags(n: usize, dofs: &[usize]) -> Vec<bool> {
    let mut flag = vec![false; n];
    for &s in dofs {
        flag[s] = true;
    }
    flag
}

/// The truncated cycle's levels below the finest: A's hierarchy `h` from its first level,
/// that level's operator changed by `delta` and the levels below by its Galerkin products
/// ([`Hierarchy::changes_below`]). Only this cycle reads them, through their f32 copies
/// where there are any.
fn coarse_levels(h: &Hierarchy, delta: Csr) -> Result<VCycle, FactorError> {
    let mut coarse = h.updated(1, &h.changes_below(1, delta))?;
    coarse.shed_operators(&[]);
    Ok(Arc::new(coarse).vcycle())
}

/// The cycle's work vectors on the finest level and the first coarse one, for A's
/// hierarchy `h`.
fn work_vectors(h: &Hierarchy) -> [Vec<f64>; 8] {
    let sizes = h.sizes();
    let (n, nc) = (sizes[0], sizes[1]);
    [
        vec![0.0; n],
        vec![0.0; n],
        vec![0.0; n],
        vec![0.0; n],
        vec![0.0; n],
        vec![0.0; nc],
        vec![0.0; nc],
        vec![0.0; h.restriction_scratch(0)],
    ]
}

impl Preconditioner for Truncated {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        let op = Jacobian {
            a: &self.a,
            fixed: &self.fixed,
            is_fixed: &self.is_fixed,
            blocks: &self.positive,
        };
        match &mut self.cycle {
            Cycle::Direct(c) => {
                z.copy_from_slice(r);
                c.solve_in_place(z);
            }
            Cycle::Levels(levels) => {
                let Levels {
                    smoother,
                    fine,
                    coarse,
                    work,
                } = &mut **levels;
                let mixed = fine.level_f32(0).map(|a32| MixedJacobian {
                    a32,
                    fixed: &self.fixed,
                    blocks: &self.positive,
                });
                let op: &dyn LinearOperator = match &mixed {
                    Some(m) => m,
                    None => &op,
                };
                let p = fine
                    .prolongator(0)
                    .expect("A's hierarchy has a first level");
                let [b, x, rr, d, t, bc, xc, pieces] = work;
                b.copy_from_slice(r);
                x.iter_mut().for_each(|v| *v = 0.0);
                smoother.smooth(op, b, x, rr, d, t, true);
                op.apply(x, t);
                par::zip_apply(t, b, |t, b| b - t);
                for &s in &self.fixed {
                    t[s] = 0.0;
                }
                fine.restrict(0, t, bc, pieces);
                coarse.apply(bc, xc);
                p.mul_vec(xc, t);
                for &s in &self.fixed {
                    t[s] = 0.0;
                }
                par::zip_apply(x, t, |x, t| x + t);
                smoother.smooth(op, b, x, rr, d, t, false);
                z.copy_from_slice(x);
            }
        }
        for &s in &self.fixed {
            z[s] = r[s];
        }
    }
}

#[cfg(test)]
mod tests;
