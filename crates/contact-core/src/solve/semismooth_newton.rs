//! The velocity HVI (3.13) on all free DOFs, without the Schur complement: a truncated
//! nonsmooth Newton multigrid method (Gräser & Kornhuber, "Truncated nonsmooth Newton
//! multigrid methods for convex minimization problems", 2009), for the multigrid path.
//!
//!   minimise E(w) = ½ wᵀ K w − fᵀ w + Σ_i ω_i j(|x_i|),   x_i = node i's tangential DOFs,
//!
//! over the free DOFs (interior first, then the d − 1 tangential DOFs of each Γ3 node). Each
//! iteration:
//! 1. **Nonlinear Gauss–Seidel over the Γ3 nodes.** Node by node, x_i ← argmin of E over x_i
//!    with the rest fixed: prox_{ω_i j / K_ii}(x_i − g_i / K_ii) in 2D (exact), a few
//!    proximal-gradient steps with step 1/λ_max(K_ii) in 3D. Each decreases E, which is what
//!    makes the method globally convergent; it also sets stick nodes exactly to zero and
//!    lets stuck nodes start slipping.
//! 2. **Partition.** Stick: x_i = 0; slip: the rest.
//! 3. **Newton step** on the smooth problem that remains (stick DOFs held at zero): with
//!    ρ = |x_i|, ẑ = x_i/ρ at a slip node, the gradient r = K w − f + ω_i μ(ρ) ẑ and the
//!    Hessian M = K + E on the other DOFs, E_i = ω_i [μ′(ρ) ẑẑᵀ + μ(ρ)/ρ (I − ẑẑᵀ)] (2D:
//!    ω_i μ′(ρ); the term μ(ρ)/ρ capped at [`CURVATURE_CAP`] × the node's stiffness / ω_i),
//!    solved by conjugate gradients preconditioned with the truncated V-cycle of
//!    K's hierarchy ([`crate::linalg::multigrid::truncated`]: truncated prolongator, E⁺ in
//!    the smoother and the first coarse operator). The inexact-Newton tolerance is
//!    min(0.1, KKT residual after step 1)·‖r‖∞, never below the velocity step's Krylov
//!    floor. When step 1 alone meets the tolerance, no Newton step is taken. With a
//!    slip-weakening law (μ′ < 0) M may be indefinite away from the solution: CG stops at
//!    the first direction of non-positive curvature and the step is its last iterate (a
//!    descent direction of the quadratic model), or −B r if that is the first direction.
//! 4. **Landing, then line search.** First the full step with every slip node whose step
//!    reverses its slip set at rest instead (`try_landing`), if that lowers E; else a line
//!    search on E along the step: α = 1, ½, … until E decreases, the change formed from the
//!    step (α dᵀg + ½ α² dᵀK d + Σ ω ∫ μ), not from E itself, so that it can be judged near
//!    the solution.
//!
//! The preconditioner is made again (updated on the nodes that changed) only when the stick
//! set changes or a block of E⁺ moves by more than a tenth of its node's stiffness plus the
//! smaller of its old and new sizes ([`REBUILD_FLOOR`]); CG is run on the exact M either way.
//! Convergence is declared on the KKT residual of the full problem (as the direct path's),
//! from a freshly computed K w − f.

use super::friction_node;
use super::{SolveError, SolverSettings};
use crate::linalg::multigrid::truncated::{Jacobian, NodeBlock, Truncated};
use crate::linalg::multigrid::Hierarchy;
use crate::linalg::pcg::{self, PcgWork, Preconditioner};
use crate::linalg::solver::MAX_KRYLOV_ITERATIONS;
use crate::linalg::Sparse;
use crate::problem::FrictionLaw;
use std::sync::Arc;

