//! The velocity step (3.13): w_n minimises
//!   E(w) = ½ (A ε(w), ε(w)) + (B_{n−1}, ε(w)) − (f_n, w) + Σ_i ω_i j(w_τ(x_i))
//! over the free DOFs. With K the matrix of (A ε(·), ε(·)) and f the load (external minus
//! the explicit elastic term), split interior (I) / contact-tangential (C) DOFs:
//!   [K_II K_IC; K_CI K_CC] [w_I; x] = [f_I; f_C − ∂J(x)].
//! Eliminating w_I = K_II⁻¹ (f_I − K_IC x) leaves the small non-smooth problem of
//! [`super::friction_reduced`] with S = K_CC − K_CI K_II⁻¹ K_IC and b = f_C − K_CI K_II⁻¹ f_I.
//!
//! K_II is factored once per job, or (the multigrid path) gets a multigrid hierarchy once and
//! is solved by preconditioned conjugate gradients to half the step's tolerance
//! ([`LinearSolver`], `INTERIOR_FRACTION`). Per step: one solve for y = K_II⁻¹ f_I (on the multigrid path
//! from the K_II-projection of y onto the earlier steps' solutions,
//! [`crate::linalg::projection`]); if every contact node
//! sticks (|b_i| ≤ ω_i μ(0), checked exactly) then x = 0 and w_I = y: done. Otherwise S is
//! formed (once, lazily: as the trailing block of a factor of K with the contact DOFs last,
//! [`crate::linalg::schur`], or on the multigrid path column by column by solves), the
//! reduced problem is solved, and one more solve recovers w_I.
//!
//! On the multigrid path with K's own hierarchy on all free DOFs ([`VelocityStep::with_hierarchy`];
//! K_II is then solved through it as well, [`LinearSolver::LeadingBlock`]) a slipping step
//! never forms S: (3.13) is solved on all free DOFs by the truncated
//! nonsmooth Newton multigrid method of [`super::semismooth_newton`], warm-started from the
//! previous step's velocity.
//!
//! Each Γ3 node has d − 1 consecutive tangential DOFs: one in 2D (the reduced problem of
//! [`super::friction_reduced`]), two in 3D (the isotropic, group-sparse one of
//! [`super::friction_isotropic`], with the Euclidean norm of the node's 2-vector).

use super::semismooth_newton::SemismoothNewton;
use super::{friction_isotropic, friction_node, friction_reduced, galerkin_guess};
use super::{SolveError, SolverReport, SolverSettings};
use crate::fem::DofMap;
use crate::linalg::multigrid::Hierarchy;
use crate::linalg::projection::{self, SolutionSpace};
use crate::linalg::schur::{schur_by_solves, SCHUR_COLUMN_TOLERANCE};
use crate::linalg::{schur_complement, Csr, LinearSolver, SchurPath};
use crate::problem::FrictionLaw;
use nalgebra::DMatrix;
use std::sync::Arc;

/// How a velocity step's friction problem is solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ContactSolver {
    /// Every step of a run stuck: the exact all-stick test held, or the problem's solution
    /// had every Γ3 node at rest.
    #[default]
    StickOnly,
    /// The dense reduced problem on S, formed as given.
    DenseSchur(SchurPath),
    /// Semismooth Newton on all free DOFs with multigrid (no S).
    SemismoothNewton,
}

impl ContactSolver {
    /// What the summary says (`mesh.contact_solver`).
    pub fn describe(self) -> &'static str {
        match self {
            ContactSolver::StickOnly => "none needed (every step stuck)",
            ContactSolver::DenseSchur(SchurPath::TrailingBlock) => {
                "dense Schur complement (trailing block of the factor)"
            }
            ContactSolver::DenseSchur(SchurPath::BlockedSolves) => {
                "dense Schur complement (blocked solves)"
            }
            ContactSolver::SemismoothNewton => "semismooth Newton on all DOFs (multigrid)",
        }
    }
}

/// Most rounds of iterative refinement of the interior velocity per step.
const REFINEMENTS: usize = 3;

