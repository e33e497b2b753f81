//! The summary of a run (the CLI's stdout and `summary.json`; a stable contract):
//! `mesh.{nodes, triangles}`, `time.steps`, `initial` and `final` `{t, w_V, u_V, zeta_L2,
//! zeta_min}` (step 0 and the last step), `steps[]` (the same per solved step, 1 to N, plus
//! `velocity` and `damage` solver reports, and the a posteriori `estimate` when asked),
//! `timing`, `estimate` (over the run, when asked).

use crate::a_posteriori::{Parts, RunEstimate};
use crate::estimate::ErrorEstimate;
use crate::problem::{FrictionLaw, MeshPattern, Problem};
use crate::solve::smallness::SmallnessReport;
use crate::solve::stepper::{Simulation, StepReport};
use crate::solve::velocity::ContactSolver;
use crate::solve::SolverSettings;
use serde::Serialize;

#[derive(Debug, Clone, Serialize)]
pub struct MeshInfo {
    /// The body's dimension d: 2 (triangles) or 3 (tetrahedra).
    pub dim: usize,
    pub nodes: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub triangles: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tetrahedra: Option<usize>,
    /// Rectangle or box: n = round(1/h); absent for a given mesh, which has no such n.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cells_per_unit: Option<usize>,
    /// Rectangle or box: h = 1/n; absent for a given mesh (see `cell_size`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub h: Option<f64>,
    /// A given mesh: its cells' diameters (longest edges), which vary from cell to cell.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cell_size: Option<CellSizes>,
    /// Rectangle: the diagonal pattern; box: "kuhn"; a given mesh: "unstructured".
    pub pattern: &'static str,
    /// A given mesh: where it came from ("mesh <id or file>", "polygon").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// A given mesh: the red refinements applied to it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refine: Option<usize>,
    /// Γ3 nodes whose contact frame is rotated (normal not along an axis).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotated_frames: Option<usize>,
    /// Free velocity DOFs (interior + Γ3 tangential).
    pub unknowns: usize,
    pub contact_dofs: usize,
    /// Size and factor fill of the velocity system actually factored (interior DOFs).
    pub factor_n: usize,
    pub factor_nnz: usize,
    /// How the reduced friction problem on Γ3 is solved: "none" (no Γ3), or "dense Schur
    /// complement" (S formed by substitutions, semismooth Newton on it).
    pub contact_solver: &'static str,
    /// How the linear systems are solved: "direct (Cholesky)", "multigrid (smoothed
    /// aggregation, 4 levels)", "multigrid (geometric, 3 levels)".
    pub linear_solver: String,
    /// Multigrid path: Σ nnz of the velocity hierarchy's level operators ÷ nnz of the finest
    /// (1 would be no coarse levels at all).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub operator_complexity: Option<f64>,
}

/// The shortest, mean and longest cell diameter of a given mesh.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct CellSizes {
    pub min: f64,
    pub mean: f64,
    pub max: f64,
}

/// The run's memory: predicted before any numeric work ([`crate::memory`]) and measured.
#[derive(Debug, Clone, Serialize)]
pub struct MemoryInfo {
    pub predicted_bytes: u64,
    /// The process's peak resident bytes at the end of the run (VmHWM; on a node running
    /// several jobs at once, an upper bound of this job's own).
    pub peak_bytes: Option<u64>,
    /// `peak_bytes` ÷ the velocity unknowns.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bytes_per_unknown: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct TimeInfo {
    pub t_end: f64,
    pub k: f64,
    pub steps: usize,
}

#[derive(Debug, Clone, Serialize)]
pub struct Physics {
    pub damage: bool,
    pub contact: bool,
    pub friction: Option<&'static str>,
    pub elasticity: &'static str,
}

