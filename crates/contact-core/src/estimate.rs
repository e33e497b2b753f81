//! The error bar of a single simulation: the same scene also run at (2h, 2k) on the nested
//! coarse mesh (about 1/8 of the work), and at (4h, 4k) when h and k allow (1/64 more) to
//! check the model.
//!
//! Model: e_h ≈ C h^p with p = 1 (the velocity's order in Tables 1–2; ζ converges at least as
//! fast), so |u_h − u_2h| ≈ (2^p − 1) e_h and the estimate of the relative error of the fine
//! run is |u_h − I u_2h| / |u_h| / (2^p − 1), at every stored step whose time is a coarse
//! time node, and at T. With the (4h, 4k) run the observed order
//! p_obs = log2(|I u_2h − I u_4h| / |u_h − I u_2h|) is reported; a step is flagged when
//! p_obs < 1/2 (the differences do not shrink as the model assumes, so the estimate is not
//! trustworthy) or when the estimate exceeds 1/2 (the runs are too far from each other for
//! an asymptotic model).

use crate::fem::{assembly, norms, prolongation::prolongate};
use crate::linalg::Csr;
use crate::problem::{MeshPattern, Problem};
use crate::solve::stepper::Simulation;
use crate::solve::{SolveError, SolverSettings};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Order of the error model.
pub const MODEL_ORDER: f64 = 1.0;
/// Observed orders below this flag an estimate.
pub const MIN_ORDER: f64 = 0.5;
/// Relative estimates above this are flagged (outside any asymptotic regime).
pub const MAX_RELATIVE: f64 = 0.5;

/// Why a scene cannot have an error estimate (reported at `/error_estimate`).
pub fn unsupported(p: &Problem) -> Option<String> {
    if let Some(body) = &p.body {
        if body.refine == 0 {
            return Some("on an imported or polygon mesh needs mesh.refine ≥ 1: the (2h, 2k) run uses the mesh with one refinement less, and this mesh is the one given".into());
        }
        if !p.steps.is_multiple_of(2) {
            return Some(format!(
                "needs a run at (2h, 2k): the number of steps N = {} must be even",
                p.steps
            ));
        }
        return None;
    }
    if p.pattern == MeshPattern::Cross {
        return Some(
            "the cross pattern's meshes are not nested; use diagonal or anti_diagonal".into(),
        );
    }
    if !p.cells_per_unit.is_multiple_of(2) || !p.steps.is_multiple_of(2) {
        return Some(format!(
            "needs a run at (2h, 2k) on the nested coarse mesh: 1/h = {} and the number of steps N = {} must both be even",
            p.cells_per_unit, p.steps
        ));
    }
    let (nx, ny) = p.cells();
    let nz = p.depth_cells();
    if nx % 2 != 0 || ny % 2 != 0 || nz.is_some_and(|nz| nz % 2 != 0) {
        let cells = match nz {
            Some(nz) => format!("{nx} × {ny} × {nz}"),
            None => format!("{nx} × {ny}"),
        };
        return Some(format!(
            "the {cells} cells of the domain cannot be coarsened by 2"
        ));
    }
    None
}

/// The estimate at one time node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EstimateRow {
    pub n: usize,
    pub t: f64,
    /// Estimated relative error |w − w^hk|_V / |w^hk|_V (None when w^hk = 0).
    pub w: Option<f64>,
    /// Estimated relative error of ζ in the Z0 norm (None without damage).
    pub zeta: Option<f64>,
    /// Observed orders from the (4h, 4k) run, at nodes that are also its time nodes.
    pub observed_order_w: Option<f64>,
    pub observed_order_zeta: Option<f64>,
    pub flagged: bool,
}

/// What a summary reports.
#[derive(Debug, Clone, Serialize)]
pub struct ErrorEstimate {
    pub model_order: f64,
    pub coarse_h: f64,
    pub coarse_k: f64,
    /// (4h, 4k) run present (observed orders available).
    pub check: bool,
    pub coarse_seconds: f64,
    /// Per stored step whose time is a coarse time node.
    pub steps: Vec<EstimateRow>,
    #[serde(rename = "final")]
    pub final_: Option<EstimateRow>,
    pub flagged_steps: usize,
}

/// Runs the coarse companions in lock-step with the fine run.
pub struct ErrorEstimator<const D: usize = 2> {
    coarse: Simulation<D>,
    coarser: Option<Simulation<D>>,
    mass: Csr,
    damage: bool,
    seconds: f64,
    pub rows: Vec<EstimateRow>,
    final_: Option<EstimateRow>,
}

/// The problem at (by·h, by·k), by = 2 or 4: the rectangle's n / by, or the given mesh with
/// log2(by) refinements less.
fn coarsened(p: &Problem, by: usize) -> Problem {
    let body = p.body.as_ref().map(|b| {
        std::sync::Arc::new(crate::problem::Body {
            refine: b.refine - by.trailing_zeros() as usize,
            ..(**b).clone()
        })
    });
    Problem {
        body,
        cells_per_unit: p.cells_per_unit / by,
        steps: p.steps / by,
        ..p.clone()
    }
}

/// Can the problem be coarsened by 4 in h and k?
fn has_coarser(p: &Problem) -> bool {
    if !p.steps.is_multiple_of(4) {
        return false;
    }
    match &p.body {
        Some(b) => b.refine >= 2,
        None => {
            let (nx, ny) = p.cells();
            let nz = p.depth_cells().unwrap_or(0);
            p.cells_per_unit.is_multiple_of(4) && nx % 4 == 0 && ny % 4 == 0 && nz.is_multiple_of(4)
        }
    }
}

