//! Convergence studies: runs of one scene at several (h, k), compared at t = T with a finer
//! reference run on its (nested) mesh. Errors as in SCHEME.md: the coarse P1 fields are
//! interpolated onto the reference mesh, relative errors |w − w^hk|_V / |w|_V and
//! |ζ − ζ^hk|_Z0 / |ζ|_Z0, observed order between consecutive levels log2(e_coarse/e_fine)
//! (for ladders that halve h or k).

use crate::fem::{assembly, norms, prolongation::prolongate, Geometry};
use crate::problem::Problem;
use crate::run::{run_to_end, RunError};
use crate::solve::SolverSettings;
use serde::Serialize;
use std::time::Instant;

/// One level of a ladder.
#[derive(Debug, Clone, Serialize)]
pub struct StudyRow {
    pub h: f64,
    pub k: f64,
    pub err_w: f64,
    pub err_zeta: f64,
    pub order_w: Option<f64>,
    pub order_zeta: Option<f64>,
    pub unknowns: usize,
    pub steps: usize,
    pub seconds: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct StudyReference {
    pub h: f64,
    pub k: f64,
    #[serde(rename = "w_V")]
    pub w_v: f64,
    #[serde(rename = "zeta_Z0")]
    pub zeta_z0: f64,
    pub seconds: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct StudyResult {
    pub reference: StudyReference,
    pub rows: Vec<StudyRow>,
}

#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error(transparent)]
    Run(#[from] RunError),
    #[error("level h = {h}, k = {k} is not nested in the reference (h = {ref_h}, k = {ref_k}): the reference mesh must refine it and its time grid must contain t = T")]
    NotNested {
        h: f64,
        k: f64,
        ref_h: f64,
        ref_k: f64,
    },
}

/// Runs every `(cells_per_unit, steps)` level of `base` and the reference, and tabulates the
/// errors at t = T.
pub fn run_ladder(
    base: &Problem,
    levels: &[(usize, usize)],
    reference: (usize, usize),
) -> Result<StudyResult, StudyError> {
    let with = |(n, steps): (usize, usize)| Problem {
        cells_per_unit: n,
        steps,
        ..base.clone()
    };
    let settings = SolverSettings::default();
    let t = Instant::now();
    let fine = run_to_end(with(reference), settings)?;
    let ref_seconds = t.elapsed().as_secs_f64();
    let geo = Geometry::new(&fine.mesh);
    let mass = assembly::mass(&fine.mesh, &geo);
    let mut scratch = vec![0.0; fine.mesh.n_nodes()];
    let w_norm = norms::strain_norm(&fine.mesh, &geo, &fine.w);
    let z_norm = norms::mass_norm(&mass, &fine.state.zeta, &mut scratch);
    let mut rows: Vec<StudyRow> = Vec::new();
    for &level in levels {
        let t = Instant::now();
        let coarse = run_to_end(with(level), settings)?;
        let seconds = t.elapsed().as_secs_f64();
        let not_nested = || StudyError::NotNested {
            h: 1.0 / level.0 as f64,
            k: base.t_end / level.1 as f64,
            ref_h: 1.0 / reference.0 as f64,
            ref_k: base.t_end / reference.1 as f64,
        };
        let w = prolongate(&coarse.mesh, &coarse.w, 2, &fine.mesh).ok_or_else(not_nested)?;
        let z =
            prolongate(&coarse.mesh, &coarse.state.zeta, 1, &fine.mesh).ok_or_else(not_nested)?;
        let dw: Vec<f64> = fine.w.iter().zip(&w).map(|(a, b)| a - b).collect();
        let dz: Vec<f64> = fine.state.zeta.iter().zip(&z).map(|(a, b)| a - b).collect();
        let err_w = norms::strain_norm(&fine.mesh, &geo, &dw) / w_norm;
        let err_zeta = norms::mass_norm(&mass, &dz, &mut scratch) / z_norm;
        let order = |prev: f64, cur: f64| (prev / cur).log2();
        let (order_w, order_zeta) = match rows.last() {
            Some(p) => (
                Some(order(p.err_w, err_w)),
                Some(order(p.err_zeta, err_zeta)),
            ),
            None => (None, None),
        };
        rows.push(StudyRow {
            h: 1.0 / level.0 as f64,
            k: base.t_end / level.1 as f64,
            err_w,
            err_zeta,
            order_w,
            order_zeta,
            unknowns: coarse.dofs.n_free(),
            steps: level.1,
            seconds,
        });
    }
    Ok(StudyResult {
        reference: StudyReference {
            h: 1.0 / reference.0 as f64,
            k: base.t_end / reference.1 as f64,
            w_v: w_norm,
            zeta_z0: z_norm,
            seconds: ref_seconds,
        },
        rows,
    })
}

impl StudyResult {
    /// The table in the layout of the paper's Tables 1–2.
    pub fn text_table(&self, vary: &str) -> String {
        let fmt_opt = |o: Option<f64>| o.map_or("      -".to_string(), |v| format!("{v:7.4}"));
        let mut s = format!(
            "reference h = 1/{:.0}, k = 1/{:.0}: |w|_V = {:.5}, |zeta|_Z0 = {:.5} ({:.2} s)\n{:>6} {:>11} {:>7} {:>11} {:>7} {:>8}\n",
            1.0 / self.reference.h,
            1.0 / self.reference.k,
            self.reference.w_v,
            self.reference.zeta_z0,
            self.reference.seconds,
            vary,
            "err_w",
            "order",
            "err_zeta",
            "order",
            "seconds"
        );
        for r in &self.rows {
            let v = if vary == "h" { r.h } else { r.k };
            s += &format!(
                "{:>6} {:11.4e} {} {:11.4e} {} {:8.3}\n",
                format!("1/{:.0}", 1.0 / v),
                r.err_w,
                fmt_opt(r.order_w),
                r.err_zeta,
                fmt_opt(r.order_zeta),
                r.seconds
            );
        }
        s
    }
}