/// Proximal-gradient sweeps of one 3D node in the nonlinear Gauss–Seidel step.
const LOCAL_SWEEPS: usize = 3;
/// Most halvings of the line search.
const HALVINGS: usize = 40;
/// The turning curvature ω_i μ/ρ of a 3D slip block is capped at this multiple of its node's
/// stiffness. A node the sweep has just set slipping, at the edge of the friction cone,
/// has a tiny ρ and so a huge curvature, and M is as ill-conditioned. Uncapped, Newton
/// steps solved to more than one digit stopped descending (box-exp3, g = 2, 1/64: step 30
/// failed after 28 Newton iterations once the forcing term followed the swept residual).
/// M stays SPD with the cap and the line search is on the exact E, so only the Newton
/// step's quality near such a node changes.
const CURVATURE_CAP: f64 = 1e4;
/// A block of E⁺ that moved by more than [`REBUILD_FLOOR`] × its node's stiffness plus the
/// smaller of its old and new sizes triggers a new preconditioner: M's block at the node then
/// differs from the preconditioner's by more than a factor of two either way, or by more than
/// a tenth of the node's stiffness where both are small.
///
/// The floor is a tenth, not one stiffness, because the first coarse operator holds
/// P̃ᵀE⁺P̃: a tangential translation of an aggregate on Γ3 has almost no energy in K, so a
/// stale block far below the node's stiffness still pins it on the coarse level. On the part
/// of benches/part with g = 0.02 (every node slips, no stick set change after the first
/// step), blocks left from the first Newton iterations at 0.6 × the stiffness, now 3e-4 ×,
/// cost 17–20 CG iterations a step against 7–8 with a fresh preconditioner (12 steps on two
/// threads: 319 against 160 iterations, 11.0 against 7.3 s).
const REBUILD_FLOOR: f64 = 0.1;

/// How a solve went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonReport {
    /// Newton steps taken (linearised solves; a sweep that alone converges is not one).
    pub newton_iterations: usize,
    pub krylov_iterations: usize,
    /// Relative KKT residual of the full problem.
    pub residual: f64,
    pub slip_nodes: usize,
    /// Preconditioners built during the solve.
    pub preconditioners: usize,
}

/// The preconditioner and the stick set and blocks it was made for.
struct Cached {
    stick: Vec<bool>,
    blocks: Vec<NodeBlock>,
    truncated: Truncated,
}

/// The solver of (3.13) on all free DOFs for one operator K (fixed for a run).
pub struct SemismoothNewton {
    k: Sparse,
    hierarchy: Arc<Hierarchy>,
    n_i: usize,
    /// Tangential DOFs per Γ3 node: d − 1.
    block: usize,
    /// ω_i per Γ3 node.
    weights: Vec<f64>,
    law: FrictionLaw,
    /// K's diagonal block of each Γ3 node (row-major, block² entries used).
    node_k: Vec<[f64; 4]>,
    cached: Option<Cached>,
    /// The current stick set's DOFs (the Jacobian's identity rows), as a list and a flag per
    /// DOF.
    fixed: Vec<usize>,
    is_fixed: Vec<bool>,
    work: PcgWork,
    /// K w − f at the last solution, computed afresh.
    gradient: Vec<f64>,
}

/// A clone shares K and its hierarchy and builds its own preconditioner when first used.
impl Clone for SemismoothNewton {
    fn clone(&self) -> Self {
        SemismoothNewton {
            k: self.k.clone(),
            hierarchy: self.hierarchy.clone(),
            n_i: self.n_i,
            block: self.block,
            weights: self.weights.clone(),
            law: self.law.clone(),
            node_k: self.node_k.clone(),
            cached: None,
            fixed: Vec::new(),
            is_fixed: Vec::new(),
            work: PcgWork::default(),
            gradient: Vec::new(),
        }
    }
}

impl SemismoothNewton {
    /// `k` on all free DOFs (the first `n_i` interior, then `block` DOFs per Γ3 node),
    /// `hierarchy` the multigrid hierarchy of `k`.
    pub fn new(
        k: Sparse,
        hierarchy: Arc<Hierarchy>,
        n_i: usize,
        block: usize,
        weights: Vec<f64>,
        law: FrictionLaw,
    ) -> Self {
        let node_k = (0..weights.len())
            .map(|i| {
                let c = n_i + block * i;
                let mut m = [0.0; 4];
                for r in 0..block {
                    for s in 0..block {
                        m[r * block + s] = k.get(c + r, c + s);
                    }
                }
                m
            })
            .collect();
        SemismoothNewton {
            k,
            hierarchy,
            n_i,
            block,
            weights,
            law,
            node_k,
            cached: None,
            fixed: Vec::new(),
            is_fixed: Vec::new(),
            work: PcgWork::default(),
            gradient: Vec::new(),
        }
    }

