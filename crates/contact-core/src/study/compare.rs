//! The error table of a study: each level's fields, interpolated onto the reference mesh
//! (exact for nested P1 meshes), compared with the reference at the common time nodes.

use super::levels::{LevelRun, RunStats};
use super::reference::{double_dot, strains, sym_len, Reference};
use super::spec::{Plan, Vary};
use crate::fem::prolongation::{parent_cells, prolongate};
use crate::fem::{norms, Geometry};
use serde::Serialize;
use std::collections::BTreeSet;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// One level of a ladder. Errors are relative: at t = T, |e(T)| / |ref(T)|; over time, the
/// maximum of |e(t)| / |ref(t)| over the compared nodes, skipping nodes where the reference
/// vanishes (|ref(t)| < 1e-12 max_s |ref(s)|, where a relative error means nothing).
#[derive(Debug, Clone, Serialize)]
pub struct StudyRow {
    pub h: f64,
    pub k: f64,
    pub err_w: f64,
    pub err_zeta: f64,
    /// Observed order against the previous row: log(e_prev/e) / log(p_prev/p), p = h or k.
    pub order_w: Option<f64>,
    pub order_zeta: Option<f64>,
    pub err_w_max: f64,
    pub err_zeta_max: f64,
    /// Time nodes compared for the maxima (t = T included).
    pub compared_nodes: usize,
    /// Free velocity DOFs.
    pub unknowns: usize,
    pub steps: usize,
    /// Wall time of the run, set-up included.
    pub seconds: f64,
    pub seconds_per_step: f64,
    #[serde(flatten)]
    pub stats: RunStats,
}

#[derive(Debug, Clone, Serialize)]
pub struct StudyReference {
    pub h: f64,
    pub k: f64,
    pub unknowns: usize,
    pub steps: usize,
    #[serde(rename = "w_V")]
    pub w_v: f64,
    #[serde(rename = "zeta_Z0")]
    pub zeta_z0: f64,
    /// Wall time of the reference run (when it was computed).
    pub seconds: f64,
    /// True when this study reused a reference computed for an earlier one.
    pub cached: bool,
    /// Content hash of the scene and resolution the reference is keyed by.
    pub key: String,
    #[serde(flatten)]
    pub stats: RunStats,
}

#[derive(Debug, Clone, Serialize)]
pub struct StudyResult {
    pub kind: &'static str,
    pub name: String,
    pub vary: Vary,
    pub reference: StudyReference,
    pub rows: Vec<StudyRow>,
    /// Least-squares slope of log e against log p over the whole ladder.
    pub lsq_order_w: Option<f64>,
    pub lsq_order_zeta: Option<f64>,
    /// Wall time of the whole study (runs overlap on several threads).
    pub seconds: f64,
    pub threads: usize,
}

pub(super) fn tabulate<const D: usize>(
    plan: &Plan,
    reference: &Reference<D>,
    from_cache: bool,
    levels: &[LevelRun<D>],
    compared: &BTreeSet<usize>,
    threads: usize,
    seconds: f64,
) -> StudyResult {
    let ref_steps = plan.reference.1;
    let errors = parallel_map(levels.len(), threads, |i| {
        level_errors(reference, &levels[i], ref_steps / levels[i].steps, compared)
    });
    let p = |(n, steps): (usize, usize)| match plan.vary {
        Vary::K => plan.base.t_end / steps as f64,
        Vary::H | Vary::Both => 1.0 / n as f64,
    };
    let mut rows: Vec<StudyRow> = Vec::with_capacity(levels.len());
    for ((run, e), &level) in levels.iter().zip(errors).zip(&plan.levels) {
        let order = |prev: &StudyRow, f: fn(&StudyRow) -> f64, cur: f64| {
            let prev_level = (
                (1.0 / prev.h).round() as usize,
                (plan.base.t_end / prev.k).round() as usize,
            );
            observed_order(f(prev), cur, p(prev_level), p(level))
        };
        let (order_w, order_zeta) = match rows.last() {
            Some(prev) => (
                order(prev, |r| r.err_w, e.at_t_end.0),
                order(prev, |r| r.err_zeta, e.at_t_end.1),
            ),
            None => (None, None),
        };
        rows.push(StudyRow {
            h: 1.0 / level.0 as f64,
            k: plan.base.t_end / level.1 as f64,
            err_w: e.at_t_end.0,
            err_zeta: e.at_t_end.1,
            order_w,
            order_zeta,
            err_w_max: e.max.0,
            err_zeta_max: e.max.1,
            compared_nodes: e.nodes,
            unknowns: run.unknowns,
            steps: run.steps,
            seconds: run.seconds,
            seconds_per_step: run.seconds / run.steps.max(1) as f64,
            stats: run.stats,
        });
    }
    let ps: Vec<f64> = plan.levels.iter().map(|&l| p(l)).collect();
    let lsq =
        |f: fn(&StudyRow) -> f64| least_squares_order(&ps, &rows.iter().map(f).collect::<Vec<_>>());
    let last = reference.snapshots.len() - 1;
    StudyResult {
        kind: "study",
        name: plan.name.clone(),
        vary: plan.vary,
        lsq_order_w: lsq(|r| r.err_w),
        lsq_order_zeta: lsq(|r| r.err_zeta),
        reference: StudyReference {
            h: 1.0 / plan.reference.0 as f64,
            k: plan.base.t_end / plan.reference.1 as f64,
            unknowns: reference.unknowns,
            steps: reference.steps,
            w_v: reference.w_norms[last],
            zeta_z0: reference.zeta_norms[last],
            seconds: reference.seconds,
            cached: from_cache,
            key: plan.reference_key.clone(),
            stats: reference.stats,
        },
        rows,
        seconds,
        threads,
    }
}

