//! Initial guesses for a sequence of systems A x_j = b_j with one SPD matrix A and slowly
//! varying right-hand sides (the velocity step's K_II y_n = f_{I,n}): the A-orthogonal
//! projection of the new solution onto the span of the earlier ones (Fischer, "Projection
//! techniques for iterative solution of Ax = b with successive right-hand sides", Comput.
//! Methods Appl. Mech. Engrg. 163 (1998)).
//!
//! With an A-orthonormal basis x̃_1 … x̃_l of the span (x̃_iᵀ A x̃_j = δ_ij), the projection of
//! x = A⁻¹b is
//!   x̄ = Σ_i (x̃_iᵀ b) x̃_i,
//! which needs b only, not x: it minimises ‖x − x̄‖_A over the span, so it is at least as good
//! as any extrapolation of the earlier solutions (linear, quadratic, …), which all lie in it.
//! After the solve, d = x − x̄ is A-orthogonal to the span up to the solve's tolerance; it is
//! orthogonalised once more (classical Gram–Schmidt in the A inner product, one product with
//! A) and normalised into the next basis vector.
//!
//! Every solution lies in the span, so its coordinates c_j (x_j = Σ_i c_ji x̃_i) are known
//! without further products, and A-inner products of solutions are Euclidean ones of their
//! coordinates. A full basis is compressed to the span of the newest half of the solutions
//! (orthonormalised in coordinates, then formed from the basis): the long history is what
//! makes the guess good (measured on box-exp3: 3–6 iterations against 13–15 with linear
//! extrapolation), so it is shortened only as far as the memory budget requires.
//!
//! The guess changes only where the iteration starts: the solve still runs to its own residual.

use super::{par, LinearOperator};
use std::collections::VecDeque;

/// The basis size the velocity step keeps: on box-exp3 (1/24) the solves after the first
/// steps take 3–5 iterations with 12, 5–8 with 8 (each an n_I-vector; 15 MB a vector at 1/64).
pub const CAPACITY: usize = 12;

/// A basis vector is added only when x − x̄, orthogonalised once more, keeps this fraction of
/// ‖x‖_A (otherwise it is rounding or solver noise, not a new direction).
const NEW_DIRECTION: f64 = 1e-10;

/// The A-orthonormal basis spanned by the earlier solutions, their coordinates, and the
/// last guess.
#[derive(Debug, Clone)]
pub struct SolutionSpace {
    capacity: usize,
    basis: Vec<Vec<f64>>,
    /// Coordinates of the newest solutions in the basis (shorter ones: zeros beyond).
    history: VecDeque<Vec<f64>>,
    /// x̃_iᵀ b of the last [`SolutionSpace::project`]: the coordinates of x̄.
    coefficients: Vec<f64>,
    /// x̄ of the last [`SolutionSpace::project`].
    guess: Vec<f64>,
    /// A d, scratch.
    ad: Vec<f64>,
}

/// aᵀb: in fixed chunks on the pool's threads for the n-vectors ([`par::dot`]), the same
/// bits for any thread count.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    par::dot(a, b)
}

impl SolutionSpace {
    /// An empty space of systems of size `n`, holding at most `capacity` (≥ 2) basis vectors.
    pub fn new(n: usize, capacity: usize) -> SolutionSpace {
        let capacity = capacity.max(2);
        SolutionSpace {
            capacity,
            basis: Vec::with_capacity(capacity),
            history: VecDeque::with_capacity(capacity),
            coefficients: Vec::with_capacity(capacity),
            guess: vec![0.0; n],
            ad: vec![0.0; n],
        }
    }

    /// The n-vectors a space of `capacity` holds at most (basis, guess, d, A d): for memory
    /// budgets.
    pub fn vectors(capacity: usize) -> usize {
        capacity.max(2) + 3
    }

    /// Current basis size l.
    pub fn len(&self) -> usize {
        self.basis.len()
    }

    pub fn is_empty(&self) -> bool {
        self.basis.is_empty()
    }

    /// Forgets every earlier solution.
    pub fn clear(&mut self) {
        self.basis.clear();
        self.history.clear();
        self.coefficients.clear();
        self.guess.iter_mut().for_each(|v| *v = 0.0);
    }

    /// x ← x̄ = Σ_i (x̃_iᵀ b) x̃_i, the A-orthogonal projection of A⁻¹ b onto the span (zero
    /// when the span is empty).
    pub fn project(&mut self, b: &[f64], x: &mut [f64]) {
        let c = self.coordinates(b);
        self.combine(&c, x);
    }

    /// The basis x̃_1 … x̃_l.
    pub fn basis(&self) -> &[Vec<f64>] {
        &self.basis
    }

    /// x̃_iᵀ b for each basis vector (the coordinates of the projection of A⁻¹ b).
    pub fn coordinates(&self, b: &[f64]) -> Vec<f64> {
        self.basis.iter().map(|v| dot(v, b)).collect()
    }

