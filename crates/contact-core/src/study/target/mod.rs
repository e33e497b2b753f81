//! A study with a target instead of a ladder: "the cheapest run whose relative error in w, u
//! or ζ at t = T is below e" (docs/src/explanation/numerics.md#target-studies).
//!
//! ```json
//! {"name": "...", "scene": {...} | "paper-convergence",
//!  "target": {"error": 0.05, "quantity": "w", "meshes": "uniform" | "auto"}, "budget_s": 60}
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
//! 5. With `"meshes": "auto"` ([`adaptive`]): adaptive meshes at the chosen k, from the
//!    coarsest pilot mesh, refined until their estimate's spatial part is at most the chosen
//!    uniform run's; the first such mesh with fewer nodes than the uniform level's replaces
//!    it as the chosen run. The result's `meshes` says which was taken, and why.

use super::levels::{self, LevelRun, Snapshot, StatsAccumulator, Work};
use super::plan::{self, Candidate, CostModel, ErrorModel, Timing};
use super::reference::{double_dot, strains, sym_len};
use super::{run_all, with, Done, Execution, StudyError};
use crate::admission;
use crate::fem::prolongation::{parent_cells, prolongate};
use crate::fem::{assembly, norms, Geometry};
use crate::output::Summary;
use crate::problem::{MeshPattern, Problem};
use crate::run::{Hooks, Run, RunError};
use crate::scene::{self, ValidationErrors};
use crate::solve::stepper::{StepFields, StepReport};
use serde::Serialize;
use serde_json::{json, Map, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

mod adaptive;
mod chosen;
mod planner;
mod result;
mod walk;

use planner::Planner;
pub use result::{Attempt, Companion, MeshChoice, PilotRow, TargetResult};
use walk::run_in;
pub use walk::{difference, relative_difference};

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
const TARGET_FIELDS: &[&str] = &["error", "quantity", "meshes"];

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

/// Which meshes the chosen run may be on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Meshes {
    /// The uniform refinements of the walk (the default).
    Uniform,
    /// The walk's uniform level, or an adaptive mesh at its k where that has fewer nodes
    /// and an estimate no larger ([`adaptive`]).
    Auto,
}

/// A target study's pilot ladders: resolutions n of the h-ladder (run at `s_h` steps) and
/// step counts N of the k-ladder (run at resolution `n_k`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PilotLadders {
    pub h: Vec<usize>,
    pub k: Vec<usize>,
    pub n_k: usize,
    pub s_h: usize,
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
    pub meshes: Meshes,
    pub budget_s: Option<f64>,
}

impl TargetSpec {
    /// Whether the scene is a given mesh (resolutions are refinements of it).
    pub fn given_mesh(&self) -> bool {
        self.base.body.is_some()
    }

    /// The first pilot ladders: the h-ladder n0·2^i at the k-ladder's finest N and the
    /// k-ladder N0·2^j at the h-ladder's finest n, i, j < [`FIRST_PILOT_LEVELS`]. They cross
    /// at their finest levels: each is run where the other parameter is already resolved a
    /// little (at the coarsest one, the other part's interaction distorts it: on the paper's
    /// test, k barely matters on a 2 × 2 mesh).
    pub fn first_ladders(&self) -> PilotLadders {
        let last = FIRST_PILOT_LEVELS - 1;
        PilotLadders {
            h: (0..FIRST_PILOT_LEVELS).map(|i| self.n0 << i).collect(),
            k: (0..FIRST_PILOT_LEVELS).map(|j| PILOT_STEPS << j).collect(),
            n_k: self.n0 << last,
            s_h: PILOT_STEPS << last,
        }
    }

    /// The runs (n, N) of the first pilot ladders ([`TargetSpec::first_ladders`]).
    pub fn first_pilots(&self) -> BTreeSet<(usize, usize)> {
        let l = self.first_ladders();
        let h_runs = l.h.iter().map(|&n| (n, l.s_h));
        h_runs.chain(l.k.iter().map(|&s| (l.n_k, s))).collect()
    }

    /// Time steps of the first pilot runs: a target study's progress scale before its plan.
    pub fn first_pilot_steps(&self) -> usize {
        self.first_pilots().iter().map(|l| l.1).sum()
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
        if !TARGET_FIELDS.contains(&k.as_str()) {
            return Err(err(
                &format!("/target/{k}"),
                format!(
                    "unknown field {k:?} (allowed: {})",
                    TARGET_FIELDS.join(", ")
                ),
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
    let meshes = match target.get("meshes") {
        None => Meshes::Uniform,
        Some(v) => match v.as_str() {
            Some("uniform") => Meshes::Uniform,
            Some("auto") if quantity == Quantity::W => Meshes::Auto,
            Some("auto") => {
                return Err(err(
                    "/target/meshes",
                    format!("adaptive meshes are compared by the velocity's a posteriori estimate: \"auto\" needs quantity \"w\", not \"{}\"", quantity.name()),
                ))
            }
            _ => {
                return Err(err(
                    "/target/meshes",
                    format!("meshes must be \"uniform\" or \"auto\", got {v}"),
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
    // The scene as given: its own errors, and whether it is a given mesh.
    let given = super::spec::given_scene(&scene_doc, at, files)?;
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
        meshes,
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
    // Only when asked: a uniform study's document (and hash) is what it was before `meshes`.
    if meshes == Meshes::Auto {
        expanded["target"]["meshes"] = json!("auto");
    }
    if let Some(b) = budget_s {
        expanded.insert("budget_s".into(), json!(b));
    }
    Ok((spec, Value::Object(expanded)))
}

/// The host's per-job limits bound every run of a target study, the chosen one included
/// (its stored steps too); the memory limit is the one its runs are set up under.
pub use crate::admission::Limits;

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
        assert_eq!(spec.meshes, Meshes::Uniform);
        let (auto, doc) = parse(
            &json!({"scene": "paper-convergence", "target": {"error": 0.05, "meshes": "auto"}}),
            "",
        )
        .unwrap();
        assert_eq!(auto.meshes, Meshes::Auto);
        assert_eq!(doc["target"]["meshes"], json!("auto"));
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
        for meshes in [json!("adaptive"), json!(true)] {
            let e = pointers(t(json!({"error": 0.1, "meshes": meshes})));
            assert_eq!(e, ["/study/target/meshes"]);
        }
        // Adaptive meshes are compared by the velocity's estimate.
        let e = pointers(t(json!({"error": 0.1, "quantity": "u", "meshes": "auto"})));
        assert_eq!(e, ["/study/target/meshes"]);
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
