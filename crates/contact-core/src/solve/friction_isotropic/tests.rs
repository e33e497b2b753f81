use super::*;
use crate::problem::FrictionLaw;
use crate::solve::friction_reduced;
use nalgebra::DMatrix;

use proptest::prelude::RngExt;
use proptest::test_runner::{RngAlgorithm, TestRng};

/// The tolerance the velocity step passes (half its own).
const TOL: f64 = 0.5e-10;

/// A reproducible random stream.
fn seeded(seed: u8) -> TestRng {
    TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32])
}

fn uniform(rng: &mut TestRng) -> f64 {
    rng.random::<f64>() - 0.5
}

fn random_spd(rng: &mut TestRng, n: usize, shift: f64) -> DMatrix<f64> {
    let a = DMatrix::from_fn(n, n, |_, _| uniform(rng));
    &a * a.transpose() + DMatrix::identity(n, n) * shift
}

fn random_vec(rng: &mut TestRng, n: usize, amplitude: f64) -> Vec<f64> {
    (0..n).map(|_| amplitude * uniform(rng)).collect()
}

fn settings(tolerance: f64) -> SolverSettings {
    SolverSettings {
        tolerance,
        ..SolverSettings::default()
    }
}

/// The problem's data, owned.
struct Data {
    s: DMatrix<f64>,
    b: Vec<f64>,
    w: Vec<f64>,
    law: FrictionLaw,
}

impl Data {
    fn reduced(&self) -> Reduced<'_> {
        Reduced {
            s: &self.s,
            b: &self.b,
            weights: &self.w,
            law: &self.law,
            scale: None,
        }
    }

    /// Solves from `x0` to `tolerance`, panicking on failure.
    fn solve_from(&self, x0: &[f64], tolerance: f64) -> (Vec<f64>, SolverReport) {
        let mut x = x0.to_vec();
        let rep = solve(&self.reduced(), &mut x, &settings(tolerance), 0)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(rep.residual <= tolerance, "{rep:?}");
        (x, rep)
    }

    /// g = S x − b by plain loops (independent of the solver's product).
    fn gradient(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        (0..n)
            .map(|i| (0..n).map(|j| self.s[(i, j)] * x[j]).sum::<f64>() - self.b[i])
            .collect()
    }

    /// Φ(x) by plain loops.
    fn energy(&self, x: &[f64]) -> f64 {
        let n = x.len();
        let mut e = 0.0;
        for i in 0..n {
            for j in 0..n {
                e += 0.5 * x[i] * self.s[(i, j)] * x[j];
            }
            e -= self.b[i] * x[i];
        }
        for (i, w) in self.w.iter().enumerate() {
            e += w * self
                .law
                .potential((x[2 * i].powi(2) + x[2 * i + 1].powi(2)).sqrt());
        }
        e
    }

    /// The stick/slip conditions checked directly, node by node: a stuck node is exactly 0
    /// and its force is within the friction disc; a slipping node's force −g_i has magnitude
    /// ω_i μ(|x_i|) and the direction of x_i.
    fn assert_kkt(&self, x: &[f64], tol: f64) {
        let g = self.gradient(x);
        let scale = self.b.iter().fold(1e-300f64, |s, v| s.max(v.abs()));
        for (i, &w) in self.w.iter().enumerate() {
            let (x0, x1) = (x[2 * i], x[2 * i + 1]);
            let (f0, f1) = (-g[2 * i], -g[2 * i + 1]);
            let force = (f0 * f0 + f1 * f1).sqrt();
            if x0 == 0.0 && x1 == 0.0 {
                assert!(
                    force <= w * self.law.mu(0.0) + tol * scale,
                    "stick violated at node {i}: |force| {force} > {}",
                    w * self.law.mu(0.0)
                );
            } else {
                let r = (x0 * x0 + x1 * x1).sqrt();
                let bound = w * self.law.mu(r);
                assert!(
                    (force - bound).abs() <= tol * scale,
                    "slip magnitude violated at node {i}: {force} vs {bound}"
                );
                // Parallel: the cross product vanishes and the dot product is positive.
                assert!(
                    (f0 * x1 - f1 * x0).abs() <= tol * scale * r,
                    "slip direction violated at node {i}"
                );
                assert!(f0 * x0 + f1 * x1 >= -tol * scale * r);
            }
        }
    }

    /// Φ does not decrease under random perturbations of x: small ones everywhere, one node
    /// moved off or onto 0, and one node's slip rotated.
    fn assert_minimal(&self, x: &[f64], rng: &mut TestRng) {
        let e = self.energy(x);
        let slack = 1e-11 * (1.0 + e.abs());
        let m = self.w.len();
        for trial in 0..30 {
            let mut y = x.to_vec();
            let i = rng.random_range(0..m);
            match trial % 3 {
                0 => y.iter_mut().for_each(|v| *v += 1e-3 * uniform(rng)),
                1 => {
                    if y[2 * i] == 0.0 && y[2 * i + 1] == 0.0 {
                        y[2 * i] = 1e-4 * uniform(rng);
                        y[2 * i + 1] = 1e-4 * uniform(rng);
                    } else {
                        y[2 * i] = 0.0;
                        y[2 * i + 1] = 0.0;
                    }
                }
                _ => {
                    let t: f64 = 0.01 * uniform(rng);
                    let (c, s) = (t.cos(), t.sin());
                    let (a, b) = (y[2 * i], y[2 * i + 1]);
                    y[2 * i] = c * a - s * b;
                    y[2 * i + 1] = s * a + c * b;
                }
            }
            let ey = self.energy(&y);
            assert!(
                ey >= e - slack,
                "Φ decreased from {e} to {ey} (trial {trial})"
            );
        }
    }
}

