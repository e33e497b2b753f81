//! Problem 3.1's time step ([`crate::run::Run`] loops over them). For n = 1..N, from
//! (u_{n−1}, ζ_{n−1}) only ([`Simulation::step`]):
//! 1. B_{n−1} = B(ε(u_{n−1}), ζ_{n−1}) per element (3.8);
//! 2. velocity load and velocity step (3.13) → w_n  ∥  damage step (3.10) → ζ_n;
//! 3. u_n = u_{n−1} + k w_n (3.12);
//! 4. the step's norms; σ_n = A ε(w_n) + B_{n−1} (3.8) only when stored ([`Simulation::fields`]).
//!
//! The two sub-problems of step 2 are independent and run beside each other (`rayon::join`
//! in the run's pool, [`crate::linalg::par`]) when the run has more than one thread and the
//! mesh is large enough to pay for it. Physics absent from the scene is not computed: no damage block → ζ ≡ 1
//! and no damage solve; no Γ3 → a single linear solve per step.
//!
//! The set-up before the first step (mesh, operators, solvers, the initial state) is in
//! `setup.rs`; what a step stores and reports beyond its norms (fields, the contact state,
//! stresses, the initial fields) in `output.rs`.

mod output;
mod setup;

pub use output::{initial_fields, initial_fields_of, ContactNode, StepFields, Stress};
pub use setup::Prepared;

use super::damage::DamageStep;
use super::smallness::SmallnessReport;
use super::velocity::VelocityStep;
use super::{SolveError, SolverReport, SolverSettings};
use crate::a_posteriori::{Estimator, Parts, StepData, StepEstimate};
use crate::fem::{loads, norms, CellTensors, DofMap, Geometry, NodeCells};
use crate::laws::constitutive::elastic_stress;
use crate::laws::damage_source::phi;
use crate::laws::Tensor;
use crate::linalg::{par, Csr, LinearPath};
use crate::mesh::locality::Numbering;
use crate::mesh::{Mesh, SharedMesh};
use crate::problem::Elasticity;
use crate::problem::Problem;
use setup::formula_text;
use std::sync::Arc;

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
    /// ζ_{n−1}, from which the damage step's starting point is extrapolated (empty: none),
    /// so that a resumed run on the multigrid path starts its damage solves where the
    /// uninterrupted one does.
    #[serde(default)]
    pub damage_before: Vec<f64>,
    /// w_n (global, interleaved) when the run estimates its error (empty otherwise): the
    /// next step's time indicator reads it, so a resumed run estimates as an uninterrupted
    /// one does.
    #[serde(default)]
    pub w: Vec<f64>,
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
    /// The step's a posteriori estimate ([`crate::a_posteriori`]), when the scene's output
    /// asks for it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<Parts>,
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
    /// The source vector F_{n−1} ([`loads::damage_source`]).
    f: Vec<f64>,
    /// ζ_n once solved; on entry ζ_{n−1}, from which the starting point is predicted.
    next: Vec<f64>,
    /// ζ_{n−2} (empty at the start and after a resume: no prediction then).
    before: Vec<f64>,
}

/// What the two sub-problems of step n read, borrowed from the [`Simulation`]: the data, the
/// discretisation, and the state at t_{n−1} with its per-element B_{n−1}.
struct StepInput<'a, const D: usize> {
    n: usize,
    k: f64,
    t: f64,
    problem: &'a Problem,
    mesh: &'a Mesh<D>,
    geo: &'a Geometry<D>,
    cells: &'a NodeCells,
    dofs: &'a DofMap<D>,
    settings: &'a SolverSettings,
    mass: &'a Csr,
    /// u_{n−1} and ζ_{n−1} (global, interleaved; per node).
    u_prev: &'a [f64],
    zeta_prev: &'a [f64],
    /// B_{n−1} of every cell where the run keeps it, else formed where it is read.
    b: Option<&'a CellTensors<D>>,
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
        par::fill(load, 0.0);
        loads::add_body_force(s.mesh, s.geo, &s.problem.body_force, s.t, load);
        loads::add_tractions(s.mesh, &s.problem.boundary, s.t, load);
        if load.iter().any(|v| !v.is_finite()) {
            return Err(load_fault(s.problem, s.mesh, s.t, s.n));
        }
        match s.b {
            Some(b) => loads::add_stress_divergence(s.cells, s.geo, |e| b.get(e), load),
            None => {
                let elasticity = &s.problem.material.elasticity;
                let b = |e| history_stress_of(elasticity, s.mesh, s.geo, s.u_prev, s.zeta_prev, e);
                loads::add_stress_divergence(s.cells, s.geo, b, load)
            }
        }
        Ok(())
    }
}

