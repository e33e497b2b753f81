//! A study with a target instead of a ladder: "the cheapest run whose relative error in w, u
//! or ζ at t = T is below e" (docs/src/explanation/numerics.md#target-studies).
//!
//! ```json
//! {"name": "...", "scene": {...} | "paper-convergence",
//!  "target": {"error": 0.05, "quantity": "w"}, "budget_s": 60}
//! ```
//!
//! 1. Pilot levels: an h-ladder n0, 2n0, 4n0 at 4N0 steps and a k-ladder N0, 2N0, 4N0 at
//!    4n0, N0 = [`PILOT_STEPS`] (on a given mesh n = 2^refine, n0 = 1: the mesh as given), n0
//!    the coarsest resolution of 2, 4, 8, 16 cells per unit length that fits the domain.
//! 2. [`plan`]: the error model from the ladders' differences, the cost model from their times,
//!    the cheapest (h, k) of the nested grid whose predicted error is below target/SAFETY
//!    within the limits. It only decides whether the target is within reach: pilots are
//!    pre-asymptotic and the model's choice can be a whole level too fine. While it finds
//!    none, the ladders are extended towards the most accurate run within the limits (up to
//!    [`MAX_PILOT_LEVELS`]), and the plan is made again.
//! 3. Out of reach (limits, budget): [`StudyError::Unreachable`], before the expensive run.
//! 4. The walk: from the cheapest candidate (2n0, 2N0) up, each level (its stored steps go to
//!    a [`Sink`]) beside its (2h, 2k) companion; the error bar |f − I f_2h| / |f| (the
//!    service's error estimate, model order 1) checks it, and the first level that passes is
//!    the result. Otherwise h or k is halved, whichever the model predicts to buy more error
//!    per doubling of the work; each such step adds a point to the model, which is fitted
//!    again. Each step at least doubles the work, so the walk costs at most about twice its
//!    last level.

use super::levels::{self, LevelRun, Snapshot, StatsAccumulator, Work};
use super::plan::{self, Candidate, CostModel, ErrorModel, Timing};
use super::reference::{double_dot, strains, sym_len};
use super::{run_all, with, Done, Execution, StudyError};
use crate::fem::prolongation::{parent_cells, prolongate};
use crate::fem::{assembly, norms, Geometry};
use crate::output::Summary;
use crate::problem::{MeshPattern, Problem};
use crate::run::RunError;
use crate::scene::{self, FieldError, ValidationErrors};
use crate::solve::stepper::{Simulation, StepFields};
use serde::Serialize;
use serde_json::{json, Map, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Time steps of the pilot levels' coarsest k (N0). N = 2 is avoided: with the paper's data
/// k = 1/2 makes w(T) vanish exactly (kμ/η = 1), a degenerate level for any ladder.
pub const PILOT_STEPS: usize = 4;
/// Levels of each pilot ladder at first.
pub const FIRST_PILOT_LEVELS: usize = 3;
/// Levels of a pilot ladder at most.
pub const MAX_PILOT_LEVELS: usize = 6;
/// While the target is out of reach by the fit, a pilot ladder is extended while its next
/// level is predicted to cost at most this share of the most accurate run within the limits
/// (and at most 4 × the pilots so far): a refinement of the fit that may bring the target
/// within reach, at a small share of the run it would lead to.
pub const PILOT_SHARE: f64 = 1.0 / 6.0;
/// The grid of candidates: n0·2^i and N0·2^j, i ≤ this, j ≤ 2 × this.
const MAX_DOUBLINGS: u32 = 12;
/// Coarsest resolutions tried for a rectangle or box (cells per unit length).
const COARSEST: [usize; 4] = [2, 4, 8, 16];
const FIELDS: &[&str] = &["name", "scene", "target", "budget_s"];

/// A study document is a target study when it has a `target`.
pub fn is_target(doc: &Value) -> bool {
    doc.get("target").is_some()
}

/// The quantity whose relative error at t = T is targeted, in the study's norms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Quantity {
    /// Velocity, |·|_V.
    W,
    /// Displacement, |·|_V.
    U,
    /// Damage, |·|_Z0.
    Zeta,
}

impl Quantity {
    pub fn name(self) -> &'static str {
        match self {
            Quantity::W => "w",
            Quantity::U => "u",
            Quantity::Zeta => "zeta",
        }
    }
}

/// A validated target study.
#[derive(Debug, Clone)]
pub struct TargetSpec {
    pub name: String,
    /// The scene document (preset names expanded).
    pub scene: Value,
    /// The scene at the coarsest pilot level (n0, N0).
    pub base: Problem,
    pub n0: usize,
    pub quantity: Quantity,
    pub error: f64,
    pub budget_s: Option<f64>,
}

impl TargetSpec {
    /// Whether the scene is a given mesh (resolutions are refinements of it).
    pub fn given_mesh(&self) -> bool {
        self.base.body.is_some()
    }

    /// Nodes of the finest first pilot level (n0·2^(FIRST_PILOT_LEVELS − 1), at N0 steps):
    /// below it a node limit leaves nothing to plan with.
    pub fn pilot_nodes(&self) -> usize {
        with(
            &self.base,
            (self.n0 << (FIRST_PILOT_LEVELS - 1), PILOT_STEPS),
        )
        .n_nodes()
    }

