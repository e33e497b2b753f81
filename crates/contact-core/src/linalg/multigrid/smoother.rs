//! The smoother of every level: Chebyshev polynomial acceleration of point-block Jacobi
//! (Adams, Brezina, Hu, Tuminaro, "Parallel multigrid smoothing: polynomial versus
//! Gauss–Seidel", J. Comput. Phys. 188 (2003)).
//!
//! D is the block diagonal of A over the node blocks (one node's 2 or 3 velocity components,
//! or one aggregate's coarse DOFs); D⁻¹A is self-adjoint in the D inner product, so its
//! largest eigenvalue λ is estimated by a short Lanczos run in that inner product. The
//! smoother is the degree-m Chebyshev iteration for A x = b preconditioned by D⁻¹ on the
//! interval [λ/ratio, 1.1 λ]: a fixed polynomial q with x ← x + q(D⁻¹A) D⁻¹ (b − A x), whose
//! matrix q(D⁻¹A) D⁻¹ is symmetric, so the same smoother before and after the coarse
//! correction gives a symmetric V-cycle.

#![allow(clippy::needless_range_loop)] // Index loops over nodes, blocks and components spell out the formulas.

use super::Blocks;
use crate::linalg::block_csr::BlockCsr32;
use crate::linalg::dense::tridiagonal_max_eig;
use crate::linalg::par;
use crate::linalg::{Csr, LinearOperator};
use nalgebra::DMatrix;
use std::sync::Arc;

/// Lanczos steps of the λ_max estimate.
const LANCZOS_STEPS: usize = 12;
/// The upper end of the Chebyshev interval is this times the estimate (Lanczos Ritz values
/// approach λ_max from below).
const UPPER: f64 = 1.1;

/// The inverse of the block diagonal of A, and the block diagonal itself.
#[derive(Debug, Clone)]
pub struct BlockJacobi {
    /// Shared with the copies [`BlockJacobi::patched`] makes.
    shared: Arc<Diagonal>,
    /// This copy's own blocks, where it has any.
    patch: Option<Patch>,
}

#[derive(Debug, Clone)]
struct Diagonal {
    blocks: Blocks,
    /// Per block, its s × s inverse and its s × s diagonal block, row-major; `offset[b]`.
    /// Only the λ_max estimate reads the blocks themselves ([`BlockJacobi::mul`]), so a
    /// smoother drops them once made ([`BlockJacobi::drop_matrix_blocks`]): `diag` is then
    /// empty, and patches hold no blocks either.
    inv: Vec<f64>,
    diag: Vec<f64>,
    offset: Vec<usize>,
    split: Split,
}

/// Blocks that replace the shared ones in one copy: `slot[b]` indexes them ([`NO_SLOT`]:
/// block b is the shared one), whose entries are laid out as [`Diagonal`]'s; `list` holds
/// the replaced blocks in increasing order.
#[derive(Debug, Clone)]
struct Patch {
    slot: Vec<u32>,
    list: Vec<u32>,
    inv: Vec<f64>,
    diag: Vec<f64>,
    offset: Vec<usize>,
}

const NO_SLOT: u32 = u32::MAX;

/// Where the block products split over threads: pieces of whole blocks, `blocks[s]` the first
/// block of piece s and `dofs[s]` its first DOF (both ending with the totals). Blocks whose
/// DOFs are consecutive and in order (the node blocks of the fine level, aggregates) split
/// every [`par::ROW_CHUNK`] DOFs; others make a single piece.
#[derive(Debug, Clone)]
struct Split {
    blocks: Vec<usize>,
    dofs: Vec<usize>,
}

impl Split {
    fn of(blocks: &Blocks) -> Split {
        let n = blocks.n_dofs();
        let in_order = blocks.dofs.iter().enumerate().all(|(p, &d)| p == d);
        let mut split = Split {
            blocks: vec![0],
            dofs: vec![0],
        };
        if in_order {
            for b in 1..blocks.len() {
                if blocks.ptr[b] - split.dofs.last().unwrap() >= par::ROW_CHUNK {
                    split.blocks.push(b);
                    split.dofs.push(blocks.ptr[b]);
                }
            }
        }
        split.blocks.push(blocks.len());
        split.dofs.push(n);
        split
    }
}

