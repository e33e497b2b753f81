//! The velocity step (3.13): w_n minimises
//!   E(w) = ½ (A ε(w), ε(w)) + (B_{n−1}, ε(w)) − (f_n, w) + Σ_i ω_i j(w_τ(x_i))
//! over the free DOFs. With K the matrix of (A ε(·), ε(·)) and f the load (external minus
//! the explicit elastic term), split interior (I) / contact-tangential (C) DOFs:
//!   [K_II K_IC; K_CI K_CC] [w_I; x] = [f_I; f_C − ∂J(x)].
//! Eliminating w_I = K_II⁻¹ (f_I − K_IC x) leaves the small non-smooth problem of
//! [`super::friction_reduced`] with S = K_CC − K_CI K_II⁻¹ K_IC and b = f_C − K_CI K_II⁻¹ f_I.
//!
//! The run's backend ([`super::backend`]) hands the step its solver of K_II ([`LinearSolver`]:
//! a factor made once per job, or a multigrid hierarchy made once and preconditioned
//! conjugate gradients to half the step's tolerance, `INTERIOR_FRACTION`) and its solver of
//! slipping steps ([`SlipSolver`]). Per step: one solve for y = K_II⁻¹ f_I (from the
//! K_II-projection of y onto the earlier steps' solutions where the backend attached a
//! solution space, [`crate::linalg::projection`]); if every contact node sticks
//! (|b_i| ≤ ω_i μ(0), checked exactly) then x = 0 and w_I = y: done. Otherwise the slip
//! solver solves the step: the direct family's the dense reduced problem on S (formed once,
//! lazily) and one more solve for w_I; the multigrid family's the truncated nonsmooth Newton
//! multigrid method of [`super::semismooth_newton`] on all free DOFs, never forming S, to
//! which a step after a slipping one goes at once. Either way the step's residual is the
//! full problem's KKT residual, checked here.
//!
//! Each Γ3 node has d − 1 consecutive tangential DOFs: one in 2D (the reduced problem of
//! [`super::friction_reduced`]), two in 3D (the isotropic, group-sparse one of
//! [`super::friction_isotropic`], with the Euclidean norm of the node's 2-vector).

use super::{friction_node, SolveError, SolverReport, SolverSettings};
use crate::fem::DofMap;
use crate::linalg::projection::{self, SolutionSpace};
use crate::linalg::{Csr, LinearSolver, SchurPath, Sparse};
use crate::problem::FrictionLaw;
use std::any::Any;

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

/// The solver of a velocity step in which some Γ3 node slips, handed to the step by the
/// run's backend ([`super::backend::Backend::velocity`]): the dense reduced problem on S
/// (`backend/direct.rs`), semismooth Newton on all free DOFs (`backend/multigrid.rs`).
pub trait SlipSolver: Send + Sync {
    /// How a slipping step is (or was) solved (the summary's `mesh.contact_solver`).
    fn report(&self) -> ContactSolver;

    /// Whether a step after a slipping one comes here at once, without the stick test's
    /// solve (a solver that also finds an all-stick solution, from the last velocity).
    fn after_slip_at_once(&self) -> bool {
        false
    }

