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
use crate::linalg::dense::tridiagonal_max_eig;
use crate::linalg::{Csr, LinearOperator};
use nalgebra::DMatrix;

/// Lanczos steps of the λ_max estimate.
const LANCZOS_STEPS: usize = 12;
/// The upper end of the Chebyshev interval is this times the estimate (Lanczos Ritz values
/// approach λ_max from below).
const UPPER: f64 = 1.1;

/// The inverse of the block diagonal of A, and the block diagonal itself.
#[derive(Debug, Clone)]
pub struct BlockJacobi {
    blocks: Blocks,
    /// Per block, its s × s inverse and its s × s diagonal block, row-major; `offset[b]`.
    inv: Vec<f64>,
    diag: Vec<f64>,
    offset: Vec<usize>,
}

impl BlockJacobi {
    pub fn new(a: &Csr, blocks: &Blocks) -> BlockJacobi {
        let mut offset = Vec::with_capacity(blocks.len() + 1);
        offset.push(0);
        for b in 0..blocks.len() {
            let s = blocks.dofs(b).len();
            offset.push(offset[b] + s * s);
        }
        let total = *offset.last().unwrap();
        let (inv, diag) = (vec![0.0; total], vec![0.0; total]);
        let mut jacobi = BlockJacobi {
            blocks: blocks.clone(),
            inv,
            diag,
            offset,
        };
        for b in 0..blocks.len() {
            let dofs = blocks.dofs(b);
            let m = DMatrix::from_fn(dofs.len(), dofs.len(), |i, j| a.get(dofs[i], dofs[j]));
            jacobi.set_block(b, &m);
        }
        jacobi
    }

    /// The node blocks.
    pub fn blocks(&self) -> &Blocks {
        &self.blocks
    }

    /// Makes block b's matrix `m` (s × s, s its DOF count).
    pub fn set_block(&mut self, b: usize, m: &DMatrix<f64>) {
        let s = self.blocks.dofs(b).len();
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
        let o = self.offset[b];
        for i in 0..s {
            for j in 0..s {
                self.inv[o + i * s + j] = mi[(i, j)];
                self.diag[o + i * s + j] = m[(i, j)];
            }
        }
    }

    /// y ← keep·y + M x with M the blocks in `values`.
    fn apply_blocks(&self, values: &[f64], x: &[f64], y: &mut [f64], sign: f64, keep: f64) {
        for b in 0..self.blocks.len() {
            let dofs = self.blocks.dofs(b);
            let s = dofs.len();
            let m = &values[self.offset[b]..self.offset[b] + s * s];
            for i in 0..s {
                let mut v = 0.0;
                for j in 0..s {
                    v += m[i * s + j] * x[dofs[j]];
                }
                y[dofs[i]] = keep * y[dofs[i]] + sign * v;
            }
        }
    }

    /// D⁻¹ as a sparse (block-diagonal) matrix.
    pub fn inverse_matrix(&self) -> Csr {
        let n = self.blocks.n_dofs();
        let mut t = Vec::with_capacity(self.inv.len());
        for b in 0..self.blocks.len() {
            let dofs = self.blocks.dofs(b);
            let s = dofs.len();
            for i in 0..s {
                for j in 0..s {
                    t.push((dofs[i], dofs[j], self.inv[self.offset[b] + i * s + j]));
                }
            }
        }
        Csr::from_triplets(n, n, t)
    }

    /// y ← D⁻¹ x.
    pub fn solve(&self, x: &[f64], y: &mut [f64]) {
        self.apply_blocks(&self.inv, x, y, 1.0, 0.0);
    }

    /// y ← y − D⁻¹ x.
    pub fn solve_sub(&self, x: &[f64], y: &mut [f64]) {
        self.apply_blocks(&self.inv, x, y, -1.0, 1.0);
    }

    /// y ← D x.
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        self.apply_blocks(&self.diag, x, y, 1.0, 0.0);
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
        v.iter()
            .zip(dv.iter())
            .map(|(a, b)| a * b)
            .sum::<f64>()
            .sqrt()
    };
    let s = dnorm(&v, &mut dv);
    v.iter_mut().for_each(|x| *x /= s);
    let mut v_prev = vec![0.0; n];
    let (mut alphas, mut betas) = (Vec::new(), Vec::new());
    let mut beta = 0.0;
    for _ in 0..LANCZOS_STEPS.min(n) {
        a.apply(&v, &mut av);
        d.solve(&av, &mut w);
        let alpha: f64 = av.iter().zip(&v).map(|(a, b)| a * b).sum();
        for i in 0..n {
            w[i] -= alpha * v[i] + beta * v_prev[i];
        }
        alphas.push(alpha);
        beta = dnorm(&w, &mut dv);
        if beta <= 1e-12 * alpha.abs() {
            break;
        }
        betas.push(beta);
        std::mem::swap(&mut v_prev, &mut v);
        v.iter_mut().zip(&w).for_each(|(v, w)| *v = w / beta);
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
        let jacobi = BlockJacobi::new(a, blocks);
        let lambda = lambda_max(a, &jacobi);
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
        a: &impl LinearOperator,
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
            t.copy_from_slice(b);
        } else {
            a.apply(x, t);
            t.iter_mut().zip(b).for_each(|(t, b)| *t = b - *t);
        }
        self.jacobi.solve(t, r);
        d.iter_mut().zip(r.iter()).for_each(|(d, r)| *d = r / theta);
        for k in 0..self.degree {
            x.iter_mut().zip(d.iter()).for_each(|(x, d)| *x += d);
            if k + 1 == self.degree {
                break;
            }
            a.apply(d, t);
            self.jacobi.solve_sub(t, r);
            let rho_next = 1.0 / (2.0 * sigma - rho);
            let (c1, c2) = (rho_next * rho, 2.0 * rho_next / delta);
            d.iter_mut()
                .zip(r.iter())
                .for_each(|(d, r)| *d = c1 * *d + c2 * r);
            rho = rho_next;
        }
    }
}
