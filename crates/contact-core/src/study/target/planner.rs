//! The plan of a target study: the grid of candidate (h, k) with their predicted error,
//! time and the limit each breaks; the work–precision frontier; why a target is out of reach.

use super::*;
use crate::study::format::sig;

/// Why a candidate is out of reach: a per-job limit, with what the run needs, or the
/// study's time budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Limit {
    Run {
        limit: admission::Limit,
        needed: u64,
        allowed: u64,
    },
    Budget,
}

impl Limit {
    /// The node or memory limit: both grow with n only.
    pub(super) fn is_size(self) -> bool {
        matches!(
            self,
            Limit::Run {
                limit: admission::Limit::Nodes | admission::Limit::Memory,
                ..
            }
        )
    }

    /// The step or stored-bytes limit: both grow with the steps at a given n.
    pub(super) fn is_length(self) -> bool {
        matches!(
            self,
            Limit::Run {
                limit: admission::Limit::Steps | admission::Limit::StoredBytes,
                ..
            }
        )
    }
}

pub(super) struct Planner<'a> {
    pub(super) spec: &'a TargetSpec,
    pub(super) exec: Execution,
    pub(super) limits: Limits,
    pub(super) started: Instant,
}

impl Planner<'_> {
    pub(super) fn problem(&self, (n, steps): (usize, usize)) -> Problem {
        with(&self.spec.base, (n, steps))
    }

    pub(super) fn h(&self, n: usize) -> f64 {
        1.0 / n as f64
    }

    pub(super) fn k(&self, steps: usize) -> f64 {
        self.spec.base.t_end / steps as f64
    }

    pub(super) fn unknowns(&self, level: (usize, usize)) -> f64 {
        let p = self.problem(level);
        (p.dim() * p.n_nodes()) as f64
    }

    /// The first per-job limit a run of the level breaks ([`admission::check_run`]), budget
    /// aside.
    pub(super) fn breaks(&self, level: (usize, usize)) -> Option<Limit> {
        let p = self.problem(level);
        admission::check_run(&p, &self.limits, &admission::Pointers::scene())
            .err()
            .map(|e| Limit::Run {
                limit: e.limit,
                needed: e.needed,
                allowed: e.allowed,
            })
    }

    /// Every candidate of the grid (n0·2^i, N0·2^j; i, j ≥ 1 so that the (2h, 2k) companion
    /// exists) with its predictions and the limit it breaks, if any. `spent` is the time
    /// already used; the companion's time counts unless it was run already.
    pub(super) fn candidates(
        &self,
        model: &ErrorModel,
        cost: &CostModel,
        done: &dyn Fn((usize, usize)) -> bool,
    ) -> Vec<(Candidate, Option<Limit>)> {
        let spent = self.started.elapsed().as_secs_f64();
        let mut out = Vec::new();
        let n0 = self.spec.n0;
        for i in 1..=MAX_DOUBLINGS {
            let n = n0 << i;
            let mut size_broken = false;
            for j in 1..=2 * MAX_DOUBLINGS {
                let steps = PILOT_STEPS << j;
                let level = (n, steps);
                let unknowns = self.unknowns(level);
                let predicted_seconds = cost.predict(unknowns, steps);
                let companion = (n / 2, steps / 2);
                let companion_s = if done(companion) {
                    0.0
                } else {
                    cost.predict(self.unknowns(companion), companion.1)
                };
                let c = Candidate {
                    n,
                    steps,
                    h: self.h(n),
                    k: self.k(steps),
                    unknowns,
                    predicted_error: model.predict(self.h(n), self.k(steps)),
                    predicted_seconds,
                };
                let limit = self.breaks(level).or_else(|| {
                    self.spec
                        .budget_s
                        .is_some_and(|b| spent + predicted_seconds + companion_s > b)
                        .then_some(Limit::Budget)
                });
                out.push((c, limit));
                // The node and memory limits grow with n only: a row whose coarsest k
                // breaks one is the last row; finer k of a row past the step limit break it.
                if j == 1 && limit.is_some_and(Limit::is_size) {
                    size_broken = true;
                    break;
                }
                if limit.is_some_and(Limit::is_length) {
                    break;
                }
            }
            if size_broken {
                break;
            }
        }
        out
    }
}