/// The multigrid path solves K_II y = f_I to this fraction of the step's tolerance (max norm,
/// relative to ‖f‖∞). When Γ3 sticks, that residual and the stick test's force are the whole
/// KKT residual (no product follows), so the margin only has to absorb the difference between
/// CG's recursive residual, on which it stops, and the true one it reports.
const INTERIOR_FRACTION: f64 = 0.5;

/// The Newton iterations of a slipping step solve their Jacobian systems (at least) to this
/// fraction of the step's tolerance: the full KKT residual then stays a decade below the
/// tolerance, and the norms agree with the direct path to about 1e-13 (box-exp3 at 1/16: 2e-14
/// with g = 2, where 0.01 cost 25 % more iterations).
const JACOBIAN_FRACTION: f64 = 0.1;

/// Cloning shares the factor of K_II (see [`Cholesky`]); the clone has its own warm start.
#[derive(Clone)]
pub struct VelocityStep {
    /// The operator on all free DOFs (for residuals), interior first, contact last.
    k: Arc<Csr>,
    n_i: usize,
    k_ii: LinearSolver,
    /// Contact rows, interior columns.
    k_ci: Csr,
    /// Tangential DOFs per Γ3 node: d − 1.
    block: usize,
    /// ω_i per contact DOF (repeated over a node's DOFs) ...
    weights: Vec<f64>,
    /// ... and per Γ3 node (what the 3D reduced problem takes).
    node_weights: Vec<f64>,
    law: FrictionLaw,
    /// How S is formed; after forming it, the path taken.
    schur_path: SchurPath,
    schur: Option<DMatrix<f64>>,
    /// Tangential velocities on Γ3 (the warm start of the next step).
    x: Vec<f64>,
    /// Reaction on the contact DOFs, −(S x − b): the discrete friction force at each node.
    reaction: Vec<f64>,
    y: Vec<f64>,
    /// The earlier steps' velocities on all free DOFs (multigrid path): the K-projection of
    /// y onto them starts the stick test's solve, the minimiser of E over their span a
    /// slipping step's Newton method ([`galerkin_guess`]).
    space: Option<SolutionSpace>,
    /// Some vector of the space moves on Γ3 (a slipping step's velocity): the stick test's
    /// projection, which needs a span with x = 0, then starts from an empty space.
    space_slips: bool,
    r: Vec<f64>,
    /// Krylov iterations of the current step (multigrid path).
    krylov: usize,
    /// The multigrid path's solver of slipping steps on all free DOFs.
    newton: Option<Box<SemismoothNewton>>,
    /// The last step's free-DOF velocity (the Newton warm start).
    w_last: Vec<f64>,
    /// `r` holds K w − f of this step's solution already (the Newton method's own, or the
    /// stick solve's true residual).
    r_fresh: bool,
}

impl VelocityStep {
    /// The step with a given solver of K_II (the leading n_interior block of `k`).
    pub fn with_solver<const D: usize>(
        k: Arc<Csr>,
        dofs: &DofMap<D>,
        law: FrictionLaw,
        path: SchurPath,
        k_ii: LinearSolver,
    ) -> Self {
        let n_i = dofs.n_interior;
        let n = dofs.n_free();
        debug_assert_eq!(k_ii.n(), n_i);
        let k_ci = k.block(n_i..n, 0..n_i);
        let m = dofs.n_contact();
        VelocityStep {
            n_i,
            k_ii,
            k_ci,
            schur_path: path,
            block: D - 1,
            weights: dofs.contact.iter().map(|c| c.weight).collect(),
            node_weights: dofs
                .contact
                .iter()
                .step_by(D - 1)
                .map(|c| c.weight)
                .collect(),
            law,
            schur: None,
            x: vec![0.0; m],
            reaction: vec![0.0; m],
            y: vec![0.0; n_i],
            space: None,
            space_slips: false,
            r: vec![0.0; n],
            krylov: 0,
            newton: None,
            w_last: vec![0.0; n],
            r_fresh: false,
            k,
        }
    }

