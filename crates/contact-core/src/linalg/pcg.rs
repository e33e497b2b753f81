//! Preconditioned conjugate gradients for an SPD system A x = b with an SPD preconditioner
//! B ≈ A⁻¹ (Hestenes–Stiefel; Saad, Iterative Methods, Alg. 9.1).
//!
//! Stopping is on the **max-norm** residual ‖b − A x‖∞ ≤ `atol`, the norm in which the
//! sub-problem solvers state their KKT residuals, so a caller asks for exactly what it checks
//! afterwards. The recursive residual drifts from the true one in long runs; at the end the
//! true residual is recomputed and, if it misses the target, the iteration restarts from the
//! current x (at most [`RESTARTS`] times).

use super::par::{self, dot, max_abs};
use super::LinearOperator;

/// Restarts from the true residual when the recursive one has drifted.
const RESTARTS: usize = 2;

/// z ← B r for an SPD preconditioner B.
pub trait Preconditioner {
    fn apply(&mut self, r: &[f64], z: &mut [f64]);
}

/// The identity (plain CG), for tests and tiny systems.
pub struct Identity;

impl Preconditioner for Identity {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        z.copy_from_slice(r);
    }
}

/// How a solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PcgReport {
    pub iterations: usize,
    /// True residual ‖b − A x‖∞ at exit.
    pub residual: f64,
    pub converged: bool,
    /// pᵀ A p ≤ 0 was met (A not positive definite on the Krylov space): x is the last
    /// iterate before that direction.
    pub negative_curvature: bool,
}

/// Work vectors of one system size, owned by the caller and reused across solves.
#[derive(Debug, Clone, Default)]
pub struct PcgWork {
    r: Vec<f64>,
    z: Vec<f64>,
    p: Vec<f64>,
    q: Vec<f64>,
}

impl PcgWork {
    /// b − A x of the last solve's x, computed afresh at its end (not the recursive one).
    pub fn residual(&self) -> &[f64] {
        &self.r
    }

    pub fn new(n: usize) -> Self {
        PcgWork {
            r: vec![0.0; n],
            z: vec![0.0; n],
            p: vec![0.0; n],
            q: vec![0.0; n],
        }
    }
}

/// r ← b − A x.
fn residual(a: &(impl LinearOperator + ?Sized), b: &[f64], x: &[f64], r: &mut [f64]) {
    a.apply(x, r);
    par::zip_apply(r, b, |r, b| b - r);
}

/// x ← x + α p, r ← r − α q, and ‖r‖∞ of the new r, in one pass over the four vectors.
fn step(alpha: f64, p: &[f64], q: &[f64], x: &mut [f64], r: &mut [f64]) -> f64 {
    par::map_chunks2_mut(x, r, par::VECTOR_CHUNK, |s, xc, rc| {
        let (pc, qc) = (&p[s..s + xc.len()], &q[s..s + xc.len()]);
        let mut m = 0.0f64;
        for (((x, r), p), q) in xc.iter_mut().zip(rc.iter_mut()).zip(pc).zip(qc) {
            *x += alpha * p;
            *r -= alpha * q;
            m = m.max(r.abs());
        }
        m
    })
    .into_iter()
    .fold(0.0, f64::max)
}

/// Solves A x = b from the initial guess in `x` (a warm start) until ‖b − A x‖∞ ≤ `atol`
/// or `max_iterations` products with A have been made.
pub fn solve(
    a: &(impl LinearOperator + ?Sized),
    precond: &mut dyn Preconditioner,
    b: &[f64],
    x: &mut [f64],
    atol: f64,
    max_iterations: usize,
    work: &mut PcgWork,
) -> PcgReport {
    let n = b.len();
    assert_eq!(a.dim(), n);
    if work.r.len() != n {
        *work = PcgWork::new(n);
    }
    let PcgWork { r, z, p, q } = work;
    let mut iterations = 0;
    let mut negative_curvature = false;
    if x.iter().all(|&v| v == 0.0) {
        // A cold start: r = b, without a product.
        par::copy(r, b);
    } else {
        residual(a, b, x, r);
    }
    let mut res = max_abs(r);
    for _ in 0..=RESTARTS {
        if res <= atol || iterations >= max_iterations || negative_curvature {
            break;
        }
        precond.apply(r, z);
        par::copy(p, z);
        let mut rz = dot(r, z);
        while iterations < max_iterations {
            a.apply(p, q);
            iterations += 1;
            let pq = dot(p, q);
            if pq <= 0.0 || !pq.is_finite() {
                negative_curvature = pq <= 0.0;
                break;
            }
            let alpha = rz / pq;
            if step(alpha, p, q, x, r) <= atol {
                break;
            }
            precond.apply(r, z);
            let rz_next = dot(r, z);
            let beta = rz_next / rz;
            rz = rz_next;
            par::zip_apply(p, z, |p, z| z + beta * p);
        }
        residual(a, b, x, r);
        res = max_abs(r);
    }
    PcgReport {
        iterations,
        residual: res,
        converged: res <= atol,
        negative_curvature,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::cholesky::tests::laplace_1d;

    #[test]
    fn plain_cg_solves_in_at_most_n_steps_and_warm_start_is_free() {
        let n = 40;
        let a = laplace_1d(n);
        let xs: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).cos()).collect();
        let mut b = vec![0.0; n];
        a.mul_vec(&xs, &mut b);
        let mut x = vec![0.0; n];
        let mut work = PcgWork::default();
        let rep = solve(&a, &mut Identity, &b, &mut x, 1e-12, 200, &mut work);
        assert!(rep.converged && rep.iterations <= n + 2, "{rep:?}");
        for (u, v) in x.iter().zip(&xs) {
            assert!((u - v).abs() < 1e-9);
        }
        let again = solve(&a, &mut Identity, &b, &mut x, 1e-12, 200, &mut work);
        assert_eq!(again.iterations, 0);
    }

    #[test]
    fn indefinite_direction_is_detected() {
        let mut a = laplace_1d(5);
        a.values.iter_mut().for_each(|v| *v = -*v);
        let mut x = vec![0.0; 5];
        let rep = solve(
            &a,
            &mut Identity,
            &[1.0; 5],
            &mut x,
            1e-12,
            50,
            &mut PcgWork::default(),
        );
        assert!(rep.negative_curvature && !rep.converged);
    }
}