    /// Coordinates of the newest solution added (x = Σ_i c_i x̃_i), if any.
    pub fn newest(&self) -> Option<Vec<f64>> {
        self.history.back().map(|c| {
            let mut c = c.clone();
            c.resize(self.basis.len(), 0.0);
            c
        })
    }

    /// x ← Σ_i c_i x̃_i, which becomes the guess that the next [`SolutionSpace::extend`]
    /// measures the new solution from.
    pub fn combine(&mut self, c: &[f64], x: &mut [f64]) {
        assert_eq!(c.len(), self.basis.len());
        let basis = &self.basis;
        // Entry by entry the sum runs over the basis in order: the same bits on any split.
        par::for_each_chunk_mut(x, par::VECTOR_CHUNK, |start, xc| {
            let range = start..start + xc.len();
            xc.fill(0.0);
            for (v, &c) in basis.iter().zip(c) {
                xc.iter_mut()
                    .zip(&v[range.clone()])
                    .for_each(|(x, v)| *x += c * v);
            }
        });
        self.coefficients.clear();
        self.coefficients.extend_from_slice(c);
        par::copy(&mut self.guess, x);
    }

    /// Adds the solution `x` of the system whose guess [`SolutionSpace::project`] (or
    /// [`SolutionSpace::combine`]) gave last:
    /// d = x − x̄, d ← d − Σ_i (x̃_iᵀ A d) x̃_i, x̃_{l+1} = d / ‖d‖_A. One product with `a`:
    /// A d taken as the solve's true initial minus final residual, (b − A x̄) − (b − A x),
    /// carries the rounding of those products, about ε‖|A||x|‖ (K's condition times ε‖b‖),
    /// which as the guesses improve is no longer small against ‖A d‖ and degrades the basis
    /// (measured on box-exp3 at 1/32: 12–13 iterations a step from step 11 on, instead of 2–4).
    pub fn extend(&mut self, a: &(impl LinearOperator + ?Sized), x: &[f64]) {
        let mut d = vec![0.0; x.len()];
        par::copy(&mut d, x);
        par::zip_apply(&mut d, &self.guess, |x, g| x - g);
        a.apply(&d, &mut self.ad);
        let ad = &self.ad;
        let before = dot(&d, ad);
        let mut after = before;
        let mut coordinates = self.coefficients.clone();
        for (v, c_x) in self.basis.iter().zip(coordinates.iter_mut()) {
            let c = dot(v, ad);
            par::zip_apply(&mut d, v, |d, v| d - c * v);
            after -= c * c;
            *c_x += c;
        }
        // ‖x‖²_A = ‖x̄‖²_A + ‖x − x̄‖²_A, with ‖x̄‖²_A = Σ_i c_i² in the orthonormal basis.
        let x_norm2 = self.coefficients.iter().map(|c| c * c).sum::<f64>() + before;
        if before > 0.0 && after > (NEW_DIRECTION * NEW_DIRECTION) * x_norm2 {
            let norm = after.sqrt();
            par::for_each_chunk_mut(&mut d, par::VECTOR_CHUNK, |_, dc| {
                dc.iter_mut().for_each(|v| *v /= norm)
            });
            self.basis.push(d);
            coordinates.push(norm);
        }
        if self.history.len() == self.capacity {
            self.history.pop_front();
        }
        self.history.push_back(coordinates);
        if self.basis.len() >= self.capacity {
            self.compress();
        }
    }

