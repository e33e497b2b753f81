//! The hard-case table: scenes beyond the paper's (friction bounds from 0 to 1e4, non-convex
//! friction near and beyond the smallness condition (2.31), near-total damage, extreme κ,
//! k from T to T/4096, h from 1/2 to 1/256, a 20:1 beam, loads with jumps and large ramps),
//! each run to completion with every invariant checked after every step
//! ([`crate::solve::invariants`]) — or refused up front with the reason. `contact-sim stress`
//! prints the table; tests/stability.rs runs the quick subset.
//!
//! The cases are data (`stress_cases.json` beside this file): a preset with JSON-pointer
//! edits, what the case must do, and its resolutions. On the 3D box the slip-weakening slopes
//! are small because its discrete trace constant is large (cτ² ≈ 18 at h = 1/4, 21 at h = 1/8:
//! a body clamped at one end bends softly), so (2.31), c2τ cτ² < m_A = 4, admits only
//! c2τ = 0.8 α below about 0.19, and each discrete step stays strongly convex up to
//! c2τ ≈ 0.24–0.27.

use crate::problem::Problem;
use crate::run::{Hooks, Run};
use crate::scene::{self, presets, Overrides};
use crate::solve::invariants;
use crate::solve::stepper::StepReport;
use crate::solve::{SolveError, SolverSettings};
use serde::{Deserialize, Serialize};
use serde_json::{json, Map, Value};
use std::ops::ControlFlow;
use std::time::Instant;

/// What a case must do.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Expect {
    /// Run to t = T with residuals at tolerance and every invariant intact.
    Complete,
    /// Be refused before the first step with a reason containing this text.
    Refused(String),
}

/// How much of Γ3 must slip (checked over all steps of a completed run).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Slip {
    /// No requirement.
    Any,
    /// Every Γ3 DOF sticks at every step.
    FullStick,
    /// Every Γ3 DOF slips at every step.
    FullSlip,
    /// Some Γ3 DOF slips at some step.
    Some,
}

/// One hard scene: an entry of `stress_cases.json`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Case {
    pub name: String,
    /// What makes it hard.
    pub about: String,
    pub expect: Expect,
    pub slip: Slip,
    /// (1/h, T/k) of the full table.
    pub full: (usize, usize),
    /// (1/h, T/k) in the quick subset; `None`: not in it.
    pub quick: Option<(usize, usize)>,
    /// The preset the scene starts from ...
    preset: String,
    /// ... and its edits: JSON pointer → value (a missing key is added to its parent).
    edits: Map<String, Value>,
}

impl Case {
    /// The scene at the resolution of the full table or of the quick subset.
    pub fn scene(&self, quick: bool) -> Option<Value> {
        let (nh, nk) = if quick { self.quick? } else { self.full };
        let mut doc = edit(&self.preset, &self.edits);
        let o = Overrides {
            h: Some(Value::String(format!("1/{nh}"))),
            k: Some(Value::String(format!("{}/{nk}", t_end(&doc)))),
            t_end: None,
        };
        scene::apply_overrides(&mut doc, &o);
        doc["output"] = json!({"every": 0, "last": false, "fields": []});
        Some(doc)
    }
}

fn t_end(doc: &Value) -> f64 {
    doc["time"]["t_end"].as_f64().unwrap_or(1.0)
}

/// A preset with JSON edits (pointer → value) applied.
fn edit(preset: &str, edits: &Map<String, Value>) -> Value {
    let mut doc = presets::get(preset).expect("stress cases use existing presets");
    for (ptr, v) in edits {
        match doc.pointer_mut(ptr) {
            Some(slot) => *slot = v.clone(),
            None => {
                let (parent, key) = ptr.rsplit_once('/').expect("pointer");
                doc.pointer_mut(parent).expect("parent exists")[key] = v.clone();
            }
        }
    }
    doc
}

