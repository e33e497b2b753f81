//! The damage step (3.10) as a box-constrained QP:
//!   ζ_n = argmin ½ ζᵀ H ζ − gᵀ ζ  subject to 0 ≤ ζ_i ≤ 1,
//! H = M/k + κK (fixed for the whole run), g = M ζ_{n−1}/k + F_{n−1}.
//!
//! Method: primal–dual active set (PDAS, i.e. semismooth Newton on
//! ζ = P_[0,1](ζ − D⁻¹(Hζ − g)), D = diag H). Each iteration fixes the active nodes at their
//! bound and solves for the rest: the masked system, H with the rows and columns of the
//! active nodes replaced by the identity, solved by the run's backend ([`MaskedSolver`]: a
//! factor refactored when the active set changes, or conjugate gradients applied from H's
//! storage, [`crate::solve::backend`]). The active set of the previous step is the warm
//! start, so a step whose active set does not change costs one masked solve.
//!
//! KKT conditions (checked as the residual): with λ = Hζ − g,
//!   0 < ζ_i < 1 ⇒ λ_i = 0;  ζ_i = 0 ⇒ λ_i ≥ 0;  ζ_i = 1 ⇒ λ_i ≤ 0.

use super::{SolveError, SolverReport, SolverSettings};
use crate::linalg::cholesky::FactorError;
use crate::linalg::solver::NotConverged;
use crate::linalg::Csr;
use std::sync::Arc;

/// Iterative masked solves reach this fraction of the step's tolerance (max norm, relative
/// to ‖g‖∞).
const KRYLOV_FRACTION: f64 = 0.01;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bound {
    Free,
    Lower,
    Upper,
}

/// A solver of the damage step's masked systems, the run backend's: H with the rows and
/// columns of the active nodes replaced by the identity.
pub trait MaskedSolver: Send + Sync {
    /// Makes its systems those of the active set `active` (a factor refactored; nothing
    /// where the masked H is applied from H's storage).
    fn set_active(&mut self, h: &Csr, active: &[Bound]) -> Result<(), FactorError>;

    /// ζ ← (masked H)⁻¹ rhs from ζ as given, to ‖rhs − (masked H) ζ‖∞ ≤ `atol` (a factor
    /// reaches round-off whatever `atol`). Returns the Krylov iterations.
    fn solve(
        &mut self,
        h: &Csr,
        active: &[Bound],
        rhs: &[f64],
        zeta: &mut [f64],
        atol: f64,
    ) -> Result<usize, NotConverged>;

    /// How far a node may pass a bound (its multiplier, relative to ‖g‖∞) before it changes
    /// sides: above what the solves leave in ζ, so that degenerate nodes (bound active with
    /// zero multiplier) do not flip back and forth with rounding.
    fn hysteresis(&self, tolerance: f64) -> f64;

    /// Numeric factorisations so far (0 without a factor).
    fn factorizations(&self) -> usize;
}

pub struct DamageStep {
    /// Shared with the multigrid hierarchy's finest level on that path.
    h: Arc<Csr>,
    diag: Vec<f64>,
    solver: Box<dyn MaskedSolver>,
    /// Active set the solver's systems are those of.
    factored: Vec<Bound>,
    /// Warm start for the next solve.
    active: Vec<Bound>,
    /// Krylov iterations of the last solve.
    krylov: usize,
}

impl DamageStep {
    /// The step on H with the backend's masked solver, whose systems are H's own.
    pub fn new(h: Arc<Csr>, solver: Box<dyn MaskedSolver>) -> Self {
        let n = h.nrows;
        DamageStep {
            diag: h.diagonal(),
            h,
            solver,
            factored: vec![Bound::Free; n],
            active: vec![Bound::Free; n],
            krylov: 0,
        }
    }

    /// Numeric factorisations so far (for the summary; 0 without a factor).
    pub fn refactorizations(&self) -> usize {
        self.solver.factorizations()
    }

    /// Krylov iterations of the last solve (0 on the direct path).
    pub fn krylov_iterations(&self) -> usize {
        self.krylov
    }

    /// Makes the solver's systems those of `active`.
    fn factor_for(&mut self, active: &[Bound]) -> Result<(), SolveError> {
        self.solver
            .set_active(&self.h, active)
            .map_err(|source| SolveError::Factor {
                what: "damage",
                source,
            })?;
        self.factored.copy_from_slice(active);
        Ok(())
    }