    /// Each solve with K_II started from the K-projection of its load onto the earlier
    /// steps' velocities ([`crate::linalg::projection`]): for a solver that takes a
    /// starting guess.
    pub fn with_solution_space(mut self) -> Self {
        self.space = Some(SolutionSpace::new(self.k.nrows, projection::CAPACITY));
        self
    }

    /// Slipping steps solved on all free DOFs by semismooth Newton with the multigrid
    /// `hierarchy` of K (all free DOFs), instead of on the dense S.
    pub fn with_hierarchy(mut self, hierarchy: Arc<Hierarchy>) -> Self {
        self.newton = Some(Box::new(SemismoothNewton::new(
            self.k.clone(),
            hierarchy,
            self.n_i,
            self.block,
            self.node_weights.clone(),
            self.law.clone(),
        )));
        self
    }

    /// How a slipping step is (or was) solved.
    pub fn slip_solver(&self) -> ContactSolver {
        if self.newton.is_some() {
            ContactSolver::SemismoothNewton
        } else {
            ContactSolver::DenseSchur(self.schur_path)
        }
    }

    pub fn n_contact(&self) -> usize {
        self.weights.len()
    }

    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Tangential velocity of each Γ3 DOF after the last solve.
    pub fn contact_velocity(&self) -> &[f64] {
        &self.x
    }

    /// Discrete friction force −(S x − b) of each Γ3 DOF after the last solve (integrated over
    /// the node's share ω_i of Γ3; divide by ω_i for a traction density).
    pub fn contact_force(&self) -> &[f64] {
        &self.reaction
    }

    /// Set the warm start (e.g. when resuming from a checkpoint).
    pub fn set_contact_velocity(&mut self, x: &[f64]) {
        self.x.copy_from_slice(x);
    }

    /// Nonzeros of the factor of K_II and its dimension (0 nonzeros on the multigrid path).
    pub fn factor_size(&self) -> (usize, usize) {
        (self.k_ii.n(), self.k_ii.factor().map_or(0, |c| c.nnz_l()))
    }

    /// The solver of K_II.
    pub fn linear_solver(&self) -> &LinearSolver {
        &self.k_ii
    }

    /// Krylov iterations of the last step (0 on the direct path).
    pub fn krylov_iterations(&self) -> usize {
        self.krylov
    }

    /// How S is (to be) formed.
    pub fn schur_path(&self) -> SchurPath {
        self.schur_path
    }

    /// The free-DOF operator K and the number of interior DOFs (for benchmarks).
    pub fn operator(&self) -> (&Csr, usize) {
        (self.k.as_ref(), self.n_i)
    }

    /// K on all free DOFs, shared (no copy).
    pub fn shared_operator(&self) -> Arc<Csr> {
        self.k.clone()
    }

    /// One solve with K_II, in place (for benchmarks): a substitution pair on the direct
    /// path, a multigrid-CG solve from zero to 1e-10 relative on the other.
    pub fn substitute(&mut self, v: &mut [f64]) {
        let b = v.to_vec();
        let atol = 1e-10 * b.iter().fold(f64::MIN_POSITIVE, |m, x| m.max(x.abs()));
        v.iter_mut().for_each(|x| *x = 0.0);
        let _ = self.k_ii.solve(&b, v, atol);
    }

    /// S = K_CC − K_CI K_II⁻¹ K_IC, computed on first use.
    pub fn schur(&mut self) -> Result<&DMatrix<f64>, SolveError> {
        if self.schur.is_none() {
            let s = match self.k_ii.factor() {
                Some(f) => {
                    let (s, path) = schur_complement(&self.k, self.n_i, f, self.schur_path);
                    self.schur_path = path;
                    s
                }
                None => self.schur_by_solves()?,
            };
            self.schur = Some(s);
        }
        Ok(self.schur.as_ref().unwrap())
    }