    /// The scene document of the run at resolution n (1/h, or 2^refine) and N steps.
    pub fn scene_at(&self, n: usize, steps: usize) -> Value {
        let mut d = self.scene.clone();
        if let Some(o) = d.as_object_mut() {
            o.remove("error_estimate");
            let mesh = o.entry("mesh").or_insert_with(|| json!({}));
            if let Some(m) = mesh.as_object_mut() {
                if self.given_mesh() {
                    m.insert("refine".into(), json!(n.trailing_zeros()));
                } else {
                    m.insert("h".into(), json!(format!("1/{n}")));
                }
            }
            let time = o.entry("time").or_insert_with(|| json!({}));
            if let Some(t) = time.as_object_mut() {
                for k in ["k", "N", "steps"] {
                    t.remove(k);
                }
                t.insert("N".into(), json!(steps));
            }
        }
        d
    }
}

/// Reads a target study (`doc` at JSON pointer `at`); the expanded document is what a job
/// stores.
pub fn parse(doc: &Value, at: &str) -> Result<(TargetSpec, Value), ValidationErrors> {
    parse_with(doc, at, &scene::Bundled)
}

/// [`parse`], with the meshes a scene names looked up in `files`.
pub fn parse_with(
    doc: &Value,
    at: &str,
    files: &dyn scene::MeshFiles,
) -> Result<(TargetSpec, Value), ValidationErrors> {
    let err = |p: &str, m: String| super::spec::field_error(at, p, m);
    let Some(obj) = doc.as_object() else {
        return Err(err("", "a study must be an object".into()));
    };
    for k in obj.keys() {
        if !FIELDS.contains(&k.as_str()) {
            let why = if ["h", "k", "refine", "reference", "preset"].contains(&k.as_str()) {
                format!("a study with a target chooses h and k itself: remove {k:?}")
            } else {
                format!(
                    "unknown field {k:?} in a target study (allowed: {})",
                    FIELDS.join(", ")
                )
            };
            return Err(err(&format!("/{k}"), why));
        }
    }
    let name = super::spec::study_name(obj, at)?;
    let Some(target) = obj.get("target").and_then(Value::as_object) else {
        return Err(err(
            "/target",
            "target must be an object {\"error\": 0.05, \"quantity\": \"w\"}".into(),
        ));
    };
    for k in target.keys() {
        if k != "error" && k != "quantity" {
            return Err(err(
                &format!("/target/{k}"),
                format!("unknown field {k:?} (allowed: error, quantity)"),
            ));
        }
    }
    let error = match target.get("error").and_then(Value::as_f64) {
        Some(e) if e > 0.0 && e < 1.0 => e,
        _ => {
            return Err(err(
                "/target/error",
                "error must be a relative error between 0 and 1 (exclusive), e.g. 0.05".into(),
            ))
        }
    };
    let quantity = match target.get("quantity") {
        None => Quantity::W,
        Some(v) => match v.as_str() {
            Some("w") => Quantity::W,
            Some("u") => Quantity::U,
            Some("zeta") => Quantity::Zeta,
            _ => {
                return Err(err(
                    "/target/quantity",
                    format!("quantity must be \"w\", \"u\" or \"zeta\", got {v}"),
                ))
            }
        },
    };
    let budget_s = match obj.get("budget_s") {
        None => None,
        Some(v) => match v.as_f64() {
            Some(b) if b > 0.0 && b.is_finite() => Some(b),
            _ => {
                return Err(err(
                    "/budget_s",
                    "budget_s must be a positive number of seconds".into(),
                ))
            }
        },
    };
    let scene_doc = super::spec::scene_document(obj, at)?;
    let at_scene = format!("{at}/scene");
    let relocate = |ValidationErrors(es): ValidationErrors| {
        ValidationErrors(
            es.into_iter()
                .map(|e| FieldError {
                    pointer: format!("{at_scene}{}", e.pointer),
                    message: e.message,
                })
                .collect(),
        )
    };
    // The scene as given: its own errors, and whether it is a given mesh.
    let mut as_given = scene_doc.clone();
    if let Some(o) = as_given.as_object_mut() {
        o.remove("error_estimate");
    }
    let given = scene::validate_with(&as_given, files).map_err(relocate)?;
    if given.pattern == MeshPattern::Cross {
        return Err(err(
            "/scene/mesh/pattern",
            "the cross pattern's meshes are not nested (its cell-centre nodes are not nodes of the finer mesh); use diagonal or anti_diagonal".into(),
        ));
    }
    if quantity == Quantity::Zeta && given.damage.is_none() {
        return Err(err(
            "/target/quantity",
            "the scene has no damage: target w or u".into(),
        ));
    }
    let mut spec = TargetSpec {
        name: name
            .clone()
            .unwrap_or_else(|| format!("target study of {}", given.name)),
        scene: scene_doc.clone(),
        base: given.clone(),
        n0: 1,
        quantity,
        error,
        budget_s,
    };
    if given.body.is_some() {
        spec.base = with(&given, (1, PILOT_STEPS));
    } else {
        let mut first_error = None;
        let mut found = None;
        for n in COARSEST {
            match scene::validate_with(&spec.scene_at(n, PILOT_STEPS), files) {
                Ok(p) => {
                    found = Some((n, p));
                    break;
                }
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
        match found {
            Some((n, p)) => {
                spec.n0 = n;
                spec.base = p;
            }
            None => {
                let why = first_error.map(|e| e.to_string()).unwrap_or_default();
                return Err(err(
                    "/scene/mesh/h",
                    format!(
                        "no coarse mesh of 1/h in {COARSEST:?} cells per unit length fits the domain, so no pilot levels can be made: {why}"
                    ),
                ));
            }
        }
    }
    let mut expanded = Map::new();
    if let Some(n) = &name {
        expanded.insert("name".into(), json!(n));
    }
    expanded.insert("scene".into(), scene_doc);
    expanded.insert(
        "target".into(),
        json!({"error": error, "quantity": quantity.name()}),
    );
    if let Some(b) = budget_s {
        expanded.insert("budget_s".into(), json!(b));
    }
    Ok((spec, Value::Object(expanded)))
}

/// Limits of the host besides the per-job memory limit (`exec.settings.memory_limit`).
#[derive(Debug, Clone, Copy, Default)]
pub struct Limits {
    pub max_nodes: Option<usize>,
    pub max_steps: Option<usize>,
}

/// Where the chosen run's stored steps go (the scene's `output` selects them).
pub trait Sink {
    /// Forget the steps written so far (a finer run replaces the chosen one).
    fn restart(&mut self) -> std::io::Result<()>;
    fn step(&mut self, fields: &StepFields) -> std::io::Result<()>;
}

/// A sink that keeps nothing.
pub struct Discard;

impl Sink for Discard {
    fn restart(&mut self) -> std::io::Result<()> {
        Ok(())
    }
    fn step(&mut self, _: &StepFields) -> std::io::Result<()> {
        Ok(())
    }
}

/// A pilot run as reported.
#[derive(Debug, Clone, Serialize)]
pub struct PilotRow {
    /// "h" or "k": the ladder it belongs to (the run where they cross is "h").
    pub ladder: &'static str,
    pub h: f64,
    pub k: f64,
    /// d × nodes (the cost model's N).
    pub unknowns: usize,
    pub steps: usize,
    pub seconds: f64,
}

/// The (2h, 2k) companion of a chosen run.
#[derive(Debug, Clone, Serialize)]
pub struct Companion {
    pub h: f64,
    pub k: f64,
    pub seconds: f64,
    /// It was a pilot run or the previous attempt (not run again).
    pub reused: bool,
}

/// One run at a chosen (h, k).
#[derive(Debug, Clone, Serialize)]
pub struct Attempt {
    pub h: f64,
    pub k: f64,
    /// Refinements of the given mesh (given meshes only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refine: Option<usize>,
    pub steps: usize,
    /// d × nodes.
    pub unknowns: usize,
    pub predicted_error: f64,
    /// The (2h, 2k) error bar: |f − I f_2h| / |f| at t = T.
    pub estimated_error: f64,
    /// estimated_error ≤ the target.
    pub check_passed: bool,
    pub predicted_seconds: f64,
    /// Wall time of the run, set-up included.
    pub seconds: f64,
    pub companion: Companion,
}

#[derive(Debug, Clone, Serialize)]
pub struct TargetResult {
    pub kind: &'static str,
    pub name: String,
    pub quantity: Quantity,
    pub target_error: f64,
    pub safety_factor: f64,
    pub budget_s: Option<f64>,
    /// The last attempt: the run whose fields are served.
    pub chosen: Attempt,
    /// Every run at a chosen (h, k), in order (two when the first failed its check).
    pub attempts: Vec<Attempt>,
    pub error_model: ErrorModel,
    pub cost_model: CostModel,
    pub pilots: Vec<PilotRow>,
    /// Predicted work–precision frontier of the grid within the limits: the candidates no
    /// other beats in both predicted time and error, cheapest first.
    pub frontier: Vec<Candidate>,
    /// The chosen run's scene document.
    pub scene: Value,
    /// The chosen run's simulation summary.
    pub run: Summary,
    /// Wall time of the whole study (pilots, plan, chosen runs and companions).
    pub seconds: f64,
    pub threads: usize,
}

/// Runs a target study. `progress(done, total)` after every time step of every run (the
/// total grows as the plan unfolds); `Break` cancels.
pub fn run(
    spec: &TargetSpec,
    exec: Execution,
    limits: Limits,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    sink: &mut dyn Sink,
) -> Result<TargetResult, StudyError> {
    let planner = Planner {
        spec,
        exec,
        limits,
        started: Instant::now(),
    };
    match spec.base.dim() {
        2 => run_in::<2>(&planner, progress, sink),
        _ => run_in::<3>(&planner, progress, sink),
    }
}

/// Why a candidate is out of reach.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Limit {
    Nodes,
    Steps,
    Memory,
    Budget,
}

struct Planner<'a> {
    spec: &'a TargetSpec,
    exec: Execution,
    limits: Limits,
    started: Instant,
}

