//! Problem 3.1's time loop. For n = 1..N, from (u_{n−1}, ζ_{n−1}) only
//! ([`Simulation::step`]):
//! 1. B_{n−1} = B(ε(u_{n−1}), ζ_{n−1}) per element (3.8);
//! 2. velocity load and velocity step (3.13) → w_n  ∥  damage step (3.10) → ζ_n;
//! 3. u_n = u_{n−1} + k w_n (3.12);
//! 4. the step's norms; σ_n = A ε(w_n) + B_{n−1} (3.8) only when stored ([`Simulation::fields`]).
//!
//! The two sub-problems of step 2 are independent and run on two threads for meshes large
//! enough to pay for it. Physics absent from the scene is not computed: no damage block → ζ ≡ 1
//! and no damage solve; no Γ3 → a single linear solve per step.

use super::damage::DamageStep;
use super::smallness::{self, SmallnessReport};
use super::velocity::VelocityStep;
use super::{SolveError, SolverReport, SolverSettings};
use crate::fem::multilevel;
use crate::fem::{assembly, loads, norms, DofMap, Geometry};
use crate::laws::constitutive::{elastic_stress, viscous_stress, von_mises};
use crate::laws::damage_source::phi;
use crate::laws::Tensor;
use crate::linalg::multigrid::{Hierarchy, Params};
use crate::linalg::{Cholesky, CholeskyPlan, Csr, LinearPath, LinearSolver, SchurPath};
use crate::memory;
use crate::mesh::{AnyMesh, Mesh};
use crate::problem::{Problem, SmallnessPolicy};
use std::sync::Arc;
use std::time::Instant;

/// Below this many nodes the two sub-problems run one after the other (thread hand-off
/// would cost more than it saves).
const PARALLEL_MIN_NODES: usize = 3000;

/// The state at a time node: all that is needed to continue (a checkpoint).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct State {
    /// Index n of the time node t_n = n k.
    pub step: usize,
    /// Displacement u_n, interleaved (x, y[, z]) per node.
    pub u: Vec<f64>,
    /// Damage ζ_n per node.
    pub zeta: Vec<f64>,
    /// Warm starts of the two sub-problem solvers after step n, filled only by
    /// [`Simulation::checkpoint_state`] (empty otherwise): the tangential velocities on Γ3
    /// and the damage active set (0 free, 1 at ζ = 0, 2 at ζ = 1). Restoring them makes a
    /// resumed run on the direct path repeat an uninterrupted one bit for bit; without them,
    /// or on the multigrid path (whose CG starting guesses are not kept), it agrees to the
    /// solver tolerance.
    #[serde(default)]
    pub contact_velocity: Vec<f64>,
    #[serde(default)]
    pub damage_active: Vec<u8>,
}

/// What one time step did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepReport {
    pub n: usize,
    pub t: f64,
    #[serde(rename = "w_V")]
    pub w_v: f64,
    #[serde(rename = "u_V")]
    pub u_v: f64,
    #[serde(rename = "zeta_L2")]
    pub zeta_l2: f64,
    pub zeta_min: f64,
    pub velocity: SolverReport,
    pub damage: Option<SolverReport>,
    /// Γ3 nodes with nonzero tangential velocity.
    pub slip_nodes: usize,
}

/// Contact state at a Γ3 node.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ContactNode {
    pub node: usize,
    /// Tangential velocity w_τ: in 2D its signed component along the node's tangent, in 3D
    /// its length |w_τ|.
    pub slip_velocity: f64,
    /// Friction traction density (the discrete friction force divided by ω_i): in 2D signed
    /// along the tangent, in 3D its length.
    pub friction_traction: f64,
    /// The bound μ(|w_τ|) the traction is compared with.
    pub bound: f64,
    pub slipping: bool,
    /// 3D only: w_τ and the friction traction density as Cartesian vectors.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tangential_velocity: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub traction: Option<[f64; 3]>,
}

/// Per-element stresses of a stored step, symmetric: (σ_xx, σ_yy, σ_xy) in 2D and
/// (σ_xx, σ_yy, σ_zz, σ_xy, σ_yz, σ_xz) in 3D (the order of VTK's symmetric tensors).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum Stress {
    Plane(Vec<[f64; 3]>),
    Solid(Vec<[f64; 6]>),
}

impl FromIterator<[f64; 3]> for Stress {
    fn from_iter<I: IntoIterator<Item = [f64; 3]>>(iter: I) -> Self {
        Stress::Plane(iter.into_iter().collect())
    }
}