    /// K w − f at the solution of the last successful [`SemismoothNewton::solve`], computed
    /// afresh (what its convergence was judged on).
    pub fn gradient(&self) -> &[f64] {
        &self.gradient
    }

    fn node(&self, v: &[f64], i: usize) -> [f64; 2] {
        let c = self.n_i + self.block * i;
        if self.block == 1 {
            [v[c], 0.0]
        } else {
            [v[c], v[c + 1]]
        }
    }

    /// Γ3 node i's stiffness: the largest entry of K's block on its tangential DOFs.
    fn stiffness(&self, i: usize) -> f64 {
        self.node_k[i].iter().fold(0.0f64, |m, v| m.max(v.abs()))
    }

    /// max of the interior residual and the Γ3 stick/slip violations, unscaled.
    fn kkt(&self, g: &[f64], w: &[f64]) -> f64 {
        let n_i = self.n_i;
        let interior = g[..n_i].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let contact = friction_node::kkt_violation(
            self.block,
            &g[n_i..],
            &w[n_i..],
            &self.weights,
            &self.law,
        );
        if contact.is_nan() {
            f64::NAN
        } else {
            interior.max(contact)
        }
    }

    /// g += K[:, c..c+block] δ (K symmetric: its rows).
    fn update_gradient(&self, g: &mut [f64], c: usize, delta: [f64; 2]) {
        for (r, &d) in delta.iter().enumerate().take(self.block) {
            if d == 0.0 {
                continue;
            }
            self.k.for_each_in_row(c + r, |j, v| g[j] += v * d);
        }
    }

    /// Step 1: nonlinear Gauss–Seidel over the Γ3 nodes (w and g = K w − f updated).
    fn smooth_contact(&self, w: &mut [f64], g: &mut [f64]) {
        for i in 0..self.weights.len() {
            let c = self.n_i + self.block * i;
            let om = self.weights[i];
            let kb = self.node_k[i];
            let x = self.node(w, i);
            let y = if self.block == 1 {
                [
                    friction_node::prox_line(&self.law, om / kb[0], x[0] - g[c] / kb[0]),
                    0.0,
                ]
            } else {
                // λ_max of the 2 × 2 block.
                let (a, b, d) = (kb[0], 0.5 * (kb[1] + kb[2]), kb[3]);
                let lam = 0.5 * (a + d) + (0.25 * (a - d) * (a - d) + b * b).sqrt();
                let step = 1.0 / lam;
                let mut y = x;
                let mut gy = [g[c], g[c + 1]];
                for _ in 0..LOCAL_SWEEPS {
                    let z = [y[0] - step * gy[0], y[1] - step * gy[1]];
                    let next = friction_node::prox_plane(&self.law, step * om, z);
                    let dv = [next[0] - y[0], next[1] - y[1]];
                    if dv == [0.0, 0.0] {
                        break;
                    }
                    gy[0] += a * dv[0] + kb[1] * dv[1];
                    gy[1] += kb[2] * dv[0] + d * dv[1];
                    y = next;
                }
                y
            };
            let delta = [y[0] - x[0], y[1] - x[1]];
            if delta != [0.0, 0.0] {
                w[c] = y[0];
                if self.block == 2 {
                    w[c + 1] = y[1];
                }
                self.update_gradient(g, c, delta);
            }
        }
    }

