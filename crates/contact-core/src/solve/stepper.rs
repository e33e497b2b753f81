//! Problem 3.1's time loop. For n = 1..N, from (u_{n−1}, ζ_{n−1}) only:
//! 1. velocity (3.13) → w_n;     2. u_n = u_{n−1} + k w_n (3.12);
//! 3. damage (3.10) → ζ_n;       4. σ_n = A ε(w_n) + B_{n−1} (3.8), only when stored.
//!
//! Steps 1 and 3 are independent and run on two threads for meshes large enough to pay for
//! it. Physics absent from the scene is not computed: no damage block → ζ ≡ 1 and no damage
//! solve; no Γ3 → a single linear solve per step.

use super::damage::DamageStep;
use super::smallness::{self, SmallnessReport};
use super::velocity::VelocityStep;
use super::{SolveError, SolverReport, SolverSettings};
use crate::fem::{assembly, loads, norms, DofMap, Geometry};
use crate::laws::constitutive::{elastic_stress, viscous_stress, von_mises};
use crate::laws::damage_source::phi;
use crate::laws::Tensor2;
use crate::linalg::Csr;
use crate::mesh::Mesh;
use crate::problem::{Problem, SmallnessPolicy};
use std::time::Instant;

/// Below this many nodes the two sub-problems run one after the other (thread hand-off
/// would cost more than it saves).
const PARALLEL_MIN_NODES: usize = 3000;

/// The state at a time node: all that is needed to continue (a checkpoint).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct State {
    /// Index n of the time node t_n = n k.
    pub step: usize,
    /// Displacement u_n, interleaved (x, y) per node.
    pub u: Vec<f64>,
    /// Damage ζ_n per node.
    pub zeta: Vec<f64>,
    /// Warm starts of the two sub-problem solvers after step n, filled only by
    /// [`Simulation::checkpoint_state`] (empty otherwise): the tangential velocities on Γ3
    /// and the damage active set (0 free, 1 at ζ = 0, 2 at ζ = 1). Restoring them makes a
    /// resumed run repeat an uninterrupted one bit for bit; without them it agrees to the
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

/// Contact state at a Γ3 DOF.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ContactNode {
    pub node: usize,
    /// Tangential velocity w_τ.
    pub slip_velocity: f64,
    /// Friction traction density: the discrete friction force divided by ω_i.
    pub friction_traction: f64,
    /// The bound μ(|w_τ|) the traction is compared with.
    pub bound: f64,
    pub slipping: bool,
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
    /// Per triangle (σ_xx, σ_yy, σ_xy).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<Vec<[f64; 3]>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub von_mises: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<Vec<ContactNode>>,
}

struct DamagePart {
    solver: DamageStep,
    g: Vec<f64>,
    f: Vec<f64>,
    next: Vec<f64>,
}

/// The set-up that depends only on the mesh, the boundary, the viscosity and the friction law,
/// not on the time step: mesh, geometry, DOF numbering, the factored velocity operator, the
/// smallness estimate and the mass matrix. Cloning shares the velocity factor.
#[derive(Clone)]
pub struct Prepared {
    mesh: Mesh,
    geo: Geometry,
    dofs: DofMap,
    velocity: VelocityStep,
    smallness: SmallnessReport,
    mass: Csr,
    /// Wall time it took.
    pub seconds: f64,
}

impl Prepared {
    /// Meshes, assembles and factors the velocity operator; estimates the smallness
    /// condition (2.31).
    pub fn new(problem: &Problem) -> Result<Prepared, SolveError> {
        let start = Instant::now();
        let (nx, ny) = problem.cells();
        let mut mesh = Mesh::rectangle(problem.width, problem.height, nx, ny, problem.pattern);
        let segments: Vec<_> = problem.boundary.iter().map(|p| p.segment).collect();
        mesh.tag_boundary(&segments);
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::new(&mesh, &problem.boundary);
        let visc = problem.material.viscosity;
        let k = assembly::viscous_stiffness(&mesh, &geo, &dofs, visc.eta, visc.xi);
        let mut velocity = VelocityStep::new(k, &dofs, problem.friction.clone())?;
        let smallness = smallness::check(problem, &mesh, &geo, &dofs, &mut velocity)?;
        let mass = assembly::mass(&mesh, &geo);
        Ok(Prepared {
            mesh,
            geo,
            dofs,
            velocity,
            smallness,
            mass,
            seconds: start.elapsed().as_secs_f64(),
        })
    }
}

/// One job's assembled operators, factorisations and current state.
pub struct Simulation {
    pub problem: Problem,
    pub mesh: Mesh,
    pub geo: Geometry,
    pub dofs: DofMap,
    pub settings: SolverSettings,
    pub smallness: SmallnessReport,
    pub state: State,
    /// w_n of the last step (global, interleaved).
    pub w: Vec<f64>,
    mass: Csr,
    velocity: VelocityStep,
    damage: Option<DamagePart>,
    /// Per-element ε(u_{n−1}) and B_{n−1} of the current step.
    eps: Vec<Tensor2<f64>>,
    b: Vec<Tensor2<f64>>,
    load: Vec<f64>,
    load_free: Vec<f64>,
    w_free: Vec<f64>,
    pub setup_seconds: f64,
}

