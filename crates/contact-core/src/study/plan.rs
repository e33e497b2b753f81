//! The planner of a target study (docs/src/explanation/numerics.md#target-studies): an
//! error model e(h, k) ≈ a·h^p + b·k^q and a cost model t ≈ c·N^α·(T/k) fitted from cheap
//! pilot runs, and the cheapest (h, k) of the nested grid whose predicted error is below the
//! target divided by [`SAFETY`]: whether the target is within reach. Which run is chosen is
//! decided by measured error bars ([`super::target`]'s walk), the model giving its direction.
//!
//! Pure arithmetic on figures the runs measured; running them is [`super::target`]'s.

use super::compare::least_squares_order;
use serde::Serialize;

/// The plan (whether the target is within reach) aims at target / SAFETY. The model is
/// extrapolated from coarse levels by one to three halvings, over which the observed orders
/// drift (about 0.1 per level in the paper's Table 1, i.e. 10–20 % on the predicted error);
/// the coefficient's convention (see [`fit_part`]) already errs on the large side, so the
/// margin is 25 %.
pub const SAFETY: f64 = 1.25;
/// Fitted orders are clamped to this range: below it a ladder is not in its asymptotic
/// regime (the errors barely shrink) and a smaller order would send the planner to meshes
/// it cannot afford on the strength of noise; above it the scheme cannot converge (P1, Euler).
pub const ORDER_RANGE: (f64, f64) = (0.5, 3.0);
/// The cost exponent α is clamped to this range: no solver is cheaper than linear per step
/// in the unknowns, and the direct 2D/3D factorisations grow at most quadratically. Pilot
/// runs are small, where fixed overheads make the observed α smaller than at scale.
pub const COST_EXPONENT_RANGE: (f64, f64) = (1.0, 2.0);
/// Relative differences at or below this are zero (round-off of the solver tolerance).
pub const ZERO_DIFFERENCE: f64 = 1e-9;
/// At most this many of the finest differences of a ladder enter its order's fit: the
/// coarsest levels are the farthest from the asymptotic regime.
pub const FIT_POINTS: usize = 2;

/// One part of the error model: e ≈ coefficient · x^order, x = h or k.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartFit {
    pub coefficient: f64,
    /// The order used (the observed one clamped to [`ORDER_RANGE`]); None when the part is
    /// zero.
    pub order: Option<f64>,
    /// The least-squares slope of log(difference) against log(x), when defined.
    pub observed_order: Option<f64>,
    /// The (x, relative difference to the run at x/2) the fit used, coarsest first.
    pub points: Vec<(f64, f64)>,
    /// How a degenerate fit was resolved, if it was.
    pub note: Option<String>,
}

impl PartFit {
    pub fn at(&self, x: f64) -> f64 {
        match self.order {
            Some(p) => self.coefficient * x.powf(p),
            None => 0.0,
        }
    }
}

/// Fits one part from a ladder's differences `(x_i, d_i)`, d_i = |f(x_i) − f(x_i/2)| / |f|
/// (x halves from one point to the next). The order p is the least-squares slope of log d
/// against log x over the [`FIT_POINTS`] finest positive differences, clamped to
/// [`ORDER_RANGE`]. The coefficient follows the convention of the service's error bar
/// (crate::estimate, model order 1): the error of the finer run of a pair is its difference,
/// e(x/2) ≈ d(x), so a = d·2^p / x^p, anchored at the finest positive difference (the one
/// nearest the asymptotic regime). With errors of one direction e(x/2) = d(x)/(2^p − 1)
/// would be exact; errors of a pre-asymptotic ladder turn from level to level, which makes
/// the difference of the fields larger than that of their norms (on the paper's test about
/// 1.6 × at h = 1/16), and the check uses this convention too.
///
/// Degenerate ladders: all differences zero → the part is zero (the solution does not depend
/// on x); a single positive difference → the scheme's nominal order 1.
pub fn fit_part(points: &[(f64, f64)]) -> PartFit {
    let positive: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|&(x, d)| x > 0.0 && d.is_finite() && d > ZERO_DIFFERENCE)
        .collect();
    let used: Vec<(f64, f64)> = positive[positive.len().saturating_sub(FIT_POINTS)..].to_vec();
    let Some(&(x_fine, d_fine)) = used.last() else {
        return PartFit {
            coefficient: 0.0,
            order: None,
            observed_order: None,
            points: points.to_vec(),
            note: Some(
                "no difference between the levels: this part of the error is taken as zero".into(),
            ),
        };
    };
    let xs: Vec<f64> = used.iter().map(|p| p.0).collect();
    let ds: Vec<f64> = used.iter().map(|p| p.1).collect();
    let observed = least_squares_order(&xs, &ds);
    let (order, note) = match observed {
        None => (
            1.0,
            Some("a single positive difference: the nominal order 1 is assumed".to_string()),
        ),
        Some(o) if o < ORDER_RANGE.0 || !o.is_finite() => (
            ORDER_RANGE.0,
            Some(format!(
                "observed order {o:.2} below {}: the levels are not in the asymptotic regime; {} is used",
                ORDER_RANGE.0, ORDER_RANGE.0
            )),
        ),
        Some(o) if o > ORDER_RANGE.1 => (
            ORDER_RANGE.1,
            Some(format!(
                "observed order {o:.2} above {}: clamped",
                ORDER_RANGE.1
            )),
        ),
        Some(o) => (o, None),
    };
    PartFit {
        coefficient: d_fine * 2f64.powf(order) / x_fine.powf(order),
        order: Some(order),
        observed_order: observed,
        points: points.to_vec(),
        note,
    }
}