impl DamagePart {
    /// The damage step (3.10): ζ_n minimises ½ ζᵀ (M/k + κK) ζ − gᵀζ subject to
    /// 0 ≤ ζ_i ≤ 1 at every node, g from [`DamagePart::assemble_rhs`].
    fn step<const D: usize>(&mut self, s: &StepInput<D>) -> Result<SolverReport, SolveError> {
        self.assemble_rhs(s)?;
        self.predict();
        self.solver.solve(&self.g, &mut self.next, s.settings, s.n)
    }

    /// The starting point of an iterative damage solve: ζ_{n−1} + (ζ_{n−1} − ζ_{n−2}) in
    /// [0, 1], the linear extrapolation in time, a residual O(k²) from ζ_n where ζ_{n−1} is
    /// O(k) from it. On the multigrid path CG starts closer (`benches/part` at 23k nodes: 11.0
    /// iterations a step on average, 9.6 with it) where the solver has no earlier solutions
    /// of the step's masked system to project onto; a direct solve overwrites it, so the
    /// direct path's numbers are unchanged.
    fn predict(&mut self) {
        if self.before.len() != self.next.len() {
            self.before.clone_from(&self.next);
            return;
        }
        for (z, b) in self.next.iter_mut().zip(&mut self.before) {
            let last = *z;
            *z = (2.0 * last - *b).clamp(0.0, 1.0);
            *b = last;
        }
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
            s.cells,
            s.geo,
            s.zeta_prev,
            |e| s.geo.strain(s.mesh, e, s.u_prev),
            |eps, z| phi(&source, eps, z),
            &mut self.f,
        );
        s.mass.mul_vec(s.zeta_prev, &mut self.g);
        par::zip_apply(&mut self.g, &self.f, |g, f| g / s.k + f);
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

/// One job's assembled operators, factorisations and current state, in dimension D.
pub struct Simulation<const D: usize = 2> {
    pub problem: Problem,
    /// The mesh the scheme runs on ([`Problem::mesh`]), shared with the problem's body
    /// where it is not refined; every vector of the run is in its numbering.
    pub mesh: SharedMesh<D>,
    /// How `mesh` relates to the mesh outputs and checkpoints are given on
    /// ([`Problem::any_mesh`]), where the two differ: [`Simulation::fields`],
    /// [`Simulation::checkpoint_state`] and [`Simulation::restore`] map through it.
    numbering: Option<Arc<Numbering>>,
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
    /// Per-element B_{n−1} of the current step where outputs read it after the step
    /// ([`crate::problem::OutputSpec::keeps_history_stress`]): 48 bytes a tetrahedron, 21 MB
    /// of the 441k-cell part. Otherwise the velocity load forms it where it reads it, as
    /// ε(u_{n−1}) is formed again where it is read (the damage source, the norms).
    b: Option<CellTensors<D>>,
    /// The a posteriori estimator when the scene's output asks for it, with the cell
    /// indicators of the last step.
    estimator: Option<Box<Estimator<D>>>,
    estimate: Option<StepEstimate>,
    /// w_{n−1} while the estimate of step n is computed (empty without an estimator), and
    /// whether `w` holds the last step's velocity (not before the first step, nor after a
    /// restore from a state without it): the time indicator is 0 where it does not.
    w_prev: Vec<f64>,
    w_known: bool,
    /// The cells around each node: the element scatters of a step gather over them.
    cells: NodeCells,
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

    /// The state with the solvers' warm starts, for a checkpoint, in the numbering of the
    /// output mesh.
    pub fn checkpoint_state(&self) -> State {
        let state = State {
            contact_velocity: self.velocity.solver.contact_velocity().to_vec(),
            damage_active: self
                .damage
                .as_ref()
                .map_or_else(Vec::new, |d| d.solver.active_codes()),
            damage_before: self
                .damage
                .as_ref()
                .map_or_else(Vec::new, |d| d.before.clone()),
            w: match self.estimator {
                Some(_) if self.state.step > 0 => self.w.clone(),
                _ => Vec::new(),
            },
            ..self.state.clone()
        };
        self.renumbered(state, false)
    }