    /// Step 2–3's data: the stick flags, the Newton gradient r (zero on stick DOFs) and the
    /// blocks E at the slip nodes.
    fn linearise(&self, w: &[f64], g: &[f64], r: &mut [f64]) -> (Vec<bool>, Vec<NodeBlock>) {
        r.copy_from_slice(g);
        let mut stick = vec![false; self.weights.len()];
        let mut blocks = Vec::new();
        for (i, &om) in self.weights.iter().enumerate() {
            let c = self.n_i + self.block * i;
            let x = self.node(w, i);
            let rho = (x[0] * x[0] + x[1] * x[1]).sqrt();
            if rho == 0.0 {
                stick[i] = true;
                r[c..c + self.block].iter_mut().for_each(|v| *v = 0.0);
                continue;
            }
            let (mu, dmu) = (self.law.mu(rho), self.law.dmu(rho));
            let z = [x[0] / rho, x[1] / rho];
            let mut m = [0.0; 4];
            if self.block == 1 {
                r[c] += om * mu * z[0];
                m[0] = om * dmu;
            } else {
                r[c] += om * mu * z[0];
                r[c + 1] += om * mu * z[1];
                let stiffness = self.stiffness(i);
                let t = (mu / rho).min(CURVATURE_CAP * stiffness / om);
                for a in 0..2 {
                    for b in 0..2 {
                        let zz = z[a] * z[b];
                        let id = if a == b { 1.0 } else { 0.0 };
                        m[2 * a + b] = om * (dmu * zz + t * (id - zz));
                    }
                }
            }
            blocks.push(NodeBlock {
                start: c,
                size: self.block,
                m,
            });
        }
        (stick, blocks)
    }

    /// The Jacobian's stick DOFs for this stick set, and the preconditioner: the cached one
    /// if it was made for this stick set and its E⁺ blocks have not moved far, else the
    /// cached one updated to them ([`Truncated::updated`]: the same operator as a new one,
    /// for work on the changed nodes only). Returns whether one was made or updated.
    ///
    /// A preconditioner of a nearby stick set is not enough: a node that has just started to
    /// slip has a tiny |x_i| and so a huge curvature ω μ/|x_i|, which an old preconditioner
    /// (that held the node fixed) leaves unscaled. Tried on box-exp3 with g = 2 at 1/64 (with
    /// up to a tenth of the slipping nodes changed): CG ran to its iteration limit on step 19
    /// and the step failed. Rebuilding is about 40 % of that run's time.
    fn prepare(&mut self, stick: Vec<bool>, blocks: &[NodeBlock]) -> Result<bool, SolveError> {
        let n = self.k.nrows();
        self.is_fixed.clear();
        self.is_fixed.resize(n, false);
        self.fixed.clear();
        for (i, _) in stick.iter().enumerate().filter(|(_, &s)| s) {
            let c = self.n_i + self.block * i;
            for dof in c..c + self.block {
                self.fixed.push(dof);
                self.is_fixed[dof] = true;
            }
        }
        let positive: Vec<NodeBlock> = blocks.iter().map(NodeBlock::positive_part).collect();
        if let Some(c) = &self.cached {
            let same = c.stick == stick && c.blocks.len() == positive.len();
            // Blocks of the nodes that slip, matched by their first DOF.
            let moved_far = positive.iter().any(|new| {
                let Ok(k) = c.blocks.binary_search_by_key(&new.start, |b| b.start) else {
                    return false;
                };
                let old = &c.blocks[k];
                let i = (new.start - self.n_i) / self.block;
                let stiffness = self.stiffness(i);
                let moved = old
                    .m
                    .iter()
                    .zip(&new.m)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                // The smaller size: a block that fell from far above its node's stiffness has
                // moved by less than its old size, yet the preconditioner still holds the node
                // nearly fixed across its slip.
                let size = |b: &NodeBlock| b.m.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                moved > REBUILD_FLOOR * stiffness + size(old).min(size(new))
            });
            if same && !moved_far {
                return Ok(false);
            }
        }
        // The old preconditioner is updated where there is one, not built again beside it.
        let truncated = match self.cached.take() {
            Some(c) => c
                .truncated
                .updated(&self.hierarchy, self.fixed.clone(), blocks),
            None => Truncated::with_operator(
                &self.hierarchy,
                self.k.clone(),
                self.fixed.clone(),
                blocks,
            ),
        }
        .map_err(|source| SolveError::Factor {
            what: "truncated multigrid coarse",
            source,
        })?;
        self.cached = Some(Cached {
            stick,
            blocks: positive,
            truncated,
        });
        Ok(true)
    }

