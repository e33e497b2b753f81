//! The hard-case table: scenes beyond the paper's (friction bounds from 0 to 1e4, non-convex
//! friction near and beyond the smallness condition (2.31), near-total damage, extreme κ,
//! k from T to T/4096, h from 1/2 to 1/256, a 20:1 beam, loads with jumps and large ramps),
//! each run to completion with every invariant checked after every step
//! ([`crate::solve::invariants`]) — or refused up front with the reason. `contact-sim stress`
//! prints the table; tests/stability.rs runs the quick subset.

use crate::problem::Problem;
use crate::run::{Hooks, Run};
use crate::scene::{self, presets, Overrides};
use crate::solve::invariants;
use crate::solve::stepper::StepReport;
use crate::solve::{SolveError, SolverSettings};
use serde::Serialize;
use serde_json::{json, Value};
use std::ops::ControlFlow;
use std::time::Instant;

/// What a case must do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Expect {
    /// Run to t = T with residuals at tolerance and every invariant intact.
    Complete,
    /// Be refused before the first step with a reason containing this text.
    Refused(&'static str),
}

/// How much of Γ3 must slip (checked over all steps of a completed run).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
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

/// One hard scene.
pub struct Case {
    pub name: &'static str,
    /// What makes it hard.
    pub about: &'static str,
    pub expect: Expect,
    pub slip: Slip,
    /// (1/h, T/k) of the full table.
    pub full: (usize, usize),
    /// (1/h, T/k) in the quick subset; `None`: not in it.
    pub quick: Option<(usize, usize)>,
    /// The scene document (its h and k are replaced).
    build: fn() -> Value,
}

