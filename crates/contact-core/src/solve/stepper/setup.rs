//! The set-up of a run before its first step: the mesh, its geometry and DOF numbering, the
//! operators and their solvers on the linear path that fits the memory limit, the smallness
//! estimate (2.31), and the initial state (3.11) with its data checked where the scheme
//! reads it.

use super::{DamagePart, Simulation, State, VelocityPart};
use crate::a_posteriori::Estimator;
use crate::fem::{assembly, CellTensors, DofMap, Geometry, NodeCells};
use crate::linalg::{Csr, LinearPath};
use crate::mesh::locality::Numbering;
use crate::mesh::{Mesh, SharedMesh};
use crate::problem::{Problem, SmallnessPolicy};
use crate::solve::backend::{self, Backend};
use crate::solve::smallness::{self, SmallnessReport};
use crate::solve::velocity::VelocityStep;
use crate::solve::{SolveError, SolverSettings};
use std::sync::Arc;
use std::time::Instant;

/// The set-up that depends only on the mesh, the boundary, the viscosity and the friction law,
/// not on the time step: mesh, geometry, DOF numbering, the run's solver backend with the
/// velocity step built on it (K_II factored or its hierarchy made), the smallness estimate
/// and the mass matrix. Cloning shares the velocity factor.
#[derive(Clone)]
pub struct Prepared<const D: usize = 2> {
    /// The linear path taken and its predicted peak bytes.
    pub linear: LinearPath,
    pub predicted_bytes: u64,
    backend: Arc<dyn Backend<D>>,
    mesh: SharedMesh<D>,
    /// How `mesh` relates to the mesh outputs are given on, where the two differ.
    numbering: Option<Arc<Numbering>>,
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

    /// [`Prepared::new`] under a per-job memory limit: the backend is chosen (or the run
    /// refused) from the predicted peak before anything is meshed, and a direct pick is
    /// confirmed on the exact factor sizes before anything is assembled ([`backend`]).
    pub fn within(problem: &Problem, memory_limit: Option<u64>) -> Result<Prepared<D>, SolveError> {
        let start = Instant::now();
        let pick = backend::pick(problem, memory_limit)?;
        let (mesh, numbering) = problem.mesh_and_numbering().map_err(|e| SolveError::Data {
            pointer: format!("/boundary/{}", e.part()),
            message: e.to_string(),
        })?;
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::new(&mesh, &problem.boundary);
        let backend = backend::confirm(pick, problem, &mesh, &dofs, memory_limit)?;
        let visc = problem.material.viscosity;
        let k = backend.stiffness(&mesh, &geo, &dofs, visc.eta, visc.xi);
        let mut velocity = backend.velocity(Arc::new(k), &mesh, &dofs, problem.friction.clone())?;
        let smallness =
            smallness::check(problem, &mesh, &geo, &dofs, &mut velocity, backend.as_ref())?;
        let mass = backend.mass(&mesh, &geo);
        Ok(Prepared {
            linear: backend.path(),
            predicted_bytes: backend.predicted_bytes(),
            backend,
            mesh,
            numbering,
            geo,
            dofs,
            velocity,
            smallness,
            mass,
            seconds: start.elapsed().as_secs_f64(),
        })
    }
}

impl<const D: usize> Simulation<D> {
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
            backend,
            mesh,
            numbering,
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
                let laplacian = backend.laplacian(&mesh, &geo, &mass);
                let h = assembly::combine(1.0 / problem.k(), &mass, d.kappa, &laplacian);
                drop(laplacian);
                let mut solver = backend.damage(&mesh, h)?;
                solver.set_active_from(&zeta);
                Some(DamagePart {
                    solver,
                    g: vec![0.0; nn],
                    f: vec![0.0; nn],
                    next: zeta.clone(),
                    before: Vec::new(),
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
            b: problem
                .output
                .keeps_history_stress()
                .then(|| CellTensors::zeros(nt)),
            estimator: problem
                .output
                .estimate
                .then(|| Box::new(Estimator::new(&problem, &mesh, &geo))),
            estimate: None,
            w_prev: match problem.output.estimate {
                true => vec![0.0; D * nn],
                false => Vec::new(),
            },
            w_known: false,
            cells: NodeCells::new(&mesh),
            setup_seconds: prepared_seconds + start.elapsed().as_secs_f64(),
            linear,
            predicted_bytes,
            problem,
            mesh,
            numbering,
            geo,
            dofs,
            settings,
            smallness,
        })
    }
}

/// u_0 (interleaved per node) and ζ_0 (per node; ≡ 1 without damage): the nodal
/// interpolants of the scene's `initial.u0` and `damage.zeta0` at t = 0, (3.11).
pub(super) fn initial_values<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
) -> (Vec<f64>, Vec<f64>) {
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

/// Where a formula meets the scheme: the scene's sampling check (a small grid at t = 0, T/2,
/// T) cannot see every node, quadrature point and time node, so the data are checked again
/// where they are used, and a bad value is reported at the field's JSON pointer.
pub(super) fn formula_text(f: &crate::problem::ScalarField) -> String {
    match f {
        crate::problem::ScalarField::Const(c) => c.to_string(),
        crate::problem::ScalarField::Expr(e) => format!("\"{}\"", e.source()),
    }
}

/// u0 finite and ζ0 in [0, 1] at every node.
pub(super) fn check_initial<const D: usize>(
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

/// "(x, y) = (…, …)" or "(x, y, z) = (…, …, …)" for messages.
fn at_point<const D: usize>(p: &[f64; D]) -> String {
    let names = ["x", "y", "z"][..D].join(", ");
    let values: Vec<String> = p.iter().map(|v| v.to_string()).collect();
    format!("({names}) = ({})", values.join(", "))
}