/// The norms of one state: t, |w|_V, |u|_V, |ζ|_Z0 and min ζ.
#[derive(Debug, Clone, Serialize)]
pub struct FinalNorms {
    pub t: f64,
    #[serde(rename = "w_V")]
    pub w_v: f64,
    #[serde(rename = "u_V")]
    pub u_v: f64,
    #[serde(rename = "zeta_L2")]
    pub zeta_l2: f64,
    pub zeta_min: f64,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct SolverStats {
    pub velocity_max_iterations: usize,
    pub velocity_max_residual: f64,
    pub damage_max_iterations: usize,
    pub damage_max_residual: f64,
    pub damage_refactorizations: usize,
    /// Most conjugate-gradient iterations of one step's velocity and damage solves
    /// (multigrid path; 0 on the direct path).
    pub velocity_max_krylov_iterations: usize,
    pub damage_max_krylov_iterations: usize,
    /// Steps in which some Γ3 node slipped (the non-smooth solver was exercised).
    pub steps_with_slip: usize,
    /// Steps in which a sub-problem solver used ≥ 80 % of its iteration limit.
    pub steps_near_iteration_limit: usize,
}

#[derive(Debug, Clone, Serialize)]
pub struct Timing {
    pub setup_s: f64,
    pub solve_s: f64,
    pub per_step_s: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub scene: String,
    pub version: &'static str,
    pub mesh: MeshInfo,
    pub time: TimeInfo,
    pub physics: Physics,
    pub smallness: SmallnessReport,
    pub solver: SolverSettings,
    /// Step 0, the initial state at t = 0 (u_0, w_0 = 0, ζ_0): where the norms over time
    /// start; `steps` holds the solved steps 1 to N.
    pub initial: FinalNorms,
    #[serde(rename = "final")]
    pub final_: Option<FinalNorms>,
    pub stats: SolverStats,
    pub timing: Timing,
    pub memory: MemoryInfo,
    pub warnings: Vec<String>,
    /// Estimated discretisation error (scenes with `error_estimate: true`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_estimate: Option<ErrorEstimate>,
    /// The a posteriori estimate over the run (scenes with `output.estimate: true`): each
    /// part's (k Σ_n η_n²)^½ ([`crate::a_posteriori`]); `steps[].estimate` holds each step's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate: Option<Parts>,
    pub steps: Vec<StepReport>,
}

/// The norms of step 0: the nodal interpolants of the scene's u_0 and ζ_0 (1 without damage)
/// at t = 0, the state the stepper starts from (3.11), with w_0 = 0.
fn initial_norms<const D: usize>(sim: &Simulation<D>) -> FinalNorms {
    let (p, mesh) = (&sim.problem, &sim.mesh);
    let u0: Vec<f64> = mesh.nodes.iter().flat_map(|x| p.u0.at(x, 0.0)).collect();
    let zeta0: Vec<f64> = match &p.damage {
        Some(d) => mesh.nodes.iter().map(|x| d.zeta0.at(x, 0.0)).collect(),
        None => vec![1.0; mesh.n_nodes()],
    };
    FinalNorms {
        t: 0.0,
        w_v: 0.0,
        u_v: crate::fem::norms::strain_norm(mesh, &sim.geo, &u0),
        zeta_l2: sim.zeta_l2(&zeta0),
        zeta_min: zeta0.iter().copied().fold(f64::INFINITY, f64::min),
    }
}

impl Summary {
    pub fn new<const D: usize>(
        sim: &Simulation<D>,
        steps: Vec<StepReport>,
        solve_s: f64,
    ) -> Summary {
        let p: &Problem = &sim.problem;
        let (factor_n, factor_nnz) = sim.velocity_factor_size();
        let contact = sim.dofs.n_contact() > 0;
        let peak_bytes = crate::memory::peak_bytes();
        let mut stats = SolverStats {
            damage_refactorizations: sim.damage_refactorizations(),
            ..Default::default()
        };
        for s in &steps {
            stats.velocity_max_iterations =
                stats.velocity_max_iterations.max(s.velocity.iterations);
            stats.velocity_max_residual = stats.velocity_max_residual.max(s.velocity.residual);
            stats.velocity_max_krylov_iterations = stats
                .velocity_max_krylov_iterations
                .max(s.velocity.krylov_iterations);
            if let Some(d) = s.damage {
                stats.damage_max_iterations = stats.damage_max_iterations.max(d.iterations);
                stats.damage_max_residual = stats.damage_max_residual.max(d.residual);
                stats.damage_max_krylov_iterations =
                    stats.damage_max_krylov_iterations.max(d.krylov_iterations);
            }
            stats.steps_with_slip += (s.slip_nodes > 0) as usize;
            let near = |r: Option<crate::solve::SolverReport>| {
                r.is_some_and(|r| sim.settings.near_iteration_limit(r.iterations))
            };
            stats.steps_near_iteration_limit +=
                usize::from(near(Some(s.velocity)) || near(s.damage));
        }
        let mut warnings = Vec::new();
        if !sim.smallness.holds {
            warnings.push(format!(
                "smallness condition (2.31) violated: c2τ·cτ² = {:.4} ≥ m_A = {:.4}; the computed velocity is a stationary point, uniqueness is not guaranteed",
                sim.smallness.lhs, sim.smallness.m_a
            ));
        }
        Summary {
            scene: p.name.clone(),
            version: env!("CARGO_PKG_VERSION"),
            mesh: MeshInfo {
                dim: D,
                nodes: sim.mesh.n_nodes(),
                triangles: (D == 2).then(|| sim.mesh.n_cells()),
                tetrahedra: (D == 3).then(|| sim.mesh.n_cells()),
                cells_per_unit: p.body.is_none().then_some(p.cells_per_unit),
                h: p.body.is_none().then(|| 1.0 / p.cells_per_unit as f64),
                cell_size: p.body.as_ref().map(|_| {
                    let f = crate::mesh::quality::figures(&sim.mesh);
                    CellSizes {
                        min: f.min_cell_size,
                        mean: f.mean_cell_size,
                        max: f.max_cell_size,
                    }
                }),
                pattern: match (&p.body, p.pattern) {
                    (Some(_), _) => "unstructured",
                    (None, _) if D == 3 => "kuhn",
                    (None, MeshPattern::Diagonal) => "diagonal",
                    (None, MeshPattern::AntiDiagonal) => "anti_diagonal",
                    (None, MeshPattern::Cross) => "cross",
                },
                source: p.body.as_ref().map(|b| b.source.clone()),
                refine: p.body.as_ref().map(|b| b.refine),
                rotated_frames: p.body.as_ref().map(|_| sim.dofs.frames.len()),
                unknowns: sim.dofs.n_free(),
                contact_dofs: sim.dofs.n_contact(),
                factor_n,
                factor_nnz,
                contact_solver: if contact && stats.steps_with_slip == 0 {
                    ContactSolver::StickOnly.describe()
                } else if contact {
                    sim.slip_solver().describe()
                } else {
                    "none"
                },
                linear_solver: sim.linear_solver(),
                operator_complexity: sim.operator_complexity(),
            },
            time: TimeInfo {
                t_end: p.t_end,
                k: p.k(),
                steps: p.steps,
            },
            physics: Physics {
                damage: p.damage.is_some(),
                contact,
                friction: contact.then_some(match p.friction {
                    FrictionLaw::Tresca { .. } => "tresca",
                    FrictionLaw::SlipWeakening { .. } => "slip_weakening",
                    FrictionLaw::PiecewiseLinear { .. } => "piecewise_linear",
                }),
                elasticity: match p.material.elasticity {
                    crate::problem::Elasticity::Linear { .. } => "linear",
                    crate::problem::Elasticity::VonMises { .. } => "von_mises",
                },
            },
            smallness: sim.smallness.clone(),
            solver: sim.settings,
            initial: initial_norms(sim),
            final_: steps.last().map(|s| FinalNorms {
                t: s.t,
                w_v: s.w_v,
                u_v: s.u_v,
                zeta_l2: s.zeta_l2,
                zeta_min: s.zeta_min,
            }),
            stats,
            timing: Timing {
                setup_s: sim.setup_seconds,
                solve_s,
                per_step_s: if steps.is_empty() {
                    0.0
                } else {
                    solve_s / steps.len() as f64
                },
            },
            memory: MemoryInfo {
                predicted_bytes: sim.predicted_bytes,
                peak_bytes,
                bytes_per_unknown: peak_bytes.map(|b| b as f64 / sim.dofs.n_free().max(1) as f64),
            },
            warnings,
            error_estimate: None,
            estimate: p.output.estimate.then(|| {
                let mut run = RunEstimate::default();
                for s in steps.iter() {
                    if let Some(e) = &s.estimate {
                        run.add(e, s.w_v, p.k());
                    }
                }
                run.parts()
            }),
            steps,
        }
    }
}