fn random_tresca(rng: &mut TestRng, m: usize) -> Data {
    let shift = 0.1 + rng.random::<f64>();
    Data {
        s: random_spd(rng, 2 * m, shift),
        b: random_vec(rng, 2 * m, 4.0),
        w: (0..m).map(|_| 0.05 + rng.random::<f64>()).collect(),
        law: FrictionLaw::Tresca {
            g: 3.0 * rng.random::<f64>(),
        },
    }
}

#[test]
fn tresca_random_problems_satisfy_kkt_and_minimise() {
    let mut rng = seeded(0x3d);
    let mut most = 0;
    let (mut slip, mut stick) = (0, 0);
    for trial in 0..200 {
        let m = [1, 2, 3, 5, 8, 13, 21, 40][trial % 8];
        let d = random_tresca(&mut rng, m);
        // Cold and warm (random) starts.
        let x0 = if trial % 2 == 0 {
            vec![0.0; 2 * m]
        } else {
            random_vec(&mut rng, 2 * m, 1.0)
        };
        let (x, rep) = d.solve_from(&x0, TOL);
        d.assert_kkt(&x, 1e-9);
        d.assert_minimal(&x, &mut rng);
        most = most.max(rep.iterations);
        for i in 0..m {
            if x[2 * i] == 0.0 && x[2 * i + 1] == 0.0 {
                stick += 1;
            } else {
                slip += 1;
            }
        }
    }
    // Both regimes occur, and Newton (not the gradient fallback) does the work.
    assert!(slip > 300 && stick > 300, "slip {slip}, stick {stick}");
    assert!(most <= 30, "{most} iterations");
}

#[test]
fn nonconvex_laws_under_smallness_satisfy_kkt_and_minimise() {
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
        let law = laws[trial % 2].clone();
        let m = 1 + (trial % 17);
        let w: Vec<f64> = (0..m).map(|_| 0.05 + 0.5 * rng.random::<f64>()).collect();
        // S − diag(ω c2) ≻ 0: shift by max ω · c2 plus a margin (checked below).
        let c2 = law.relaxed_monotonicity();
        let wmax = w.iter().cloned().fold(0.0, f64::max);
        let s = random_spd(&mut rng, 2 * m, wmax * c2 + 0.05);
        let relaxed = DMatrix::from_fn(2 * m, 2 * m, |i, j| {
            s[(i, j)] - if i == j { w[i / 2] * c2 } else { 0.0 }
        });
        assert!(relaxed.symmetric_eigenvalues().min() > 0.0);
        let d = Data {
            s,
            b: random_vec(&mut rng, 2 * m, 3.0),
            w,
            law,
        };
        let x0 = random_vec(&mut rng, 2 * m, 1.0);
        let (x, _) = d.solve_from(&x0, TOL);
        d.assert_kkt(&x, 1e-9);
        // Strongly convex under the smallness condition: the stationary point is the minimum.
        d.assert_minimal(&x, &mut rng);
    }
}

