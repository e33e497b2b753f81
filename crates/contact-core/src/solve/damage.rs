//! The damage step (3.10) as a box-constrained QP:
//!   ζ_n = argmin ½ ζᵀ H ζ − gᵀ ζ  subject to 0 ≤ ζ_i ≤ 1,
//! H = M/k + κK (fixed for the whole run), g = M ζ_{n−1}/k + F_{n−1}.
//!
//! Method: primal–dual active set (PDAS, i.e. semismooth Newton on
//! ζ = P_[0,1](ζ − D⁻¹(Hζ − g)), D = diag H). Each iteration fixes the active nodes at their
//! bound and solves for the rest. faer has no rank update, so the pattern of H is kept and
//! active rows/columns are replaced by the identity; the symbolic analysis is reused and a
//! numeric refactorisation happens only when the active set changes. The active set of the
//! previous step is the warm start, so a step whose active set does not change costs one
//! triangular solve pair.
//!
//! On the multigrid path the masked system is solved by conjugate gradients instead,
//! preconditioned by the V-cycle B of the whole H restricted to the free nodes
//! (diag(B_FF, I): a principal block of an SPD matrix is SPD), warm-started from the previous
//! ζ; the hierarchy is built once per run, whatever the active set.
//!
//! KKT conditions (checked as the residual): with λ = Hζ − g,
//!   0 < ζ_i < 1 ⇒ λ_i = 0;  ζ_i = 0 ⇒ λ_i ≥ 0;  ζ_i = 1 ⇒ λ_i ≤ 0.

use super::{SolveError, SolverReport, SolverSettings};
use crate::linalg::multigrid::VCycle;
use crate::linalg::pcg::{self, PcgWork, Preconditioner};
use crate::linalg::{Cholesky, CholeskyPlan, Csr, LinearOperator, LinearSolver};
use faer::sparse::SparseColMat;
use std::sync::Arc;

/// Conjugate gradients on the multigrid path solve each masked system to this fraction of
/// the step's tolerance (max norm, relative to ‖g‖∞).
const KRYLOV_FRACTION: f64 = 0.01;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bound {
    Free,
    Lower,
    Upper,
}

/// The direct path: H's factor on a fixed pattern, refactored with the active rows and
/// columns replaced by the identity.
struct Factored {
    /// Lower triangle of H in faer's CSC form; its values are refilled with the masked H.
    lower: SparseColMat<usize, f64>,
    /// (row, col) of each stored entry of `lower`.
    entries: Vec<(usize, usize)>,
    lower_values: Vec<f64>,
    chol: Cholesky,
}

/// The multigrid path: CG on the masked H (applied from H's storage) with the V-cycle of H.
struct Iterative {
    vcycle: VCycle,
    work: PcgWork,
    buffer: Vec<f64>,
}

/// H with the rows and columns of the active nodes replaced by the identity, applied from
/// H's storage (the masked matrix is never formed).
struct Masked<'a> {
    h: &'a Csr,
    active: &'a [Bound],
}

impl LinearOperator for Masked<'_> {
    fn dim(&self) -> usize {
        self.h.nrows
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let h = self.h;
        for (r, yr) in y.iter_mut().enumerate() {
            *yr = if self.active[r] != Bound::Free {
                x[r]
            } else {
                let row = h.indptr[r]..h.indptr[r + 1];
                h.indices[row.clone()]
                    .iter()
                    .zip(&h.values[row])
                    .filter(|(&c, _)| self.active[c as usize] == Bound::Free)
                    .map(|(&c, &v)| v * x[c as usize])
                    .sum()
            };
        }
    }
}

enum Linear {
    Direct(Box<Factored>),
    Multigrid(Box<Iterative>),
}

/// diag(B_FF, I) for the V-cycle B of H and the free set F.
struct MaskedVCycle<'a> {
    vcycle: &'a mut VCycle,
    active: &'a [Bound],
    buffer: &'a mut Vec<f64>,
}