impl<const D: usize> ErrorEstimator<D> {
    /// Set-up for `fine`, whose problem must pass [`unsupported`].
    pub fn new(
        fine: &Simulation<D>,
        settings: SolverSettings,
    ) -> Result<ErrorEstimator<D>, SolveError> {
        let start = Instant::now();
        let p = &fine.problem;
        let coarse = Simulation::new(coarsened(p, 2), settings)?;
        let coarser = if has_coarser(p) {
            Some(Simulation::new(coarsened(p, 4), settings)?)
        } else {
            None
        };
        Ok(ErrorEstimator {
            coarse,
            coarser,
            mass: assembly::mass(&fine.mesh, &fine.geo),
            damage: p.damage.is_some(),
            seconds: start.elapsed().as_secs_f64(),
            rows: Vec::new(),
            final_: None,
        })
    }

    /// Call after every fine step: advances the companions to the fine run's time when it
    /// is one of their nodes, and records an estimate at stored steps and at T.
    pub fn after_step(&mut self, fine: &Simulation<D>, stored: bool) -> Result<(), SolveError> {
        let start = Instant::now();
        let n = fine.state.step;
        self.advance(n)?;
        if n.is_multiple_of(2) && (stored || fine.finished()) {
            let row = self.estimate(fine);
            if stored {
                self.rows.push(row.clone());
            }
            if fine.finished() {
                self.final_ = Some(row);
            }
        }
        self.seconds += start.elapsed().as_secs_f64();
        Ok(())
    }

    /// Brings the companions to fine step `n` without estimating (resuming a run from a
    /// checkpoint at step n); `rows` are the estimates recorded before it.
    pub fn catch_up(&mut self, n: usize, rows: Vec<EstimateRow>) -> Result<(), SolveError> {
        let start = Instant::now();
        for m in 1..=n {
            self.advance(m)?;
        }
        self.rows = rows;
        self.seconds += start.elapsed().as_secs_f64();
        Ok(())
    }

    fn advance(&mut self, n: usize) -> Result<(), SolveError> {
        if n.is_multiple_of(2) && self.coarse.state.step < n / 2 {
            self.coarse.step()?;
        }
        if let Some(c) = self.coarser.as_mut() {
            if n.is_multiple_of(4) && c.state.step < n / 4 {
                c.step()?;
            }
        }
        Ok(())
    }

    fn estimate(&self, fine: &Simulation<D>) -> EstimateRow {
        let n = fine.state.step;
        let (mesh, geo) = (&fine.mesh, &fine.geo);
        let mut scratch = vec![0.0; mesh.n_nodes()];
        let lift = |s: &Simulation<D>| {
            (
                prolongate(&s.mesh, &s.w, D, mesh).expect("nested meshes"),
                prolongate(&s.mesh, &s.state.zeta, 1, mesh).expect("nested meshes"),
            )
        };
        let diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x - y).collect::<Vec<_>>();
        let (w2, z2) = lift(&self.coarse);
        let scale = 2f64.powf(MODEL_ORDER) - 1.0;
        let w_norm = norms::strain_norm(mesh, geo, &fine.w);
        let d1_w = norms::strain_norm(mesh, geo, &diff(&fine.w, &w2));
        let z_norm = norms::mass_norm(&self.mass, &fine.state.zeta, &mut scratch);
        let d1_z = norms::mass_norm(&self.mass, &diff(&fine.state.zeta, &z2), &mut scratch);
        let rel = |d: f64, norm: f64| (norm > 0.0).then(|| d / norm / scale);
        let w = rel(d1_w, w_norm);
        let zeta = if self.damage { rel(d1_z, z_norm) } else { None };
        let (mut ow, mut oz) = (None, None);
        if let Some(c) = self
            .coarser
            .as_ref()
            .filter(|c| n.is_multiple_of(4) && c.state.step == n / 4)
        {
            let (w4, z4) = lift(c);
            let d2_w = norms::strain_norm(mesh, geo, &diff(&w2, &w4));
            let d2_z = norms::mass_norm(&self.mass, &diff(&z2, &z4), &mut scratch);
            let order = |d2: f64, d1: f64| (d1 > 0.0 && d2 > 0.0).then(|| (d2 / d1).log2());
            ow = order(d2_w, d1_w);
            oz = if self.damage { order(d2_z, d1_z) } else { None };
        }
        let flagged = [ow, oz].iter().flatten().any(|&o| o < MIN_ORDER)
            || [w, zeta].iter().flatten().any(|&e| e > MAX_RELATIVE);
        EstimateRow {
            n,
            t: n as f64 * fine.problem.k(),
            w,
            zeta,
            observed_order_w: ow,
            observed_order_zeta: oz,
            flagged,
        }
    }

    pub fn finish(self) -> ErrorEstimate {
        ErrorEstimate {
            model_order: MODEL_ORDER,
            coarse_h: match &self.coarse.problem.body {
                None => 1.0 / self.coarse.problem.cells_per_unit as f64,
                Some(_) => crate::mesh::quality::figures(&self.coarse.mesh).max_cell_size,
            },
            coarse_k: self.coarse.problem.k(),
            check: self.coarser.is_some(),
            coarse_seconds: self.seconds,
            flagged_steps: self.rows.iter().filter(|r| r.flagged).count(),
            steps: self.rows,
            final_: self.final_,
        }
    }
}