impl BlockJacobi {
    pub fn new(a: &Csr, blocks: &Blocks) -> BlockJacobi {
        Self::of(|i, j| a.get(i, j), blocks)
    }

    /// The blocks of the operator whose entry (i, j) is `entry(i, j)`.
    pub fn of(entry: impl Fn(usize, usize) -> f64, blocks: &Blocks) -> BlockJacobi {
        let mut offset = Vec::with_capacity(blocks.len() + 1);
        offset.push(0);
        for b in 0..blocks.len() {
            let s = blocks.dofs(b).len();
            offset.push(offset[b] + s * s);
        }
        let total = *offset.last().unwrap();
        let (inv, diag) = (vec![0.0; total], vec![0.0; total]);
        let mut jacobi = BlockJacobi {
            shared: Arc::new(Diagonal {
                split: Split::of(blocks),
                blocks: blocks.clone(),
                inv,
                diag,
                offset,
            }),
            patch: None,
        };
        for b in 0..blocks.len() {
            let dofs = blocks.dofs(b);
            let m = DMatrix::from_fn(dofs.len(), dofs.len(), |i, j| entry(dofs[i], dofs[j]));
            jacobi.set_block(b, &m);
        }
        jacobi
    }

    /// Drops the diagonal blocks themselves, keeping their inverses: all that smoothing,
    /// the prolongator's smoothing and the truncated cycles' patches read. On the 82k-node
    /// part the finest level's blocks were 5.9 MB of a one-step run's peak.
    pub fn drop_matrix_blocks(&mut self) {
        Arc::make_mut(&mut self.shared).diag = Vec::new();
        if let Some(p) = &mut self.patch {
            p.diag = Vec::new();
        }
    }

    /// Whether it still holds the diagonal blocks themselves ([`BlockJacobi::mul`]).
    fn has_matrix_blocks(&self) -> bool {
        !self.shared.diag.is_empty() || self.shared.offset.last() == Some(&0)
    }

    /// The node blocks.
    pub fn blocks(&self) -> &Blocks {
        &self.shared.blocks
    }

    /// A copy whose [`BlockJacobi::set_block`] changes only itself, sharing every block it
    /// does not set (the truncated cycles remake the few blocks of Γ3 nodes; a whole copy of
    /// the finest level's blocks was 14 MB of the 82k-node part's peak, twice in a
    /// slipping run).
    pub fn patched(&self) -> BlockJacobi {
        BlockJacobi {
            shared: self.shared.clone(),
            patch: Some(Patch {
                slot: vec![NO_SLOT; self.shared.blocks.len()],
                list: Vec::new(),
                inv: Vec::new(),
                diag: Vec::new(),
                offset: vec![0],
            }),
        }
    }

    /// Block b's inverse and matrix, s × s row-major.
    fn block(&self, b: usize) -> (&[f64], &[f64]) {
        match &self.patch {
            Some(p) if p.slot[b] != NO_SLOT => {
                let k = p.slot[b] as usize;
                let r = p.offset[k]..p.offset[k + 1];
                (&p.inv[r.clone()], p.diag.get(r).unwrap_or(&[]))
            }
            _ => {
                let d = &*self.shared;
                let r = d.offset[b]..d.offset[b + 1];
                (&d.inv[r.clone()], d.diag.get(r).unwrap_or(&[]))
            }
        }
    }