/// The table.
pub fn cases() -> Vec<Case> {
    serde_json::from_str(include_str!("stress_cases.json")).expect("stress_cases.json parses")
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MaxMean {
    pub max: f64,
    pub mean: f64,
}

impl MaxMean {
    fn of(values: &[f64]) -> Option<MaxMean> {
        (!values.is_empty()).then(|| MaxMean {
            max: values.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            mean: values.iter().sum::<f64>() / values.len() as f64,
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Completed,
    Refused,
    Failed,
}

/// What one case did.
#[derive(Debug, Clone, Serialize)]
pub struct CaseReport {
    pub name: String,
    pub about: String,
    pub h: String,
    pub k: String,
    pub nodes: usize,
    pub steps: usize,
    pub expect: Expect,
    pub outcome: Outcome,
    /// Did the case do what it must (outcome, refusal reason, slip requirement)?
    pub as_expected: bool,
    /// The refusal or failure message, or why the outcome is not as expected.
    pub reason: Option<String>,
    /// c2τ·cτ²/m_A of (2.31) (None for convex friction).
    pub smallness_ratio: Option<f64>,
    /// λ_min(W^-½ S_A W^-½) − c2τ (None for convex friction).
    pub discrete_margin: Option<f64>,
    pub velocity_iterations: Option<MaxMean>,
    pub damage_iterations: Option<MaxMean>,
    pub velocity_residual_max: Option<f64>,
    pub damage_residual_max: Option<f64>,
    /// Fraction of Γ3 DOFs slipping: (min, max) over the steps.
    pub slip_fraction: Option<[f64; 2]>,
    /// Smallest ζ over the run and the fraction of nodes with ζ = 0 at t = T.
    pub zeta_min: Option<f64>,
    pub zeta_zero_fraction: Option<f64>,
    /// Set-up and time loop, seconds.
    pub seconds: f64,
}

/// The whole table.
#[derive(Debug, Clone, Serialize)]
pub struct StressReport {
    pub quick: bool,
    pub tolerance: f64,
    pub all_as_expected: bool,
    pub seconds: f64,
    pub cases: Vec<CaseReport>,
}

/// Runs the table (or its quick subset).
pub fn run(quick: bool) -> StressReport {
    run_with(quick, |_, _, _| {})
}

/// [`run`], calling `starting(i, n, case)` before case `i` of the `n` it runs (progress).
pub fn run_with(quick: bool, mut starting: impl FnMut(usize, usize, &Case)) -> StressReport {
    let start = Instant::now();
    let all = cases();
    let selected: Vec<&Case> = all.iter().filter(|c| c.quick.is_some() || !quick).collect();
    let cases: Vec<CaseReport> = selected
        .iter()
        .enumerate()
        .filter_map(|(i, c)| {
            starting(i, selected.len(), c);
            run_case(c, quick)
        })
        .collect();
    StressReport {
        quick,
        tolerance: SolverSettings::default().tolerance,
        all_as_expected: cases.iter().all(|c| c.as_expected),
        seconds: start.elapsed().as_secs_f64(),
        cases,
    }
}

/// Runs one case at the resolution of the full table or the quick subset (`None` if the case
/// is not in the quick subset).
pub fn run_case(case: &Case, quick: bool) -> Option<CaseReport> {
    run_case_on(case, quick, None)
}

/// [`run_case`] on the linear path given (`"direct"`, `"multigrid"`; None: the scene's).
pub fn run_case_on(case: &Case, quick: bool, linear: Option<&str>) -> Option<CaseReport> {
    let mut doc = case.scene(quick)?;
    if let Some(path) = linear {
        doc["solver"] = json!({"linear": path});
    }
    let mut report = CaseReport {
        name: case.name.clone(),
        about: case.about.clone(),
        h: doc["mesh"]["h"].as_str().unwrap_or("?").to_string(),
        k: doc["time"]["k"].as_str().unwrap_or("?").to_string(),
        nodes: 0,
        steps: 0,
        expect: case.expect.clone(),
        outcome: Outcome::Failed,
        as_expected: false,
        reason: None,
        smallness_ratio: None,
        discrete_margin: None,
        velocity_iterations: None,
        damage_iterations: None,
        velocity_residual_max: None,
        damage_residual_max: None,
        slip_fraction: None,
        zeta_min: None,
        zeta_zero_fraction: None,
        seconds: 0.0,
    };
    let problem = match scene::validate(&doc) {
        Ok(p) => p,
        Err(e) => {
            report.reason = Some(format!("the case's scene is invalid: {e}"));
            return Some(report);
        }
    };
    let start = Instant::now();
    let result = simulate(problem, &mut report);
    report.seconds = start.elapsed().as_secs_f64();
    match result {
        Ok(()) => report.outcome = Outcome::Completed,
        Err(Stop::Refused(why)) => {
            report.outcome = Outcome::Refused;
            report.reason = Some(why);
        }
        Err(Stop::Failed(why)) => report.reason = Some(why),
    }
    let (ok, why) = judge(case, &report);
    report.as_expected = ok;
    if let Some(why) = why {
        report.reason = Some(match report.reason.take() {
            Some(r) => format!("{why}; {r}"),
            None => why,
        });
    }
    Some(report)
}

enum Stop {
    Refused(String),
    Failed(String),
}

fn simulate(problem: Problem, report: &mut CaseReport) -> Result<(), Stop> {
    match problem.dim() {
        2 => simulate_in::<2>(problem, report),
        _ => simulate_in::<3>(problem, report),
    }
}

fn simulate_in<const D: usize>(problem: Problem, report: &mut CaseReport) -> Result<(), Stop> {
    report.nodes = problem.n_nodes();
    report.steps = problem.steps;
    let mut run = match Run::<D>::new(problem, SolverSettings::default()) {
        Ok(run) => run,
        Err(e @ SolveError::Smallness(_)) => return Err(Stop::Refused(e.to_string())),
        Err(e) => return Err(Stop::Failed(format!("set-up failed: {e}"))),
    };
    let sim = run.sim();
    report.nodes = sim.mesh.n_nodes();
    if sim.smallness.c2 > 0.0 {
        report.smallness_ratio = Some(sim.smallness.lhs / sim.smallness.m_a);
        report.discrete_margin = sim.smallness.discrete_margin;
    }
    let mut watch = Watch {
        report,
        contact_nodes: sim.dofs.n_contact() / (D - 1),
        vel_it: Vec::new(),
        dam_it: Vec::new(),
        vel_res: 0.0,
        dam_res: None,
        slip: [f64::INFINITY, 0.0],
        zeta_min: f64::INFINITY,
    };
    match run.drive(&mut watch) {
        Err(e) => return Err(Stop::Failed(e.to_string())),
        Ok(ControlFlow::Break(stop)) => return Err(stop),
        Ok(ControlFlow::Continue(())) => {}
    }
    let zeta = &run.sim().state.zeta;
    let zeros = zeta.iter().filter(|z| **z == 0.0).count();
    watch.report.zeta_zero_fraction = Some(zeros as f64 / zeta.len() as f64);
    Ok(())
}

/// A case's hooks: the invariants of every step ([`invariants::check_step`]) and the
/// figures of its report, kept up to date after every step (a failing case reports the
/// steps it made).
struct Watch<'a> {
    report: &'a mut CaseReport,
    contact_nodes: usize,
    vel_it: Vec<f64>,
    dam_it: Vec<f64>,
    vel_res: f64,
    dam_res: Option<f64>,
    slip: [f64; 2],
    zeta_min: f64,
}

impl<const D: usize> Hooks<D> for Watch<'_> {
    type Stop = Stop;

    fn after_step(&mut self, run: &Run<D>, r: &StepReport) -> ControlFlow<Stop> {
        if let Err(e) = invariants::check_step(run.sim(), r) {
            return ControlFlow::Break(Stop::Failed(format!("invariant violated: {e}")));
        }
        self.vel_it.push(r.velocity.iterations as f64);
        self.vel_res = self.vel_res.max(r.velocity.residual);
        if let Some(d) = r.damage {
            self.dam_it.push(d.iterations as f64);
            self.dam_res = Some(self.dam_res.unwrap_or(0.0).max(d.residual));
        }
        if self.contact_nodes > 0 {
            let f = r.slip_nodes as f64 / self.contact_nodes as f64;
            self.slip = [self.slip[0].min(f), self.slip[1].max(f)];
        }
        self.zeta_min = self.zeta_min.min(r.zeta_min);
        let report = &mut *self.report;
        report.velocity_iterations = MaxMean::of(&self.vel_it);
        report.damage_iterations = MaxMean::of(&self.dam_it);
        report.velocity_residual_max = Some(self.vel_res);
        report.damage_residual_max = self.dam_res;
        report.slip_fraction = (self.contact_nodes > 0).then_some(self.slip);
        report.zeta_min = Some(self.zeta_min);
        ControlFlow::Continue(())
    }
}

/// Is the report what the case requires? With the reason when it is not.
fn judge(case: &Case, r: &CaseReport) -> (bool, Option<String>) {
    match (&case.expect, r.outcome) {
        (Expect::Complete, Outcome::Completed) => {
            let [lo, hi] = r.slip_fraction.unwrap_or([0.0, 0.0]);
            let ok = match case.slip {
                Slip::Any => true,
                Slip::FullStick => hi == 0.0,
                Slip::FullSlip => lo == 1.0,
                Slip::Some => hi > 0.0,
            };
            let why = (!ok).then(|| {
                format!(
                    "expected {:?} on Γ3, slipping fraction was {lo}..{hi}",
                    case.slip
                )
            });
            (ok, why)
        }
        (Expect::Refused(text), Outcome::Refused) => {
            let ok = r
                .reason
                .as_deref()
                .is_some_and(|m| m.contains(text.as_str()));
            (ok, (!ok).then(|| format!("refused, but not for {text:?}")))
        }
        (Expect::Complete, _) => (false, Some("expected to complete".into())),
        (Expect::Refused(text), _) => (false, Some(format!("expected a refusal ({text:?})"))),
    }
}

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or_else(|| "–".to_string(), f)
}

impl StressReport {
    /// A plain-text table (one line per case; refusal and failure reasons below it).
    pub fn text_table(&self) -> String {
        let mut s = format!(
            "{:<24} {:>6} {:>7} {:>6} {:>5} {:<9} {:>9} {:>9} {:>8} {:>8} {:>11} {:>6} {:>5} {:>6} {:>7} {:>8}\n",
            "case",
            "h",
            "k",
            "nodes",
            "steps",
            "outcome",
            "vel it",
            "dmg it",
            "vel res",
            "dmg res",
            "slip %",
            "ζ min",
            "ζ=0 %",
            "(2.31)",
            "margin",
            "s"
        );
        let mut notes = String::new();
        for c in &self.cases {
            let mark = if c.as_expected { "" } else { " !" };
            let outcome = match c.outcome {
                Outcome::Completed => "ok",
                Outcome::Refused => "refused",
                Outcome::Failed => "FAILED",
            };
            s += &format!(
                "{:<24} {:>6} {:>7} {:>6} {:>5} {:<9} {:>9} {:>9} {:>8} {:>8} {:>11} {:>6} {:>5} {:>6} {:>7} {:>8.3}\n",
                format!("{}{mark}", c.name),
                c.h,
                c.k,
                c.nodes,
                c.steps,
                outcome,
                c.velocity_iterations
                    .map_or("–".into(), |m| format!("{}/{:.1}", m.max, m.mean)),
                c.damage_iterations
                    .map_or("–".into(), |m| format!("{}/{:.1}", m.max, m.mean)),
                opt(c.velocity_residual_max, |v| format!("{v:.1e}")),
                opt(c.damage_residual_max, |v| format!("{v:.1e}")),
                c.slip_fraction.map_or("–".into(), |[a, b]| format!(
                    "{:.0}–{:.0}",
                    100.0 * a,
                    100.0 * b
                )),
                opt(c.zeta_min, |v| format!("{v:.3}")),
                opt(c.zeta_zero_fraction, |v| format!("{:.0}", 100.0 * v)),
                opt(c.smallness_ratio, |v| format!("{v:.2}")),
                opt(c.discrete_margin, |v| format!("{v:+.2}")),
                c.seconds,
            );
            if let Some(r) = &c.reason {
                notes += &format!("  {}: {r}\n", c.name);
            }
        }
        s += &format!(
            "{} cases, {} as expected, {:.1} s (tolerance {:.0e}; it = max/mean iterations per step; \
             (2.31) = c2τ·cτ²/m_A, \
             margin = λ_min(W^-½ S_A W^-½) − c2τ)\n",
            self.cases.len(),
            self.cases.iter().filter(|c| c.as_expected).count(),
            self.seconds,
            self.tolerance
        );
        if !notes.is_empty() {
            s += "reasons:\n";
            s += &notes;
        }
        s
    }
}
