//! The velocity HVI (3.13) reduced to the tangential DOFs x ∈ R^m of the Γ3 nodes:
//!
//!   minimise Φ(x) = ½ xᵀ S x − bᵀ x + Σ_i ω_i j(|x_i|),   j(r) = ∫_0^r μ(s) ds,
//!
//! with S the (dense, SPD) Schur complement of the velocity operator, b the reduced load and
//! ω_i the nodal trapezoid weights. The optimality (Clarke stationarity) conditions are, per
//! node, with g = S x − b:
//!   stick:  x_i = 0  and |g_i| ≤ ω_i μ(0),
//!   slip:   x_i ≠ 0  and g_i + ω_i μ(|x_i|) sign(x_i) = 0.
//! Under the (discrete) smallness condition S − diag(ω c2τ) ≻ 0, Φ is strongly convex even
//! for non-convex j, so its stationary point is unique and is the minimiser.
//!
//! Method: a semismooth Newton / active-set iteration (stick/slip prediction from the local
//! force, Newton step on the slip equations), globalised by comparing Φ at the Newton point
//! with Φ after a proximal-gradient step (which always decreases Φ) and keeping the better:
//! global convergence from the gradient step, fast local convergence from Newton. For Tresca
//! the Newton step is exact once the stick/slip partition is right, so it terminates finitely.

use super::friction_node::{self, prox_line as prox};
use super::{SolveError, SolverReport, SolverSettings};
use crate::linalg::dense::solve_principal;

pub use super::reduced::Reduced;

/// Solves the reduced problem from the warm start `x` (overwritten with the solution).
pub fn solve(
    p: &Reduced,
    x: &mut [f64],
    settings: &SolverSettings,
    step: usize,
) -> Result<SolverReport, SolveError> {
    let m = p.nodes();
    // Lipschitz bound of ∇ of the smooth part (Gershgorin) for the proximal-gradient fallback.
    let lip = (0..m)
        .map(|i| (0..m).map(|j| p.s[(i, j)].abs()).sum::<f64>())
        .fold(f64::MIN_POSITIVE, f64::max);
    for it in 0..=settings.max_iterations {
        let g = p.gradient(x);
        let residual = friction_node::kkt_violation(1, &g, x, p.weights, p.law) / p.scale();
        if residual <= settings.tolerance {
            return Ok(SolverReport {
                iterations: it,
                residual,
                krylov_iterations: 0,
            });
        }
        if it == settings.max_iterations {
            return Err(SolveError::NotConverged {
                what: "velocity (friction) solver",
                step,
                iterations: it,
                residual,
                tolerance: settings.tolerance,
            });
        }
        // Candidates: the proximal-gradient step (guaranteed decrease, hence global
        // convergence) and the semismooth Newton point, possibly shortened. The one with the
        // lowest Φ is taken, so Newton's fast local convergence is kept and a poor Newton
        // step can never stall the iteration.
        let c = 1.0 / lip;
        let mut best: Vec<f64> = (0..m)
            .map(|i| prox(p.law, c * p.weights[i], x[i] - c * g[i]))
            .collect();
        let mut best_energy = p.energy(&best);
        // The prox-gradient point identifies the stick/slip partition as it converges; a
        // Newton step on that partition finishes exactly where the local prediction fails.
        let slip: Vec<usize> = (0..m).filter(|&i| best[i] != 0.0).collect();
        let sign: Vec<f64> = slip.iter().map(|&i| best[i].signum()).collect();
        if let Some(t) = newton_on_partition(p, &best, &slip, &sign) {
            let e = p.energy(&t);
            if e < best_energy {
                best = t;
                best_energy = e;
            }
        }
        if let Some(t) = newton_candidate(p, x, &g) {
            let mut alpha = 1.0;
            for _ in 0..4 {
                let y: Vec<f64> = x.iter().zip(&t).map(|(a, b)| a + alpha * (b - a)).collect();
                let e = p.energy(&y);
                if e < best_energy {
                    best = y;
                    best_energy = e;
                    break;
                }
                alpha *= 0.5;
            }
        }
        x.copy_from_slice(&best);
    }
    unreachable!()
}

/// One semismooth Newton step: predict stick/slip from the local force z_i = S_ii x_i − g_i,
/// set stick DOFs to 0, and take a Newton step on the slip equations with the signs fixed.
fn newton_candidate(p: &Reduced, x: &[f64], g: &[f64]) -> Option<Vec<f64>> {
    let mut slip = Vec::new();
    let mut sign = Vec::new();
    for i in 0..p.nodes() {
        let z = p.s[(i, i)] * x[i] - g[i];
        if z.abs() > p.weights[i] * p.law.mu(0.0) {
            slip.push(i);
            sign.push(z.signum());
        }
    }
    newton_on_partition(p, x, &slip, &sign)
}