/// The candidates within the limits that no other beats in both predicted time and error,
/// cheapest first.
pub(super) fn frontier(candidates: &[(Candidate, Option<Limit>)]) -> Vec<Candidate> {
    let mut ok: Vec<Candidate> = candidates
        .iter()
        .filter(|c| c.1.is_none())
        .map(|c| c.0)
        .collect();
    ok.sort_by(|a, b| {
        a.predicted_seconds
            .partial_cmp(&b.predicted_seconds)
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut out: Vec<Candidate> = Vec::new();
    for c in ok {
        if out
            .last()
            .is_none_or(|l| c.predicted_error < l.predicted_error)
        {
            out.push(c);
        }
    }
    out
}

/// The refusal: the best error reachable within the limits and its cost, and what stops the
/// target (the limit the cheapest candidate meeting it breaks).
pub(super) fn unreachable(
    planner: &Planner,
    model: &ErrorModel,
    cost: &CostModel,
    candidates: &[(Candidate, Option<Limit>)],
) -> StudyError {
    let spec = planner.spec;
    let frac = crate::study::format::fraction;
    let feasible: Vec<Candidate> = candidates
        .iter()
        .filter(|c| c.1.is_none())
        .map(|c| c.0)
        .collect();
    let best = plan::most_accurate(&feasible);
    // The cheapest run of the whole grid meeting the target, limits ignored, and the limit it
    // breaks.
    let mut all = Vec::new();
    for i in 1..=MAX_DOUBLINGS {
        for j in 1..=2 * MAX_DOUBLINGS {
            let (n, steps) = (spec.n0 << i, PILOT_STEPS << j);
            let (h, k) = (planner.h(n), planner.k(steps));
            let unknowns = planner.unknowns((n, steps));
            all.push(Candidate {
                n,
                steps,
                h,
                k,
                unknowns,
                predicted_error: model.predict(h, k),
                predicted_seconds: cost.predict(unknowns, steps),
            });
        }
    }
    let needed = plan::cheapest(&all, spec.error);
    let reason = match needed.map(|n| {
        let limit = planner
            .breaks((n.n, n.steps))
            .unwrap_or(Limit::Budget);
        (n, limit)
    }) {
        Some((n, l)) => {
            use crate::memory::human;
            let what = match l {
                Limit::Run {
                    limit,
                    needed,
                    allowed,
                } => match limit {
                    admission::Limit::Nodes => {
                        format!("{needed} nodes, more than the node limit of {allowed}")
                    }
                    admission::Limit::Steps => {
                        format!("{needed} time steps, more than the step limit of {allowed}")
                    }
                    admission::Limit::StoredBytes => format!(
                        "about {} of stored steps, more than the per-job limit of {}",
                        human(needed),
                        human(allowed)
                    ),
                    admission::Limit::Memory => format!(
                        "about {} of memory (predicted), more than the per-job memory limit of {}",
                        human(needed),
                        human(allowed)
                    ),
                },
                Limit::Budget => {
                    format!("beyond the budget of {} s", spec.budget_s.unwrap_or(0.0))
                }
            };
            format!(
                "it needs h = {}, k = {} (predicted error {}, about {} s): {what}",
                frac(n.h),
                frac(n.k),
                sig(n.predicted_error),
                sig(n.predicted_seconds)
            )
        }
        None => format!(
            "no resolution of the grid (up to 2^{MAX_DOUBLINGS} times the coarsest) is predicted to reach it (fit: {}·h^{} + {}·k^{})",
            sig(model.h.coefficient),
            model.h.order.map_or("–".into(), |p| format!("{p:.2}")),
            sig(model.k.coefficient),
            model.k.order.map_or("–".into(), |q| format!("{q:.2}")),
        ),
    };
    let best_text = match best {
        Some(b) => format!(
            "; the best reachable is a predicted error of {} at h = {}, k = {} in about {} s",
            sig(b.predicted_error),
            frac(b.h),
            frac(b.k),
            sig(b.predicted_seconds)
        ),
        None => match spec.budget_s {
            Some(b) => format!("; no run of the grid fits the limits and the budget of {b} s"),
            None => "; no run of the grid fits the limits".into(),
        },
    };
    StudyError::Unreachable {
        message: format!(
            "the target error {} in {} cannot be reached within the limits: {reason}{best_text}",
            spec.error,
            spec.quantity.name()
        ),
        best_error: best.map(|b| b.predicted_error),
        best_seconds: best.map(|b| b.predicted_seconds),
    }
}