    /// Solves the QP for the linear term `g`; `zeta` holds the previous ζ on entry (used
    /// only for its size) and ζ_n on exit.
    pub fn solve(
        &mut self,
        g: &[f64],
        zeta: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<SolverReport, SolveError> {
        let n = g.len();
        let scale = g.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
        // Hysteresis against rounding at degenerate nodes (bound active with zero multiplier).
        let eps = self.solver.hysteresis(settings.tolerance);
        self.krylov = 0;
        let mut active = self.active.clone();
        let mut rhs = vec![0.0; n];
        let mut lambda = vec![0.0; n];
        let mut fixed = vec![0.0; n];
        for it in 1..=settings.max_iterations {
            if active != self.factored {
                self.factor_for(&active)?;
            }
            // rhs_i = bound for active i; g_i − Σ_{j active} H_ij ζ_j for free i.
            for i in 0..n {
                fixed[i] = match active[i] {
                    Bound::Free => 0.0,
                    Bound::Lower => 0.0,
                    Bound::Upper => 1.0,
                };
            }
            self.h.mul_vec(&fixed, &mut lambda);
            for i in 0..n {
                rhs[i] = match active[i] {
                    Bound::Free => g[i] - lambda[i],
                    _ => fixed[i],
                };
            }
            self.solve_masked(&active, &rhs, zeta, scale, settings, step)?;
            self.h.mul_vec(zeta, &mut lambda);
            lambda.iter_mut().zip(g).for_each(|(l, g)| *l -= g);
            // New active set from ζ − λ/d, keeping degenerate nodes where they are.
            let mut next = active.clone();
            for i in 0..n {
                let t = zeta[i] - lambda[i] / self.diag[i];
                next[i] = match active[i] {
                    Bound::Free if zeta[i] < -eps => Bound::Lower,
                    Bound::Free if zeta[i] > 1.0 + eps => Bound::Upper,
                    Bound::Lower if lambda[i] < -eps * scale => {
                        if t > 1.0 {
                            Bound::Upper
                        } else {
                            Bound::Free
                        }
                    }
                    Bound::Upper if lambda[i] > eps * scale => {
                        if t < 0.0 {
                            Bound::Lower
                        } else {
                            Bound::Free
                        }
                    }
                    b => b,
                };
            }
            if next == active {
                for z in zeta.iter_mut() {
                    *z = z.clamp(0.0, 1.0);
                }
                let residual = kkt_residual(&self.h, g, zeta);
                if !residual.is_finite() {
                    return Err(SolveError::NonFinite("damage", step));
                }
                if residual > settings.tolerance {
                    return Err(SolveError::NotConverged {
                        what: "damage step",
                        step,
                        iterations: it,
                        residual,
                        tolerance: settings.tolerance,
                    });
                }
                self.active = active;
                return Ok(SolverReport {
                    iterations: it,
                    residual,
                    krylov_iterations: self.krylov,
                });
            }
            active = next;
        }
        Err(SolveError::NotConverged {
            what: "damage step (active set cycling)",
            step,
            iterations: settings.max_iterations,
            residual: kkt_residual(&self.h, g, zeta),
            tolerance: settings.tolerance,
        })
    }

    /// ζ ← (masked H)⁻¹ rhs from ζ's current values (the previous iterate), to
    /// KRYLOV_FRACTION of the tolerance where the solver is iterative.
    fn solve_masked(
        &mut self,
        active: &[Bound],
        rhs: &[f64],
        zeta: &mut [f64],
        scale: f64,
        settings: &SolverSettings,
        step: usize,
    ) -> Result<(), SolveError> {
        let atol = KRYLOV_FRACTION * settings.tolerance * scale;
        match self.solver.solve(&self.h, active, rhs, zeta, atol) {
            Ok(iterations) => {
                self.krylov += iterations;
                Ok(())
            }
            Err(e) => {
                self.krylov += e.iterations;
                Err(SolveError::NotConverged {
                    what: "damage step (multigrid conjugate gradients)",
                    step,
                    iterations: e.iterations,
                    residual: e.residual / scale,
                    tolerance: KRYLOV_FRACTION * settings.tolerance,
                })
            }
        }
    }

    /// The warm start for the next solve as codes: 0 free, 1 at the lower bound, 2 at the
    /// upper bound (what a checkpoint stores).
    pub fn active_codes(&self) -> Vec<u8> {
        self.active
            .iter()
            .map(|b| match b {
                Bound::Free => 0,
                Bound::Lower => 1,
                Bound::Upper => 2,
            })
            .collect()
    }

    /// Restores a warm start saved by [`DamageStep::active_codes`]; false (and nothing
    /// changed) when the codes do not fit this problem.
    pub fn set_active_codes(&mut self, codes: &[u8]) -> bool {
        if codes.len() != self.active.len() || codes.iter().any(|&c| c > 2) {
            return false;
        }
        for (a, &c) in self.active.iter_mut().zip(codes) {
            *a = match c {
                0 => Bound::Free,
                1 => Bound::Lower,
                _ => Bound::Upper,
            };
        }
        true
    }

    /// Warm start from a given ζ (e.g. the initial data or a checkpoint).
    pub fn set_active_from(&mut self, zeta: &[f64]) {
        for (a, &z) in self.active.iter_mut().zip(zeta) {
            *a = if z <= 0.0 {
                Bound::Lower
            } else if z >= 1.0 {
                Bound::Upper
            } else {
                Bound::Free
            };
        }
    }
}

/// Relative KKT residual of the box QP at ζ, computed from scratch:
/// max_i of |λ_i| (free), max(0, −λ_i) (at 0), max(0, λ_i) (at 1), and bound violations,
/// over max(‖g‖_∞, ‖Hζ‖_∞).
pub fn kkt_residual(h: &Csr, g: &[f64], zeta: &[f64]) -> f64 {
    let mut hz = vec![0.0; zeta.len()];
    h.mul_vec(zeta, &mut hz);
    let scale = g
        .iter()
        .chain(&hz)
        .fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
    let mut worst = 0.0f64;
    for i in 0..zeta.len() {
        let l = hz[i] - g[i];
        let z = zeta[i];
        let v = if z <= 0.0 {
            (-l).max(0.0) + (-z) * scale
        } else if z >= 1.0 {
            l.max(0.0) + (z - 1.0) * scale
        } else {
            l.abs()
        };
        worst = worst.max(v);
    }
    worst / scale
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::{assembly, Geometry};
    use crate::mesh::Mesh;
    use crate::problem::MeshPattern;
    use crate::solve::backend::{direct, multigrid, Backend};
    use proptest::prelude::RngExt;
    use proptest::test_runner::{RngAlgorithm, TestRng};

    fn square(n: usize) -> Mesh {
        Mesh::rectangle(1.0, 1.0, n, n, MeshPattern::Diagonal)
    }

    /// The direct backend's damage step on H.
    fn direct_step(h: &Csr) -> DamageStep {
        direct::damage_step(h.clone(), direct::damage_plan(h).unwrap()).unwrap()
    }

    fn h_matrix(n: usize, k: f64, kappa: f64) -> (Csr, Csr, usize) {
        let mesh = square(n);
        let geo = Geometry::new(&mesh);
        let m = assembly::mass(&mesh, &geo);
        let lap = assembly::laplacian(&mesh, &geo);
        (
            assembly::combine(1.0 / k, &m, kappa, &lap),
            m,
            mesh.n_nodes(),
        )
    }

    /// g = M ζ_prev / k + F with F random in sign and of amplitude cycling over four decades
    /// with `trial`: many nodes hit 0 and 1.
    fn random_load(
        rng: &mut TestRng,
        m: &Csr,
        zeta: &[f64],
        k: f64,
        n: usize,
        trial: usize,
    ) -> Vec<f64> {
        let mut mz = vec![0.0; zeta.len()];
        m.mul_vec(zeta, &mut mz);
        let amp = [0.1, 1.0, 10.0, 100.0][trial % 4];
        mz.iter()
            .map(|v| v / k + amp * (rng.random::<f64>() - 0.5) * 2.0 / (n * n) as f64)
            .collect()
    }

    /// Independent check of the KKT conditions (not via `kkt_residual`).
    fn assert_kkt(h: &Csr, g: &[f64], z: &[f64]) {
        let mut hz = vec![0.0; z.len()];
        h.mul_vec(z, &mut hz);
        let scale = g.iter().fold(1e-300f64, |s, v| s.max(v.abs()));
        for i in 0..z.len() {
            assert!((0.0..=1.0).contains(&z[i]));
            let l = hz[i] - g[i];
            if z[i] > 0.0 && z[i] < 1.0 {
                assert!(l.abs() <= 1e-9 * scale, "free node {i}: λ = {l}");
            } else if z[i] == 0.0 {
                assert!(l >= -1e-9 * scale);
            } else {
                assert!(l <= 1e-9 * scale);
            }
        }
    }

    #[test]
    fn random_and_adversarial_box_qps() {
        let mut rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[7; 32]);
        for &(n, k, kappa) in &[
            (8, 1.0 / 128.0, 0.5),
            (8, 1.0, 1e-4),
            (12, 1.0 / 4096.0, 100.0),
            (6, 0.5, 0.5),
        ] {
            let (h, m, nn) = h_matrix(n, k, kappa);
            let mut solver = direct_step(&h);
            let mut zeta = vec![1.0; nn];
            solver.set_active_from(&zeta);
            for trial in 0..12 {
                let g = random_load(&mut rng, &m, &zeta, k, n, trial);
                let rep = solver
                    .solve(&g, &mut zeta, &SolverSettings::default(), trial)
                    .unwrap();
                assert!(rep.residual <= 1e-10);
                assert_kkt(&h, &g, &zeta);
            }
        }
    }