#[test]
fn adversarial_cases() {
    let tresca = |g| FrictionLaw::Tresca { g };
    let iso = |m: usize, a: f64| DMatrix::identity(2 * m, 2 * m) * a;
    // Two nodes coupled in both components: S = [[2I, −I], [−I, 2I]].
    let coupled = DMatrix::from_fn(4, 4, |i, j| match (i == j, i % 2 == j % 2) {
        (true, _) => 2.0,
        (false, true) => -1.0,
        _ => 0.0,
    });
    let cases: Vec<(&str, Data, Vec<f64>)> = vec![
        // |b_i| = 5 = ω g exactly: x = 0 with the force on the bound.
        (
            "force at the bound",
            Data {
                s: coupled.clone(),
                b: vec![3.0, 4.0, -4.0, 3.0],
                w: vec![1.0, 1.0],
                law: tresca(5.0),
            },
            vec![0.0; 4],
        ),
        (
            "zero weights",
            Data {
                s: coupled.clone(),
                b: vec![1.0, 0.5, -2.0, 0.25],
                w: vec![0.0, 0.0],
                law: tresca(5.0),
            },
            {
                let b = nalgebra::DVector::from_vec(vec![1.0, 0.5, -2.0, 0.25]);
                coupled
                    .clone()
                    .cholesky()
                    .unwrap()
                    .solve(&b)
                    .as_slice()
                    .to_vec()
            },
        ),
        (
            "huge bound",
            Data {
                s: coupled.clone(),
                b: vec![1e3, -1e3, 5e2, 7e2],
                w: vec![1.0, 1.0],
                law: tresca(1e6),
            },
            vec![0.0; 4],
        ),
        (
            "zero load",
            Data {
                s: coupled.clone(),
                b: vec![0.0; 4],
                w: vec![1.0, 1.0],
                law: tresca(0.5),
            },
            vec![0.0; 4],
        ),
        (
            "zero load, no friction",
            Data {
                s: coupled.clone(),
                b: vec![0.0; 4],
                w: vec![1.0, 1.0],
                law: tresca(0.0),
            },
            vec![0.0; 4],
        ),
        // One node, S = 2I: x = (|b| − ω g)/2 · b/|b| = (5 − 1)/2 · (0.6, 0.8).
        (
            "one node",
            Data {
                s: iso(1, 2.0),
                b: vec![3.0, 4.0],
                w: vec![0.5],
                law: tresca(2.0),
            },
            vec![1.2, 1.6],
        ),
        // S = diag(2, 3), b along the first axis: x = ((5 − 1)/2, 0).
        (
            "slip along one axis",
            Data {
                s: DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![2.0, 3.0])),
                b: vec![5.0, 0.0],
                w: vec![1.0],
                law: tresca(1.0),
            },
            vec![2.0, 0.0],
        ),
    ];
    for (name, d, expect) in &cases {
        for x0 in [vec![0.0; d.b.len()], vec![0.3; d.b.len()]] {
            let (x, _) = d.solve_from(&x0, TOL);
            d.assert_kkt(&x, 1e-12);
            for (a, e) in x.iter().zip(expect) {
                assert!((a - e).abs() <= 1e-12 * (1.0 + e.abs()), "{name}: {x:?}");
            }
        }
    }
    // The exact zeros of the stuck and the axis cases are exact, not merely small.
    let (x, _) = cases[2].1.solve_from(&[0.3; 4], TOL);
    assert_eq!(x, vec![0.0; 4]);
    let (x, _) = cases[6].1.solve_from(&[0.0; 2], TOL);
    assert_eq!(x[1], 0.0);
}