    /// Solves (3.13) for the free-DOF load `f` into `w` (a step that does not stick, or one
    /// after a slipping step when [`SlipSolver::after_slip_at_once`]). On entry `state`
    /// holds the warm start `x` and, after the stick test, y = K_II⁻¹ f_I and its contact
    /// load `b`; on return `state.x` holds the tangential velocities (`w[n_i..]`), and
    /// `state.r` K w − f where `state.r_fresh` says so. Returns the solver's iterations.
    fn solve(
        &mut self,
        state: &mut StepState,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<usize, SolveError>;

    /// A clone (sharing what the solver shares: operators, factors, hierarchies).
    fn boxed_clone(&self) -> Box<dyn SlipSolver>;

    /// The solver as [`Any`], for its backend to reach its own type (the direct family's
    /// smallness estimate reuses its S).
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

/// The slip solver of a velocity step without a Γ3: nothing slips, it is never called.
#[derive(Clone, Copy)]
pub struct NoContact;

impl SlipSolver for NoContact {
    fn report(&self) -> ContactSolver {
        ContactSolver::StickOnly
    }

    fn solve(
        &mut self,
        _state: &mut StepState,
        _f: &[f64],
        _w: &mut [f64],
        _settings: &SolverSettings,
        _step: usize,
    ) -> Result<usize, SolveError> {
        unreachable!("a velocity step without a Γ3 never slips")
    }

    fn boxed_clone(&self) -> Box<dyn SlipSolver> {
        Box::new(*self)
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// Most rounds of iterative refinement of the interior velocity per step.
const REFINEMENTS: usize = 3;

/// The multigrid path solves K_II y = f_I to this fraction of the step's tolerance (max norm,
/// relative to ‖f‖∞). When Γ3 sticks, that residual and the stick test's force are the whole
/// KKT residual (no product follows), so the margin only has to absorb the difference between
/// CG's recursive residual, on which it stops, and the true one it reports.
const INTERIOR_FRACTION: f64 = 0.5;

/// The velocity step: its state and the backend's solver of slipping steps. Cloning shares
/// the factor of K_II (see [`crate::linalg::Cholesky`]); the clone has its own warm start.
pub struct VelocityStep {
    state: StepState,
    slip: Box<dyn SlipSolver>,
}

impl Clone for VelocityStep {
    fn clone(&self) -> Self {
        VelocityStep {
            state: self.state.clone(),
            slip: self.slip.boxed_clone(),
        }
    }
}

/// What a velocity step holds whatever its slip solver: the operators, the solver of K_II,
/// the warm starts and the step's work; what a [`SlipSolver`] reads and writes.
#[derive(Clone)]
pub struct StepState {
    /// The operator on all free DOFs (for residuals), interior first, contact last.
    pub(crate) k: Sparse,
    pub(crate) n_i: usize,
    pub(crate) k_ii: LinearSolver,
    /// Contact rows, interior columns.
    pub(crate) k_ci: Csr,
    /// Tangential DOFs per Γ3 node: d − 1.
    pub(crate) block: usize,
    /// ω_i per contact DOF (repeated over a node's DOFs) ...
    pub(crate) weights: Vec<f64>,
    /// ... and per Γ3 node (what the 3D reduced problem takes).
    pub(crate) node_weights: Vec<f64>,
    pub(crate) law: FrictionLaw,
    /// Tangential velocities on Γ3 (the warm start of the next step).
    pub(crate) x: Vec<f64>,
    /// Reaction on the contact DOFs, −(S x − b): the discrete friction force at each node.
    pub(crate) reaction: Vec<f64>,
    /// K_II⁻¹ f_I of the step's stick test ...
    pub(crate) y: Vec<f64>,
    /// ... and its contact load b = f_C − K_CI y.
    pub(crate) b: Vec<f64>,
    /// The earlier steps' velocities on all free DOFs (a solver that takes a starting
    /// guess): the K-projection of y onto them starts the stick test's solve, the minimiser
    /// of E over their span a slipping step's Newton method
    /// ([`super::galerkin_guess`]).
    pub(crate) space: Option<SolutionSpace>,
    /// Some vector of the space moves on Γ3 (a slipping step's velocity): the stick test's
    /// projection, which needs a span with x = 0, then starts from an empty space.
    pub(crate) space_slips: bool,
    pub(crate) r: Vec<f64>,
    /// Krylov iterations of the current step (multigrid path).
    pub(crate) krylov: usize,
    /// The last step's free-DOF velocity (a warm start).
    pub(crate) w_last: Vec<f64>,
    /// `r` holds K w − f of this step's solution already (the slip solver's own, or the
    /// stick solve's true residual).
    pub(crate) r_fresh: bool,
}

impl VelocityStep {
    /// The step with a given solver of K_II (the leading n_interior block of `k`) and of
    /// slipping steps.
    pub fn with_solver<const D: usize>(
        k: Sparse,
        dofs: &DofMap<D>,
        law: FrictionLaw,
        k_ii: LinearSolver,
        slip: Box<dyn SlipSolver>,
    ) -> Self {
        let n_i = dofs.n_interior;
        let n = dofs.n_free();
        debug_assert_eq!(k_ii.n(), n_i);
        let k_ci = k.block(n_i..n, 0..n_i);
        let m = dofs.n_contact();
        let state = StepState {
            n_i,
            k_ii,
            k_ci,
            block: D - 1,
            weights: dofs.contact.iter().map(|c| c.weight).collect(),
            node_weights: dofs
                .contact
                .iter()
                .step_by(D - 1)
                .map(|c| c.weight)
                .collect(),
            law,
            x: vec![0.0; m],
            reaction: vec![0.0; m],
            y: vec![0.0; n_i],
            b: vec![0.0; m],
            space: None,
            space_slips: false,
            r: vec![0.0; n],
            krylov: 0,
            w_last: vec![0.0; n],
            r_fresh: false,
            k,
        };
        VelocityStep { state, slip }
    }

    /// Each solve with K_II started from the K-projection of its load onto the earlier
    /// steps' velocities ([`crate::linalg::projection`]): for a solver that takes a
    /// starting guess.
    pub fn with_solution_space(mut self) -> Self {
        self.state.space = Some(SolutionSpace::new(
            self.state.k.nrows(),
            projection::CAPACITY,
        ));
        self
    }

    /// How a slipping step is (or was) solved.
    pub fn slip_solver(&self) -> ContactSolver {
        self.slip.report()
    }

    /// The step's state and its slip solver, borrowed together (for its backend).
    pub fn parts_mut(&mut self) -> (&mut StepState, &mut dyn SlipSolver) {
        (&mut self.state, self.slip.as_mut())
    }

    pub fn n_contact(&self) -> usize {
        self.state.weights.len()
    }

    pub fn weights(&self) -> &[f64] {
        &self.state.weights
    }

    /// Tangential velocity of each Γ3 DOF after the last solve.
    pub fn contact_velocity(&self) -> &[f64] {
        &self.state.x
    }

    /// Discrete friction force −(S x − b) of each Γ3 DOF after the last solve (integrated over
    /// the node's share ω_i of Γ3; divide by ω_i for a traction density).
    pub fn contact_force(&self) -> &[f64] {
        &self.state.reaction
    }

    /// Set the warm start (e.g. when resuming from a checkpoint).
    pub fn set_contact_velocity(&mut self, x: &[f64]) {
        self.state.x.copy_from_slice(x);
    }

    /// Nonzeros of the factor of K_II and its dimension (0 nonzeros on the multigrid path).
    pub fn factor_size(&self) -> (usize, usize) {
        let k_ii = &self.state.k_ii;
        (k_ii.n(), k_ii.factor_nnz())
    }

    /// The solver of K_II.
    pub fn linear_solver(&self) -> &LinearSolver {
        &self.state.k_ii
    }

    /// Krylov iterations of the last step (0 on the direct path).
    pub fn krylov_iterations(&self) -> usize {
        self.state.krylov
    }

    /// The free-DOF operator K and the number of interior DOFs (for benchmarks).
    pub fn operator(&self) -> (&Sparse, usize) {
        (&self.state.k, self.state.n_i)
    }

    /// K on all free DOFs, shared (no copy).
    pub fn shared_operator(&self) -> Sparse {
        self.state.k.clone()
    }

    /// One solve with K_II, in place (for benchmarks): a substitution pair on the direct
    /// path, a multigrid-CG solve from zero to 1e-10 relative on the other.
    pub fn substitute(&mut self, v: &mut [f64]) {
        let b = v.to_vec();
        let atol = 1e-10 * b.iter().fold(f64::MIN_POSITIVE, |m, x| m.max(x.abs()));
        v.iter_mut().for_each(|x| *x = 0.0);
        let _ = self.state.k_ii.solve(&b, v, atol);
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
        let state = &mut self.state;
        let slip = self.slip.as_mut();
        let n_i = state.n_i;
        let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
        state.krylov = 0;
        state.r_fresh = false;
        let iterations = if slip.after_slip_at_once() && state.x.iter().any(|&v| v != 0.0) {
            // The last step slipped: this one goes to the slip solver at once (which also
            // finds an all-stick solution), without the stick test's solve.
            let iterations = slip.solve(state, f, w, settings, step)?;
            state.y.copy_from_slice(&w[..n_i]);
            iterations
        } else {
            state.solve_stick_or_slip(slip, f, w, settings, step)?
        };
        let mut residual = if std::mem::take(&mut state.r_fresh) {
            state.kkt_of_residual()
        } else {
            state.full_residual(f, w)
        } / scale;
        if residual > settings.tolerance && residual.is_finite() {
            residual = state.refine(f, w, scale, settings.tolerance);
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
        state.w_last.copy_from_slice(w);
        Ok(SolverReport {
            iterations,
            residual,
            krylov_iterations: state.krylov,
        })
    }
}

impl StepState {
    /// The stick test with y = K_II⁻¹ f_I, then (if some node slips) the slip solver.
    /// Returns the slip solver's iterations.
    fn solve_stick_or_slip(
        &mut self,
        slip: &mut dyn SlipSolver,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<usize, SolveError> {
        let n_i = self.n_i;
        let m = self.weights.len();
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
            space.extend(&self.k, w);
        }
        self.y = y;
        solved?;
        let mut iterations = 0;
        if m > 0 {
            self.b.copy_from_slice(&f[n_i..]);
            let mut kci_y = vec![0.0; m];
            self.k_ci.mul_vec(&self.y, &mut kci_y);
            self.b.iter_mut().zip(&kci_y).for_each(|(b, v)| *b -= v);
            if friction_node::all_stick(self.block, &self.b, &self.node_weights, &self.law) {
                self.x.iter_mut().for_each(|v| *v = 0.0);
                w[..n_i].copy_from_slice(&self.y);
                // K w − f of w = (y, 0) is (−(f_I − K_II y), −b): the solve's true residual
                // and the stick test's b, so the KKT check needs no product.
                if let Some(residual) = self.k_ii.last_residual() {
                    let (r_i, r_c) = self.r.split_at_mut(n_i);
                    r_i.iter_mut().zip(residual).for_each(|(r, v)| *r = -v);
                    r_c.iter_mut().zip(&self.b).for_each(|(r, v)| *r = -v);
                    self.r_fresh = true;
                }
            } else {
                iterations = slip.solve(self, f, w, settings, step)?;
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

    /// K_II y = b on the solver's path, from the guess in `y`, to INTERIOR_FRACTION of the
    /// tolerance relative to `scale`.
    pub(crate) fn solve_interior(
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
        let floor = self.k.max_abs_row_product(w).max(f64::MIN_POSITIVE);
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
    use std::sync::Arc;

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

    /// Each family hands the step its slip solver, and a clone of the step keeps it: the
    /// dense reduced problem on S (the trailing block of the factor) on the direct path,
    /// semismooth Newton on all DOFs on the multigrid one.
    #[test]
    fn each_backend_hands_its_slip_solver() {
        let (direct, _, _) = velocity("direct", 0.5);
        let dense = ContactSolver::DenseSchur(SchurPath::TrailingBlock);
        assert_eq!(direct.slip_solver(), dense);
        assert_eq!(direct.clone().slip_solver(), dense);
        let (multigrid, _, _) = velocity("multigrid", 0.5);
        assert_eq!(multigrid.slip_solver(), ContactSolver::SemismoothNewton);
        assert_eq!(
            multigrid.clone().slip_solver(),
            ContactSolver::SemismoothNewton
        );
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