/// Newton step on the slip equations g_i + ω_i μ(|x_i|) s_i = 0 (i in `slip`, signs `sign`)
/// from `x`, with every other DOF stuck at 0. For Tresca μ' = 0 and this is the exact
/// solution for that partition.
fn newton_on_partition(p: &Reduced, x: &[f64], slip: &[usize], sign: &[f64]) -> Option<Vec<f64>> {
    let mut y = vec![0.0; p.nodes()];
    for &i in slip {
        y[i] = x[i];
    }
    if slip.is_empty() {
        return Some(y);
    }
    // Residual of the slip equations at y (stick DOFs zeroed), and the Jacobian
    // S_FF + diag(ω μ'(r)).
    let mut jac = p.s.clone();
    let mut rhs = Vec::with_capacity(slip.len());
    for (k, &i) in slip.iter().enumerate() {
        let r = (sign[k] * y[i]).max(0.0);
        let si: f64 = slip.iter().map(|&j| p.s[(i, j)] * y[j]).sum();
        rhs.push(-(si - p.b[i] + p.weights[i] * p.law.mu(r) * sign[k]));
        jac[(i, i)] += p.weights[i] * p.law.dmu(r);
    }
    let delta = solve_principal(&jac, slip, &rhs)?;
    for (k, &i) in slip.iter().enumerate() {
        y[i] += delta[k];
    }
    Some(y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::FrictionLaw;

    use nalgebra::DMatrix;
    use proptest::prelude::RngExt;
    use proptest::test_runner::{RngAlgorithm, TestRng};

    /// A reproducible random stream.
    fn seeded(seed: u8) -> TestRng {
        TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32])
    }

    fn random_spd(rng: &mut TestRng, m: usize, shift: f64) -> DMatrix<f64> {
        let a = DMatrix::from_fn(m, m, |_, _| rng.random::<f64>() - 0.5);
        &a * a.transpose() + DMatrix::identity(m, m) * shift
    }

    /// Checks the stick/slip conditions directly (independent of the solver's own residual).
    fn assert_kkt(p: &Reduced, x: &[f64], tol: f64) {
        let g = p.gradient(x);
        let scale = p.b.iter().fold(1e-300f64, |s, v| s.max(v.abs()));
        for i in 0..x.len() {
            let w = p.weights[i];
            if x[i] == 0.0 {
                assert!(
                    g[i].abs() <= w * p.law.mu(0.0) + tol * scale,
                    "stick violated at {i}"
                );
            } else {
                let force = -g[i];
                assert!(
                    (force - w * p.law.mu(x[i].abs()) * x[i].signum()).abs() <= tol * scale,
                    "slip violated at {i}"
                );
                // The reaction −g balances friction, which opposes the slip velocity.
                assert!(force * x[i].signum() >= -tol * scale);
            }
        }
    }

    #[test]
    fn tresca_random_problems_satisfy_kkt() {
        let mut rng = seeded(0x9e);
        for trial in 0..200 {
            let m = 1 + (trial % 17);
            let shift = 0.1 + rng.random::<f64>();
            let s = random_spd(&mut rng, m, shift);
            let b: Vec<f64> = (0..m).map(|_| 4.0 * (rng.random::<f64>() - 0.5)).collect();
            let weights: Vec<f64> = (0..m).map(|_| 0.05 + rng.random::<f64>()).collect();
            let law = FrictionLaw::Tresca {
                g: rng.random::<f64>() * 2.0,
            };
            let p = Reduced {
                s: &s,
                b: &b,
                weights: &weights,
                law: &law,
                scale: None,
            };
            let mut x = vec![0.0; m];
            let rep = solve(&p, &mut x, &SolverSettings::default(), 0).unwrap();
            assert!(rep.residual <= 1e-10);
            assert_kkt(&p, &x, 1e-9);
            // Minimality: Φ does not decrease under random perturbations (convex case).
            let e = p.energy(&x);
            for _ in 0..20 {
                let y: Vec<f64> = x
                    .iter()
                    .map(|v| v + 1e-3 * (rng.random::<f64>() - 0.5))
                    .collect();
                assert!(p.energy(&y) >= e - 1e-12);
            }
        }
    }

    #[test]
    fn nonconvex_laws_under_smallness_satisfy_kkt() {
        let mut rng = seeded(42);
        let laws = [
            FrictionLaw::SlipWeakening {
                mu0: 1.2,
                mu1: 0.4,
                alpha: 3.0,
            },
            FrictionLaw::PiecewiseLinear {
                points: vec![[0.0, 1.0], [0.3, 0.5], [1.0, 0.6]],
            },
        ];
        for trial in 0..200 {
            let law = &laws[trial % 2];
            let m = 1 + (trial % 13);
            let weights: Vec<f64> = (0..m).map(|_| 0.05 + 0.5 * rng.random::<f64>()).collect();
            // Make S − diag(ω c2) ≻ 0: shift by max ω · c2 plus a margin.
            let c2 = law.relaxed_monotonicity();
            let wmax = weights.iter().cloned().fold(0.0, f64::max);
            let s = random_spd(&mut rng, m, wmax * c2 + 0.05);
            let b: Vec<f64> = (0..m).map(|_| 3.0 * (rng.random::<f64>() - 0.5)).collect();
            let p = Reduced {
                s: &s,
                b: &b,
                weights: &weights,
                law,
                scale: None,
            };
            let mut x: Vec<f64> = (0..m).map(|_| rng.random::<f64>() - 0.5).collect();
            let rep = solve(&p, &mut x, &SolverSettings::default(), 0).unwrap();
            assert!(rep.residual <= 1e-10, "{rep:?}");
            assert_kkt(&p, &x, 1e-9);
        }
    }

    #[test]
    fn adversarial_degenerate_cases() {
        // Forces exactly at the friction bound, zero weights, and a huge bound.
        let s = DMatrix::from_row_slice(2, 2, &[2.0, -1.0, -1.0, 2.0]);
        for (b, w, g) in [
            (vec![1.0, -1.0], vec![1.0, 1.0], 1.0),
            (vec![1.0, 0.5], vec![0.0, 0.0], 5.0),
            (vec![1e3, -1e3], vec![1.0, 1.0], 1e4),
            (vec![0.0, 0.0], vec![1.0, 1.0], 0.0),
        ] {
            let law = FrictionLaw::Tresca { g };
            let p = Reduced {
                s: &s,
                b: &b,
                weights: &w,
                law: &law,
                scale: None,
            };
            let mut x = vec![0.3, -0.7];
            let rep = solve(&p, &mut x, &SolverSettings::default(), 0).unwrap();
            assert!(rep.residual <= 1e-10);
            assert_kkt(&p, &x, 1e-9);
        }
    }
}