    /// Makes block b's matrix `m` (s × s, s its DOF count).
    pub fn set_block(&mut self, b: usize, m: &DMatrix<f64>) {
        let s = self.blocks().dofs(b).len();
        // SPD A has SPD diagonal blocks; a singular one (a DOF without stiffness) falls
        // back to the inverse of its positive diagonal entries.
        let mi = m
            .clone()
            .cholesky()
            .map(|c| c.inverse())
            .unwrap_or_else(|| {
                DMatrix::from_fn(s, s, |i, j| {
                    if i == j && m[(i, i)] > 0.0 {
                        1.0 / m[(i, i)]
                    } else {
                        0.0
                    }
                })
            });
        let keep_blocks = self.has_matrix_blocks();
        let (inv, diag, o) = match &mut self.patch {
            Some(p) => {
                if p.slot[b] == NO_SLOT {
                    p.slot[b] = (p.offset.len() - 1) as u32;
                    let at = p.list.partition_point(|&c| (c as usize) < b);
                    p.list.insert(at, b as u32);
                    let end = p.offset.last().unwrap() + s * s;
                    p.offset.push(end);
                    p.inv.resize(end, 0.0);
                    if keep_blocks {
                        p.diag.resize(end, 0.0);
                    }
                }
                let o = p.offset[p.slot[b] as usize];
                (&mut p.inv, &mut p.diag, o)
            }
            None => {
                let d = Arc::make_mut(&mut self.shared);
                let o = d.offset[b];
                (&mut d.inv, &mut d.diag, o)
            }
        };
        for i in 0..s {
            for j in 0..s {
                inv[o + i * s + j] = mi[(i, j)];
                if keep_blocks {
                    diag[o + i * s + j] = m[(i, j)];
                }
            }
        }
    }

    /// y ← keep·y + sign·M x with M the blocks' inverses (`inverse`) or the blocks.
    fn apply_blocks(&self, inverse: bool, x: &[f64], y: &mut [f64], sign: f64, keep: f64) {
        let d = &*self.shared;
        let Blocks { ptr, dofs } = &d.blocks;
        let values = if inverse { &d.inv } else { &d.diag };
        let patched: &[u32] = self.patch.as_ref().map_or(&[], |p| &p.list);
        par::for_each_segment_mut(y, &d.split.dofs, |seg, y| {
            // A piece of y holds the DOFs of its blocks, from `base` on (all of y, from 0,
            // when the blocks are not contiguous and there is one piece).
            let base = d.split.dofs[seg];
            let shared = |blocks: std::ops::Range<usize>, y: &mut [f64]| {
                for b in blocks {
                    let m = &values[d.offset[b]..d.offset[b + 1]];
                    apply_block(&dofs[ptr[b]..ptr[b + 1]], m, x, y, base, sign, keep);
                }
            };
            // The shared blocks run by run between this copy's own, so that a copy without
            // any costs no test per block.
            let (first, end) = (d.split.blocks[seg], d.split.blocks[seg + 1]);
            let own = patched.partition_point(|&b| (b as usize) < first)
                ..patched.partition_point(|&b| (b as usize) < end);
            let mut next = first;
            for &b in &patched[own] {
                let b = b as usize;
                shared(next..b, y);
                let (inv, diag) = self.block(b);
                let m = if inverse { inv } else { diag };
                apply_block(&dofs[ptr[b]..ptr[b + 1]], m, x, y, base, sign, keep);
                next = b + 1;
            }
            shared(next..end, y);
        });
    }

    /// D⁻¹ as a sparse (block-diagonal) matrix.
    pub fn inverse_matrix(&self) -> Csr {
        let blocks = self.blocks();
        let n = blocks.n_dofs();
        let mut t = Vec::with_capacity(self.shared.inv.len());
        for b in 0..blocks.len() {
            let dofs = blocks.dofs(b);
            let s = dofs.len();
            let inv = self.block(b).0;
            for i in 0..s {
                for j in 0..s {
                    t.push((dofs[i], dofs[j], inv[i * s + j]));
                }
            }
        }
        Csr::from_triplets(n, n, t)
    }

    /// y ← D⁻¹ x.
    pub fn solve(&self, x: &[f64], y: &mut [f64]) {
        self.apply_blocks(true, x, y, 1.0, 0.0);
    }

    /// y ← y − D⁻¹ x.
    pub fn solve_sub(&self, x: &[f64], y: &mut [f64]) {
        self.apply_blocks(true, x, y, -1.0, 1.0);
    }

    /// y ← D x (not after [`BlockJacobi::drop_matrix_blocks`]).
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        assert!(self.has_matrix_blocks(), "the diagonal blocks were dropped");
        self.apply_blocks(false, x, y, 1.0, 0.0);
    }
}