impl Simulation {
    /// Meshes, assembles and factors everything once; checks the smallness condition.
    pub fn new(problem: Problem, settings: SolverSettings) -> Result<Simulation, SolveError> {
        let prepared = Prepared::new(&problem)?;
        Simulation::from_prepared(problem, settings, prepared)
    }

    /// The set-up on a [`Prepared`] made for a problem with the same mesh, boundary,
    /// viscosity and friction law (only the time step, loads, damage data and outputs may
    /// differ): what runs of one study on one mesh do instead of factoring again.
    pub fn from_prepared(
        problem: Problem,
        settings: SolverSettings,
        prepared: Prepared,
    ) -> Result<Simulation, SolveError> {
        let start = Instant::now();
        let Prepared {
            mesh,
            geo,
            dofs,
            velocity,
            smallness,
            mass,
            seconds: prepared_seconds,
        } = prepared;
        debug_assert_eq!(
            (mesh.nx, mesh.ny),
            problem.cells(),
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
        let zeta: Vec<f64> = match &problem.damage {
            Some(d) => mesh
                .nodes
                .iter()
                .map(|p| d.zeta0.eval(p[0], p[1], 0.0))
                .collect(),
            None => vec![1.0; nn],
        };
        let damage = match &problem.damage {
            Some(d) => {
                let h = assembly::combine(
                    1.0 / problem.k(),
                    &mass,
                    d.kappa,
                    &assembly::laplacian(&mesh, &geo),
                );
                let mut solver = DamageStep::new(h)?;
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
        let u: Vec<f64> = mesh
            .nodes
            .iter()
            .flat_map(|p| problem.u0.eval(p[0], p[1], 0.0))
            .collect();
        check_initial(&problem, &mesh, &u, &zeta)?;
        let nt = mesh.triangles.len();
        let n_free = dofs.n_free();
        Ok(Simulation {
            state: State {
                step: 0,
                u,
                zeta,
                ..State::default()
            },
            w: vec![0.0; 2 * nn],
            mass,
            velocity,
            damage,
            eps: vec![Tensor2::zeros(); nt],
            b: vec![Tensor2::zeros(); nt],
            load: vec![0.0; 2 * nn],
            load_free: vec![0.0; n_free],
            w_free: vec![0.0; n_free],
            setup_seconds: prepared_seconds + start.elapsed().as_secs_f64(),
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
            contact_velocity: self.velocity.contact_velocity().to_vec(),
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
        if warm.len() == self.velocity.n_contact() {
            self.velocity.set_contact_velocity(&warm);
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

    /// Advances one time step.
    pub fn step(&mut self) -> Result<StepReport, SolveError> {
        let n = self.state.step + 1;
        let k = self.problem.k();
        let t = n as f64 * k;
        // ε(u_{n−1}) per element, shared by B_{n−1} and φ.
        for (e, eps) in self.eps.iter_mut().enumerate() {
            *eps = self.geo.strain(&self.mesh, e, &self.state.u);
        }
        let zeta_prev = &self.state.zeta;
        let elasticity = self.problem.material.elasticity;
        for (e, tri) in self.mesh.triangles.iter().enumerate() {
            let zbar = (zeta_prev[tri[0]] + zeta_prev[tri[1]] + zeta_prev[tri[2]]) / 3.0;
            self.b[e] = elastic_stress(&elasticity, &self.eps[e], zbar);
        }

        let parallel = self.damage.is_some() && self.mesh.n_nodes() >= PARALLEL_MIN_NODES;
        let (vel, dam) = {
            let Simulation {
                problem,
                mesh,
                geo,
                dofs,
                settings,
                state,
                velocity,
                damage,
                eps,
                b,
                load,
                load_free,
                w_free,
                mass,
                ..
            } = self;
            let mut velocity_job = || -> Result<SolverReport, SolveError> {
                load.iter_mut().for_each(|v| *v = 0.0);
                loads::add_body_force(mesh, geo, &problem.body_force, t, load);
                loads::add_tractions(mesh, &problem.boundary, t, load);
                if load.iter().any(|v| !v.is_finite()) {
                    return Err(load_fault(problem, mesh, t, n));
                }
                loads::add_stress_divergence(mesh, geo, b, load);
                dofs.to_free(load, load_free);
                velocity.solve(load_free, w_free, settings, n)
            };
            let damage_job = |d: &mut DamagePart| -> Result<SolverReport, SolveError> {
                let dm = problem
                    .damage
                    .as_ref()
                    .expect("damage part implies damage data");
                let src = dm.source;
                loads::damage_source(
                    mesh,
                    geo,
                    &state.zeta,
                    |e, z| phi(&src, &eps[e], z),
                    &mut d.f,
                );
                mass.mul_vec(&state.zeta, &mut d.g);
                for (g, f) in d.g.iter_mut().zip(&d.f) {
                    *g = *g / k + f;
                }
                let DamagePart {
                    solver, g, next, ..
                } = d;
                solver.solve(g, next, settings, n)
            };
            match damage.as_mut() {
                Some(d) if parallel => std::thread::scope(|s| {
                    let h = s.spawn(|| damage_job(d));
                    let v = velocity_job();
                    (v, Some(h.join().expect("damage thread panicked")))
                }),
                Some(d) => (velocity_job(), Some(damage_job(d))),
                None => (velocity_job(), None),
            }
        };
        let velocity_report = vel?;
        let damage_report = dam.transpose()?;

        self.dofs.to_global(&self.w_free, &mut self.w);
        for (u, w) in self.state.u.iter_mut().zip(&self.w) {
            *u += k * w;
        }
        if let Some(d) = &self.damage {
            self.state.zeta.copy_from_slice(&d.next);
        }
        self.state.step = n;
        // |w_n|_V and |u_n|_V in one pass: ε(u_n) = ε(u_{n−1}) + k ε(w_n) per element.
        let (mut w2, mut u2) = (0.0, 0.0);
        for (e, eps) in self.eps.iter().enumerate() {
            let ew = self.geo.strain(&self.mesh, e, &self.w);
            w2 += self.geo.area[e] * ew.norm_squared();
            u2 += self.geo.area[e] * (eps + ew * k).norm_squared();
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
            velocity: velocity_report,
            damage: damage_report,
            slip_nodes: self
                .velocity
                .contact_velocity()
                .iter()
                .filter(|x| **x != 0.0)
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
        let sigma: Vec<Tensor2<f64>> = if need_sigma {
            (0..self.mesh.triangles.len())
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
        StepFields {
            n,
            t: n as f64 * self.problem.k(),
            u: sel.u.then(|| self.state.u.clone()),
            w: sel.w.then(|| self.w.clone()),
            zeta: sel.zeta.then(|| self.state.zeta.clone()),
            sigma: sel.sigma.then(|| {
                sigma
                    .iter()
                    .map(|s| [s[(0, 0)], s[(1, 1)], s[(0, 1)]])
                    .collect()
            }),
            von_mises: sel.von_mises.then(|| sigma.iter().map(von_mises).collect()),
            contact: sel.contact.then(|| self.contact_state()),
        }
    }

    /// Stick/slip state of every Γ3 DOF after the last step.
    pub fn contact_state(&self) -> Vec<ContactNode> {
        let x = self.velocity.contact_velocity();
        let force = self.velocity.contact_force();
        self.dofs
            .contact
            .iter()
            .enumerate()
            .map(|(i, c)| ContactNode {
                node: c.node,
                slip_velocity: x[i],
                friction_traction: force[i] / c.weight,
                bound: self.problem.friction.mu(x[i].abs()),
                slipping: x[i] != 0.0,
            })
            .collect()
    }

    /// Dimension and factor size of the velocity system (interior DOFs).
    pub fn velocity_factor_size(&self) -> (usize, usize) {
        self.velocity.factor_size()
    }

    /// One forward+backward substitution with the velocity factor on a copy of the current
    /// load (the unit of the benchmark's per-step ratio).
    pub fn time_one_substitution(&mut self) -> f64 {
        let mut v = self.load_free[..self.dofs.n_interior].to_vec();
        let start = Instant::now();
        self.velocity.substitute(&mut v);
        start.elapsed().as_secs_f64()
    }

    /// Damage refactorisations so far (0 without damage).
    pub fn damage_refactorizations(&self) -> usize {
        self.damage
            .as_ref()
            .map_or(0, |d| d.solver.refactorizations)
    }
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
fn check_initial(
    problem: &Problem,
    mesh: &Mesh,
    u: &[f64],
    zeta: &[f64],
) -> Result<(), SolveError> {
    for (i, p) in mesh.nodes.iter().enumerate() {
        for c in 0..2 {
            let v = u[2 * i + c];
            if !v.is_finite() {
                return Err(SolveError::Data {
                    pointer: format!("/initial/u0/{c}"),
                    message: format!(
                        "{} evaluates to {v} at the node (x, y) = ({}, {}); the initial \
                         displacement must be finite at every node",
                        formula_text(&problem.u0.0[c]),
                        p[0],
                        p[1]
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
                        "{} evaluates to {z} at the node (x, y) = ({}, {}); the initial damage \
                         must be in [0, 1] (1 = intact) at every node",
                        formula_text(&d.zeta0),
                        p[0],
                        p[1]
                    ),
                });
            }
        }
    }
    Ok(())
}

/// The error for a non-finite load vector at step n: the field and point responsible.
fn load_fault(problem: &Problem, mesh: &Mesh, t: f64, n: usize) -> SolveError {
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
            "{} evaluates to {} at (x, y, t) = ({}, {}, {t}), a quadrature point of time step \
             {n}; loads must be finite on the whole domain and time interval",
            formula_text(field),
            f.value,
            f.at[0],
            f.at[1]
        ),
    }
}
