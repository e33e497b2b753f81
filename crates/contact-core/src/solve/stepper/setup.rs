//! The set-up of a run before its first step: the mesh, its geometry and DOF numbering, the
//! operators and their solvers on the linear path that fits the memory limit, the smallness
//! estimate (2.31), and the initial state (3.11) with its data checked where the scheme
//! reads it.

use super::{DamagePart, Simulation, State, VelocityPart};
use crate::fem::multilevel;
use crate::fem::{assembly, DofMap, Geometry};
use crate::laws::Tensor;
use crate::linalg::multigrid::{Hierarchy, Params};
use crate::linalg::{Cholesky, CholeskyPlan, Csr, LinearPath, LinearSolver, SchurPath};
use crate::memory;
use crate::mesh::Mesh;
use crate::problem::{Problem, SmallnessPolicy};
use crate::solve::damage::DamageStep;
use crate::solve::smallness::{self, SmallnessReport};
use crate::solve::velocity::VelocityStep;
use crate::solve::{SolveError, SolverSettings};
use std::sync::Arc;
use std::time::Instant;

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
}

/// u_0 (interleaved per node) and ζ_0 (per node; ≡ 1 without damage): the nodal
/// interpolants of the scene's `initial.u0` and `damage.zeta0` at t = 0, (3.11).
pub(super) fn initial_values<const D: usize>(problem: &Problem, mesh: &Mesh<D>) -> (Vec<f64>, Vec<f64>) {
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