struct LevelErrors {
    /// Relative (w, ζ) errors at t = T.
    at_t_end: (f64, f64),
    /// Relative (w, ζ) errors, maximum over the compared nodes.
    max: (f64, f64),
    nodes: usize,
}

/// `ratio` = reference steps per level step. |w − I w_c|_V is summed over the reference
/// cells with the coarse strain taken on each one's parent (exact for nested P1 meshes,
/// no interpolation); ζ is interpolated and measured with the reference mass matrix.
fn level_errors<const D: usize>(
    reference: &Reference<D>,
    level: &LevelRun<D>,
    ratio: usize,
    compared: &BTreeSet<usize>,
) -> LevelErrors {
    let fine = &reference.mesh;
    // Nesting was checked when the plan was made, so these cannot fail here.
    let parents = parent_cells(&level.mesh, fine).expect("nested meshes");
    let coarse_geo = Geometry::new(&level.mesh);
    let mut scratch = vec![0.0; fine.n_nodes()];
    let biggest = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
    let floor = (
        1e-12 * biggest(&reference.w_norms),
        1e-12 * biggest(&reference.zeta_norms),
    );
    let mut max = (0.0f64, 0.0f64);
    let mut at_t_end = (f64::NAN, f64::NAN);
    let mut nodes = 0;
    for snap in &level.snapshots {
        let ref_step = snap.step * ratio;
        if !compared.contains(&ref_step) {
            continue;
        }
        let Some(i) = reference.index(ref_step) else {
            continue;
        };
        let rs = &reference.snapshots[i];
        let coarse_strain = strains(&level.mesh, &coarse_geo, &snap.w);
        let s = sym_len(D);
        let mut diff = [0.0; 6];
        let ew2: f64 = rs
            .strain
            .chunks_exact(s)
            .zip(&parents)
            .zip(reference.geo.measures())
            .map(|((e, &p), a)| {
                let c = &coarse_strain[s * p as usize..][..s];
                for ((d, e), c) in diff.iter_mut().zip(e).zip(c) {
                    *d = e - c;
                }
                a * double_dot::<D>(&diff[..s])
            })
            .sum();
        let z = prolongate(&level.mesh, &snap.zeta, 1, fine).expect("nested meshes");
        let dz: Vec<f64> = rs.zeta.iter().zip(&z).map(|(a, b)| a - b).collect();
        let (nw, nz) = (reference.w_norms[i], reference.zeta_norms[i]);
        let ew = ew2.sqrt() / nw;
        let ez = norms::mass_norm(&reference.mass, &dz, &mut scratch) / nz;
        if nw > floor.0 {
            max.0 = max.0.max(ew);
        }
        if nz > floor.1 {
            max.1 = max.1.max(ez);
        }
        nodes += 1;
        if ref_step == reference.steps {
            at_t_end = (ew, ez);
        }
    }
    LevelErrors {
        at_t_end,
        max,
        nodes,
    }
}