impl Stress {
    /// Every component of every element, in storage order.
    pub fn values(&self) -> Box<dyn Iterator<Item = f64> + '_> {
        match self {
            Stress::Plane(s) => Box::new(s.iter().flatten().copied()),
            Stress::Solid(s) => Box::new(s.iter().flatten().copied()),
        }
    }

    /// The 6 components (xx, yy, zz, xy, yz, xz) of element e (zero out-of-plane in 2D).
    pub fn six(&self, e: usize) -> [f64; 6] {
        match self {
            Stress::Plane(s) => [s[e][0], s[e][1], 0.0, s[e][2], 0.0, 0.0],
            Stress::Solid(s) => s[e],
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Stress::Plane(s) => s.len(),
            Stress::Solid(s) => s.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The fields of one stored step (only the requested ones are `Some`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StepFields {
    pub n: usize,
    pub t: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub u: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zeta: Option<Vec<f64>>,
    /// Per element, see [`Stress`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<Stress>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub von_mises: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<Vec<ContactNode>>,
}

/// The velocity sub-problem (3.13): its solver and work vectors.
struct VelocityPart {
    solver: VelocityStep,
    /// The velocity load over all DOFs (global, interleaved) ...
    load: Vec<f64>,
    /// ... and on the free DOFs.
    load_free: Vec<f64>,
    /// w_n on the free DOFs.
    w_free: Vec<f64>,
}

/// The damage sub-problem (3.10): its solver and work vectors.
struct DamagePart {
    solver: DamageStep,
    /// The linear term M ζ_{n−1}/k + F_{n−1}.
    g: Vec<f64>,
    /// The source vector F_{n−1}.
    f: Vec<f64>,
    /// ζ_n once solved; on entry the solver's starting point.
    next: Vec<f64>,
}

/// What the two sub-problems of step n read, borrowed from the [`Simulation`]: the data, the
/// discretisation, and the state at t_{n−1} with its per-element ε(u_{n−1}) and B_{n−1}.
struct StepInput<'a, const D: usize> {
    n: usize,
    k: f64,
    t: f64,
    problem: &'a Problem,
    mesh: &'a Mesh<D>,
    geo: &'a Geometry<D>,
    dofs: &'a DofMap<D>,
    settings: &'a SolverSettings,
    mass: &'a Csr,
    zeta_prev: &'a [f64],
    eps: &'a [Tensor<D>],
    b: &'a [Tensor<D>],
}

impl VelocityPart {
    /// The velocity step (3.13): w_n is the stationary point over V^h of
    /// E(w) = ½ (A ε(w), ε(w)) + (B_{n−1}, ε(w)) − (f_n, w) + Σ_i ω_i j(w_τ(x_i)),
    /// its minimiser when j is convex (unique under the smallness condition (2.31)).
    fn step<const D: usize>(&mut self, s: &StepInput<D>) -> Result<SolverReport, SolveError> {
        self.assemble_load(s)?;
        s.dofs.to_free(&self.load, &mut self.load_free);
        self.solver
            .solve(&self.load_free, &mut self.w_free, s.settings, s.n)
    }

    /// The velocity load, the linear part of (3.13): (f_n, ψ)_V − (B_{n−1}, ε(ψ))_Q for every
    /// nodal basis function ψ, with f_n of (2.23) from the body force f0 and the tractions f2
    /// at t_n. A load that is not finite is reported at the formula responsible.
    fn assemble_load<const D: usize>(&mut self, s: &StepInput<D>) -> Result<(), SolveError> {
        let load = &mut self.load;
        load.iter_mut().for_each(|v| *v = 0.0);
        loads::add_body_force(s.mesh, s.geo, &s.problem.body_force, s.t, load);
        loads::add_tractions(s.mesh, &s.problem.boundary, s.t, load);
        if load.iter().any(|v| !v.is_finite()) {
            return Err(load_fault(s.problem, s.mesh, s.t, s.n));
        }
        loads::add_stress_divergence(s.mesh, s.geo, s.b, load);
        Ok(())
    }
}

impl DamagePart {
    /// The damage step (3.10): ζ_n minimises ½ ζᵀ (M/k + κK) ζ − gᵀζ subject to
    /// 0 ≤ ζ_i ≤ 1 at every node, g from [`DamagePart::assemble_rhs`].
    fn step<const D: usize>(&mut self, s: &StepInput<D>) -> Result<SolverReport, SolveError> {
        self.assemble_rhs(s)?;
        self.solver.solve(&self.g, &mut self.next, s.settings, s.n)
    }

    /// g = M ζ_{n−1}/k + F_{n−1} with (F_{n−1})_i = ∫_Ω φ(ε(u_{n−1}), ζ_{n−1}) ψ_i dx: the
    /// backward difference (3.1) of ζ and the source of (3.10), both at step n−1. A source
    /// that overflows is reported at the coefficient responsible: the box QP of an infinite
    /// g has no solution, and its iterates would be NaN.
    fn assemble_rhs<const D: usize>(&mut self, s: &StepInput<D>) -> Result<(), SolveError> {
        let source = s
            .problem
            .damage
            .as_ref()
            .expect("damage part implies damage data")
            .source;
        loads::damage_source(
            s.mesh,
            s.geo,
            s.zeta_prev,
            |e, z| phi(&source, &s.eps[e], z),
            &mut self.f,
        );
        s.mass.mul_vec(s.zeta_prev, &mut self.g);
        for (g, f) in self.g.iter_mut().zip(&self.f) {
            *g = *g / s.k + f;
        }
        if self.g.iter().all(|g| g.is_finite()) {
            return Ok(());
        }
        let z = source.zeta_star;
        let pointer = if (source.a * (1.0 - z) / z).is_finite() {
            "/damage/source/b"
        } else {
            "/damage/source/a"
        };
        Err(SolveError::Data {
            pointer: pointer.into(),
            message: format!(
                "the damage source φ = a (1 − ζ)/ζ − b |ε(u)|² with a = {}, b = {}, ζ* = {} \
                 is not finite in step {} (its integral overflows); the damage equation \
                 (3.10) needs a finite source",
                source.a, source.b, source.zeta_star, s.n
            ),
        })
    }
}

/// The set-up that depends only on the mesh, the boundary, the viscosity and the friction law,
/// not on the time step: mesh, geometry, DOF numbering, the factored velocity operator, the
/// smallness estimate and the mass matrix. Cloning shares the velocity factor.
#[derive(Clone)]
pub struct Prepared<const D: usize = 2> {
    /// The linear path taken and its predicted peak bytes.
    pub linear: LinearPath,
    pub predicted_bytes: u64,
    /// The direct path's analysis of H's factor, made with K_II's for the prediction.
    damage_plan: Option<CholeskyPlan>,
    mesh: Mesh<D>,
    geo: Geometry<D>,
    dofs: DofMap<D>,
    velocity: VelocityStep,
    smallness: SmallnessReport,
    mass: Csr,
    /// Wall time it took.
    pub seconds: f64,
}

impl<const D: usize> Prepared<D> {
    /// Meshes, assembles and factors the velocity operator; estimates the smallness
    /// condition (2.31). No memory limit: the path is the scene's (`auto` as if unlimited).
    pub fn new(problem: &Problem) -> Result<Prepared<D>, SolveError> {
        Self::within(problem, None)
    }

    /// [`Prepared::new`] under a per-job memory limit: the linear path is chosen (or the run
    /// refused) from the predicted peak before anything is assembled, and on the direct path
    /// from the exact factor sizes before anything is factorised ([`memory::refine`]).
    pub fn within(problem: &Problem, memory_limit: Option<u64>) -> Result<Prepared<D>, SolveError> {
        let start = Instant::now();
        // A demanded direct path is decided on its exact factor sizes, once analysed.
        let first = match problem.linear {
            LinearPath::Direct => memory::without_factors(problem),
            _ => memory::predict(problem),
        };
        let (linear, predicted_bytes) = memory::choose_with(problem, memory_limit, first)?;
        match Self::on_path(problem, memory_limit, linear, predicted_bytes, start)? {
            Setup::Ready(p) => Ok(*p),
            Setup::Multigrid(bytes) => {
                match Self::on_path(problem, memory_limit, LinearPath::Multigrid, bytes, start)? {
                    Setup::Ready(p) => Ok(*p),
                    Setup::Multigrid(_) => unreachable!("only the direct path is refined"),
                }
            }
        }
    }

    fn on_path(
        problem: &Problem,
        memory_limit: Option<u64>,
        linear: LinearPath,
        mut predicted_bytes: u64,
        start: Instant,
    ) -> Result<Setup<D>, SolveError> {
        let mesh = problem.mesh().map_err(|e| SolveError::Data {
            pointer: format!("/boundary/{}", e.part()),
            message: e.to_string(),
        })?;
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::new(&mesh, &problem.boundary);
        let visc = problem.material.viscosity;
        // The multigrid path is the one for large meshes: it assembles into the pattern and
        // never holds the element triplets; the direct path keeps its summation order.
        let k = match linear {
            LinearPath::Multigrid => {
                assembly::viscous_stiffness_in_pattern(&mesh, &geo, &dofs, visc.eta, visc.xi)
            }
            _ => assembly::viscous_stiffness(&mesh, &geo, &dofs, visc.eta, visc.xi),
        };
        let n_i = dofs.n_interior;
        let k = Arc::new(k);
        let factor_error = |source| SolveError::Factor {
            what: "velocity",
            source,
        };
        // The direct path analyses H's pattern (M's) with K_II's before either is factorised.
        let mut mass = None;
        let mut damage_plan = None;
        // With a Γ3 the multigrid path builds one hierarchy, of K on all free DOFs: the slip
        // solver's, through which K_II is solved too (never copied).
        let full_space = linear == LinearPath::Multigrid && dofs.n_contact() > 0;
        let (k_ii, hierarchy) = if full_space {
            let (blocks, levels) = multilevel::velocity_levels(&mesh, &dofs, dofs.n_free());
            let h = Hierarchy::new(k.clone(), blocks, levels, Params::default())
                .map(Arc::new)
                .map_err(factor_error)?;
            let k_ii =
                LinearSolver::leading_block(h.clone(), k.clone(), n_i).map_err(factor_error)?;
            (k_ii, Some(h))
        } else if linear == LinearPath::Multigrid {
            let k_ii =
                multilevel::velocity_solver(&mesh, &dofs, k.block(0..n_i, 0..n_i), n_i, linear)
                    .map_err(factor_error)?;
            (k_ii, None)
        } else {
            let lower = k.block(0..n_i, 0..n_i).lower_csc();
            let plan = multilevel::direct_plan::<D>(lower.as_ref()).map_err(factor_error)?;
            let m = assembly::mass(&mesh, &geo);
            if problem.damage.is_some() {
                damage_plan = Some(DamageStep::plan(&m)?);
            }
            mass = Some(m);
            let plans: Vec<_> = std::iter::once(&plan).chain(&damage_plan).collect();
            let refined = memory::refine(problem, &plans);
            match memory::choose_with(problem, memory_limit, refined)? {
                (LinearPath::Multigrid, bytes) => return Ok(Setup::Multigrid(bytes)),
                (_, bytes) => predicted_bytes = bytes,
            }
            let factor = Cholesky::from_plan(plan, lower.as_ref()).map_err(factor_error)?;
            (LinearSolver::Direct(factor), None)
        };
        let mut velocity = VelocityStep::with_solver(
            k,
            &dofs,
            problem.friction.clone(),
            SchurPath::default(),
            k_ii,
        );
        if let Some(h) = hierarchy {
            velocity = velocity.with_hierarchy(h);
        }
        let smallness = smallness::check(problem, &mesh, &geo, &dofs, &mut velocity)?;
        let mass = mass.unwrap_or_else(|| assembly::mass_in_pattern(&mesh, &geo));
        Ok(Setup::Ready(Box::new(Prepared {
            linear,
            predicted_bytes,
            damage_plan,
            mesh,
            geo,
            dofs,
            velocity,
            smallness,
            mass,
            seconds: start.elapsed().as_secs_f64(),
        })))
    }
}

/// A set-up's outcome: ready, or (`auto`) to be made on the multigrid path with that
/// path's predicted bytes, what was built for the direct path dropped first.
enum Setup<const D: usize> {
    Ready(Box<Prepared<D>>),
    Multigrid(u64),
}

/// One job's assembled operators, factorisations and current state, in dimension D.
pub struct Simulation<const D: usize = 2> {
    pub problem: Problem,
    pub mesh: Mesh<D>,
    pub geo: Geometry<D>,
    pub dofs: DofMap<D>,
    pub settings: SolverSettings,
    pub smallness: SmallnessReport,
    pub state: State,
    /// w_n of the last step (global, interleaved).
    pub w: Vec<f64>,
    mass: Csr,
    velocity: VelocityPart,
    damage: Option<DamagePart>,
    /// Per-element ε(u_{n−1}) and B_{n−1} of the current step.
    eps: Vec<Tensor<D>>,
    b: Vec<Tensor<D>>,
    pub setup_seconds: f64,
    /// The linear path taken and its predicted peak bytes ([`crate::memory`]).
    pub linear: LinearPath,
    pub predicted_bytes: u64,
}

impl<const D: usize> Simulation<D> {
    /// Meshes, assembles and factors everything once; checks the smallness condition.
    pub fn new(problem: Problem, settings: SolverSettings) -> Result<Simulation<D>, SolveError> {
        let prepared = Prepared::within(&problem, settings.memory_limit)?;
        Simulation::from_prepared(problem, settings, prepared)
    }

    /// The set-up on a [`Prepared`] made for a problem with the same mesh, boundary,
    /// viscosity and friction law (only the time step, loads, damage data and outputs may
    /// differ): what runs of one study on one mesh do instead of factoring again.
    pub fn from_prepared(
        problem: Problem,
        settings: SolverSettings,
        prepared: Prepared<D>,
    ) -> Result<Simulation<D>, SolveError> {
        let start = Instant::now();
        let Prepared {
            linear,
            predicted_bytes,
            damage_plan,
            mesh,
            geo,
            dofs,
            velocity,
            smallness,
            mass,
            seconds: prepared_seconds,
        } = prepared;
        debug_assert_eq!(
            mesh.n_nodes(),
            problem.n_nodes(),
            "prepared for another mesh"
        );
        if !smallness.holds && problem.smallness == SmallnessPolicy::Refuse {
            let discrete = match smallness.discrete_margin {
                Some(m) if m > 0.0 => format!("each discrete velocity step is still strongly convex (margin {m:.4}), so \"smallness\": \"warn\" computes its unique solution"),
                _ => "the discrete velocity step is not strongly convex either: its stationary point may not be unique".to_string(),
            };
            return Err(SolveError::Smallness(format!(
                "c2τ·cτ² = {:.4} ≥ m_A = {:.4} (c2τ = {:.4}, cτ = {:.4}); {discrete}. Set \"smallness\": \"warn\" to run anyway.",
                smallness.lhs,
                smallness.m_a,
                smallness.c2,
                smallness.c_tau.unwrap_or(f64::NAN)
            )));
        }
        let nn = mesh.n_nodes();
        let (u, zeta) = initial_values(&problem, &mesh);
        let damage = match &problem.damage {
            Some(d) => {
                let laplacian = match linear {
                    LinearPath::Multigrid => assembly::laplacian_in_pattern_of(&mesh, &geo, &mass),
                    _ => assembly::laplacian(&mesh, &geo),
                };
                let h = assembly::combine(1.0 / problem.k(), &mass, d.kappa, &laplacian);
                drop(laplacian);
                let mut solver = match linear {
                    LinearPath::Multigrid => {
                        let mg = multilevel::scalar_solver(&mesh, h, linear).map_err(|source| {
                            SolveError::Factor {
                                what: "damage",
                                source,
                            }
                        })?;
                        DamageStep::multigrid(mg)?
                    }
                    _ => match damage_plan {
                        Some(plan) => DamageStep::with_plan(h, plan)?,
                        None => DamageStep::new(h)?,
                    },
                };
                solver.set_active_from(&zeta);
                Some(DamagePart {
                    solver,
                    g: vec![0.0; nn],
                    f: vec![0.0; nn],
                    next: zeta.clone(),
                })
            }
            None => None,
        };
        check_initial(&problem, &mesh, &u, &zeta)?;
        let nt = mesh.n_cells();
        let n_free = dofs.n_free();
        Ok(Simulation {
            state: State {
                step: 0,
                u,
                zeta,
                ..State::default()
            },
            w: vec![0.0; D * nn],
            mass,
            velocity: VelocityPart {
                solver: velocity,
                load: vec![0.0; D * nn],
                load_free: vec![0.0; n_free],
                w_free: vec![0.0; n_free],
            },
            damage,
            eps: vec![Tensor::zeros(); nt],
            b: vec![Tensor::zeros(); nt],
            setup_seconds: prepared_seconds + start.elapsed().as_secs_f64(),
            linear,
            predicted_bytes,
            problem,
            mesh,
            geo,
            dofs,
            settings,
            smallness,
        })
    }

    /// The state with the solvers' warm starts, for a checkpoint.
    pub fn checkpoint_state(&self) -> State {
        State {
            contact_velocity: self.velocity.solver.contact_velocity().to_vec(),
            damage_active: self
                .damage
                .as_ref()
                .map_or_else(Vec::new, |d| d.solver.active_codes()),
            ..self.state.clone()
        }
    }

    /// Continue from a checkpointed state (warm starts restored when present and of the
    /// right size, else rebuilt from ζ).
    pub fn restore(&mut self, mut state: State) {
        assert_eq!(state.u.len(), self.state.u.len());
        assert_eq!(state.zeta.len(), self.state.zeta.len());
        let warm = std::mem::take(&mut state.contact_velocity);
        if warm.len() == self.velocity.solver.n_contact() {
            self.velocity.solver.set_contact_velocity(&warm);
        }
        let active = std::mem::take(&mut state.damage_active);
        if let Some(d) = &mut self.damage {
            if !d.solver.set_active_codes(&active) {
                d.solver.set_active_from(&state.zeta);
            }
            d.next.copy_from_slice(&state.zeta);
        }
        self.state = state;
    }

    pub fn finished(&self) -> bool {
        self.state.step >= self.problem.steps
    }

    /// Advances one time step of Problem 3.1, from (u_{n−1}, ζ_{n−1}) only: B_{n−1}, then the
    /// velocity step (3.13) ∥ the damage step (3.10), then u_n and ζ_n, then the step's norms.
    pub fn step(&mut self) -> Result<StepReport, SolveError> {
        let n = self.state.step + 1;
        let k = self.problem.k();
        let t = n as f64 * k;
        self.history_stress();
        let (velocity, damage) = self.solve_sub_problems(n, k, t)?;
        self.advance(n, k);
        self.report(n, k, t, velocity, damage)
    }

    /// B_{n−1} = B(ε(u_{n−1}), ζ̄_{n−1}) on every element, the history term of (3.8) and (3.13),
    /// with ζ̄ the mean of ζ_{n−1} at the element's vertices (the P0 projection of (3.8) for
    /// the paper's B (4.1)); keeps ε(u_{n−1}), which the damage source φ reads too.
    fn history_stress(&mut self) {
        history_stress(
            &self.problem,
            &self.mesh,
            &self.geo,
            &self.state.u,
            &self.state.zeta,
            &mut self.eps,
            &mut self.b,
        );
    }

    /// The velocity step (3.13) ∥ the damage step (3.10) of step n: neither reads the other's
    /// result, so on large meshes the damage step runs on a second thread. A velocity error
    /// is reported before a damage error.
    fn solve_sub_problems(
        &mut self,
        n: usize,
        k: f64,
        t: f64,
    ) -> Result<(SolverReport, Option<SolverReport>), SolveError> {
        let parallel = self.damage.is_some() && self.mesh.n_nodes() >= PARALLEL_MIN_NODES;
        let input = StepInput {
            n,
            k,
            t,
            problem: &self.problem,
            mesh: &self.mesh,
            geo: &self.geo,
            dofs: &self.dofs,
            settings: &self.settings,
            mass: &self.mass,
            zeta_prev: &self.state.zeta,
            eps: &self.eps,
            b: &self.b,
        };
        let velocity = &mut self.velocity;
        let (v, d) = match self.damage.as_mut() {
            Some(d) if parallel => std::thread::scope(|s| {
                let h = s.spawn(|| d.step(&input));
                let v = velocity.step(&input);
                (v, Some(h.join().expect("damage thread panicked")))
            }),
            Some(d) => (velocity.step(&input), Some(d.step(&input))),
            None => (velocity.step(&input), None),
        };
        Ok((v?, d.transpose()?))
    }

    /// u_n = u_{n−1} + k w_n (3.12) and ζ_n from the damage step: the state moves to t_n.
    fn advance(&mut self, n: usize, k: f64) {
        self.dofs.to_global(&self.velocity.w_free, &mut self.w);
        for (u, w) in self.state.u.iter_mut().zip(&self.w) {
            *u += k * w;
        }
        if let Some(d) = &self.damage {
            self.state.zeta.copy_from_slice(&d.next);
        }
        self.state.step = n;
    }

    /// The report of step n: |w_n|_V and |u_n|_V (|v|_V = ‖ε(v)‖_L2(Ω)), |ζ_n|_Z0 =
    /// (ζ_nᵀ M ζ_n)^½, min ζ_n, the solvers' reports and the slipping Γ3 nodes. A norm that
    /// is not finite is an error.
    fn report(
        &self,
        n: usize,
        k: f64,
        t: f64,
        velocity: SolverReport,
        damage: Option<SolverReport>,
    ) -> Result<StepReport, SolveError> {
        // Both in one pass: ε(u_n) = ε(u_{n−1}) + k ε(w_n) per element.
        let (mut w2, mut u2) = (0.0, 0.0);
        for (e, eps) in self.eps.iter().enumerate() {
            let ew = self.geo.strain(&self.mesh, e, &self.w);
            w2 += self.geo.measure[e] * ew.norm_squared();
            u2 += self.geo.measure[e] * (eps + ew * k).norm_squared();
        }
        let mut scratch = vec![0.0; self.mesh.n_nodes()];
        let report = StepReport {
            n,
            t,
            w_v: w2.sqrt(),
            u_v: u2.sqrt(),
            zeta_l2: norms::mass_norm(&self.mass, &self.state.zeta, &mut scratch),
            zeta_min: self
                .state
                .zeta
                .iter()
                .cloned()
                .fold(f64::INFINITY, f64::min),
            velocity,
            damage,
            slip_nodes: self
                .velocity
                .solver
                .contact_velocity()
                .chunks(D - 1)
                .filter(|x| x.iter().any(|v| *v != 0.0))
                .count(),
        };
        if !(report.w_v.is_finite() && report.u_v.is_finite() && report.zeta_l2.is_finite()) {
            return Err(SolveError::NonFinite("solution", n));
        }
        Ok(report)
    }

    /// The requested fields of the step just computed (σ_n = A ε(w_n) + B_{n−1}, (3.8)).
    pub fn fields(&self) -> StepFields {
        let sel = self.problem.output.fields;
        let n = self.state.step;
        let need_sigma = sel.sigma || sel.von_mises;
        let sigma: Vec<Tensor<D>> = if need_sigma {
            (0..self.mesh.n_cells())
                .map(|e| {
                    viscous_stress(
                        &self.problem.material.viscosity,
                        &self.geo.strain(&self.mesh, e, &self.w),
                    ) + self.b[e]
                })
                .collect()
        } else {
            Vec::new()
        };
        let (sigma, von_mises) = stress_fields(&self.problem, &sigma);
        StepFields {
            n,
            t: n as f64 * self.problem.k(),
            u: sel.u.then(|| self.state.u.clone()),
            w: sel.w.then(|| self.w.clone()),
            zeta: sel.zeta.then(|| self.state.zeta.clone()),
            sigma,
            von_mises,
            contact: sel.contact.then(|| self.contact_state()),
        }
    }

    /// Stick/slip state of every Γ3 node after the last step.
    pub fn contact_state(&self) -> Vec<ContactNode> {
        let x = self.velocity.solver.contact_velocity();
        let force = self.velocity.solver.contact_force();
        let nd = D - 1;
        self.dofs
            .contact
            .chunks(nd)
            .enumerate()
            .map(|(i, c)| {
                let (xi, fi) = (&x[nd * i..nd * (i + 1)], &force[nd * i..nd * (i + 1)]);
                let weight = c[0].weight;
                let speed = xi.iter().map(|v| v * v).sum::<f64>().sqrt();
                let mut node = ContactNode {
                    node: c[0].node,
                    slip_velocity: xi[0],
                    friction_traction: fi[0] / weight,
                    bound: self.problem.friction.mu(speed),
                    slipping: xi.iter().any(|v| *v != 0.0),
                    tangential_velocity: None,
                    traction: None,
                };
                if D == 3 {
                    // Cartesian vectors from the tangent directions of the node's DOFs.
                    let cartesian = |v: &[f64]| -> [f64; 3] {
                        let mut out = [0.0; 3];
                        for (cd, &vi) in c.iter().zip(v) {
                            let t = self.dofs.direction(cd);
                            (0..D).for_each(|k| out[k] += vi * t[k]);
                        }
                        out
                    };
                    let f: Vec<f64> = fi.iter().map(|v| v / weight).collect();
                    node.slip_velocity = speed;
                    node.friction_traction = f.iter().map(|v| v * v).sum::<f64>().sqrt();
                    node.tangential_velocity = Some(cartesian(xi));
                    node.traction = Some(cartesian(&f));
                }
                node
            })
            .collect()
    }

    /// "direct (Cholesky)" or "multigrid (smoothed aggregation, 4 levels)": how the
    /// velocity (and damage) systems are solved.
    pub fn linear_solver(&self) -> String {
        self.velocity.solver.linear_solver().describe()
    }

    /// Krylov iterations of the last step's velocity and damage solves.
    pub fn krylov_iterations(&self) -> (usize, usize) {
        (
            self.velocity.solver.krylov_iterations(),
            self.damage
                .as_ref()
                .map_or(0, |d| d.solver.krylov_iterations()),
        )
    }

    /// Dimension and factor size of the velocity system (interior DOFs).
    pub fn velocity_factor_size(&self) -> (usize, usize) {
        self.velocity.solver.factor_size()
    }

    /// How a slipping velocity step is (or was) solved.
    pub fn slip_solver(&self) -> super::velocity::ContactSolver {
        self.velocity.solver.slip_solver()
    }

    /// How the velocity step forms its Schur complement onto Γ3.
    pub fn schur_path(&self) -> crate::linalg::SchurPath {
        self.velocity.solver.schur_path()
    }

    /// The free-DOF velocity operator K (interior DOFs first) and the number of interior
    /// DOFs (for benchmarks of its factorisation).
    pub fn velocity_operator(&self) -> (&Csr, usize) {
        self.velocity.solver.operator()
    }

    /// One forward+backward substitution with the velocity factor on a copy of the current
    /// load (the unit of the benchmark's per-step ratio).
    pub fn time_one_substitution(&mut self) -> f64 {
        let mut v = self.velocity.load_free[..self.dofs.n_interior].to_vec();
        let start = Instant::now();
        self.velocity.solver.substitute(&mut v);
        start.elapsed().as_secs_f64()
    }

    /// `count` products with the free-DOF velocity operator K on the current load, each timed
    /// alone into one output buffer written once before (so no page faults are timed): the
    /// unit of the benchmark's matvec-equivalents.
    pub fn time_products(&self, count: usize) -> Vec<f64> {
        let (k, _) = self.velocity.solver.operator();
        let x = &self.velocity.load_free;
        let mut y = vec![0.0; k.nrows];
        k.mul_vec(x, &mut y);
        (0..count)
            .map(|_| {
                let start = Instant::now();
                k.mul_vec(x, &mut y);
                let secs = start.elapsed().as_secs_f64();
                std::hint::black_box(&y);
                secs
            })
            .collect()
    }

    /// Damage refactorisations so far (0 without damage).
    pub fn damage_refactorizations(&self) -> usize {
        self.damage
            .as_ref()
            .map_or(0, |d| d.solver.refactorizations)
    }
}

/// The initial state (t_0 = 0) as the fields of step 0, for output: the requested ones of
/// u_0 and ζ_0 (the nodal interpolants the run starts from, (3.11)), w_0 = 0 (the velocity
/// before the first step; the scheme never uses it) and σ_0 = A ε(w_0) + B(ε(u_0), ζ̄_0) =
/// B_0, the history stress the first step reads ((3.8) with w_0 = 0), with its von Mises
/// stress. There is no contact state before the first step: `contact` is `None` even when
/// requested. Needs no factorisation: cheap enough to derive on request.
pub fn initial_fields<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
) -> Result<StepFields, SolveError> {
    let (u, zeta) = initial_values(problem, mesh);
    check_initial(problem, mesh, &u, &zeta)?;
    let sel = problem.output.fields;
    let (sigma, von_mises) = if sel.sigma || sel.von_mises {
        let nt = mesh.n_cells();
        let mut eps = vec![Tensor::zeros(); nt];
        let mut b = vec![Tensor::zeros(); nt];
        history_stress(
            problem,
            mesh,
            &Geometry::new(mesh),
            &u,
            &zeta,
            &mut eps,
            &mut b,
        );
        stress_fields(problem, &b)
    } else {
        (None, None)
    };
    Ok(StepFields {
        n: 0,
        t: 0.0,
        w: sel.w.then(|| vec![0.0; u.len()]),
        u: sel.u.then_some(u),
        zeta: sel.zeta.then_some(zeta),
        sigma,
        von_mises,
        contact: None,
    })
}

/// [`initial_fields`] on a mesh of either dimension.
pub fn initial_fields_of(problem: &Problem, mesh: &AnyMesh) -> Result<StepFields, SolveError> {
    match mesh {
        AnyMesh::Plane(m) => initial_fields(problem, m),
        AnyMesh::Solid(m) => initial_fields(problem, m),
    }
}

/// u_0 (interleaved per node) and ζ_0 (per node; ≡ 1 without damage): the nodal
/// interpolants of the scene's `initial.u0` and `damage.zeta0` at t = 0, (3.11).
fn initial_values<const D: usize>(problem: &Problem, mesh: &Mesh<D>) -> (Vec<f64>, Vec<f64>) {
    let zeta: Vec<f64> = match &problem.damage {
        Some(d) => mesh.nodes.iter().map(|p| d.zeta0.at(p, 0.0)).collect(),
        None => vec![1.0; mesh.n_nodes()],
    };
    let u: Vec<f64> = mesh
        .nodes
        .iter()
        .flat_map(|p| problem.u0.at(p, 0.0))
        .collect();
    (u, zeta)
}

/// ε(u)|_T and B(ε(u), ζ̄)|_T on every element, ζ̄ the mean of ζ at the element's vertices
/// (the P0 projection of (3.8) for the paper's B (4.1)).
fn history_stress<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    u: &[f64],
    zeta: &[f64],
    eps: &mut [Tensor<D>],
    b: &mut [Tensor<D>],
) {
    for (e, eps) in eps.iter_mut().enumerate() {
        *eps = geo.strain(mesh, e, u);
    }
    let elasticity = problem.material.elasticity;
    for (e, cell) in mesh.cells().enumerate() {
        let zbar = cell.iter().map(|&n| zeta[n]).sum::<f64>() / (D + 1) as f64;
        b[e] = elastic_stress(&elasticity, &eps[e], zbar);
    }
}