/// Many nodes slipping along the first axis: S = S1 ⊗ I₂ has no coupling between the
/// components, so the second components stay exactly 0.
#[test]
fn slip_along_one_axis_stays_on_it() {
    let mut rng = seeded(7);
    let m = 9;
    let s1 = random_spd(&mut rng, m, 0.5);
    let d = Data {
        s: DMatrix::from_fn(2 * m, 2 * m, |i, j| {
            if i % 2 == j % 2 {
                s1[(i / 2, j / 2)]
            } else {
                0.0
            }
        }),
        b: (0..2 * m)
            .map(|k| {
                if k % 2 == 0 {
                    4.0 * uniform(&mut rng)
                } else {
                    0.0
                }
            })
            .collect(),
        w: vec![0.3; m],
        law: FrictionLaw::Tresca { g: 1.0 },
    };
    let (x, _) = d.solve_from(&vec![0.0; 2 * m], TOL);
    d.assert_kkt(&x, 1e-9);
    assert!((0..m).all(|i| x[2 * i + 1] == 0.0), "{x:?}");
    assert!((0..m).any(|i| x[2 * i] != 0.0));
}

/// A nearly singular S: two nodes whose common mode (x_1 = x_2) has stiffness 1e-8 (condition
/// number 2e8), loaded along that mode slightly beyond the friction bound: the slip is 1e3
/// while the load is 1.
#[test]
fn nearly_singular_matrix() {
    let eps = 1e-8;
    let s = DMatrix::from_fn(4, 4, |i, j| match (i == j, i % 2 == j % 2) {
        (true, _) => 1.0,
        (false, true) => -(1.0 - eps),
        _ => 0.0,
    });
    assert!(s.clone().cholesky().is_some());
    for (law, f, slip) in [
        (FrictionLaw::Tresca { g: 1.0 }, 1.0 + 1e-5, 1e3),
        (FrictionLaw::Tresca { g: 1.0 }, 0.5, 0.0),
        // c2τ = 1e-9 < 1e-8: the smallness condition holds.
        (
            FrictionLaw::SlipWeakening {
                mu0: 1.0,
                mu1: 0.999,
                alpha: 1e-6,
            },
            1.0 + 1e-5,
            // ε r = f − μ(r), μ(r) ≈ 1 − 1e-9 r: r = 1e-5 / (1e-8 − 1e-9).
            1e-5 / 0.9e-8,
        ),
    ] {
        let d = Data {
            s: s.clone(),
            b: vec![f * 0.6, f * 0.8, f * 0.6, f * 0.8],
            w: vec![1.0, 1.0],
            law,
        };
        for x0 in [[0.0; 4], [1.0, -1.0, 0.5, 2.0]] {
            let (x, _) = d.solve_from(&x0, TOL);
            d.assert_kkt(&x, 1e-9);
            // Symmetric load, symmetric answer along the load: x_1 = x_2 = r (0.6, 0.8).
            let r = x[0].hypot(x[1]);
            assert!((r - slip).abs() <= 1e-3 * slip, "{x:?}");
            assert!((x[0] - x[2]).abs() <= 1e-12 * (1.0 + r), "{x:?}");
            assert!((x[1] - x[3]).abs() <= 1e-12 * (1.0 + r), "{x:?}");
            // Across the load the stiffness is only ε + ω μ/r ≈ 1e-3: the tolerance allows
            // an angle of about 1e-10.
            assert!((x[0] * 0.8 - x[1] * 0.6).abs() <= 1e-9 * (1.0 + r), "{x:?}");
        }
    }
}