    /// E(w + α d) − E(w) from g = K w − f and K d.
    fn energy_change(&self, w: &[f64], d: &[f64], dg: f64, dkd: f64, alpha: f64) -> f64 {
        let friction: f64 = (0..self.weights.len())
            .filter(|&i| self.weights[i] != 0.0)
            .map(|i| {
                let x = self.node(w, i);
                let di = self.node(d, i);
                if di == [0.0, 0.0] {
                    return 0.0;
                }
                self.weights[i]
                    * self
                        .law
                        .node_potential_change(x, [alpha * di[0], alpha * di[1]])
            })
            .sum();
        alpha * dg + 0.5 * alpha * alpha * dkd + friction
    }

    /// The full step with every slip node whose step reverses its slip (x_i·(x_i + d_i) ≤ 0)
    /// landing at rest instead (d_i = −x_i), taken if it lowers E; d and K d are changed
    /// only then. A node that should stop slipping is overshot by the Newton step (the
    /// model's radial curvature is K's alone), and the line search then cuts the step of every
    /// other node too: on box-exp3 with g = 2 at 1/64 that made the swept residual fall by
    /// only 0.6–0.8 an iteration, 4–6 Newton iterations a step, where landing the node on
    /// its kink ends the step in one.
    fn try_landing(&self, w: &[f64], g: &[f64], d: &mut [f64], kd: &mut [f64]) -> bool {
        // (node, its step d_i, the landing step −x_i)
        let landing: Vec<(usize, [f64; 2], [f64; 2])> = (0..self.weights.len())
            .filter_map(|i| {
                let (x, di) = (self.node(w, i), self.node(d, i));
                let turns = x != [0.0, 0.0] && x[0] * (x[0] + di[0]) + x[1] * (x[1] + di[1]) <= 0.0;
                turns.then_some((i, di, [-x[0], -x[1]]))
            })
            .collect();
        if landing.is_empty() {
            return false;
        }
        let set = |d: &mut [f64], kd: &mut [f64], to_landing: bool| {
            for &(i, step, land) in &landing {
                let c = self.n_i + self.block * i;
                let (from, to) = if to_landing {
                    (step, land)
                } else {
                    (land, step)
                };
                d[c..c + self.block].copy_from_slice(&to[..self.block]);
                self.update_gradient(kd, c, [to[0] - from[0], to[1] - from[1]]);
            }
        };
        set(d, kd, true);
        let dg: f64 = d.iter().zip(g).map(|(d, g)| d * g).sum();
        let dkd: f64 = d.iter().zip(kd.iter()).map(|(d, k)| d * k).sum();
        if self.energy_change(w, d, dg, dkd, 1.0) < 0.0 {
            return true;
        }
        set(d, kd, false);
        false
    }