/// log(e_prev / e) / log(p_prev / p); None when undefined (equal p, zero or non-finite e).
pub fn observed_order(e_prev: f64, e: f64, p_prev: f64, p: f64) -> Option<f64> {
    let o = (e_prev / e).ln() / (p_prev / p).ln();
    (e_prev > 0.0 && e > 0.0 && p_prev != p && o.is_finite()).then_some(o)
}

/// Slope of the least-squares line through (log p_i, log e_i), over the points with e > 0;
/// None with fewer than two distinct such p.
pub fn least_squares_order(p: &[f64], e: &[f64]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = p
        .iter()
        .zip(e)
        .filter(|(p, e)| **e > 0.0 && e.is_finite() && **p > 0.0)
        .map(|(p, e)| (p.ln(), e.ln()))
        .collect();
    let n = pts.len() as f64;
    let mx = pts.iter().map(|q| q.0).sum::<f64>() / n;
    let my = pts.iter().map(|q| q.1).sum::<f64>() / n;
    let sxx: f64 = pts.iter().map(|q| (q.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum();
    (pts.len() >= 2 && sxx > 1e-300).then(|| sxy / sxx)
}

/// `f(0..n)` on up to `threads` threads, results in index order.
fn parallel_map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let out: Vec<Mutex<Option<T>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let work = || loop {
        let i = next.fetch_add(1, Ordering::SeqCst);
        if i >= n {
            break;
        }
        *out[i].lock().unwrap() = Some(f(i));
    };
    std::thread::scope(|s| {
        for _ in 1..threads.clamp(1, n.max(1)) {
            s.spawn(work);
        }
        work();
    });
    out.into_iter()
        .map(|m| m.into_inner().unwrap().expect("computed"))
        .collect()
}

impl StudyResult {
    /// The table in the layout of the paper's Tables 1–2.
    pub fn text_table(&self) -> String {
        let vary = match self.vary {
            Vary::K => "k",
            Vary::H | Vary::Both => "h",
        };
        let frac = crate::study::format::fraction;
        let opt = |o: Option<f64>| o.map_or("      -".to_string(), |v| format!("{v:7.4}"));
        let r = &self.reference;
        let mut s = format!(
            "{}: reference h = {}, k = {}: |w|_V = {:.5}, |zeta|_Z0 = {:.5} ({:.2} s{})\n{:>7} {:>11} {:>7} {:>11} {:>7} {:>8}\n",
            self.name,
            frac(r.h),
            frac(r.k),
            r.w_v,
            r.zeta_z0,
            r.seconds,
            if r.cached { ", cached" } else { "" },
            vary,
            "err_w",
            "order",
            "err_zeta",
            "order",
            "seconds"
        );
        for row in &self.rows {
            let v = if vary == "k" { row.k } else { row.h };
            s += &format!(
                "{:>7} {:11.4e} {} {:11.4e} {} {:8.3}\n",
                frac(v),
                row.err_w,
                opt(row.order_w),
                row.err_zeta,
                opt(row.order_zeta),
                row.seconds
            );
        }
        s += &format!(
            "least-squares order: w {}, zeta {}; study {:.2} s on {} thread(s)\n",
            opt(self.lsq_order_w).trim(),
            opt(self.lsq_order_zeta).trim(),
            self.seconds,
            self.threads
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_order_recovers_an_exact_power_law() {
        let p = [0.5, 0.25, 0.125, 0.0625];
        let e: Vec<f64> = p.iter().map(|h: &f64| 3.0 * h.powf(1.5)).collect();
        assert!((least_squares_order(&p, &e).unwrap() - 1.5).abs() < 1e-12);
        assert_eq!(least_squares_order(&p[..1], &e[..1]), None);
        assert_eq!(least_squares_order(&[0.5, 0.5], &[1.0, 2.0]), None);
    }

    #[test]
    fn observed_order_between_halved_levels_is_log2_of_the_ratio() {
        assert!((observed_order(0.4, 0.1, 0.5, 0.25).unwrap() - 2.0).abs() < 1e-15);
        assert!((observed_order(0.3, 0.1, 0.3, 0.1).unwrap() - 1.0).abs() < 1e-15);
        assert_eq!(observed_order(0.4, 0.0, 0.5, 0.25), None);
        assert_eq!(observed_order(0.4, 0.2, 0.5, 0.5), None);
    }
}