/// The requested `sigma` ([`Stress`]) and `von_mises` of per-element stresses.
fn stress_fields<const D: usize>(
    problem: &Problem,
    sigma: &[Tensor<D>],
) -> (Option<Stress>, Option<Vec<f64>>) {
    let sel = problem.output.fields;
    (
        sel.sigma.then(|| match D {
            2 => Stress::Plane(
                sigma
                    .iter()
                    .map(|s| [s[(0, 0)], s[(1, 1)], s[(0, 1)]])
                    .collect(),
            ),
            _ => Stress::Solid(
                sigma
                    .iter()
                    .map(|s| {
                        [
                            s[(0, 0)],
                            s[(1, 1)],
                            s[(2, 2)],
                            s[(0, 1)],
                            s[(1, 2)],
                            s[(0, 2)],
                        ]
                    })
                    .collect(),
            ),
        }),
        sel.von_mises.then(|| sigma.iter().map(von_mises).collect()),
    )
}

/// Where a formula meets the scheme: the scene's sampling check (a small grid at t = 0, T/2,
/// T) cannot see every node, quadrature point and time node, so the data are checked again
/// where they are used, and a bad value is reported at the field's JSON pointer.
fn formula_text(f: &crate::problem::ScalarField) -> String {
    match f {
        crate::problem::ScalarField::Const(c) => c.to_string(),
        crate::problem::ScalarField::Expr(e) => format!("\"{}\"", e.source()),
    }
}