    /// Solves (3.13) for the free-DOF load `f` from the warm start in `w` (overwritten with
    /// the solution), to the relative KKT residual `settings.tolerance` (relative to ‖f‖∞).
    /// `krylov_floor` is the smallest CG residual asked for, relative to ‖f‖∞.
    pub fn solve(
        &mut self,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        krylov_floor: f64,
        step: usize,
    ) -> Result<NewtonReport, SolveError> {
        let n = self.k.nrows();
        let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
        let mut g = std::mem::take(&mut self.gradient);
        g.resize(n, 0.0);
        let (mut r, mut d, mut kd) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let fresh_gradient = |k: &Sparse, w: &[f64], g: &mut [f64]| {
            k.mul_vec(w, g);
            g.iter_mut().zip(f).for_each(|(g, f)| *g -= f);
        };
        fresh_gradient(&self.k, w, &mut g);
        let mut report = NewtonReport {
            newton_iterations: 0,
            krylov_iterations: 0,
            residual: f64::INFINITY,
            slip_nodes: 0,
            preconditioners: 0,
        };
        let mut fresh = true;
        let mut rejected = 0;
        for it in 0..=settings.max_iterations {
            let mut residual = self.kkt(&g, w) / scale;
            if residual <= settings.tolerance && !fresh {
                // g is updated by products with steps; judge convergence on K w − f itself.
                fresh_gradient(&self.k, w, &mut g);
                residual = self.kkt(&g, w) / scale;
            }
            report.residual = residual;
            if residual <= settings.tolerance {
                report.slip_nodes = (0..self.weights.len())
                    .filter(|&i| self.node(w, i) != [0.0, 0.0])
                    .count();
                self.gradient = g;
                return Ok(report);
            }
            if it == settings.max_iterations || !residual.is_finite() {
                return Err(SolveError::NotConverged {
                    what: "velocity step (semismooth Newton, multigrid)",
                    step,
                    iterations: report.newton_iterations,
                    residual,
                    tolerance: settings.tolerance,
                });
            }
            fresh = false;
            self.smooth_contact(w, &mut g);
            // The residual that sets the forcing term is the one after the sweep: a guess
            // whose resting nodes hold rounding-sized slip has a KKT residual of order one
            // that the sweep alone removes (it sets them to rest), and a forcing term taken
            // before it would ask CG for one digit only.
            let swept = self.kkt(&g, w) / scale;
            if swept <= settings.tolerance {
                continue;
            }
            report.newton_iterations += 1;
            let (stick, blocks) = self.linearise(w, &g, &mut r);
            if self.prepare(stick, &blocks)? {
                report.preconditioners += 1;
            }
            let r_norm = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if r_norm == 0.0 {
                continue;
            }
            let eta = swept.min(0.1);
            let atol = (eta * r_norm).max(krylov_floor * scale);
            r.iter_mut().for_each(|v| *v = -*v);
            d.iter_mut().for_each(|v| *v = 0.0);
            let truncated = &mut self.cached.as_mut().expect("prepared").truncated;
            let jacobian = Jacobian {
                a: &self.k,
                fixed: &self.fixed,
                is_fixed: &self.is_fixed,
                blocks: &blocks,
            };
            let rep = pcg::solve(
                &jacobian,
                truncated,
                &r,
                &mut d,
                atol,
                MAX_KRYLOV_ITERATIONS,
                &mut self.work,
            );
            report.krylov_iterations += rep.iterations;
            if rep.negative_curvature && d.iter().all(|&v| v == 0.0) {
                truncated.apply(&r, &mut d);
            }
            // Line search on E along d (r now holds −∇, d_stick = 0).
            self.k.mul_vec(&d, &mut kd);
            let mut alpha = 1.0;
            let mut accepted = self.try_landing(w, &g, &mut d, &mut kd);
            let dg: f64 = d.iter().zip(&g).map(|(d, g)| d * g).sum();
            let dkd: f64 = d.iter().zip(&kd).map(|(d, k)| d * k).sum();
            for _ in 0..HALVINGS {
                if accepted {
                    break;
                }
                if self.energy_change(w, &d, dg, dkd, alpha) < 0.0 {
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            if accepted {
                w.iter_mut().zip(&d).for_each(|(w, d)| *w += alpha * d);
                g.iter_mut().zip(&kd).for_each(|(g, k)| *g += alpha * k);
                rejected = 0;
            } else {
                // No decrease along the Newton step: at working precision (the tolerance is
                // below the rounding of E's changes), or a step that only the smoother can
                // improve on. Twice in a row is a stall.
                rejected += 1;
                if rejected == 2 {
                    fresh_gradient(&self.k, w, &mut g);
                    return Err(SolveError::NotConverged {
                        what: "velocity step (semismooth Newton, multigrid): no descent",
                        step,
                        iterations: report.newton_iterations,
                        residual: self.kkt(&g, w) / scale,
                        tolerance: settings.tolerance,
                    });
                }
            }
        }
        unreachable!()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::{assembly, multilevel, DofMap, Geometry};
    use crate::linalg::multigrid::Params;
    use crate::linalg::Csr;
    use crate::scene::{self, presets};
    use serde_json::json;

    /// box-exp3 at h = 1/4: K on the free DOFs, its hierarchy, n_I and ω per Γ3 node.
    fn box_at_quarter() -> (Arc<Csr>, Arc<Hierarchy>, usize, Vec<f64>) {
        let mut doc = presets::get("box-exp3").unwrap();
        doc["mesh"]["h"] = json!("1/4");
        let p = scene::validate(&doc).unwrap();
        let mesh = p.mesh::<3>().unwrap();
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::new(&mesh, &p.boundary);
        let visc = p.material.viscosity;
        let k = Arc::new(assembly::viscous_stiffness_in_pattern(
            &mesh, &geo, &dofs, visc.eta, visc.xi,
        ));
        let (blocks, levels) = multilevel::velocity_levels(&mesh, &dofs, dofs.n_free());
        let h = Arc::new(Hierarchy::new(k.clone(), blocks, levels, Params::default()).unwrap());
        let weights = dofs.contact.iter().step_by(2).map(|c| c.weight).collect();
        (k, h, dofs.n_interior, weights)
    }

    /// The preconditioner is rebuilt when slip blocks fall from 0.6 × their node's stiffness to
    /// 1e-3 × (a fall smaller than the old size, which the coarse level would still feel), and
    /// kept when they move by 1 %.
    #[test]
    fn slip_blocks_that_fell_far_below_the_stiffness_rebuild_the_preconditioner() {
        let (k, h, n_i, weights) = box_at_quarter();
        let law = FrictionLaw::Tresca { g: 1.0 };
        let mut newton = SemismoothNewton::new(k.into(), h, n_i, 2, weights.clone(), law);
        let at = |fraction: f64| -> Vec<NodeBlock> {
            (0..weights.len())
                .map(|i| {
                    let s = fraction * newton.stiffness(i);
                    NodeBlock {
                        start: n_i + 2 * i,
                        size: 2,
                        m: [s, 0.0, 0.0, s],
                    }
                })
                .collect()
        };
        let (high, low, moved) = (at(0.6), at(1e-3), at(1.01e-3));
        let stick = vec![false; weights.len()];
        assert!(
            newton.prepare(stick.clone(), &high).unwrap(),
            "the first is built"
        );
        assert!(
            newton.prepare(stick.clone(), &low).unwrap(),
            "blocks fallen from 0.6 to 1e-3 × the stiffness"
        );
        assert!(
            !newton.prepare(stick, &moved).unwrap(),
            "blocks moved by 1 %"
        );
    }

    /// box-exp3 at h = 1/4 (3D: two tangential DOFs per Γ3 node) under a load on every free
    /// DOF, for Tresca bounds that leave Γ3 slipping, in part and at rest: the solution meets
    /// the isotropic stick/slip conditions, checked by hand on K w − f.
    #[test]
    fn a_solve_meets_the_isotropic_stick_slip_conditions() {
        let (k, h, n_i, weights) = box_at_quarter();
        let n = k.nrows;
        let f: Vec<f64> = (0..n).map(|i| (0.37 * i as f64 + 1.0).sin()).collect();
        let tol = 1e-9 * f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let (mut slipped, mut stuck) = (0, 0);
        for g in [0.05, 0.5, 50.0] {
            let law = FrictionLaw::Tresca { g };
            let mut newton =
                SemismoothNewton::new(k.clone().into(), h.clone(), n_i, 2, weights.clone(), law);
            let mut w = vec![0.0; n];
            let settings = SolverSettings::default();
            let rep = newton
                .solve(&f, &mut w, &settings, 0.1 * settings.tolerance, 1)
                .unwrap();
            assert!(rep.residual <= settings.tolerance);
            // K w − f, by hand: zero on the interior rows; on Γ3 |r_i| ≤ ω_i g at rest,
            // r_i = −ω_i g x_i/|x_i| when slipping.
            let mut r = vec![0.0; n];
            k.mul_vec(&w, &mut r);
            r.iter_mut().zip(&f).for_each(|(r, f)| *r -= f);
            assert!(r[..n_i].iter().all(|v| v.abs() <= tol));
            let mut slipping = 0;
            for (i, om) in weights.iter().enumerate() {
                let c = n_i + 2 * i;
                let (x, ri, bound) = ([w[c], w[c + 1]], [r[c], r[c + 1]], om * g);
                let speed = x[0].hypot(x[1]);
                if speed == 0.0 {
                    assert!(ri[0].hypot(ri[1]) <= bound + tol, "node {i} at rest");
                    stuck += 1;
                } else {
                    let e = [ri[0] + bound * x[0] / speed, ri[1] + bound * x[1] / speed];
                    assert!(e[0].hypot(e[1]) <= tol, "node {i} slipping: {e:?}");
                    slipping += 1;
                }
            }
            assert_eq!(slipping, rep.slip_nodes);
            slipped += slipping;
        }
        assert!(slipped > 0 && stuck > 0, "slipped {slipped}, stuck {stuck}");
    }
}