impl Preconditioner for MaskedVCycle<'_> {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        for ((b, &r), a) in self.buffer.iter_mut().zip(r).zip(self.active) {
            *b = if *a == Bound::Free { r } else { 0.0 };
        }
        self.vcycle.apply(self.buffer, z);
        for ((z, &r), a) in z.iter_mut().zip(r).zip(self.active) {
            if *a != Bound::Free {
                *z = r;
            }
        }
    }
}

pub struct DamageStep {
    /// Shared with the multigrid hierarchy's finest level on that path.
    h: Arc<Csr>,
    diag: Vec<f64>,
    linear: Linear,
    /// Active set the current factor (or masked operator) was made for.
    factored: Vec<Bound>,
    /// Warm start for the next solve.
    active: Vec<Bound>,
    /// Numeric factorisations done so far (for the summary; 0 on the multigrid path).
    pub refactorizations: usize,
    /// Krylov iterations of the last solve (multigrid path).
    krylov: usize,
}

impl DamageStep {
    /// The multigrid path: CG on the masked systems preconditioned by `solver`'s V-cycle,
    /// whose operator is H (shared, not copied).
    pub fn multigrid(solver: LinearSolver) -> Result<Self, SolveError> {
        let LinearSolver::Multigrid(k) = solver else {
            panic!("DamageStep::multigrid takes a multigrid solver of H");
        };
        let (h, vcycle) = k.into_parts();
        let n = h.nrows;
        Ok(DamageStep {
            diag: h.diagonal(),
            linear: Linear::Multigrid(Box::new(Iterative {
                vcycle,
                work: PcgWork::new(n),
                buffer: vec![0.0; n],
            })),
            h,
            factored: vec![Bound::Free; n],
            active: vec![Bound::Free; n],
            refactorizations: 0,
            krylov: 0,
        })
    }

    /// The direct path: H's factor, refactored for the masked systems.
    pub fn new(h: Csr) -> Result<Self, SolveError> {
        let plan = Self::plan(&h)?;
        Self::with_plan(h, plan)
    }

    /// The symbolic analysis of H's factor on the direct path, from any matrix with H's
    /// pattern (the mass matrix M: H = M/k + κL is assembled into M's pattern). AMD: the
    /// scalar operator's factor is small beside K_II's.
    pub fn plan(pattern: &Csr) -> Result<CholeskyPlan, SolveError> {
        CholeskyPlan::amd(pattern.lower_csc().as_ref()).map_err(|source| SolveError::Factor {
            what: "damage",
            source,
        })
    }

    /// [`DamageStep::new`] on the analysis `plan` of H's pattern ([`DamageStep::plan`]).
    pub fn with_plan(h: Csr, plan: CholeskyPlan) -> Result<Self, SolveError> {
        let n = h.nrows;
        let lower = h.lower_csc();
        let (sym, vals) = lower.as_ref().parts();
        let mut entries = Vec::with_capacity(vals.len());
        for c in 0..sym.ncols() {
            for &r in sym.row_idx_of_col_raw(c) {
                entries.push((r, c));
            }
        }
        let lower_values = vals.to_vec();
        let chol =
            Cholesky::from_plan(plan, lower.as_ref()).map_err(|source| SolveError::Factor {
                what: "damage",
                source,
            })?;
        Ok(DamageStep {
            diag: h.diagonal(),
            h: Arc::new(h),
            linear: Linear::Direct(Box::new(Factored {
                lower,
                entries,
                lower_values,
                chol,
            })),
            factored: vec![Bound::Free; n],
            active: vec![Bound::Free; n],
            refactorizations: 1,
            krylov: 0,
        })
    }

    /// Krylov iterations of the last solve (0 on the direct path).
    pub fn krylov_iterations(&self) -> usize {
        self.krylov
    }