    /// The multigrid path (CG with the masked V-cycle) meets the same KKT conditions.
    #[test]
    fn multigrid_path_solves_the_same_box_qps() {
        let mut rng = TestRng::from_seed(RngAlgorithm::ChaCha, &[9; 32]);
        for &(n, k, kappa) in &[
            (24, 1.0 / 128.0, 0.5),
            (16, 1.0, 1e-2),
            (20, 1.0 / 4096.0, 100.0),
            // Large enough for geometric levels (the square halved twice).
            (64, 1.0 / 64.0, 1.0),
        ] {
            let (h, m, nn) = h_matrix(n, k, kappa);
            let mut solver = multigrid::Multigrid::new(0, false)
                .damage(&square(n), h.clone())
                .unwrap();
            let mut direct = direct_step(&h);
            let mut zeta = vec![1.0; nn];
            let mut zeta_d = zeta.clone();
            solver.set_active_from(&zeta);
            direct.set_active_from(&zeta);
            for trial in 0..8 {
                let g = random_load(&mut rng, &m, &zeta_d, k, n, trial);
                let rep = solver
                    .solve(&g, &mut zeta, &SolverSettings::default(), trial)
                    .unwrap();
                direct
                    .solve(&g, &mut zeta_d, &SolverSettings::default(), trial)
                    .unwrap();
                assert!(rep.residual <= 1e-10 && rep.krylov_iterations > 0);
                assert_kkt(&h, &g, &zeta);
                for (a, b) in zeta.iter().zip(&zeta_d) {
                    assert!((a - b).abs() < 1e-9, "{a} vs {b}");
                }
            }
        }
    }