/// Rotating every node's tangent plane by its own R_i (S → QᵀSQ, b → Qᵀb, Q = blockdiag R_i)
/// rotates the solution: x → Qᵀx.
#[test]
fn isotropy_under_nodewise_rotations() {
    let mut rng = seeded(11);
    for trial in 0..60 {
        let m = 1 + trial % 12;
        let mut d = random_tresca(&mut rng, m);
        if trial % 3 == 1 {
            d.law = FrictionLaw::SlipWeakening {
                mu0: 1.0,
                mu1: 0.5,
                alpha: 2.0,
            };
            let c2 = d.law.relaxed_monotonicity();
            let wmax = d.w.iter().cloned().fold(0.0, f64::max);
            d.s += DMatrix::identity(2 * m, 2 * m) * (wmax * c2);
        }
        let mut q = DMatrix::zeros(2 * m, 2 * m);
        for i in 0..m {
            let t = std::f64::consts::TAU * rng.random::<f64>();
            let (c, s) = (t.cos(), t.sin());
            q[(2 * i, 2 * i)] = c;
            q[(2 * i, 2 * i + 1)] = -s;
            q[(2 * i + 1, 2 * i)] = s;
            q[(2 * i + 1, 2 * i + 1)] = c;
        }
        let rotated = Data {
            s: q.transpose() * &d.s * &q,
            b: (q.transpose() * nalgebra::DVector::from_column_slice(&d.b))
                .as_slice()
                .to_vec(),
            w: d.w.clone(),
            law: d.law.clone(),
        };
        let (x, _) = d.solve_from(&vec![0.0; 2 * m], 1e-13);
        let (y, _) = rotated.solve_from(&vec![0.0; 2 * m], 1e-13);
        let qtx = q.transpose() * nalgebra::DVector::from_column_slice(&x);
        let size = x.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        for (a, e) in y.iter().zip(qtx.iter()) {
            assert!((a - e).abs() <= 1e-9 * size.max(1e-300), "trial {trial}");
        }
        // The same nodes stick (stuck nodes are exactly 0 in both).
        for i in 0..m {
            let zero = |v: &[f64]| v[2 * i] == 0.0 && v[2 * i + 1] == 0.0;
            assert_eq!(zero(&x), zero(&y), "trial {trial} node {i}");
        }
    }
}

/// With the second components decoupled (no coupling in S, no load), the first components
/// solve the 2D reduced problem.
#[test]
fn decoupled_problem_matches_the_2d_solver() {
    let mut rng = seeded(5);
    let laws = [
        FrictionLaw::Tresca { g: 1.0 },
        FrictionLaw::SlipWeakening {
            mu0: 1.2,
            mu1: 0.4,
            alpha: 3.0,
        },
    ];
    for trial in 0..60 {
        let m = 1 + trial % 15;
        let law = laws[trial % 2].clone();
        let w: Vec<f64> = (0..m).map(|_| 0.05 + 0.5 * rng.random::<f64>()).collect();
        let shift = 0.05 + w.iter().cloned().fold(0.0, f64::max) * law.relaxed_monotonicity();
        let s1 = random_spd(&mut rng, m, shift);
        let s2 = random_spd(&mut rng, m, shift);
        let b1 = random_vec(&mut rng, m, 3.0);
        let d = Data {
            s: DMatrix::from_fn(2 * m, 2 * m, |i, j| match (i % 2, j % 2) {
                (0, 0) => s1[(i / 2, j / 2)],
                (1, 1) => s2[(i / 2, j / 2)],
                _ => 0.0,
            }),
            b: (0..2 * m)
                .map(|k| if k % 2 == 0 { b1[k / 2] } else { 0.0 })
                .collect(),
            w: w.clone(),
            law: law.clone(),
        };
        let (x, _) = d.solve_from(&vec![0.0; 2 * m], 1e-13);
        let p2 = friction_reduced::Reduced {
            s: &s1,
            b: &b1,
            weights: &w,
            law: &law,
            scale: None,
        };
        let mut x1 = vec![0.0; m];
        friction_reduced::solve(&p2, &mut x1, &settings(1e-13), 0).unwrap();
        let size = x1.iter().fold(1e-300f64, |s, v| s.max(v.abs()));
        for i in 0..m {
            assert!(
                (x[2 * i] - x1[i]).abs() <= 1e-9 * size,
                "trial {trial} node {i}"
            );
            assert!(x[2 * i + 1].abs() <= 1e-9 * size, "trial {trial} node {i}");
            assert_eq!(x[2 * i] == 0.0, x1[i] == 0.0, "trial {trial} node {i}");
        }
    }
}

#[test]
fn warm_start_scale_and_failure() {
    let mut rng = seeded(3);
    let d = random_tresca(&mut rng, 6);
    let (x, _) = d.solve_from(&[0.0; 12], 1e-13);
    // From the solution: no iteration.
    let (y, rep) = d.solve_from(&x, 1e-13);
    assert_eq!(rep.iterations, 0);
    assert_eq!(x, y);
    // The residual is relative to the given scale.
    let mut p = d.reduced();
    let x0 = vec![0.1; 12];
    let r = p.residual(&x0);
    p.scale = Some(1e3);
    let bmax = d.b.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    assert!((p.residual(&x0) - r * bmax / 1e3).abs() <= 1e-14 * r);
    // Energy agrees with the plain loops.
    assert!((p.energy(&x0) - d.energy(&x0)).abs() <= 1e-12 * d.energy(&x0).abs());
    // Too few iterations: the 2D solver's error.
    let mut x = vec![0.0; 12];
    let tight = SolverSettings {
        tolerance: 1e-13,
        max_iterations: 1,
        ..SolverSettings::default()
    };
    match solve(&d.reduced(), &mut x, &tight, 7) {
        Err(SolveError::NotConverged {
            what,
            step,
            iterations,
            ..
        }) => {
            assert_eq!(what, "velocity (friction) solver");
            assert_eq!((step, iterations), (7, 1));
        }
        other => panic!("{other:?}"),
    }
}