/// u0 finite and ζ0 in [0, 1] at every node.
fn check_initial<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
    u: &[f64],
    zeta: &[f64],
) -> Result<(), SolveError> {
    for (i, p) in mesh.nodes.iter().enumerate() {
        for c in 0..D {
            let v = u[D * i + c];
            if !v.is_finite() {
                return Err(SolveError::Data {
                    pointer: format!("/initial/u0/{c}"),
                    message: format!(
                        "{} evaluates to {v} at the node {}; the initial displacement must \
                         be finite at every node",
                        formula_text(&problem.u0.0[c]),
                        at_point(p)
                    ),
                });
            }
        }
        if let Some(d) = &problem.damage {
            let z = zeta[i];
            if !(0.0..=1.0).contains(&z) {
                return Err(SolveError::Data {
                    pointer: "/damage/zeta0".into(),
                    message: format!(
                        "{} evaluates to {z} at the node {}; the initial damage must be in \
                         [0, 1] (1 = intact) at every node",
                        formula_text(&d.zeta0),
                        at_point(p)
                    ),
                });
            }
        }
    }
    Ok(())
}

/// The error for a non-finite load vector at step n: the field and point responsible.
fn load_fault<const D: usize>(problem: &Problem, mesh: &Mesh<D>, t: f64, n: usize) -> SolveError {
    use crate::problem::BoundaryKind;
    let Some(f) = loads::find_non_finite(mesh, &problem.body_force, &problem.boundary, t) else {
        // Finite values whose integrals overflow.
        return SolveError::NonFinite("load vector", n);
    };
    let (pointer, field) = match f.part {
        None => (
            format!("/loads/f0/{}", f.component),
            &problem.body_force.0[f.component],
        ),
        Some(p) => match &problem.boundary[p].kind {
            BoundaryKind::Traction(f2) => (
                format!("/boundary/{p}/f2/{}", f.component),
                &f2.0[f.component],
            ),
            _ => return SolveError::NonFinite("load vector", n),
        },
    };
    SolveError::Data {
        pointer,
        message: format!(
            "{} evaluates to {} at {}, a quadrature point of time step {n}; loads must be \
             finite on the whole domain and time interval",
            formula_text(field),
            f.value,
            match D {
                2 => format!("(x, y, t) = ({}, {}, {t})", f.at[0], f.at[1]),
                _ => format!(
                    "(x, y, z, t) = ({}, {}, {}, {t})",
                    f.at[0], f.at[1], f.at[2]
                ),
            }
        ),
    }
}

/// "(x, y) = (…, …)" or "(x, y, z) = (…, …, …)" for messages.
fn at_point<const D: usize>(p: &[f64; D]) -> String {
    let names = ["x", "y", "z"][..D].join(", ");
    let values: Vec<String> = p.iter().map(|v| v.to_string()).collect();
    format!("({names}) = ({})", values.join(", "))
}