/// y_i ← keep·y_i + sign·(m x)_i over one block's DOFs `block` (m: s × s, row-major; y holds
/// the DOFs from `base` on). Node blocks of 3 and 1 DOFs (3D velocity, scalar damage) are
/// spelled out: the generic loop over a block's index list cost about a tenth of the
/// products with A it sits beside.
#[inline(always)]
fn apply_block(
    block: &[usize],
    m: &[f64],
    x: &[f64],
    y: &mut [f64],
    base: usize,
    sign: f64,
    keep: f64,
) {
    match (block, m) {
        (&[i], &[m]) => {
            let yi = &mut y[i - base];
            *yi = keep * *yi + sign * m * x[i];
        }
        (&[i, j, k], &[m00, m01, m02, m10, m11, m12, m20, m21, m22]) => {
            let (a, c, e) = (x[i], x[j], x[k]);
            y[i - base] = keep * y[i - base] + sign * (m00 * a + m01 * c + m02 * e);
            y[j - base] = keep * y[j - base] + sign * (m10 * a + m11 * c + m12 * e);
            y[k - base] = keep * y[k - base] + sign * (m20 * a + m21 * c + m22 * e);
        }
        (block, m) => {
            let s = block.len();
            for (row, &i) in m.chunks_exact(s).zip(block) {
                let v: f64 = row.iter().zip(block).map(|(m, &j)| m * x[j]).sum();
                y[i - base] = keep * y[i - base] + sign * v;
            }
        }
    }
}

/// An estimate of λ_max(D⁻¹A) by Lanczos in the D inner product, from a fixed start vector
/// (deterministic: the same matrix gives the same estimate).
pub fn lambda_max(a: &impl LinearOperator, d: &BlockJacobi) -> f64 {
    let n = a.dim();
    if n == 0 {
        return 1.0;
    }
    let mut v: Vec<f64> = (0..n)
        .map(|i| 1.0 + 0.5 * ((i as f64) * 0.618_033_988_7).fract())
        .collect();
    let (mut dv, mut av, mut w) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let dnorm = |v: &[f64], dv: &mut [f64]| -> f64 {
        d.mul(v, dv);
        par::dot(v, dv).sqrt()
    };
    let s = dnorm(&v, &mut dv);
    par::zip_apply(&mut dv, &v, |_, v| v / s);
    std::mem::swap(&mut v, &mut dv);
    let mut v_prev = vec![0.0; n];
    let (mut alphas, mut betas) = (Vec::new(), Vec::new());
    let mut beta = 0.0;
    for _ in 0..LANCZOS_STEPS.min(n) {
        a.apply(&v, &mut av);
        d.solve(&av, &mut w);
        let alpha = par::dot(&av, &v);
        par::zip_apply(&mut w, &v, |w, v| w - alpha * v);
        par::zip_apply(&mut w, &v_prev, |w, v| w - beta * v);
        alphas.push(alpha);
        beta = dnorm(&w, &mut dv);
        if beta <= 1e-12 * alpha.abs() {
            break;
        }
        betas.push(beta);
        std::mem::swap(&mut v_prev, &mut v);
        par::zip_apply(&mut v, &w, |_, w| w / beta);
    }
    tridiagonal_max_eig(&alphas, &betas)
}

/// The Chebyshev smoother of one level.
#[derive(Debug, Clone)]
pub struct Chebyshev {
    pub jacobi: BlockJacobi,
    degree: usize,
    /// The interval [lo, hi] of D⁻¹A's spectrum that the polynomial damps.
    lo: f64,
    hi: f64,
}

impl Chebyshev {
    /// Degree-`degree` smoother damping [λ/ratio, 1.1 λ], λ the Lanczos estimate.
    pub fn new(a: &Csr, blocks: &Blocks, degree: usize, ratio: f64) -> Chebyshev {
        Self::estimated(a, BlockJacobi::new(a, blocks), degree, ratio)
    }

    /// [`Chebyshev::new`] for a level held only in single precision: D from its rounded
    /// entries and λ from its products, which differ from the f64 operator's by 2⁻²⁴
    /// relative.
    pub fn of_single(a: &BlockCsr32, blocks: &Blocks, degree: usize, ratio: f64) -> Chebyshev {
        let jacobi = BlockJacobi::of(|i, j| a.get(i, j), blocks);
        Self::estimated(a, jacobi, degree, ratio)
    }