/// e(h, k) ≈ a·h^p + b·k^q.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ErrorModel {
    pub h: PartFit,
    pub k: PartFit,
}

impl ErrorModel {
    pub fn predict(&self, h: f64, k: f64) -> f64 {
        self.h.at(h) + self.k.at(k)
    }
}

/// A measured run for the cost model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Timing {
    pub unknowns: f64,
    pub steps: usize,
    pub seconds: f64,
}

/// t ≈ c · N^α · steps, N the unknowns (d × nodes).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CostModel {
    pub c: f64,
    pub alpha: f64,
    /// The least-squares slope of log(t/steps) against log N, when defined.
    pub observed_alpha: Option<f64>,
    pub note: Option<String>,
}

impl CostModel {
    pub fn predict(&self, unknowns: f64, steps: usize) -> f64 {
        self.c * unknowns.powf(self.alpha) * steps as f64
    }
}

/// Fits the cost model: α is the least-squares slope of log(t/steps) against log N over the
/// runs, clamped to [`COST_EXPONENT_RANGE`] (the exponent 1 when the runs have one size);
/// c is anchored at the largest run (most unknowns × steps), whose time is the least
/// dominated by fixed overheads.
pub fn fit_cost(runs: &[Timing]) -> CostModel {
    let ok: Vec<&Timing> = runs
        .iter()
        .filter(|r| r.seconds > 0.0 && r.unknowns > 0.0 && r.steps > 0)
        .collect();
    let xs: Vec<f64> = ok.iter().map(|r| r.unknowns).collect();
    let ys: Vec<f64> = ok.iter().map(|r| r.seconds / r.steps as f64).collect();
    let observed = least_squares_order(&xs, &ys);
    let (lo, hi) = COST_EXPONENT_RANGE;
    let (alpha, note) = match observed {
        None => (1.0, Some("runs of one size: α = 1 assumed".to_string())),
        Some(a) if a < lo => (
            lo,
            Some(format!(
                "observed α = {a:.2}: the pilot runs are dominated by fixed overheads; {lo} is used"
            )),
        ),
        Some(a) if a > hi => (hi, Some(format!("observed α = {a:.2} clamped to {hi}"))),
        Some(a) => (a, None),
    };
    let c = ok
        .iter()
        .max_by(|a, b| {
            (a.unknowns * a.steps as f64)
                .partial_cmp(&(b.unknowns * b.steps as f64))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .map_or(0.0, |r| {
            r.seconds / (r.unknowns.powf(alpha) * r.steps as f64)
        });
    CostModel {
        c,
        alpha,
        observed_alpha: observed,
        note,
    }
}

/// A point of the nested (h, k) grid with its predictions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Candidate {
    /// Resolution: cells per unit length, or 2^refine on a given mesh (h = 1/n).
    pub n: usize,
    pub steps: usize,
    pub h: f64,
    pub k: f64,
    pub unknowns: f64,
    pub predicted_error: f64,
    pub predicted_seconds: f64,
}

/// The cheapest candidate (predicted time) whose predicted error is at most target/[`SAFETY`];
/// ties go to the smaller predicted error.
pub fn cheapest(candidates: &[Candidate], target: f64) -> Option<Candidate> {
    candidates
        .iter()
        .filter(|c| c.predicted_error <= target / SAFETY)
        .min_by(|a, b| {
            (a.predicted_seconds, a.predicted_error)
                .partial_cmp(&(b.predicted_seconds, b.predicted_error))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .copied()
}

/// The cheapest candidate whose predicted error is within 1 % of the smallest predicted error
/// (past some k, halving it again only adds cost).
pub fn most_accurate(candidates: &[Candidate]) -> Option<Candidate> {
    let least = candidates
        .iter()
        .map(|c| c.predicted_error)
        .fold(f64::INFINITY, f64::min);
    candidates
        .iter()
        .filter(|c| c.predicted_error <= 1.01 * least)
        .min_by(|a, b| {
            (a.predicted_seconds, a.predicted_error)
                .partial_cmp(&(b.predicted_seconds, b.predicted_error))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ladder(a: f64, p: f64, xs: &[f64]) -> Vec<(f64, f64)> {
        xs.iter()
            .map(|&x| (x, a * x.powf(p) - a * (x / 2.0).powf(p)))
            .collect()
    }

    #[test]
    fn an_exact_power_law_is_recovered() {
        let f = fit_part(&ladder(0.7, 1.3, &[0.5, 0.25, 0.125, 0.0625]));
        assert!((f.order.unwrap() - 1.3).abs() < 1e-12, "{f:?}");
        // e(x/2) ≈ d(x): a = 0.7 (1 − 2^−1.3) · 2^1.3.
        let a = 0.7 * (1.0 - 2f64.powf(-1.3)) * 2f64.powf(1.3);
        assert!((f.coefficient - a).abs() < 1e-12, "{f:?}");
        assert!(f.note.is_none());
        assert!((f.at(0.01) - a * 0.01f64.powf(1.3)).abs() < 1e-15);
    }

    #[test]
    fn degenerate_ladders_are_resolved_and_said_so() {
        let zero = fit_part(&[(0.5, 0.0), (0.25, 1e-14)]);
        assert_eq!((zero.order, zero.at(0.1)), (None, 0.0));
        assert!(zero.note.unwrap().contains("zero"));
        let one = fit_part(&[(0.5, 0.0), (0.25, 0.1)]);
        assert_eq!(one.order, Some(1.0));
        assert!((one.coefficient - 0.1 * 2.0 / 0.25).abs() < 1e-12);
        // Differences that grow with refinement: the floor order, anchored at the finest.
        let growing = fit_part(&[(0.5, 0.01), (0.25, 0.02), (0.125, 0.03)]);
        assert_eq!(growing.order, Some(ORDER_RANGE.0));
        assert!(growing.observed_order.unwrap() < 0.0);
        assert!(growing.note.unwrap().contains("asymptotic"));
        let d = 0.03 * 2f64.sqrt() / 0.125f64.sqrt();
        assert!((growing.coefficient - d).abs() < 1e-12);
    }

    #[test]
    fn only_the_finest_points_enter_the_order() {
        // A pre-asymptotic first point (order 0.2 from it) does not bend the fit of order 2.
        let mut pts = ladder(1.0, 2.0, &[0.25, 0.125, 0.0625]);
        pts.insert(0, (0.5, pts[0].1 * 1.15));
        let f = fit_part(&pts);
        assert!((f.order.unwrap() - 2.0).abs() < 1e-12, "{f:?}");
    }

    #[test]
    fn the_cost_model_fits_and_clamps() {
        let runs: Vec<Timing> = [(100.0, 4), (400.0, 4), (1600.0, 8)]
            .iter()
            .map(|&(n, s)| Timing {
                unknowns: n,
                steps: s,
                seconds: 2e-6 * f64::powf(n, 1.2) * s as f64,
            })
            .collect();
        let m = fit_cost(&runs);
        assert!((m.alpha - 1.2).abs() < 1e-9 && m.note.is_none(), "{m:?}");
        assert!((m.predict(6400.0, 16) - 2e-6 * 6400f64.powf(1.2) * 16.0).abs() < 1e-9);
        // Constant time per step (overheads only): α = 1, anchored at the largest run.
        let flat: Vec<Timing> = [100.0, 400.0]
            .iter()
            .map(|&n| Timing {
                unknowns: n,
                steps: 4,
                seconds: 0.01,
            })
            .collect();
        let m = fit_cost(&flat);
        assert_eq!(m.alpha, 1.0);
        assert!((m.predict(400.0, 4) - 0.01).abs() < 1e-15);
        assert!(m.note.is_some());
    }

    #[test]
    fn the_cheapest_candidate_meets_the_target_with_the_margin() {
        let c = |n: usize, e: f64, t: f64| Candidate {
            n,
            steps: n,
            h: 1.0 / n as f64,
            k: 1.0 / n as f64,
            unknowns: (n * n) as f64,
            predicted_error: e,
            predicted_seconds: t,
        };
        let all = [
            c(4, 0.2, 1.0),
            c(8, 0.09, 2.0),
            c(16, 0.05, 8.0),
            c(32, 0.02, 64.0),
        ];
        assert_eq!(cheapest(&all, 0.1).unwrap().n, 16, "0.09 > 0.1/1.25");
        assert_eq!(cheapest(&all, 0.2).unwrap().n, 8);
        assert!(cheapest(&all, 0.01).is_none());
        assert_eq!(most_accurate(&all).unwrap().n, 32);
    }
}