impl Planner<'_> {
    fn problem(&self, (n, steps): (usize, usize)) -> Problem {
        with(&self.spec.base, (n, steps))
    }

    fn h(&self, n: usize) -> f64 {
        1.0 / n as f64
    }

    fn k(&self, steps: usize) -> f64 {
        self.spec.base.t_end / steps as f64
    }

    fn unknowns(&self, level: (usize, usize)) -> f64 {
        let p = self.problem(level);
        (p.dim() * p.n_nodes()) as f64
    }

    /// The first limit the level breaks, budget aside.
    fn breaks(&self, level: (usize, usize)) -> Option<Limit> {
        let p = self.problem(level);
        if self.limits.max_nodes.is_some_and(|m| p.n_nodes() > m) {
            return Some(Limit::Nodes);
        }
        if self.limits.max_steps.is_some_and(|m| level.1 > m) {
            return Some(Limit::Steps);
        }
        if crate::memory::choose(&p, self.exec.settings.memory_limit).is_err() {
            return Some(Limit::Memory);
        }
        None
    }

    /// Every candidate of the grid (n0·2^i, N0·2^j; i, j ≥ 1 so that the (2h, 2k) companion
    /// exists) with its predictions and the limit it breaks, if any. `spent` is the time
    /// already used; the companion's time counts unless it was run already.
    fn candidates(
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
                if j == 1 && matches!(limit, Some(Limit::Nodes | Limit::Memory)) {
                    size_broken = true;
                    break;
                }
                if limit == Some(Limit::Steps) {
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

/// |I f_c − f_f| / |f_f| at t = T between two runs of nested meshes (f_f on the finer or the
/// same mesh): w and u in |·|_V (the coarse strain taken on each fine cell's parent, exact),
/// ζ in |·|_Z0 (nodal interpolation, exact for P1). 0 when both vanish.
pub fn relative_difference<const D: usize>(
    coarse: &LevelRun<D>,
    fine: &LevelRun<D>,
    quantity: Quantity,
) -> f64 {
    let (diff, norm) = difference(coarse, fine, quantity);
    if diff == 0.0 {
        0.0
    } else if norm > 0.0 {
        diff / norm
    } else {
        f64::INFINITY
    }
}

/// |I f_c − f_f| and |f_f| at t = T (see [`relative_difference`]).
pub fn difference<const D: usize>(
    coarse: &LevelRun<D>,
    fine: &LevelRun<D>,
    quantity: Quantity,
) -> (f64, f64) {
    let (Some(c), Some(f)) = (coarse.snapshots.last(), fine.snapshots.last()) else {
        return (f64::NAN, f64::NAN);
    };
    let geo = Geometry::new(&fine.mesh);
    let (diff, norm) = match quantity {
        Quantity::W | Quantity::U => {
            let pick = |s: &Snapshot| -> Vec<f64> {
                if quantity == Quantity::W {
                    s.w.clone()
                } else {
                    s.u.clone()
                }
            };
            let parents = parent_cells(&coarse.mesh, &fine.mesh).expect("nested meshes");
            let coarse_geo = Geometry::new(&coarse.mesh);
            let sc = strains(&coarse.mesh, &coarse_geo, &pick(c));
            let sf = strains(&fine.mesh, &geo, &pick(f));
            let s = sym_len(D);
            let mut d = [0.0; 6];
            let (mut diff2, mut norm2) = (0.0, 0.0);
            for ((ef, &p), a) in sf.chunks_exact(s).zip(&parents).zip(&geo.measure) {
                let ec = &sc[s * p as usize..][..s];
                for ((d, x), y) in d.iter_mut().zip(ef).zip(ec) {
                    *d = x - y;
                }
                diff2 += a * double_dot::<D>(&d[..s]);
                norm2 += a * double_dot::<D>(ef);
            }
            (diff2.sqrt(), norm2.sqrt())
        }
        Quantity::Zeta => {
            let mass = assembly::mass(&fine.mesh, &geo);
            let mut scratch = vec![0.0; fine.mesh.n_nodes()];
            let z = prolongate(&coarse.mesh, &c.zeta, 1, &fine.mesh).expect("nested meshes");
            let dz: Vec<f64> = f.zeta.iter().zip(&z).map(|(a, b)| a - b).collect();
            (
                norms::mass_norm(&mass, &dz, &mut scratch),
                norms::mass_norm(&mass, &f.zeta, &mut scratch),
            )
        }
    };
    (diff, norm)
}

/// |f(T)| of a run in the quantity's norm.
fn norm_at_end<const D: usize>(run: &LevelRun<D>, quantity: Quantity) -> f64 {
    difference(run, run, quantity).1
}

/// The chosen run: its stored steps to `sink`, its summary, and its fields at T.
fn run_chosen<const D: usize>(
    problem: &Problem,
    exec: Execution,
    keep_u: bool,
    sink: &mut dyn Sink,
    tick: &(dyn Fn() -> ControlFlow<()> + Sync),
) -> Result<(LevelRun<D>, Summary), StudyError> {
    let start = Instant::now();
    let mut sim = Simulation::<D>::new(problem.clone(), exec.settings).map_err(RunError::from)?;
    let solve_start = Instant::now();
    let mut acc = StatsAccumulator::new(exec.settings);
    let mut reports = Vec::with_capacity(problem.steps);
    while !sim.finished() {
        let r = sim.step().map_err(RunError::from)?;
        acc.add(&r);
        if problem.output.stores(r.n, problem.steps) {
            sink.step(&sim.fields()).map_err(StudyError::Output)?;
        }
        reports.push(r);
        if tick().is_break() {
            return Err(StudyError::Cancelled);
        }
    }
    let summary = Summary::new(&sim, reports, solve_start.elapsed().as_secs_f64());
    let snapshot = Snapshot {
        step: problem.steps,
        w: sim.w.clone(),
        zeta: sim.state.zeta.clone(),
        u: if keep_u {
            sim.state.u.clone()
        } else {
            Vec::new()
        },
    };
    let run = LevelRun {
        unknowns: sim.dofs.n_free(),
        steps: problem.steps,
        seconds: start.elapsed().as_secs_f64(),
        stats: acc.finish(),
        snapshots: vec![snapshot],
        mesh: sim.mesh,
    };
    Ok((run, summary))
}

/// [`run`] in dimension D.
fn run_in<const D: usize>(
    planner: &Planner,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    sink: &mut dyn Sink,
) -> Result<TargetResult, StudyError> {
    let (spec, exec) = (planner.spec, planner.exec);
    let keep_u = spec.quantity == Quantity::U;
    let (n0, s0) = (spec.n0, PILOT_STEPS);
    // The ladders cross at their third levels: each is run where the other parameter is
    // already resolved a little (at the coarsest one, the other part's interaction
    // distorts it: on the paper's test, k barely matters on a 2 × 2 mesh).
    let (n_k, s_h) = (
        n0 << (FIRST_PILOT_LEVELS - 1),
        s0 << (FIRST_PILOT_LEVELS - 1),
    );
    let done_steps = AtomicUsize::new(0);
    let total_steps = AtomicUsize::new(0);
    let tick = || {
        let d = done_steps.fetch_add(1, Ordering::Relaxed) + 1;
        progress(d, total_steps.load(Ordering::Relaxed).max(d))
    };
    let mut runs: BTreeMap<(usize, usize), LevelRun<D>> = BTreeMap::new();
    let mut h_ladder: Vec<usize> = (0..FIRST_PILOT_LEVELS).map(|i| n0 << i).collect();
    let mut k_ladder: Vec<usize> = (0..FIRST_PILOT_LEVELS).map(|i| s0 << i).collect();
    let (mut model, cost, choice, candidates, scale) = loop {
        let wanted: BTreeSet<(usize, usize)> = h_ladder
            .iter()
            .map(|&n| (n, s_h))
            .chain(k_ladder.iter().map(|&s| (n_k, s)))
            .filter(|l| !runs.contains_key(l))
            .collect();
        if !wanted.is_empty() {
            let jobs: Vec<Work> = wanted
                .iter()
                .map(|&(n, steps)| Work {
                    problem: planner.problem((n, steps)),
                    keep: BTreeSet::from([steps]),
                    is_reference: false,
                    // The k-ladder's runs share the mesh and its factored operator.
                    share: (wanted.iter().filter(|l| l.0 == n).count() > 1)
                        .then(|| ("target".to_string(), n)),
                    keep_u,
                })
                .collect();
            total_steps.fetch_add(wanted.iter().map(|l| l.1).sum(), Ordering::Relaxed);
            let tick2 = |_: usize, _: usize| tick();
            let done = run_all::<D>(jobs, exec, 0, &tick2)?;
            for (level, d) in wanted.iter().zip(done) {
                if let Done::Level(r) = d {
                    runs.insert(*level, r);
                }
            }
        }
        // One scale for every difference: the largest norm among the pilots (coarse runs
        // underestimate it: stiffer meshes, damped coarse steps), the nearest to the
        // solution's that the pilots know.
        let scale = runs
            .values()
            .map(|r| norm_at_end(r, spec.quantity))
            .fold(0.0, f64::max);
        let diffs = |levels: Vec<(usize, usize)>, x: &dyn Fn((usize, usize)) -> f64| {
            levels
                .windows(2)
                .map(|w| {
                    let (d, _) = difference(&runs[&w[0]], &runs[&w[1]], spec.quantity);
                    (x(w[0]), if d == 0.0 { 0.0 } else { d / scale })
                })
                .collect::<Vec<_>>()
        };
        let model = ErrorModel {
            h: plan::fit_part(&diffs(h_ladder.iter().map(|&n| (n, s_h)).collect(), &|l| {
                planner.h(l.0)
            })),
            k: plan::fit_part(&diffs(k_ladder.iter().map(|&s| (n_k, s)).collect(), &|l| {
                planner.k(l.1)
            })),
        };
        let timings: Vec<Timing> = runs
            .iter()
            .map(|(&l, r)| Timing {
                unknowns: planner.unknowns(l),
                steps: l.1,
                seconds: r.seconds,
            })
            .collect();
        let cost = plan::fit_cost(&timings);
        let candidates = planner.candidates(&model, &cost, &|l| runs.contains_key(&l));
        let feasible: Vec<Candidate> = candidates
            .iter()
            .filter(|c| c.1.is_none())
            .map(|c| c.0)
            .collect();
        let choice = plan::cheapest(&feasible, spec.error);
        let mut extended = false;
        // Within reach, the walk's own levels refine the fit. Out of reach by this fit, the
        // pilots are refined towards the most accurate run within the limits (a
        // pre-asymptotic fit may be what puts the target out of reach), but only by levels
        // costing at most 4 × the pilots so far: a refusal must stay cheap.
        let spent: f64 = runs.values().map(|r| r.seconds).sum();
        let allowed = match choice {
            Some(_) => None,
            None => plan::most_accurate(&feasible)
                .map(|c| (PILOT_SHARE * c.predicted_seconds).min(4.0 * spent)),
        };
        if let Some(allowed) = allowed {
            let affordable = |level: (usize, usize)| {
                cost.predict(planner.unknowns(level), level.1) <= allowed
                    && planner.breaks(level).is_none()
            };
            let next_h = (h_ladder.last().unwrap() * 2, s_h);
            if h_ladder.len() < MAX_PILOT_LEVELS && affordable(next_h) {
                h_ladder.push(next_h.0);
                extended = true;
            }
            let next_k = (n_k, k_ladder.last().unwrap() * 2);
            if k_ladder.len() < MAX_PILOT_LEVELS && affordable(next_k) {
                k_ladder.push(next_k.1);
                extended = true;
            }
        }
        if !extended {
            break (model, cost, choice, candidates, scale);
        }
    };
    let frontier = frontier(&candidates);
    if choice.is_none() {
        return Err(unreachable(planner, &model, &cost, &candidates));
    }

    // The walk: from the cheapest candidate up, each level checked by its (2h, 2k) error bar
    // and, while the bar is above the target, refined in h or in k, whichever the model says
    // buys more error per unit of cost. A level a pilot ran is checked on the pilot's fields
    // and run again (for its stored steps) only when it passes.
    let mut attempts: Vec<Attempt> = Vec::new();
    let mut made: BTreeMap<(usize, usize), LevelRun<D>> = BTreeMap::new();
    let mut level = (n0 << 1, s0 << 1);
    let mut previous: Option<(usize, usize)> = None;
    let (mut h_points, mut k_points) = (model.h.points.clone(), model.k.points.clone());
    let summary = loop {
        let companion_level = (level.0 / 2, level.1 / 2);
        let companion_reused =
            made.contains_key(&companion_level) || runs.contains_key(&companion_level);
        let pilot = runs.contains_key(&level);
        if !companion_reused && (pilot || exec.threads < 2) {
            total_steps.fetch_add(companion_level.1, Ordering::Relaxed);
            let work = Work {
                problem: planner.problem(companion_level),
                keep: BTreeSet::from([companion_level.1]),
                is_reference: false,
                share: None,
                keep_u,
            };
            let c = levels::run_level::<D>(&work, exec.settings, &tick, None)?;
            made.insert(companion_level, c);
        }
        if let (Some(from), true) = (previous, pilot) {
            let prev = made.get(&from).or_else(|| runs.get(&from)).expect("ran");
            learn(
                planner,
                scale,
                (from, prev),
                (level, &runs[&level]),
                &mut h_points,
                &mut k_points,
            );
            model = ErrorModel {
                h: plan::fit_part(&h_points),
                k: plan::fit_part(&k_points),
            };
        }
        let pilot_bar = pilot.then(|| {
            let c = made
                .get(&companion_level)
                .or_else(|| runs.get(&companion_level))
                .expect("the companion ran");
            relative_difference(c, &runs[&level], spec.quantity)
        });
        let next = next_level(planner, &model, &cost, level, &|l| {
            made.contains_key(&l) || runs.contains_key(&l)
        });
        let attempt = |model: &ErrorModel,
                       estimated: f64,
                       seconds: f64,
                       companion: &LevelRun<D>,
                       reused: bool| {
            let (h, k) = (planner.h(level.0), planner.k(level.1));
            Attempt {
                h,
                k,
                refine: spec.given_mesh().then(|| level.0.trailing_zeros() as usize),
                steps: level.1,
                unknowns: planner.unknowns(level) as usize,
                predicted_error: model.predict(h, k),
                estimated_error: estimated,
                check_passed: estimated <= spec.error,
                predicted_seconds: cost.predict(planner.unknowns(level), level.1),
                seconds,
                companion: Companion {
                    h: planner.h(companion_level.0),
                    k: planner.k(companion_level.1),
                    seconds: companion.seconds,
                    reused,
                },
            }
        };
        if let (Some(bar), Some(to)) = (pilot_bar, next) {
            if bar > spec.error {
                let c = made
                    .get(&companion_level)
                    .or_else(|| runs.get(&companion_level))
                    .expect("the companion ran");
                attempts.push(attempt(
                    &model,
                    bar,
                    runs[&level].seconds,
                    c,
                    companion_reused,
                ));
                previous = Some(level);
                level = to;
                continue;
            }
        }
        // The level is run with its stored steps (beside its companion, if that is new).
        let problem = planner.problem(level);
        sink.restart().map_err(StudyError::Output)?;
        total_steps.fetch_add(level.1, Ordering::Relaxed);
        let (run, summary) =
            if made.contains_key(&companion_level) || runs.contains_key(&companion_level) {
                run_chosen::<D>(&problem, exec, keep_u, sink, &tick)?
            } else {
                total_steps.fetch_add(companion_level.1, Ordering::Relaxed);
                let work = Work {
                    problem: planner.problem(companion_level),
                    keep: BTreeSet::from([companion_level.1]),
                    is_reference: false,
                    share: None,
                    keep_u,
                };
                let (chosen, companion) = std::thread::scope(|s| {
                    let c = s.spawn(|| levels::run_level::<D>(&work, exec.settings, &tick, None));
                    let chosen = run_chosen::<D>(&problem, exec, keep_u, sink, &tick);
                    (chosen, c.join().expect("companion run panicked"))
                });
                made.insert(companion_level, companion?);
                chosen?
            };
        let companion = made
            .get(&companion_level)
            .or_else(|| runs.get(&companion_level))
            .expect("the companion ran");
        let estimated = relative_difference(companion, &run, spec.quantity);
        if let (Some(from), false) = (previous, pilot) {
            let prev = made.get(&from).or_else(|| runs.get(&from)).expect("ran");
            learn(
                planner,
                scale,
                (from, prev),
                (level, &run),
                &mut h_points,
                &mut k_points,
            );
            model = ErrorModel {
                h: plan::fit_part(&h_points),
                k: plan::fit_part(&k_points),
            };
        }
        attempts.push(attempt(
            &model,
            estimated,
            run.seconds,
            companion,
            companion_reused,
        ));
        let next = next_level(planner, &model, &cost, level, &|l| {
            made.contains_key(&l) || runs.contains_key(&l)
        });
        match next {
            Some(to) if estimated > spec.error => {
                made.insert(level, run);
                previous = Some(level);
                level = to;
            }
            _ => break summary,
        }
    };
    let chosen = attempts.last().cloned().expect("one attempt");
    let pilots = runs
        .iter()
        .map(|(&(n, steps), r)| PilotRow {
            ladder: if steps == s_h { "h" } else { "k" },
            h: planner.h(n),
            k: planner.k(steps),
            unknowns: planner.unknowns((n, steps)) as usize,
            steps,
            seconds: r.seconds,
        })
        .collect();
    let last_level = ((1.0 / chosen.h).round() as usize, chosen.steps);
    Ok(TargetResult {
        kind: "target",
        name: spec.name.clone(),
        quantity: spec.quantity,
        target_error: spec.error,
        safety_factor: plan::SAFETY,
        budget_s: spec.budget_s,
        chosen,
        attempts,
        error_model: model,
        cost_model: cost,
        pilots,
        frontier,
        scene: spec.scene_at(last_level.0, last_level.1),
        run: summary,
        seconds: planner.started.elapsed().as_secs_f64(),
        threads: exec.threads,
    })
}

/// Adds what one step of the walk measured to the error model's points: when `to` halves h
/// (or k) of `from` alone, the relative difference of their fields (over the pilots' `scale`)
/// is a point of the h (or k) part at x = h (or k) of `from`, in place of any earlier point at
/// that x (a pilot's: the walk's levels are finer in the other parameter or equal). Points
/// stay coarsest first, so the fit takes its order from the finest differences known.
fn learn<const D: usize>(
    planner: &Planner,
    scale: f64,
    from: ((usize, usize), &LevelRun<D>),
    to: ((usize, usize), &LevelRun<D>),
    h_points: &mut Vec<(f64, f64)>,
    k_points: &mut Vec<(f64, f64)>,
) {
    let ((a, ra), (b, rb)) = (from, to);
    let (x, points) = if b == (a.0 * 2, a.1) {
        (planner.h(a.0), h_points)
    } else if b == (a.0, a.1 * 2) {
        (planner.k(a.1), k_points)
    } else {
        return;
    };
    let (d, _) = difference(ra, rb, planner.spec.quantity);
    let d = if d == 0.0 { 0.0 } else { d / scale };
    points.retain(|p| (p.0 - x).abs() > 1e-9 * x);
    points.push((x, d));
    points.sort_by(|p, q| q.0.partial_cmp(&p.0).unwrap_or(std::cmp::Ordering::Equal));
}

/// The next level of the walk from `level`: h or k halved, whichever the error model predicts
/// to reduce the error more per doubling of the work (unknowns × steps: deterministic, unlike
/// measured times, so the walk does not depend on the machine's load). Only levels within the
/// limits and the budget (time spent, the level's predicted time and its companion's unless
/// it ran) qualify; ties go to the cheaper level.
fn next_level(
    planner: &Planner,
    model: &ErrorModel,
    cost: &CostModel,
    level: (usize, usize),
    known: &dyn Fn((usize, usize)) -> bool,
) -> Option<(usize, usize)> {
    let (n0, s0) = (planner.spec.n0, PILOT_STEPS);
    let work = |l: (usize, usize)| planner.unknowns(l) * l.1 as f64;
    let error = |l: (usize, usize)| model.predict(planner.h(l.0), planner.k(l.1));
    let seconds = |l: (usize, usize)| cost.predict(planner.unknowns(l), l.1);
    let spent = planner.started.elapsed().as_secs_f64();
    [(level.0 * 2, level.1), (level.0, level.1 * 2)]
        .into_iter()
        .filter(|&(n, steps)| n <= n0 << MAX_DOUBLINGS && steps <= s0 << (2 * MAX_DOUBLINGS))
        .filter(|&to| planner.breaks(to).is_none())
        .filter(|&to| {
            let companion = (to.0 / 2, to.1 / 2);
            let more = seconds(to)
                + if known(companion) {
                    0.0
                } else {
                    seconds(companion)
                };
            planner.spec.budget_s.is_none_or(|b| spent + more <= b)
        })
        .map(|to| {
            let gain = (error(level) - error(to)) / (work(to) / work(level)).log2();
            (to, gain, work(to))
        })
        .max_by(|a, b| {
            a.1.partial_cmp(&b.1)
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(b.2.partial_cmp(&a.2).unwrap_or(std::cmp::Ordering::Equal))
        })
        .map(|c| c.0)
}

/// The candidates within the limits that no other beats in both predicted time and error,
/// cheapest first.
fn frontier(candidates: &[(Candidate, Option<Limit>)]) -> Vec<Candidate> {
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
fn unreachable(
    planner: &Planner,
    model: &ErrorModel,
    cost: &CostModel,
    candidates: &[(Candidate, Option<Limit>)],
) -> StudyError {
    let spec = planner.spec;
    let frac = super::report_svg::fraction;
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
            let limits = planner.limits;
            let what = match l {
                Limit::Nodes => format!(
                    "{} nodes, more than the node limit of {}",
                    planner.problem((n.n, n.steps)).n_nodes(),
                    limits.max_nodes.unwrap_or(0)
                ),
                Limit::Steps => format!(
                    "{} time steps, more than the step limit of {}",
                    n.steps,
                    limits.max_steps.unwrap_or(0)
                ),
                Limit::Memory => {
                    use crate::memory::{choose, human, MemoryError};
                    let p = planner.problem((n.n, n.steps));
                    match choose(&p, planner.exec.settings.memory_limit) {
                        Err(
                            MemoryError::TooLarge {
                                predicted, allowed, ..
                            }
                            | MemoryError::DirectTooLarge {
                                predicted, allowed, ..
                            },
                        ) => format!(
                            "about {} of memory (predicted), more than the per-job memory limit of {}",
                            human(predicted),
                            human(allowed)
                        ),
                        Ok(_) => "more memory than the per-job limit".into(),
                    }
                }
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

/// Three significant digits.
fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let digits = (2 - x.abs().log10().floor() as i32).max(0) as usize;
    format!("{x:.digits$}")
}

impl TargetResult {
    /// A short text report: the choice, the check, the fit and the pilots.
    pub fn text_table(&self) -> String {
        let frac = super::report_svg::fraction;
        let opt = |o: Option<f64>| o.map_or("–".to_string(), |v| format!("{v:.3}"));
        let c = &self.chosen;
        let mut s = format!(
            "{}: target {} in {} (safety factor {})\nchosen h = {}, k = {} ({} unknowns, {} steps): predicted error {:.4}, estimated {:.4} ({}); predicted {:.3} s, measured {:.3} s\n",
            self.name,
            self.target_error,
            self.quantity.name(),
            self.safety_factor,
            frac(c.h),
            frac(c.k),
            c.unknowns,
            c.steps,
            c.predicted_error,
            c.estimated_error,
            if c.check_passed { "check passed" } else { "check FAILED" },
            c.predicted_seconds,
            c.seconds,
        );
        if self.attempts.len() > 1 {
            s += "walk:";
            for a in &self.attempts {
                s += &format!(
                    " ({}, {}) bar {:.4}{};",
                    frac(a.h),
                    frac(a.k),
                    a.estimated_error,
                    if a.check_passed { " passed" } else { "" }
                );
            }
            s += "\n";
        }
        let m = &self.error_model;
        s += &format!(
            "error model e = {:.4}·h^{} + {:.4}·k^{} (observed orders {}, {}); cost t = {:.3e}·N^{:.2}·steps\n",
            m.h.coefficient,
            opt(m.h.order),
            m.k.coefficient,
            opt(m.k.order),
            opt(m.h.observed_order),
            opt(m.k.observed_order),
            self.cost_model.c,
            self.cost_model.alpha,
        );
        for note in [&m.h.note, &m.k.note, &self.cost_model.note]
            .into_iter()
            .flatten()
        {
            s += &format!("  note: {note}\n");
        }
        s += &format!(
            "{:>7} {:>7} {:>7} {:>9} {:>6} {:>9}\n",
            "ladder", "h", "k", "unknowns", "steps", "seconds"
        );
        for p in &self.pilots {
            s += &format!(
                "{:>7} {:>7} {:>7} {:>9} {:>6} {:>9.4}\n",
                p.ladder,
                frac(p.h),
                frac(p.k),
                p.unknowns,
                p.steps,
                p.seconds
            );
        }
        s += &format!(
            "study {:.3} s on {} thread(s)\n",
            self.seconds, self.threads
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pointers(doc: Value) -> Vec<String> {
        parse(&doc, "/study")
            .unwrap_err()
            .0
            .into_iter()
            .map(|e| e.pointer)
            .collect()
    }

    #[test]
    fn a_target_study_is_read_with_its_coarsest_level() {
        let (spec, doc) = parse(
            &json!({"scene": "paper-convergence", "target": {"error": 0.05}, "budget_s": 30}),
            "",
        )
        .unwrap();
        assert_eq!(
            (spec.n0, spec.base.cells_per_unit, spec.base.steps),
            (2, 2, PILOT_STEPS)
        );
        assert_eq!(spec.quantity, Quantity::W);
        assert_eq!(doc["target"], json!({"error": 0.05, "quantity": "w"}));
        assert!(doc["scene"].is_object(), "the preset is expanded");
        let at = spec.scene_at(16, 32);
        assert_eq!(
            (at["mesh"]["h"].clone(), at["time"]["N"].clone()),
            (json!("1/16"), json!(32))
        );
        let p = scene::validate(&at).unwrap();
        assert_eq!((p.cells_per_unit, p.steps), (16, 32));
        // A given mesh: refine levels.
        let (plate, _) = parse(
            &json!({"scene": "plate-with-hole", "target": {"error": 0.1, "quantity": "u"}}),
            "",
        )
        .unwrap();
        assert!(plate.given_mesh());
        assert_eq!(plate.scene_at(4, 8)["mesh"]["refine"], json!(2));
    }

    #[test]
    fn bad_targets_are_refused_at_their_pointer() {
        let t = |target: Value| json!({"scene": "paper-convergence", "target": target});
        assert_eq!(pointers(t(json!({"error": 0}))), ["/study/target/error"]);
        assert_eq!(pointers(t(json!({"error": 1.5}))), ["/study/target/error"]);
        assert_eq!(
            pointers(t(json!({"error": 0.1, "quantity": "v"}))),
            ["/study/target/quantity"]
        );
        assert_eq!(
            pointers(t(json!({"error": 0.1, "x": 1}))),
            ["/study/target/x"]
        );
        assert_eq!(pointers(t(json!(0.1))), ["/study/target"]);
        let mut d = t(json!({"error": 0.1}));
        d["budget_s"] = json!(-1);
        assert_eq!(pointers(d.clone()), ["/study/budget_s"]);
        d["budget_s"] = json!(1);
        d["reference"] = json!({"h": "1/8", "k": "1/8"});
        assert_eq!(pointers(d), ["/study/reference"]);
        // ζ needs damage.
        let mut scene = scene::presets::get("paper-convergence").unwrap();
        scene.as_object_mut().unwrap().remove("damage");
        let e = pointers(json!({"scene": scene, "target": {"error": 0.1, "quantity": "zeta"}}));
        assert_eq!(e, ["/study/target/quantity"]);
    }
}