    /// Replaces the basis by an A-orthonormal basis of the newest capacity/2 solutions:
    /// modified Gram–Schmidt (twice) on their coordinates gives Q (l × r, orthonormal
    /// columns), and the new basis is X̃ Q.
    fn compress(&mut self) {
        let l = self.basis.len();
        let keep = (self.capacity / 2).min(self.history.len());
        let newest: Vec<Vec<f64>> = self
            .history
            .iter()
            .skip(self.history.len() - keep)
            .map(|c| {
                let mut c = c.clone();
                c.resize(l, 0.0);
                c
            })
            .collect();
        let mut q: Vec<Vec<f64>> = Vec::with_capacity(keep);
        for c in newest.iter().rev() {
            let norm0 = dot(c, c).sqrt();
            let mut v = c.clone();
            for _ in 0..2 {
                for u in &q {
                    let s = dot(u, &v);
                    v.iter_mut().zip(u).for_each(|(v, u)| *v -= s * u);
                }
            }
            let norm = dot(&v, &v).sqrt();
            if norm > NEW_DIRECTION * norm0 {
                v.iter_mut().for_each(|x| *x /= norm);
                q.push(v);
            }
        }
        // X̃ ← X̃ Q in place, one entry position at a time (no second basis in memory).
        let n = self.guess.len();
        let (l, r) = (self.basis.len(), q.len());
        let mut row = vec![0.0; l];
        for p in 0..n {
            for (v, x) in row.iter_mut().zip(&self.basis) {
                *v = x[p];
            }
            for (k, col) in q.iter().enumerate() {
                self.basis[k][p] = dot(col, &row);
            }
        }
        self.basis.truncate(r);
        debug_assert!(r <= l);
        self.history = newest
            .iter()
            .map(|c| q.iter().map(|col| dot(col, c)).collect())
            .collect();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::cholesky::tests::laplace_1d;
    use crate::linalg::Csr;

    fn a_dot(a: &Csr, x: &[f64], y: &[f64]) -> f64 {
        let mut ay = vec![0.0; y.len()];
        a.mul_vec(y, &mut ay);
        dot(x, &ay)
    }

    fn solve_exact(a: &Csr, b: &[f64]) -> Vec<f64> {
        let mut c = crate::linalg::Cholesky::new(a.lower_csc().as_ref()).unwrap();
        let mut x = b.to_vec();
        c.solve_in_place(&mut x);
        x
    }

    #[test]
    fn basis_is_a_orthonormal_and_the_guess_is_the_a_projection() {
        let n = 30;
        let a = laplace_1d(n);
        let mut space = SolutionSpace::new(n, 5);
        let mut xs = Vec::new();
        for j in 0..4 {
            let b: Vec<f64> = (0..n)
                .map(|i| ((i + 1) as f64 * (0.2 + 0.37 * j as f64)).sin())
                .collect();
            let mut g = vec![0.0; n];
            space.project(&b, &mut g);
            let x = solve_exact(&a, &b);
            space.extend(&a, &x);
            xs.push(x);
        }
        assert_eq!(space.len(), 4);
        for i in 0..4 {
            for j in 0..4 {
                let g = a_dot(&a, &space.basis[i], &space.basis[j]);
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((g - want).abs() < 1e-10, "({i},{j}): {g}");
            }
        }
        // A right-hand side in the span of the earlier ones is solved by the guess alone.
        let b5: Vec<f64> = (0..n)
            .map(|i| {
                let t = (i + 1) as f64;
                2.0 * (t * 0.2).sin() - 0.5 * (t * 0.57).sin() + 3.0 * (t * 1.31).sin()
            })
            .collect();
        let mut g = vec![0.0; n];
        space.project(&b5, &mut g);
        let x5 = solve_exact(&a, &b5);
        let err = g
            .iter()
            .zip(&x5)
            .map(|(g, x)| (g - x).abs())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-9 * x5.iter().fold(0.0f64, |m, v| m.max(v.abs())),
            "{err}"
        );
        // Outside the span, the guess minimises the A-norm error over it: its error is
        // A-orthogonal to every basis vector.
        let b6: Vec<f64> = (0..n).map(|i| ((i * i) as f64 * 0.01).cos()).collect();
        space.project(&b6, &mut g);
        let x6 = solve_exact(&a, &b6);
        let e: Vec<f64> = x6.iter().zip(&g).map(|(x, g)| x - g).collect();
        for v in &space.basis {
            assert!(a_dot(&a, v, &e).abs() < 1e-10 * a_dot(&a, &x6, &x6).sqrt());
        }
    }

    #[test]
    fn a_repeated_solution_adds_nothing_and_a_full_space_keeps_the_newest_half() {
        let n = 20;
        let a = laplace_1d(n);
        let mut space = SolutionSpace::new(n, 4);
        let rhs = |j: usize| -> Vec<f64> {
            (0..n)
                .map(|i| ((i + 1) as f64 * (0.15 + 0.41 * j as f64)).sin() + 0.1 * j as f64)
                .collect()
        };
        let mut g = vec![0.0; n];
        let b0 = rhs(0);
        let x0 = solve_exact(&a, &b0);
        for _ in 0..2 {
            space.project(&b0, &mut g);
            space.extend(&a, &x0);
        }
        assert_eq!(space.len(), 1, "the same solution twice is one direction");
        let xs: Vec<Vec<f64>> = (1..4).map(|j| solve_exact(&a, &rhs(j))).collect();
        for (j, x) in xs.iter().enumerate() {
            space.project(&rhs(j + 1), &mut g);
            space.extend(&a, x);
        }
        // The fourth direction filled it: the span is now that of the two newest solutions.
        assert_eq!(space.len(), 2);
        for i in 0..2 {
            for j in 0..2 {
                let g = a_dot(&a, &space.basis[i], &space.basis[j]);
                assert!((g - if i == j { 1.0 } else { 0.0 }).abs() < 1e-10);
            }
        }
        let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (j, x) in xs.iter().enumerate() {
            space.project(&rhs(j + 1), &mut g);
            let err = max(&g.iter().zip(x).map(|(g, x)| g - x).collect::<Vec<_>>());
            if j >= 1 {
                assert!(err < 1e-10 * max(x), "solution {j} is kept: {err}");
            } else {
                assert!(err > 1e-6 * max(x), "solution {j} was dropped: {err}");
            }
        }
    }
}