/// A surface-like operator: T = V (Λ + δ)^½ Vᵀ / h from the Neumann Laplacian of a
/// side × side grid (condition number ∝ 1/h, like an elastic Schur complement onto Γ3),
/// S = D (T ⊗ [[1, ν], [ν, 1]]) D with a random diagonal D, and a smoothly rotating load
/// whose friction bound leaves about `stick_fraction` of the nodes stuck.
fn surface_problem(rng: &mut TestRng, side: usize, stick_fraction: f64) -> Data {
    let m = side * side;
    let pi = std::f64::consts::PI;
    let h = 1.0 / side as f64;
    let basis = |k: usize, i: usize| {
        let c = if k == 0 { h.sqrt() } else { (2.0 * h).sqrt() };
        c * (pi * k as f64 * (i as f64 + 0.5) * h).cos()
    };
    let mut v = DMatrix::zeros(m, m);
    let mut root = vec![0.0; m];
    for k in 0..side {
        for l in 0..side {
            let col = k * side + l;
            let lam = 4.0 * (0.5 * pi * k as f64 * h).sin().powi(2)
                + 4.0 * (0.5 * pi * l as f64 * h).sin().powi(2);
            root[col] = (lam + 0.01 * h * h).sqrt() / h;
            for i in 0..side {
                for j in 0..side {
                    v[(i * side + j, col)] = basis(k, i) * basis(l, j);
                }
            }
        }
    }
    let t = &v * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(root)) * v.transpose();
    let scale: Vec<f64> = (0..m).map(|_| (0.5 + rng.random::<f64>()).sqrt()).collect();
    let nu = 0.3;
    let s = DMatrix::from_fn(2 * m, 2 * m, |a, b| {
        let c = if a % 2 == b % 2 { 1.0 } else { nu };
        let (i, j) = (a / 2, b / 2);
        scale[i] * 0.5 * (t[(i, j)] + t[(j, i)]) * c * scale[j]
    });
    let b: Vec<f64> = (0..m)
        .flat_map(|i| {
            let (x, y) = ((i / side) as f64 * h, (i % side) as f64 * h);
            let th = 3.0 * x + 2.0 * y * y;
            let a = 1.0 + x * y;
            [
                a * th.cos() + 0.1 * uniform(rng),
                a * th.sin() + 0.1 * uniform(rng),
            ]
        })
        .map(|v| v * h * h)
        .collect();
    let mut bounds: Vec<f64> = (0..m).map(|i| b[2 * i].hypot(b[2 * i + 1])).collect();
    bounds.sort_by(f64::total_cmp);
    let g = bounds[((m as f64 * stick_fraction) as usize).min(m - 1)] / (h * h);
    Data {
        s,
        b,
        w: vec![h * h; m],
        law: FrictionLaw::Tresca { g },
    }
}

/// On surface-like operators Newton does the work: a handful of iterations from a cold start,
/// fewer from the solution of a slightly different load (the next time step).
#[test]
fn surface_operators_take_few_iterations() {
    let mut rng = seeded(99);
    for side in [6, 10] {
        for fraction in [0.1, 0.5, 0.9] {
            let mut d = surface_problem(&mut rng, side, fraction);
            let m = side * side;
            let (x, rep) = d.solve_from(&vec![0.0; 2 * m], TOL);
            d.assert_kkt(&x, 1e-9);
            assert!(rep.iterations <= 8, "side {side}: {rep:?}");
            for (k, b) in d.b.iter_mut().enumerate() {
                *b *= 1.0 + 0.01 * (0.37 * k as f64).sin();
            }
            let (y, rep) = d.solve_from(&x, TOL);
            d.assert_kkt(&y, 1e-9);
            assert!(rep.iterations <= 4, "side {side} warm: {rep:?}");
        }
    }
}