    /// The multigrid path starts each masked solve from the H-projection onto the earlier
    /// solutions of the same masked system: a load in the span of solved loads (interior
    /// solutions, so the active set stays empty) is solved without a Krylov iteration, and
    /// after the active set changes the earlier solutions are no start for the new system.
    #[test]
    fn multigrid_solves_start_from_the_earlier_solutions_of_the_same_system() {
        let n = 24;
        let (h, _, nn) = h_matrix(n, 1.0 / 32.0, 0.5);
        let mut solver = multigrid::Multigrid::new(0, false)
            .damage(&square(n), h.clone())
            .unwrap();
        let settings = SolverSettings::default();
        let interior = |phase: f64| -> Vec<f64> {
            let z: Vec<f64> = (0..nn)
                .map(|i| 0.5 + 0.3 * (0.37 * i as f64 + phase).sin())
                .collect();
            let mut g = vec![0.0; nn];
            h.mul_vec(&z, &mut g);
            g
        };
        let (g1, g2) = (interior(0.0), interior(1.0));
        let mut zeta = vec![0.5; nn];
        solver.set_active_from(&zeta);
        let mut solve = |g: &[f64], zeta: &mut [f64]| {
            let rep = solver.solve(g, zeta, &settings, 0).unwrap();
            assert_kkt(&h, g, zeta);
            rep.krylov_iterations
        };
        assert!(solve(&g1, &mut zeta) > 0);
        assert!(solve(&g2, &mut zeta) > 0);
        let mix: Vec<f64> = g1
            .iter()
            .zip(&g2)
            .map(|(a, b)| 0.25 * a + 0.75 * b)
            .collect();
        zeta.iter_mut().for_each(|z| *z = 0.5);
        assert_eq!(
            solve(&mix, &mut zeta),
            0,
            "a load in the span of solved ones"
        );
        // A load that drives a corner to the lower bound: another masked system, solved to
        // its own KKT conditions from the caller's start.
        let mut pushed = mix.clone();
        pushed[0] = -1.0;
        assert!(solve(&pushed, &mut zeta) > 0);
        assert_eq!(zeta[0], 0.0);
    }

    #[test]
    fn unconstrained_solution_is_the_linear_solve() {
        let (h, _, nn) = h_matrix(5, 0.1, 0.5);
        let zs: Vec<f64> = (0..nn)
            .map(|i| 0.2 + 0.6 * ((i * 7) % 11) as f64 / 11.0)
            .collect();
        let mut g = vec![0.0; nn];
        h.mul_vec(&zs, &mut g);
        let mut solver = direct_step(&h);
        let mut z = vec![0.0; nn];
        let rep = solver
            .solve(&g, &mut z, &SolverSettings::default(), 0)
            .unwrap();
        assert_eq!(rep.iterations, 1);
        for (a, b) in z.iter().zip(&zs) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}