    fn estimated(
        a: &impl LinearOperator,
        mut jacobi: BlockJacobi,
        degree: usize,
        ratio: f64,
    ) -> Chebyshev {
        let lambda = lambda_max(a, &jacobi);
        jacobi.drop_matrix_blocks();
        Chebyshev {
            jacobi,
            degree,
            lo: UPPER * lambda / ratio,
            hi: UPPER * lambda,
        }
    }

    /// The same polynomial over another block diagonal (of an operator whose λ_max(D⁻¹A) is
    /// known not to exceed this one's).
    pub fn with_jacobi(&self, jacobi: BlockJacobi) -> Chebyshev {
        Chebyshev {
            jacobi,
            degree: self.degree,
            lo: self.lo,
            hi: self.hi,
        }
    }

    /// The upper end of the damped interval (1.1 λ_max estimate).
    pub fn lambda_hi(&self) -> f64 {
        self.hi
    }

    /// x ← x + q(D⁻¹A) D⁻¹ (b − A x). `r`, `d`, `t` are work vectors of length n. With
    /// `zero_start` the caller promises x = 0, and the product A x is skipped (the
    /// pre-smoother of a V-cycle: m − 1 products for degree m instead of m).
    #[allow(clippy::too_many_arguments)] // The vectors are the caller's scratch, as in faer.
    pub fn smooth(
        &self,
        a: &(impl LinearOperator + ?Sized),
        b: &[f64],
        x: &mut [f64],
        r: &mut [f64],
        d: &mut [f64],
        t: &mut [f64],
        zero_start: bool,
    ) {
        let theta = 0.5 * (self.hi + self.lo);
        let delta = 0.5 * (self.hi - self.lo);
        let sigma = theta / delta;
        let mut rho = 1.0 / sigma;
        // r = D⁻¹ (b − A x)
        if zero_start {
            par::copy(t, b);
        } else {
            a.apply(x, t);
            par::zip_apply(t, b, |t, b| b - t);
        }
        self.jacobi.solve(t, r);
        par::zip_apply(d, r, |_, r| r / theta);
        for k in 0..self.degree {
            par::zip_apply(x, d, |x, d| x + d);
            if k + 1 == self.degree {
                break;
            }
            a.apply(d, t);
            self.jacobi.solve_sub(t, r);
            let rho_next = 1.0 / (2.0 * sigma - rho);
            let (c1, c2) = (rho_next * rho, 2.0 * rho_next / delta);
            par::zip_apply(d, r, |d, r| c1 * d + c2 * r);
            rho = rho_next;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An SPD matrix on 10 DOFs whose node blocks have 1, 2, 3 and 4 DOFs, scattered (not
    /// contiguous): every branch of the block kernel.
    fn scattered() -> (Csr, Blocks) {
        let block_of = [2u32, 0, 3, 2, 1, 3, 2, 1, 3, 3];
        let n = block_of.len();
        let mut t = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let v = if i == j {
                    10.0 + i as f64
                } else {
                    1.0 / (1.0 + (i as f64 - j as f64).abs())
                        * if (i + j) % 3 == 0 { -1.0 } else { 0.5 }
                };
                t.push((i, j, v));
            }
        }
        (
            Csr::from_triplets(n, n, t),
            Blocks::from_block_of(&block_of, 4),
        )
    }

    #[test]
    fn block_jacobi_applies_the_inverse_of_each_diagonal_block() {
        let (a, blocks) = scattered();
        let jacobi = BlockJacobi::new(&a, &blocks);
        let x: Vec<f64> = (0..10).map(|i| (i as f64 * 0.7).sin() + 0.1).collect();
        let mut dx = vec![0.0; 10];
        jacobi.mul(&x, &mut dx);
        let mut back = vec![0.0; 10];
        jacobi.solve(&dx, &mut back);
        let mut sub = x.clone();
        jacobi.solve_sub(&dx, &mut sub);
        for b in 0..blocks.len() {
            let dofs = blocks.dofs(b);
            for &i in dofs {
                let expected: f64 = dofs.iter().map(|&j| a.get(i, j) * x[j]).sum();
                assert!((dx[i] - expected).abs() < 1e-13, "D x at {i}");
            }
        }
        for i in 0..10 {
            assert!((back[i] - x[i]).abs() < 1e-13, "D⁻¹ D x at {i}");
            assert!(sub[i].abs() < 1e-13, "x − D⁻¹ D x at {i}");
        }
    }

    /// A smoother keeps the inverses only: its block Jacobi applies them as the whole one
    /// does, and a patched copy of it sets and applies blocks without the blocks themselves.
    #[test]
    fn a_smoother_keeps_only_the_inverses() {
        let (a, blocks) = scattered();
        let whole = BlockJacobi::new(&a, &blocks);
        let smoother = Chebyshev::new(&a, &blocks, 2, 7.0);
        assert!(whole.has_matrix_blocks() && !smoother.jacobi.has_matrix_blocks());
        assert!(smoother.jacobi.shared.diag.is_empty());
        let x: Vec<f64> = (0..10).map(|i| (i as f64 * 0.3).cos()).collect();
        let solve = |d: &BlockJacobi| {
            let mut y = vec![0.0; 10];
            d.solve(&x, &mut y);
            y
        };
        assert_eq!(solve(&smoother.jacobi), solve(&whole));
        let m = DMatrix::from_fn(3, 3, |i, j| if i == j { 9.0 } else { 0.5 });
        let (mut patched, mut whole_patched) = (smoother.jacobi.patched(), whole.patched());
        let b = (0..blocks.len())
            .find(|&b| blocks.dofs(b).len() == 3)
            .unwrap();
        patched.set_block(b, &m);
        whole_patched.set_block(b, &m);
        assert!(patched.patch.as_ref().unwrap().diag.is_empty());
        assert_eq!(solve(&patched), solve(&whole_patched));
        assert_ne!(solve(&patched), solve(&whole));
    }

    /// A patched copy applies its own blocks where set and the shared ones elsewhere, the
    /// same bits as a whole copy with the same blocks set, on any thread count, and leaves
    /// the blocks it shares as they were. Contiguous node blocks over several pieces of the
    /// thread split (ROW_CHUNK is 32 under test), set at the first, the last and inner
    /// blocks.
    #[test]
    fn a_patched_copy_equals_a_whole_copy_with_the_same_blocks_set() {
        let n = 3 * 100;
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 6.0 + (i % 7) as f64));
            for j in [i + 1, i + 3] {
                if j < n {
                    t.push((i, j, -1.0 / (1.0 + (i % 5) as f64)));
                    t.push((j, i, -1.0 / (1.0 + (i % 5) as f64)));
                }
            }
        }
        let a = Csr::from_triplets(n, n, t);
        let bounds: Vec<usize> = (0..=n / 3).map(|b| 3 * b).collect();
        let original = BlockJacobi::new(&a, &Blocks::contiguous(&bounds));
        let (mut whole, mut patched) = (original.clone(), original.patched());
        for b in [99usize, 0, 17, 50, 18] {
            let m = DMatrix::from_fn(3, 3, |i, j| {
                if i == j {
                    20.0 + b as f64
                } else {
                    0.5 + 0.1 * (i + j) as f64
                }
            });
            whole.set_block(b, &m);
            patched.set_block(b, &m);
        }
        let x: Vec<f64> = (0..n).map(|i| (0.37 * i as f64).sin() + 0.2).collect();
        let apply = |d: &BlockJacobi, threads: usize| {
            par::Threads::new(threads).install(|| {
                let (mut s, mut m, mut sub) = (vec![0.0; n], vec![0.0; n], x.clone());
                d.solve(&x, &mut s);
                d.mul(&x, &mut m);
                d.solve_sub(&x, &mut sub);
                (s, m, sub)
            })
        };
        for threads in [1, 2, 3] {
            assert_eq!(
                apply(&patched, threads),
                apply(&whole, threads),
                "{threads}"
            );
        }
        let (pi, wi) = (patched.inverse_matrix(), whole.inverse_matrix());
        assert_eq!(
            (pi.indptr, pi.indices, pi.values),
            (wi.indptr, wi.indices, wi.values)
        );
        assert_ne!(apply(&patched, 1), apply(&original, 1));
        assert_eq!(
            apply(&original, 1),
            apply(&BlockJacobi::new(&a, &Blocks::contiguous(&bounds)), 1)
        );
    }
}