    /// `state` from the output mesh's numbering into the run's (`into_run`), or back: the
    /// per-node vectors permuted, and the Γ3 warm start reordered by the output numbering of
    /// its nodes (the order of a run on the mesh as given).
    fn renumbered(&self, state: State, into_run: bool) -> State {
        let Some(numbering) = &self.numbering else {
            return state;
        };
        fn nodes<T: Copy>(n: &Numbering, v: Vec<T>, width: usize, into_run: bool) -> Vec<T> {
            match (v.is_empty(), into_run) {
                (true, _) => v,
                (false, true) => n.nodes_forward(&v, width),
                (false, false) => n.nodes_back(&v, width),
            }
        }
        // The run's Γ3 nodes (in its contact order) by their output index.
        let nd = D - 1;
        let mut by_output: Vec<usize> = (0..self.dofs.contact.len() / nd.max(1)).collect();
        by_output.sort_by_key(|&i| numbering.node[self.dofs.contact[nd * i].node]);
        let warm = &state.contact_velocity;
        let mut contact_velocity = warm.clone();
        if warm.len() == self.dofs.contact.len() {
            for (j, &i) in by_output.iter().enumerate() {
                let (run, out) = (nd * i..nd * (i + 1), nd * j..nd * (j + 1));
                match into_run {
                    true => contact_velocity[run].copy_from_slice(&warm[out]),
                    false => contact_velocity[out].copy_from_slice(&warm[run]),
                }
            }
        }
        State {
            step: state.step,
            u: nodes(numbering, state.u, D, into_run),
            zeta: nodes(numbering, state.zeta, 1, into_run),
            contact_velocity,
            damage_active: nodes(numbering, state.damage_active, 1, into_run),
            damage_before: nodes(numbering, state.damage_before, 1, into_run),
            w: nodes(numbering, state.w, D, into_run),
        }
    }

    /// Continue from a checkpointed state, given in the numbering of the output mesh (warm
    /// starts restored when present and of the right size, else rebuilt from ζ).
    pub fn restore(&mut self, state: State) {
        let mut state = self.renumbered(state, true);
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
            d.before = std::mem::take(&mut state.damage_before);
            if d.before.len() != d.next.len() {
                d.before.clear();
            }
        }
        state.damage_before.clear();
        let w = std::mem::take(&mut state.w);
        self.w_known = w.len() == self.w.len();
        if self.w_known {
            self.w = w;
        }
        self.state = state;
    }

    pub fn finished(&self) -> bool {
        self.state.step >= self.problem.steps
    }

    /// The a posteriori estimate of the last step, when the scene's output asks for one.
    pub fn step_estimate(&self) -> Option<&StepEstimate> {
        self.estimate.as_ref()
    }

    /// Advances one time step of Problem 3.1, from (u_{n−1}, ζ_{n−1}) only: B_{n−1}, then the
    /// velocity step (3.13) ∥ the damage step (3.10), then u_n and ζ_n, then the step's norms.
    pub fn step(&mut self) -> Result<StepReport, SolveError> {
        let n = self.state.step + 1;
        let k = self.problem.k();
        let t = n as f64 * k;
        self.history_stress();
        let (velocity, damage) = self.solve_sub_problems(n, k, t)?;
        let norms = self.advance(n, k);
        self.report(n, t, norms, velocity, damage)
    }

    /// B_{n−1} = B(ε(u_{n−1}), ζ̄_{n−1}) on every element, the history term of (3.8) and (3.13),
    /// with ζ̄ the mean of ζ_{n−1} at the element's vertices (the P0 projection of (3.8) for
    /// the paper's B (4.1)).
    fn history_stress(&mut self) {
        history_stress(
            &self.problem,
            &self.mesh,
            &self.geo,
            &self.state.u,
            &self.state.zeta,
            self.b.as_mut(),
        );
    }

    /// The velocity step (3.13) ∥ the damage step (3.10) of step n: neither reads the other's
    /// result, so on large meshes they share the run's threads. A velocity error
    /// is reported before a damage error.
    fn solve_sub_problems(
        &mut self,
        n: usize,
        k: f64,
        t: f64,
    ) -> Result<(SolverReport, Option<SolverReport>), SolveError> {
        let parallel = self.mesh.n_nodes() >= PARALLEL_MIN_NODES && par::current_threads() > 1;
        let input = StepInput {
            n,
            k,
            t,
            problem: &self.problem,
            mesh: &self.mesh,
            geo: &self.geo,
            cells: &self.cells,
            dofs: &self.dofs,
            settings: &self.settings,
            mass: &self.mass,
            u_prev: &self.state.u,
            zeta_prev: &self.state.zeta,
            b: self.b.as_ref(),
        };
        let velocity = &mut self.velocity;
        let (v, d) = match self.damage.as_mut() {
            Some(d) if parallel => {
                let (v, d) = rayon::join(|| velocity.step(&input), || d.step(&input));
                (v, Some(d))
            }
            Some(d) => (velocity.step(&input), Some(d.step(&input))),
            None => (velocity.step(&input), None),
        };
        Ok((v?, d.transpose()?))
    }