/// Badly conditioned S (λ_min down to 1e-4), cold and random starts, all three laws (the
/// non-convex ones just inside the smallness condition): all converge, within few iterations.
#[test]
fn stress_conditioning_and_laws() {
    let mut rng = seeded(123);
    let mut most = 0;
    for trial in 0..1500 {
        let m = 1 + trial % 30;
        let shift = 10f64.powf(-4.0 * rng.random::<f64>());
        let law = match trial % 3 {
            0 => FrictionLaw::Tresca {
                g: 3.0 * rng.random::<f64>(),
            },
            1 => FrictionLaw::SlipWeakening {
                mu0: 1.5,
                mu1: 0.2,
                alpha: 5.0,
            },
            _ => FrictionLaw::PiecewiseLinear {
                points: vec![[0.0, 1.0], [0.1, 0.3], [0.5, 0.4], [2.0, 0.1]],
            },
        };
        let w: Vec<f64> = (0..m).map(|_| 0.05 + rng.random::<f64>()).collect();
        let c2 = law.relaxed_monotonicity();
        let wmax = w.iter().cloned().fold(0.0, f64::max);
        let d = Data {
            s: random_spd(&mut rng, 2 * m, wmax * c2 * 1.001 + shift),
            b: random_vec(&mut rng, 2 * m, 4.0),
            w,
            law,
        };
        let x0 = if trial % 2 == 0 {
            vec![0.0; 2 * m]
        } else {
            random_vec(&mut rng, 2 * m, 1.0)
        };
        let (x, rep) = d.solve_from(&x0, TOL);
        d.assert_kkt(&x, 1e-8);
        most = most.max(rep.iterations);
    }
    assert!(most <= 20, "{most} iterations");
}

/// A tolerance below the rounding of S x − b cannot be met: the solver notices the stall and
/// stops long before the iteration limit.
#[test]
fn unreachable_tolerance_fails_fast() {
    let mut rng = seeded(77);
    for m in [3, 10, 30] {
        let d = random_tresca(&mut rng, m);
        let mut x = vec![0.0; 2 * m];
        match solve(&d.reduced(), &mut x, &settings(1e-30), 0) {
            Err(SolveError::NotConverged {
                iterations,
                residual,
                ..
            }) => {
                assert!(iterations <= 30, "m {m}: {iterations} iterations");
                assert!(residual <= 1e-13, "m {m}: {residual}");
            }
            other => panic!("{other:?}"),
        }
        // The point reached is still a solution to working precision.
        d.assert_kkt(&x, 1e-12);
    }
}

/// The integrated potential difference agrees with j(r1) − j(r0), across table kinks too.
#[test]
fn potential_change_is_the_difference_of_potentials() {
    let laws = [
        FrictionLaw::Tresca { g: 1.5 },
        FrictionLaw::SlipWeakening {
            mu0: 1.2,
            mu1: 0.4,
            alpha: 3.0,
        },
        FrictionLaw::SlipWeakening {
            mu0: 1.2,
            mu1: 0.4,
            alpha: 0.0,
        },
        FrictionLaw::PiecewiseLinear {
            points: vec![[0.0, 1.0], [0.1, 0.3], [0.5, 0.4], [2.0, 0.1]],
        },
    ];
    let radii = [0.0, 0.05, 0.1, 0.3, 0.5, 0.7, 2.0, 3.5];
    for law in &laws {
        for &r0 in &radii {
            for &r1 in &radii {
                let expect = law.potential(r1) - law.potential(r0);
                let got = law.potential_change(r0, r1, r1 - r0);
                assert!(
                    (got - expect).abs() <= 1e-14,
                    "{law:?} {r0} → {r1}: {got} vs {expect}"
                );
            }
        }
    }
    // Small steps keep their relative accuracy where the subtraction loses it.
    let law = &laws[3];
    let (r0, dr) = (0.3, 1e-13);
    let exact = dr * law.mu(r0 + 0.5 * dr);
    assert!((law.potential_change(r0, r0 + dr, dr) - exact).abs() <= 1e-12 * exact);
}