    /// S column by column on the multigrid path ([`schur_by_solves`]).
    fn schur_by_solves(&mut self) -> Result<DMatrix<f64>, SolveError> {
        self.schur_path = SchurPath::BlockedSolves;
        schur_by_solves(&self.k, self.n_i, &mut self.k_ii).map_err(|e| SolveError::NotConverged {
            what: "Schur complement column (multigrid)",
            step: 0,
            iterations: e.iterations,
            residual: e.residual,
            tolerance: SCHUR_COLUMN_TOLERANCE,
        })
    }

    /// The stick test with y = K_II⁻¹ f_I, then (if some node slips) the reduced problem or
    /// the full-space method. Returns the friction solver's iterations.
    fn solve_stick_or_reduced(
        &mut self,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<usize, SolveError> {
        let n_i = self.n_i;
        let m = self.n_contact();
        let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
        let mut y = std::mem::take(&mut self.y);
        if let Some(space) = &mut self.space {
            if std::mem::take(&mut self.space_slips) {
                space.clear();
            }
            // Every vector of the space is zero on Γ3: its K-projection is y's K_II one.
            space.project(f, w);
            y.copy_from_slice(&w[..n_i]);
        }
        let solved = self.solve_interior(&f[..n_i], &mut y, scale, settings, step);
        if let (Some(space), Ok(())) = (&mut self.space, &solved) {
            w[..n_i].copy_from_slice(&y);
            w[n_i..].iter_mut().for_each(|v| *v = 0.0);
            space.extend(self.k.as_ref(), w);
        }
        self.y = y;
        solved?;
        let mut iterations = 0;
        if m > 0 {
            let mut b = f[n_i..].to_vec();
            let mut kci_y = vec![0.0; m];
            self.k_ci.mul_vec(&self.y, &mut kci_y);
            b.iter_mut().zip(&kci_y).for_each(|(b, v)| *b -= v);
            if friction_node::all_stick(self.block, &b, &self.node_weights, &self.law) {
                self.x.iter_mut().for_each(|v| *v = 0.0);
                w[..n_i].copy_from_slice(&self.y);
                // K w − f of w = (y, 0) is (−(f_I − K_II y), −b): the solve's true residual
                // and the stick test's b, so the KKT check needs no product.
                if let Some(residual) = self.k_ii.last_residual() {
                    let (r_i, r_c) = self.r.split_at_mut(n_i);
                    r_i.iter_mut().zip(residual).for_each(|(r, v)| *r = -v);
                    r_c.iter_mut().zip(&b).for_each(|(r, v)| *r = -v);
                    self.r_fresh = true;
                }
            } else if self.newton.is_some() {
                iterations = self.solve_full(f, w, settings, step)?;
            } else {
                let mut x = std::mem::take(&mut self.x);
                let law = self.law.clone();
                let weights = std::mem::take(&mut self.weights);
                let node_weights = std::mem::take(&mut self.node_weights);
                // Same force scale as the full residual below, and half its tolerance: the
                // recovery of the interior adds rounding only.
                let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
                let inner = SolverSettings {
                    tolerance: 0.5 * settings.tolerance,
                    ..*settings
                };
                let block = self.block;
                let s = match self.schur() {
                    Ok(s) => s,
                    Err(e) => {
                        self.weights = weights;
                        self.node_weights = node_weights;
                        return Err(e);
                    }
                };
                let rep = match block {
                    1 => friction_reduced::solve(
                        &friction_reduced::Reduced {
                            s,
                            b: &b,
                            weights: &weights,
                            law: &law,
                            scale: Some(scale),
                        },
                        &mut x,
                        &inner,
                        step,
                    ),
                    _ => friction_isotropic::solve(
                        &friction_isotropic::Reduced {
                            s,
                            b: &b,
                            weights: &node_weights,
                            law: &law,
                            scale: Some(scale),
                        },
                        &mut x,
                        &inner,
                        step,
                    ),
                };
                self.weights = weights;
                self.node_weights = node_weights;
                iterations = rep?.iterations;
                // w_I = K_II⁻¹ (f_I − K_IC x).
                let mut rhs = f[..n_i].to_vec();
                let mut kic_x = vec![0.0; n_i];
                self.k_ci.tmul_vec_add(&x, &mut kic_x);
                rhs.iter_mut().zip(&kic_x).for_each(|(a, v)| *a -= v);
                self.x = x;
                let wi = &mut w[..n_i];
                wi.copy_from_slice(&self.y);
                self.solve_interior(&rhs, wi, scale, settings, step)?;
            }
            w[n_i..].copy_from_slice(&self.x);
        } else {
            w.copy_from_slice(&self.y);
            if let Some(residual) = self.k_ii.last_residual() {
                self.r.iter_mut().zip(residual).for_each(|(r, v)| *r = -v);
                self.r_fresh = true;
            }
        }
        Ok(iterations)
    }

    /// A slipping step on all free DOFs (multigrid path): semismooth Newton, started from
    /// the minimiser of E over the span of the earlier velocities ([`galerkin_guess`]; no
    /// worse in energy than the last step's velocity, or after an all-stick step this
    /// step's stick solution). Returns the Newton iterations.
    fn solve_full(
        &mut self,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<usize, SolveError> {
        let n_i = self.n_i;
        w.copy_from_slice(&self.w_last);
        if self.x.iter().all(|&v| v == 0.0) {
            w[..n_i].copy_from_slice(&self.y);
        }
        if let Some(space) = &mut self.space {
            let contact = galerkin_guess::Contact {
                n_interior: n_i,
                block: self.block,
                weights: &self.node_weights,
                law: &self.law,
            };
            galerkin_guess::minimise(space, f, &contact, w);
        }
        // Half the tolerance, as the dense path's reduced solve: the full check follows.
        let inner = SolverSettings {
            tolerance: 0.5 * settings.tolerance,
            ..*settings
        };
        let newton = self.newton.as_mut().expect("the multigrid path's");
        let rep = newton.solve(f, w, &inner, JACOBIAN_FRACTION * settings.tolerance, step)?;
        self.krylov += rep.krylov_iterations;
        self.r.copy_from_slice(newton.gradient());
        self.r_fresh = true;
        self.x.copy_from_slice(&w[n_i..]);
        if let Some(space) = &mut self.space {
            space.extend(self.k.as_ref(), w);
            self.space_slips |= self.x.iter().any(|&v| v != 0.0);
        }
        Ok(rep.newton_iterations)
    }

    /// K_II y = b on the solver's path, from the guess in `y`, to INTERIOR_FRACTION of the
    /// tolerance relative to `scale`.
    fn solve_interior(
        &mut self,
        b: &[f64],
        y: &mut [f64],
        scale: f64,
        settings: &SolverSettings,
        step: usize,
    ) -> Result<(), SolveError> {
        let atol = INTERIOR_FRACTION * settings.tolerance * scale;
        match self.k_ii.solve(b, y, atol) {
            Ok(it) => {
                self.krylov += it;
                Ok(())
            }
            Err(e) => Err(SolveError::NotConverged {
                what: "velocity step (multigrid conjugate gradients)",
                step,
                iterations: e.iterations,
                residual: e.residual / scale,
                tolerance: INTERIOR_FRACTION * settings.tolerance,
            }),
        }
    }

    /// Solves (3.13) for the free-DOF load `f`, writing the free-DOF velocity into `w`.
    /// The reported residual is the relative KKT residual of the FULL problem, computed from
    /// K w − f (not from the reduced quantities).
    pub fn solve(
        &mut self,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<SolverReport, SolveError> {
        let n_i = self.n_i;
        let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
        self.krylov = 0;
        self.r_fresh = false;
        let iterations = if self.newton.is_some() && self.x.iter().any(|&v| v != 0.0) {
            // The last step slipped: this one goes to the full-space method at once (which
            // also finds an all-stick solution), without the stick test's solve.
            let iterations = self.solve_full(f, w, settings, step)?;
            self.y.copy_from_slice(&w[..n_i]);
            iterations
        } else {
            self.solve_stick_or_reduced(f, w, settings, step)?
        };
        let mut residual = if std::mem::take(&mut self.r_fresh) {
            self.kkt_of_residual()
        } else {
            self.full_residual(f, w)
        } / scale;
        if residual > settings.tolerance && residual.is_finite() {
            residual = self.refine(f, w, scale, settings.tolerance);
        }
        if !residual.is_finite() {
            return Err(SolveError::NonFinite("velocity", step));
        }
        if residual > settings.tolerance {
            return Err(SolveError::NotConverged {
                what: "velocity step",
                step,
                iterations,
                residual,
                tolerance: settings.tolerance,
            });
        }
        self.w_last.copy_from_slice(w);
        Ok(SolverReport {
            iterations,
            residual,
            krylov_iterations: self.krylov,
        })
    }
}

impl VelocityStep {
    /// The fallback for ill-conditioned K (a slender body: its condition grows like
    /// (length/height)^4), where the rounding of K w alone, about ε·‖|K||w|‖∞, exceeds the
    /// tolerance times ‖f‖∞: a few rounds of iterative refinement of w_I (x fixed) with the
    /// same factor, then the residual relative to ‖|K||w|‖∞ instead of ‖f‖∞ (a normwise
    /// backward error: w solves K w = f + δ with ‖δ‖ ≤ residual·‖|K||w|‖∞). Steps that meet
    /// the tolerance relative to ‖f‖∞ never get here and stay bit for bit as they were.
    /// Returns the residual to report (relative to ‖f‖∞ if refinement reached the tolerance).
    fn refine(&mut self, f: &[f64], w: &mut [f64], scale: f64, tolerance: f64) -> f64 {
        let n_i = self.n_i;
        let mut residual = self.full_residual(f, w) / scale;
        for _ in 0..REFINEMENTS {
            let r = self.r[..n_i].to_vec();
            let mut d = vec![0.0; n_i];
            let r_scale = r.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
            if let Ok(it) = self.k_ii.solve(&r, &mut d, 1e-3 * r_scale) {
                self.krylov += it;
            }
            let before = w[..n_i].to_vec();
            w[..n_i].iter_mut().zip(&d).for_each(|(w, d)| *w -= d);
            let refined = self.full_residual(f, w) / scale;
            if refined >= residual || refined.is_nan() {
                w[..n_i].copy_from_slice(&before);
                self.full_residual(f, w);
                break;
            }
            residual = refined;
            if residual <= tolerance {
                return residual;
            }
        }
        let k = &self.k;
        let floor = (0..k.nrows).fold(f64::MIN_POSITIVE, |m, i| {
            let row = k.indptr[i]..k.indptr[i + 1];
            let s: f64 = k.indices[row.clone()]
                .iter()
                .zip(&k.values[row])
                .map(|(&j, v)| (v * w[j as usize]).abs())
                .sum();
            m.max(s)
        });
        residual * scale / floor.max(scale)
    }

    /// Full-system optimality of `w`: r = K w − f; interior rows must vanish, contact rows
    /// must satisfy the stick/slip conditions with g = r_C. Leaves r in `self.r` and the
    /// friction force −r_C in `self.reaction`; returns the larger violation (unscaled).
    fn full_residual(&mut self, f: &[f64], w: &[f64]) -> f64 {
        self.k.mul_vec(w, &mut self.r);
        for (r, f) in self.r.iter_mut().zip(f) {
            *r -= f;
        }
        self.kkt_of_residual()
    }

    /// [`VelocityStep::full_residual`] with r = K w − f already in `self.r`.
    fn kkt_of_residual(&mut self) -> f64 {
        let n_i = self.n_i;
        let interior = self.r[..n_i].iter().fold(0.0f64, |s, v| s.max(v.abs()));
        let contact = friction_node::kkt_violation(
            self.block,
            &self.r[n_i..],
            &self.x,
            &self.node_weights,
            &self.law,
        );
        for (q, r) in self.reaction.iter_mut().zip(&self.r[n_i..]) {
            *q = -r;
        }
        interior.max(contact)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::{assembly, Geometry};
    use crate::scene::{self, presets};
    use crate::solve::backend;
    use serde_json::json;

    /// The velocity step of paper-exp3 at h = 1/8 with Tresca bound `g` as the backend of
    /// `linear` builds it, with K assembled here by element triplets and the DOF map.
    fn velocity(linear: &str, g: f64) -> (VelocityStep, Csr, DofMap<2>) {
        let mut doc = presets::get("paper-exp3").unwrap();
        doc["mesh"]["h"] = json!("1/8");
        doc["friction"] = json!({"law": "tresca", "g": g});
        doc["solver"] = json!({"linear": linear});
        let p = scene::validate(&doc).unwrap();
        let mesh = p.mesh::<2>().unwrap();
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::new(&mesh, &p.boundary);
        let b = backend::choose(&p, &mesh, &dofs, None).unwrap();
        let visc = p.material.viscosity;
        let k = b.stiffness(&mesh, &geo, &dofs, visc.eta, visc.xi);
        let step = b
            .velocity(Arc::new(k), &mesh, &dofs, p.friction.clone())
            .unwrap();
        let k = assembly::viscous_stiffness(&mesh, &geo, &dofs, visc.eta, visc.xi);
        (step, k, dofs)
    }

    /// The conditions of (3.13) at w for the load f, checked by hand: K w − f vanishes on
    /// the interior rows; on Γ3 a stuck node's force is within ω g, a slipping node's is
    /// −ω g sign(x). Returns the slipping nodes.
    fn kkt(k: &Csr, dofs: &DofMap<2>, f: &[f64], w: &[f64], g: f64) -> usize {
        let mut r = vec![0.0; f.len()];
        k.mul_vec(w, &mut r);
        r.iter_mut().zip(f).for_each(|(r, f)| *r -= f);
        let tol = 1e-9 * f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let n_i = dofs.n_interior;
        assert!(r[..n_i].iter().all(|v| v.abs() <= tol));
        let mut slipping = 0;
        for (i, c) in dofs.contact.iter().enumerate() {
            let (x, rc, bound) = (w[n_i + i], r[n_i + i], c.weight * g);
            if x == 0.0 {
                assert!(rc.abs() <= bound + tol, "stuck: |{rc}| > {bound}");
            } else {
                slipping += 1;
                assert!(
                    (rc + bound * x.signum()).abs() <= tol,
                    "slip: {rc} vs {bound}"
                );
            }
        }
        slipping
    }

    /// Both paths solve (3.13) to its optimality conditions and to the same velocity, when
    /// Γ3 slips everywhere, in part and nowhere; the second solve of each starts from the
    /// first's warm start (on the multigrid path a slipping step's goes to semismooth Newton
    /// at once).
    #[test]
    fn both_paths_meet_the_stick_slip_conditions_and_agree() {
        let (mut slipped, mut stuck) = (0, 0);
        for g in [0.5, 5.0, 5000.0] {
            let mut solutions = Vec::new();
            for linear in ["direct", "multigrid"] {
                let (mut step, k, dofs) = velocity(linear, g);
                let n = k.nrows;
                let f: Vec<f64> = (0..n)
                    .map(|i| 10.0 * (0.37 * i as f64 + 1.0).sin())
                    .collect();
                let mut w = vec![0.0; n];
                for n in 1..=2 {
                    let rep = step
                        .solve(&f, &mut w, &SolverSettings::default(), n)
                        .unwrap();
                    assert!(rep.residual <= 1e-10);
                    let slipping = kkt(&k, &dofs, &f, &w, g);
                    slipped += slipping;
                    stuck += dofs.contact.len() - slipping;
                }
                solutions.push(w);
            }
            let scale = solutions[0].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (a, b) in solutions[0].iter().zip(&solutions[1]) {
                assert!((a - b).abs() <= 1e-8 * scale, "g = {g}: {a} vs {b}");
            }
        }
        assert!(slipped > 0 && stuck > 0, "slipped {slipped}, stuck {stuck}");
    }
}