impl Case {
    /// The scene at the resolution of the full table or of the quick subset.
    pub fn scene(&self, quick: bool) -> Option<Value> {
        let (nh, nk) = if quick { self.quick? } else { self.full };
        let mut doc = (self.build)();
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

/// A preset with JSON edits (pointer, value) applied.
fn edit(preset: &str, edits: &[(&str, Value)]) -> Value {
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

fn tresca(g: f64) -> Value {
    json!({"law": "tresca", "g": g})
}

fn slip_weakening(alpha: f64) -> Value {
    json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": alpha})
}

/// Experiment 3 (contact on the whole bottom) with traction f2 on the top and right sides.
fn exp3_with(friction: Value, f2: Value) -> Value {
    edit(
        "paper-exp3",
        &[
            ("/friction", friction),
            ("/boundary/2/f2", f2.clone()),
            ("/boundary/3/f2", f2),
        ],
    )
}

/// Experiment 3 with a stronger damage source b = 2000 (ζ reaches 0 over most of the body).
fn heavy_damage(kappa: f64) -> Value {
    edit(
        "paper-exp3",
        &[
            ("/friction", tresca(1.0)),
            ("/damage/kappa", json!(kappa)),
            ("/damage/source/b", json!(2000)),
        ],
    )
}

/// A 20 × 1 beam clamped at its left end.
fn beam(contact: bool) -> Value {
    let mut doc = edit(
        "paper-exp1",
        &[("/domain", json!({"width": 20, "height": 1}))],
    );
    doc["boundary"] = if contact {
        json!([
            {"type": "clamped", "from": [0, 0], "to": [0, 1]},
            {"type": "contact", "from": [0, 0], "to": [20, 0]},
            {"type": "traction", "from": [0, 1], "to": [20, 1], "f2": [-2, -1]}
        ])
    } else {
        json!([{"type": "clamped", "from": [0, 0], "to": [0, 1]}])
    };
    doc["loads"]["f0"] = if contact {
        json!([0, 0])
    } else {
        json!([0, -0.002])
    };
    doc["friction"] = tresca(1.0);
    doc
}

/// Slip-weakening slopes for the box: its discrete trace constant is large (cτ² ≈ 18 at
/// h = 1/4, 21 at h = 1/8: a body clamped at one end bends softly), so (2.31),
/// c2τ cτ² < m_A = 4, admits only c2τ = 0.8 α below about 0.19, and each discrete step stays
/// strongly convex up to c2τ ≈ 0.24–0.27.
const ALPHA_NEAR_3D: f64 = 0.2;
const SLIPWEAK_NEAR_3D: &str =
    "3D, slip-weakening μ0 = 1.2, μ1 = 0.4, α = 0.2 (c2τ = 0.16): inside (2.31)";
const ALPHA_BEYOND_3D: f64 = 0.5;
const SLIPWEAK_BEYOND_3D: &str =
    "3D, α = 0.5 (c2τ = 0.4): (2.31) and the discrete strong convexity both fail";

/// box-exp3 (the 2 × 1 × 1 box, contact on z = 0) with friction and traction f2 on the top
/// and the far end.
fn box_with(friction: Value, f2: Value) -> Value {
    edit(
        "box-exp3",
        &[
            ("/friction", friction),
            ("/boundary/2/f2", f2.clone()),
            ("/boundary/3/f2", f2),
        ],
    )
}

/// A 10 × 1 × 1 beam of tetrahedra on a frictional (g = 1) base, clamped at x = 0, pushed on
/// its top.
fn box_beam() -> Value {
    let mut doc = edit(
        "box-exp3",
        &[("/domain", json!({"width": 10, "height": 1, "depth": 1}))],
    );
    doc["boundary"] = json!([
        {"type": "clamped", "on": "x"},
        {"type": "contact", "on": "z"},
        {"type": "traction", "on": "z - 1", "f2": [-2, 0, -1]}
    ]);
    doc["friction"] = tresca(1.0);
    doc
}

/// The table.
pub fn cases() -> Vec<Case> {
    use Expect::*;
    vec![
        // --- friction bound g from 0 to 1e4 -----------------------------------------------
        Case {
            name: "tresca-g0",
            about: "g = 0: frictionless, every Γ3 node slides",
            expect: Complete,
            slip: Slip::FullSlip,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(0.0), json!([-1, -1])),
        },
        Case {
            name: "tresca-g1",
            about: "g = 1: partial slip",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(1.0), json!([-1, -1])),
        },
        Case {
            name: "tresca-g20",
            about: "the paper's g = 20: full stick",
            expect: Complete,
            slip: Slip::FullStick,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(20.0), json!([-1, -1])),
        },
        Case {
            name: "tresca-g1e4",
            about: "g = 1e4, paper load: full stick",
            expect: Complete,
            slip: Slip::FullStick,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(1e4), json!([-1, -1])),
        },
        Case {
            name: "tresca-g1e4-load1e5",
            about: "g = 1e4 with f2 = 1e5·(−1, −1): slip against a large bound",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(1e4), json!([-1e5, -1e5])),
        },
        // --- non-convex friction near and beyond (2.31) ---------------------------------------
        Case {
            name: "slipweak-near",
            about: "slip-weakening μ0 = 1.2, μ1 = 0.4, α = 2 (c2τ = 1.6): just inside (2.31)",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 16)),
            build: || exp3_with(slip_weakening(2.0), json!([-1, -1])),
        },
        Case {
            name: "slipweak-beyond",
            about: "α = 3 (c2τ = 2.4): (2.31) and the discrete strong convexity both fail",
            expect: Refused("not strongly convex"),
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 16)),
            build: || exp3_with(slip_weakening(3.0), json!([-1, -1])),
        },
        Case {
            name: "slipweak-2.31-only",
            about:
                "α = 2.3 (c2τ = 1.84): (2.31) fails, each discrete step is still strongly convex",
            expect: Refused("still strongly convex"),
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 16)),
            build: || exp3_with(slip_weakening(2.3), json!([-1, -1])),
        },
        Case {
            name: "slipweak-2.31-only-warn",
            about: "α = 2.3 with \"smallness\": \"warn\": the unique discrete solution",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 16)),
            build: || {
                let mut d = exp3_with(slip_weakening(2.3), json!([-1, -1]));
                d["smallness"] = json!("warn");
                d
            },
        },
        Case {
            name: "slipweak-beyond-warn",
            about:
                "α = 3 with \"smallness\": \"warn\": runs, non-unique stationary points possible",
            expect: Complete,
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 16)),
            build: || {
                let mut d = exp3_with(slip_weakening(3.0), json!([-1, -1]));
                d["smallness"] = json!("warn");
                d
            },
        },
        Case {
            name: "pwlinear-near",
            about: "piecewise-linear μ, slope −1.6 then +0.1 (c2τ = 1.6): just inside (2.31)",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 16)),
            build: || {
                exp3_with(
                    json!({"law": "piecewise_linear", "points": [[0, 1.2], [0.5, 0.4], [1, 0.45]]}),
                    json!([-1, -1]),
                )
            },
        },
        Case {
            name: "pwlinear-beyond",
            about: "piecewise-linear μ, slope −3 (c2τ = 3): beyond (2.31)",
            expect: Refused("2.31"),
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 16)),
            build: || {
                exp3_with(
                    json!({"law": "piecewise_linear", "points": [[0, 1.2], [0.2, 0.6], [1, 0.6]]}),
                    json!([-1, -1]),
                )
            },
        },
        // --- damage ------------------------------------------------------------------------
        Case {
            name: "damage-total",
            about: "φ with b = 2000: ζ → 0 over most of the body, κ = 0.5",
            expect: Complete,
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || heavy_damage(0.5),
        },
        Case {
            name: "damage-kappa-1e-4",
            about: "b = 2000, κ = 1e-4",
            expect: Complete,
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || heavy_damage(1e-4),
        },
        Case {
            name: "damage-kappa-1e2",
            about: "b = 2000, κ = 1e2",
            expect: Complete,
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || heavy_damage(1e2),
        },
        Case {
            name: "damage-below-zeta-star",
            about: "ζ0 from 0.05 to 1: the φ branch at ζ* = 0.2 from the start",
            expect: Complete,
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || {
                edit(
                    "paper-exp3",
                    &[("/damage/zeta0", json!("min(1, 0.05 + abs(x - 1))"))],
                )
            },
        },
        // --- time step and mesh size -----------------------------------------------------
        Case {
            name: "k-T",
            about: "one time step, k = T",
            expect: Complete,
            slip: Slip::Any,
            full: (32, 1),
            quick: Some((8, 1)),
            build: || exp3_with(tresca(1.0), json!([-1, -1])),
        },
        Case {
            name: "k-T/4096",
            about: "k = T/4096 (h = 1/16)",
            expect: Complete,
            slip: Slip::Some,
            full: (16, 4096),
            quick: Some((4, 1024)),
            build: || exp3_with(tresca(1.0), json!([-1, -1])),
        },
        Case {
            name: "h-1/2",
            about: "h = 1/2: 4 × 2 cells",
            expect: Complete,
            slip: Slip::Some,
            full: (2, 32),
            quick: Some((2, 8)),
            build: || exp3_with(tresca(1.0), json!([-1, -1])),
        },
        Case {
            name: "h-1/256",
            about: "h = 1/256 on the unit square (66,049 nodes), g = 1",
            expect: Complete,
            slip: Slip::Some,
            full: (256, 32),
            quick: None,
            build: || edit("paper-convergence", &[("/friction", tresca(1.0))]),
        },
        // --- geometry --------------------------------------------------------------------
        Case {
            name: "beam-20:1",
            about: "20 × 1 cantilever, clamped left end, own weight",
            expect: Complete,
            slip: Slip::Any,
            full: (8, 32),
            quick: Some((2, 8)),
            build: || beam(false),
        },
        Case {
            name: "beam-20:1-contact",
            about: "20 × 1 beam on a frictional (g = 1) base, pushed on its top",
            expect: Complete,
            slip: Slip::Some,
            full: (8, 32),
            quick: Some((2, 8)),
            build: || beam(true),
        },
        // --- loads ---------------------------------------------------------------------------
        Case {
            name: "load-jump-t",
            about: "f2 steps from (−1, 0) to (−1, −2) at t = 1/2",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(1.0), json!([-1, "-2*max(sign(t - 0.5), 0)"])),
        },
        Case {
            name: "load-jump-x",
            about: "experiment 2 with f0 = (0, −0.8) on x > 1 only (a jump across the body)",
            expect: Complete,
            slip: Slip::Any,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || {
                edit(
                    "paper-exp2",
                    &[
                        ("/friction", tresca(0.1)),
                        ("/loads/f0", json!([0, "-0.8*max(sign(x - 1), 0)"])),
                    ],
                )
            },
        },
        Case {
            name: "ramp-100",
            about: "f2 = −100·t·(1, 1), g = 20: stick, then slip",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(20.0), json!(["-100*t", "-100*t"])),
        },
        Case {
            name: "ramp-1e4",
            about: "f2 = −1e4·t·(1, 1), g = 20",
            expect: Complete,
            slip: Slip::Some,
            full: (32, 32),
            quick: Some((8, 8)),
            build: || exp3_with(tresca(20.0), json!(["-1e4*t", "-1e4*t"])),
        },
        // --- three dimensions: box-exp3, Γ3 the bottom z = 0 ------------------------------------
        Case {
            name: "box-g0",
            about: "3D, g = 0: frictionless, every Γ3 node slides (2-vector tangents)",
            expect: Complete,
            slip: Slip::FullSlip,
            full: (8, 8),
            quick: Some((4, 8)),
            build: || box_with(tresca(0.0), json!([-1, 0, -1])),
        },
        Case {
            name: "box-g2",
            about: "3D, g = 2: partial slip",
            expect: Complete,
            slip: Slip::Some,
            full: (8, 8),
            quick: Some((4, 8)),
            build: || box_with(tresca(2.0), json!([-1, 0, -1])),
        },
        Case {
            name: "box-g1e4",
            about: "3D, g = 1e4: full stick",
            expect: Complete,
            slip: Slip::FullStick,
            full: (8, 8),
            quick: Some((4, 8)),
            build: || box_with(tresca(1e4), json!([-1, 0, -1])),
        },
        Case {
            name: "box-slipweak-near",
            about: SLIPWEAK_NEAR_3D,
            expect: Complete,
            slip: Slip::Some,
            full: (8, 8),
            quick: Some((4, 8)),
            build: || box_with(slip_weakening(ALPHA_NEAR_3D), json!([-1, 0, -1])),
        },
        Case {
            name: "box-slipweak-beyond",
            about: SLIPWEAK_BEYOND_3D,
            expect: Refused("not strongly convex"),
            slip: Slip::Any,
            full: (8, 8),
            quick: Some((4, 8)),
            build: || box_with(slip_weakening(ALPHA_BEYOND_3D), json!([-1, 0, -1])),
        },
        Case {
            name: "box-damage-total",
            about: "3D, φ with b = 2000: ζ → 0 over most of the body",
            expect: Complete,
            slip: Slip::Any,
            full: (8, 8),
            quick: Some((4, 8)),
            build: || {
                let mut d = box_with(tresca(2.0), json!([-1, 0, -1]));
                d["damage"]["source"]["b"] = json!(2000);
                d
            },
        },
        Case {
            name: "box-beam-10:1-contact",
            about: "3D, a 10 × 1 × 1 beam on a frictional (g = 1) base, pushed on its top",
            expect: Complete,
            slip: Slip::Some,
            full: (4, 16),
            quick: Some((2, 8)),
            build: box_beam,
        },
        Case {
            name: "box-ramp-1e4",
            about: "3D, f2 = −1e4·t·(1, 0, 1), g = 20: stick, then slip",
            expect: Complete,
            slip: Slip::Some,
            full: (8, 8),
            quick: Some((4, 8)),
            build: || box_with(tresca(20.0), json!(["-1e4*t", 0, "-1e4*t"])),
        },
    ]
}

/// Maximum and mean over the steps.
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
    pub name: &'static str,
    pub about: &'static str,
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
        name: case.name,
        about: case.about,
        h: doc["mesh"]["h"].as_str().unwrap_or("?").to_string(),
        k: doc["time"]["k"].as_str().unwrap_or("?").to_string(),
        nodes: 0,
        steps: 0,
        expect: case.expect,
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
    match (case.expect, r.outcome) {
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
            let ok = r.reason.as_deref().is_some_and(|m| m.contains(text));
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