    /// Refactor H with the rows and columns of `active` replaced by the identity (direct
    /// path; the multigrid path applies the masked H from H's storage).
    fn factor_for(&mut self, active: &[Bound]) -> Result<(), SolveError> {
        let f = match &mut self.linear {
            Linear::Direct(f) => f,
            Linear::Multigrid(_) => {
                self.factored.copy_from_slice(active);
                return Ok(());
            }
        };
        {
            let vals = f.lower.val_mut();
            for (k, &(r, c)) in f.entries.iter().enumerate() {
                vals[k] = if active[r] != Bound::Free || active[c] != Bound::Free {
                    if r == c {
                        1.0
                    } else {
                        0.0
                    }
                } else {
                    f.lower_values[k]
                };
            }
        }
        f.chol
            .refactor(f.lower.as_ref())
            .map_err(|source| SolveError::Factor {
                what: "damage",
                source,
            })?;
        self.factored.copy_from_slice(active);
        self.refactorizations += 1;
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
        let eps = match self.linear {
            Linear::Direct(_) => 1e-13,
            // Iterative solves leave ζ accurate to about KRYLOV_FRACTION·tolerance: the
            // hysteresis must exceed that or degenerate nodes flip back and forth.
            Linear::Multigrid(_) => 0.1 * settings.tolerance,
        };
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

    /// ζ ← (masked H)⁻¹ rhs: a substitution pair, or CG from ζ's current values (the
    /// previous iterate, active entries at their bounds).
    fn solve_masked(
        &mut self,
        active: &[Bound],
        rhs: &[f64],
        zeta: &mut [f64],
        scale: f64,
        settings: &SolverSettings,
        step: usize,
    ) -> Result<(), SolveError> {
        match &mut self.linear {
            Linear::Direct(f) => {
                zeta.copy_from_slice(rhs);
                f.chol.solve_in_place(zeta);
                Ok(())
            }
            Linear::Multigrid(it) => {
                for ((z, a), r) in zeta.iter_mut().zip(active).zip(rhs) {
                    if *a != Bound::Free {
                        *z = *r;
                    }
                }
                let Iterative {
                    vcycle,
                    work,
                    buffer,
                } = &mut **it;
                let masked = Masked { h: &self.h, active };
                let mut pre = MaskedVCycle {
                    vcycle,
                    active,
                    buffer,
                };
                let atol = KRYLOV_FRACTION * settings.tolerance * scale;
                let rep = pcg::solve(
                    &masked,
                    &mut pre,
                    rhs,
                    zeta,
                    atol,
                    crate::linalg::solver::MAX_KRYLOV_ITERATIONS,
                    work,
                );
                self.krylov += rep.iterations;
                if rep.converged {
                    Ok(())
                } else {
                    Err(SolveError::NotConverged {
                        what: "damage step (multigrid conjugate gradients)",
                        step,
                        iterations: rep.iterations,
                        residual: rep.residual / scale,
                        tolerance: KRYLOV_FRACTION * settings.tolerance,
                    })
                }
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
    use proptest::prelude::RngExt;
    use proptest::test_runner::{RngAlgorithm, TestRng};

    fn square(n: usize) -> Mesh {
        Mesh::rectangle(1.0, 1.0, n, n, MeshPattern::Diagonal)
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
            let mut solver = DamageStep::new(h.clone()).unwrap();
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
            let mg = crate::fem::multilevel::scalar_solver(
                &square(n),
                h.clone(),
                crate::linalg::LinearPath::Multigrid,
            )
            .unwrap();
            let mut solver = DamageStep::multigrid(mg).unwrap();
            let mut direct = DamageStep::new(h.clone()).unwrap();
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

    #[test]
    fn unconstrained_solution_is_the_linear_solve() {
        let (h, _, nn) = h_matrix(5, 0.1, 0.5);
        let zs: Vec<f64> = (0..nn)
            .map(|i| 0.2 + 0.6 * ((i * 7) % 11) as f64 / 11.0)
            .collect();
        let mut g = vec![0.0; nn];
        h.mul_vec(&zs, &mut g);
        let mut solver = DamageStep::new(h).unwrap();
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