    /// u_n = u_{n−1} + k w_n (3.12) and ζ_n from the damage step: the state moves to t_n.
    /// A run that estimates its error does so in between, while w_{n−1}, u_{n−1} and ζ_{n−1}
    /// are at hand, and so are |w_n|_V and |u_n|_V (returned, in that order), from
    /// ε(u_n) = ε(u_{n−1}) + k ε(w_n) per element.
    fn advance(&mut self, n: usize, k: f64) -> (f64, f64) {
        if self.estimator.is_some() {
            std::mem::swap(&mut self.w, &mut self.w_prev);
        }
        self.dofs.to_global(&self.velocity.w_free, &mut self.w);
        if let Some(estimator) = &self.estimator {
            let zeta = match &self.damage {
                Some(d) => &d.next,
                None => &self.state.zeta,
            };
            let data = StepData {
                t: n as f64 * k,
                k,
                m_a: self.smallness.m_a,
                w: &self.w,
                w_prev: self.w_known.then_some(self.w_prev.as_slice()),
                b: self.b.as_ref().expect("an estimate keeps B_{n−1}"),
                u_prev: &self.state.u,
                zeta_prev: &self.state.zeta,
                zeta,
            };
            self.estimate = Some(estimator.step(&self.problem, &self.mesh, &self.geo, &data));
            self.w_known = true;
        }
        // Chunk partials added in chunk order: the same bits for any thread count.
        let (w2, u2) = par::map_ranges(self.mesh.n_cells(), par::VECTOR_CHUNK, |cells| {
            let (mut w2, mut u2) = (0.0, 0.0);
            for e in cells {
                let [ew, eu] = self.geo.strains(&self.mesh, e, [&self.w, &self.state.u]);
                w2 += self.geo.measure(e) * ew.norm_squared();
                u2 += self.geo.measure(e) * (eu + ew * k).norm_squared();
            }
            (w2, u2)
        })
        .into_iter()
        .fold((0.0, 0.0), |(a, b), (w, u)| (a + w, b + u));
        par::zip_apply(&mut self.state.u, &self.w, |u, w| u + k * w);
        if let Some(d) = &self.damage {
            self.state.zeta.copy_from_slice(&d.next);
        }
        self.state.step = n;
        (w2.sqrt(), u2.sqrt())
    }

    /// The report of step n: |w_n|_V and |u_n|_V (|v|_V = ‖ε(v)‖_L2(Ω); `norms`, from
    /// [`Simulation::advance`]), |ζ_n|_Z0 = (ζ_nᵀ M ζ_n)^½, min ζ_n, the solvers' reports and
    /// the slipping Γ3 nodes. A norm that is not finite is an error.
    fn report(
        &self,
        n: usize,
        t: f64,
        (w_v, u_v): (f64, f64),
        velocity: SolverReport,
        damage: Option<SolverReport>,
    ) -> Result<StepReport, SolveError> {
        let mut scratch = vec![0.0; self.mesh.n_nodes()];
        let report = StepReport {
            n,
            t,
            w_v,
            u_v,
            zeta_l2: norms::mass_norm(&self.mass, &self.state.zeta, &mut scratch),
            zeta_min: par::min(&self.state.zeta),
            velocity,
            damage,
            slip_nodes: self
                .velocity
                .solver
                .contact_velocity()
                .chunks(D - 1)
                .filter(|x| x.iter().any(|v| *v != 0.0))
                .count(),
            estimate: self.estimate.as_ref().map(|e| e.parts),
        };
        if !(report.w_v.is_finite() && report.u_v.is_finite() && report.zeta_l2.is_finite()) {
            return Err(SolveError::NonFinite("solution", n));
        }
        Ok(report)
    }
}

/// B(ε(u), ζ̄)|_T on every element into `b` where the run keeps it
/// ([`history_stress_of`]).
fn history_stress<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    u: &[f64],
    zeta: &[f64],
    b: Option<&mut CellTensors<D>>,
) {
    if let Some(b) = b {
        let elasticity = &problem.material.elasticity;
        b.fill(|e| history_stress_of(elasticity, mesh, geo, u, zeta, e));
    }
}

/// B(ε(u), ζ̄)|_T on element e, ζ̄ the mean of ζ at the element's vertices (the P0
/// projection of (3.8) for the paper's B (4.1)).
fn history_stress_of<const D: usize>(
    elasticity: &Elasticity,
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    u: &[f64],
    zeta: &[f64],
    e: usize,
) -> Tensor<D> {
    let zbar = mesh.cell(e).iter().map(|&n| zeta[n]).sum::<f64>() / (D + 1) as f64;
    elastic_stress(elasticity, &geo.strain(mesh, e, u), zbar)
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

#[cfg(test)]
mod tests;
