//! Parameter sweeps: one scene run with values substituted at JSON pointers,
//! `{"scene": S, "vary": {"/friction/g": [0.5, 1, 2], "/damage/kappa": [0.1, 0.5]}, "mode":
//! "grid" | "zip", "name"?}`. `grid` runs every combination (the first pointer varies
//! slowest), `zip` the i-th values together (lists of one length). Every member is an
//! ordinary scene, validated as one: a member that does not validate is refused at
//! `{at}/vary/<pointer, escaped>` (or at `{at}/scene...` for an error of the scene's own).
//!
//! The result is a table, one row per member: the varied values, the final norms, min ζ over
//! the run, the slipping Γ3 nodes at T, the largest slip speed at T and the wall time; as JSON
//! ([`SweepResult`]), CSV ([`SweepResult::csv`]), the paper-like text table and an SVG plot
//! of a quantity against one parameter, one line per value of the others ([`plot_svg`]).
//! A member equal to one computed before (the caller's `known`, e.g. a job of the same
//! computation) is taken from there, not computed again; equal members are computed once.

use super::spec::{field_error, scene_document, study_name};
use super::{Execution, StudyError};
use crate::admission::{self, Fit, Limit, LimitError, Limits, Pointers};
use crate::problem::Problem;
use crate::run::{Hooks, Run, RunError};
use crate::scene::{self, canonical, FieldError, MeshFiles, ValidationErrors};
use crate::solve::stepper::State;
use serde::{Deserialize, Serialize};
use serde_json::{json, Map, Value};
use std::fmt::Write as _;
use std::ops::ControlFlow;
use std::time::Instant;

/// Most members of one sweep.
pub const MAX_MEMBERS: usize = 64;

const FIELDS: &[&str] = &["name", "scene", "vary", "mode"];

/// Every combination, or the i-th values together.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    Grid,
    Zip,
}

/// One run of a sweep: its values (one per varied pointer), its scene and problem.
#[derive(Debug, Clone)]
pub struct Member {
    pub values: Vec<Value>,
    pub scene: Value,
    pub problem: Problem,
}

/// A validated sweep.
#[derive(Debug, Clone)]
pub struct SweepSpec {
    pub name: String,
    pub mode: Mode,
    /// The varied pointers and their values, in the request's order.
    pub vary: Vec<(String, Vec<Value>)>,
    pub members: Vec<Member>,
    /// Where the sweep is in the request (`/sweep`).
    pub at: String,
}

/// RFC 6901 escaping of one reference token (`~` → `~0`, `/` → `~1`).
pub fn escape(token: &str) -> String {
    token.replace('~', "~0").replace('/', "~1")
}

/// Puts `value` at `pointer` in `doc`: the member it names, or a new member of an existing
/// object (`/friction/g` in a scene whose friction object has no `g`).
fn substitute(doc: &mut Value, pointer: &str, value: Value) -> Result<(), String> {
    if let Some(slot) = doc.pointer_mut(pointer) {
        *slot = value;
        return Ok(());
    }
    let (parent, last) = pointer
        .rsplit_once('/')
        .ok_or_else(|| format!("{pointer:?} is not a JSON pointer (it starts with /)"))?;
    let key = last.replace("~1", "/").replace("~0", "~");
    match doc.pointer_mut(parent) {
        Some(Value::Object(o)) => {
            o.insert(key, value);
            Ok(())
        }
        _ => Err(format!(
            "{pointer} names nothing in the scene (no object at {:?})",
            if parent.is_empty() { "/" } else { parent }
        )),
    }
}

/// Reads the sweep object `doc` at `at` (errors point there), meshes looked up in `files`:
/// the spec and the expanded document (the scene preset resolved) a job stores.
pub fn parse_with(
    doc: &Value,
    at: &str,
    files: &dyn MeshFiles,
) -> Result<(SweepSpec, Value), ValidationErrors> {
    let obj = doc.as_object().ok_or_else(|| {
        field_error(
            at,
            "",
            "a sweep is an object {\"scene\", \"vary\", \"mode\"}".into(),
        )
    })?;
    if let Some(k) = obj.keys().find(|k| !FIELDS.contains(&k.as_str())) {
        return Err(field_error(
            at,
            &format!("/{}", escape(k)),
            format!("unknown field {k:?} (allowed: {})", FIELDS.join(", ")),
        ));
    }
    let name = study_name(obj, at)?;
    let base = scene_document(obj, at)?;
    let mode =
        match obj.get("mode") {
            None => Mode::Grid,
            Some(Value::String(s)) if s == "grid" => Mode::Grid,
            Some(Value::String(s)) if s == "zip" => Mode::Zip,
            Some(_) => return Err(field_error(
                at,
                "/mode",
                "mode must be \"grid\" (every combination) or \"zip\" (the i-th values together)"
                    .into(),
            )),
        };
    let vary_obj = match obj.get("vary") {
        Some(Value::Object(o)) if !o.is_empty() => o,
        _ => {
            return Err(field_error(
                at,
                "/vary",
                "vary must be a non-empty object of JSON pointers into the scene, each with a list of values: {\"/friction/g\": [0.5, 1, 2]}".into(),
            ))
        }
    };
    let mut vary = Vec::new();
    for (pointer, values) in vary_obj {
        let here = format!("/vary/{}", escape(pointer));
        if !pointer.starts_with('/') {
            return Err(field_error(
                at,
                &here,
                format!("{pointer:?} is not a JSON pointer into the scene (e.g. /friction/g)"),
            ));
        }
        if pointer == "/name" || pointer.starts_with("/name/") {
            return Err(field_error(
                at,
                &here,
                "the name changes no number: vary a field of the computation".into(),
            ));
        }
        let list = match values {
            Value::Array(a) if !a.is_empty() => a.clone(),
            _ => {
                return Err(field_error(
                    at,
                    &here,
                    "a non-empty list of the values to substitute".into(),
                ))
            }
        };
        vary.push((pointer.clone(), list));
    }
    let count = match mode {
        Mode::Grid => vary
            .iter()
            .try_fold(1usize, |n, (_, v)| n.checked_mul(v.len()))
            .unwrap_or(usize::MAX),
        Mode::Zip => {
            let n = vary[0].1.len();
            if let Some((p, v)) = vary.iter().find(|(_, v)| v.len() != n) {
                return Err(field_error(
                    at,
                    &format!("/vary/{}", escape(p)),
                    format!(
                        "zip takes lists of one length: {} values here, {n} for {}",
                        v.len(),
                        vary[0].0
                    ),
                ));
            }
            n
        }
    };
    if count > MAX_MEMBERS {
        return Err(field_error(
            at,
            "/vary",
            format!("the sweep has {count} members, more than the limit of {MAX_MEMBERS}"),
        ));
    }
    let mut members = Vec::with_capacity(count);
    for i in 0..count {
        let mut values = Vec::with_capacity(vary.len());
        let mut rest = i;
        // Grid: the first pointer varies slowest.
        let strides: Vec<usize> = (0..vary.len())
            .map(|j| vary[j + 1..].iter().map(|(_, v)| v.len()).product())
            .collect();
        for (j, (_, list)) in vary.iter().enumerate() {
            let idx = match mode {
                Mode::Zip => i,
                Mode::Grid => {
                    let idx = rest / strides[j];
                    rest %= strides[j];
                    idx
                }
            };
            values.push(list[idx].clone());
        }
        let mut scene_doc = base.clone();
        for ((pointer, _), v) in vary.iter().zip(&values) {
            substitute(&mut scene_doc, pointer, v.clone())
                .map_err(|m| field_error(at, &format!("/vary/{}", escape(pointer)), m))?;
        }
        let problem = scene::validate_with(&scene_doc, files)
            .map_err(|e| member_errors(at, &vary, &values, e))?;
        members.push(Member {
            values,
            scene: scene_doc,
            problem,
        });
    }
    let mut expanded = doc.clone();
    expanded["scene"] = base;
    expanded["mode"] = json!(mode);
    Ok((
        SweepSpec {
            name: name.unwrap_or_else(|| "sweep".to_string()),
            mode,
            vary,
            members,
            at: at.to_string(),
        },
        expanded,
    ))
}

/// A member's validation errors, each at the varied pointer it falls under
/// (`{at}/vary/<escaped>`, naming the member's values), else at `{at}/scene<pointer>`.
fn member_errors(
    at: &str,
    vary: &[(String, Vec<Value>)],
    values: &[Value],
    e: ValidationErrors,
) -> ValidationErrors {
    let which = vary
        .iter()
        .zip(values)
        .map(|((p, _), v)| format!("{p} = {v}"))
        .collect::<Vec<_>>()
        .join(", ");
    ValidationErrors(
        e.0.into_iter()
            .map(|f| {
                let varied = vary.iter().find(|(p, _)| {
                    f.pointer == *p
                        || f.pointer.starts_with(&format!("{p}/"))
                        || p.starts_with(&format!("{}/", f.pointer))
                });
                match varied {
                    Some((p, _)) => FieldError {
                        pointer: format!("{at}/vary/{}", escape(p)),
                        message: format!("the member {which}: {}: {}", f.pointer, f.message),
                    },
                    None => FieldError {
                        pointer: format!("{at}/scene{}", f.pointer),
                        message: format!("the member {which}: {}", f.message),
                    },
                }
            })
            .collect(),
    )
}

impl SweepSpec {
    /// A member's varied values by pointer: its row's `values`.
    fn values_of(&self, m: &Member) -> Map<String, Value> {
        self.vary
            .iter()
            .zip(&m.values)
            .map(|((p, _), v)| (p.clone(), v.clone()))
            .collect()
    }

    /// The sweep's result from its rows, wherever its members ran.
    fn result(&self, rows: Vec<SweepRow>, computed: usize, seconds: f64) -> SweepResult {
        SweepResult {
            kind: "sweep".into(),
            name: self.name.clone(),
            mode: self.mode,
            vary: self
                .vary
                .iter()
                .map(|(p, v)| json!({"pointer": p, "values": v}))
                .collect(),
            rows,
            computed,
            seconds,
        }
    }

    /// The pointer a member's size is set at: a varied mesh or time field, else the scene.
    fn size_pointer(&self, prefixes: &[&str]) -> String {
        self.vary
            .iter()
            .find(|(p, _)| prefixes.iter().any(|x| p.starts_with(x)))
            .map_or(format!("{}/scene", self.at), |(p, _)| {
                format!("{}/vary/{}", self.at, escape(p))
            })
    }

    /// Every member against `limits` as a job of its own (a service runs each member as one:
    /// nodes, memory and the steps it stores), the steps of all together against the step
    /// limit: the first that does not fit, or the total steps and the largest member.
    pub fn admit(&self, limits: &Limits) -> Result<(usize, Fit), LimitError> {
        let per_run = Limits {
            max_steps: None,
            ..*limits
        };
        let at = Pointers {
            mesh: self.size_pointer(&["/mesh", "/domain"]),
            steps: self.size_pointer(&["/time"]),
            output: match self.size_pointer(&["/output"]) {
                p if p.contains("/vary/") => p,
                _ => format!("{}/scene/output", self.at),
            },
            solver: None,
        };
        let mut largest: Option<Fit> = None;
        for m in &self.members {
            let fit = admission::check_run(&m.problem, &per_run, &at).map_err(|e| LimitError {
                message: format!("{}: {}", self.describe(m), e.message),
                ..e
            })?;
            if largest.is_none_or(|l| fit.memory_bytes > l.memory_bytes) {
                largest = Some(fit);
            }
        }
        let steps = self.steps();
        if let Some(max) = limits.max_steps.filter(|&m| steps > m) {
            return Err(LimitError {
                pointer: at.steps,
                limit: Limit::Steps,
                needed: steps as u64,
                allowed: max as u64,
                message: format!(
                    "the sweep's members take {steps} time steps in all, more than the per-job limit of {max}"
                ),
            });
        }
        Ok((steps, largest.expect("a sweep has members")))
    }

    /// Time steps of all members.
    pub fn steps(&self) -> usize {
        self.members.iter().map(|m| m.problem.steps).sum()
    }

    /// "/friction/g = 0.5, /damage/kappa = 0.1".
    pub fn describe(&self, m: &Member) -> String {
        self.vary
            .iter()
            .zip(&m.values)
            .map(|((p, _), v)| format!("{p} = {v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// One member's row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepRow {
    /// Index of the member (grid order: the first pointer varies slowest).
    pub member: usize,
    /// The varied values by pointer.
    pub values: Map<String, Value>,
    #[serde(rename = "w_V")]
    pub w_v: f64,
    #[serde(rename = "u_V")]
    pub u_v: f64,
    #[serde(rename = "zeta_L2")]
    pub zeta_l2: f64,
    /// ζ's minimum at T ...
    pub zeta_min: f64,
    /// ... and over the whole run.
    pub min_zeta: f64,
    /// Γ3 nodes slipping at T.
    pub slip_nodes: usize,
    /// The largest tangential speed |w_τ| on Γ3 at T.
    pub max_slip_speed: f64,
    pub steps: usize,
    /// Wall time of the member's run (of the earlier run it was taken from, when `cached`).
    pub wall_s: f64,
    /// Taken from an earlier computation, not computed by this sweep.
    pub cached: bool,
    /// The id of the job the row's figures come from, when the member ran as a job of the
    /// service ([`assemble`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub job: Option<String>,
}

/// The quantities of a row that a plot can show.
pub const QUANTITIES: &[&str] = &[
    "w_V",
    "u_V",
    "zeta_L2",
    "zeta_min",
    "min_zeta",
    "slip_nodes",
    "max_slip_speed",
    "wall_s",
];

impl SweepRow {
    /// A row from a run's summary (JSON, as stored) and its state after the last step (its
    /// Γ3 tangential velocities, D − 1 per node).
    pub fn from_run(summary: &Value, last: &State, dim: usize) -> Result<SweepRow, String> {
        let fin = &summary["final"];
        let f = |v: &Value, k: &str| {
            v[k].as_f64()
                .ok_or_else(|| format!("the summary has no {k}"))
        };
        let steps = summary["steps"]
            .as_array()
            .ok_or("the summary has no steps")?;
        let min_zeta = steps.iter().filter_map(|s| s["zeta_min"].as_f64()).fold(
            f(&summary["initial"], "zeta_min").unwrap_or(f64::INFINITY),
            f64::min,
        );
        let per_node = dim.saturating_sub(1).max(1);
        let max_slip_speed = last
            .contact_velocity
            .chunks(per_node)
            .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        Ok(SweepRow {
            member: 0,
            values: Map::new(),
            w_v: f(fin, "w_V")?,
            u_v: f(fin, "u_V")?,
            zeta_l2: f(fin, "zeta_L2")?,
            zeta_min: f(fin, "zeta_min")?,
            min_zeta,
            slip_nodes: steps
                .last()
                .and_then(|s| s["slip_nodes"].as_u64())
                .unwrap_or(0) as usize,
            max_slip_speed,
            steps: steps.len(),
            wall_s: summary["timing"]["solve_s"].as_f64().unwrap_or(0.0)
                + summary["timing"]["setup_s"].as_f64().unwrap_or(0.0),
            cached: false,
            job: None,
        })
    }

    fn quantity(&self, q: &str) -> Option<f64> {
        Some(match q {
            "w_V" => self.w_v,
            "u_V" => self.u_v,
            "zeta_L2" => self.zeta_l2,
            "zeta_min" => self.zeta_min,
            "min_zeta" => self.min_zeta,
            "slip_nodes" => self.slip_nodes as f64,
            "max_slip_speed" => self.max_slip_speed,
            "wall_s" => self.wall_s,
            _ => return None,
        })
    }
}

/// A finished sweep: the job's summary (`kind` "sweep").
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SweepResult {
    pub kind: String,
    pub name: String,
    pub mode: Mode,
    /// The varied pointers with their values.
    pub vary: Vec<Value>,
    pub rows: Vec<SweepRow>,
    /// Members computed by this sweep (the others were taken from earlier computations or
    /// equal an earlier member).
    pub computed: usize,
    pub seconds: f64,
}

/// An earlier computation of a member's scene, if the caller knows one: its summary and its
/// state after the last step.
pub type Known<'a> = dyn Fn(&Value) -> Option<(Value, State)> + 'a;

/// One member as computed elsewhere (a job of its own): the run's summary and last state,
/// whether this sweep computed it (false: taken from an earlier computation) and the id of
/// the job it comes from.
pub struct Computed {
    pub summary: Value,
    pub state: State,
    pub computed: bool,
    pub job: String,
}

/// The table of a sweep whose members ran elsewhere, one [`Computed`] per member in member
/// order (equal members may share a job: a repeated job is counted as computed once, and
/// its later rows are `cached`). A summary without the figures of a row is an error naming
/// the member.
pub fn assemble(
    spec: &SweepSpec,
    members: Vec<Computed>,
    seconds: f64,
) -> Result<SweepResult, String> {
    let mut rows = Vec::with_capacity(members.len());
    let mut seen: Vec<String> = Vec::new();
    for (i, (m, c)) in spec.members.iter().zip(members).enumerate() {
        let mut row = SweepRow::from_run(&c.summary, &c.state, m.problem.dim())
            .map_err(|e| format!("member {i} ({}): {e}", spec.describe(m)))?;
        row.cached = !c.computed || seen.contains(&c.job);
        seen.push(c.job.clone());
        row.member = i;
        row.values = spec.values_of(m);
        row.job = Some(c.job);
        rows.push(row);
    }
    let computed = rows.iter().filter(|r| !r.cached).count();
    Ok(spec.result(rows, computed, seconds))
}

/// Runs the members one after another (each on all of `exec`'s threads), taking a member
/// from `known` or from an equal earlier member when it can; `progress(done, total)` after
/// every step of a computed member (`Break` cancels the sweep; `done` counts the steps of
/// the members taken, too).
pub fn run(
    spec: &SweepSpec,
    exec: Execution,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    known: &Known,
) -> Result<SweepResult, StudyError> {
    let started = Instant::now();
    let total = spec.steps();
    let mut done = 0usize;
    let mut rows: Vec<SweepRow> = Vec::with_capacity(spec.members.len());
    let mut computed = 0;
    let mut seen: Vec<(Value, usize)> = Vec::new();
    for (i, m) in spec.members.iter().enumerate() {
        let key = canonical(&scene::computation(&m.scene));
        let mut row = if let Some(&(_, j)) = seen.iter().find(|(k, _)| *k == key) {
            SweepRow {
                cached: true,
                ..rows[j].clone()
            }
        } else if let Some((summary, state)) = known(&m.scene) {
            let mut row = SweepRow::from_run(&summary, &state, m.problem.dim()).map_err(|e| {
                StudyError::Run(RunError::Solve(crate::solve::SolveError::Data {
                    pointer: format!("{}/vary", spec.at),
                    message: e,
                }))
            })?;
            row.cached = true;
            row
        } else {
            computed += 1;
            let t0 = Instant::now();
            let (summary, state) = match m.problem.dim() {
                2 => run_member::<2>(m, exec, &mut done, total, progress)?,
                _ => run_member::<3>(m, exec, &mut done, total, progress)?,
            };
            let mut row = SweepRow::from_run(&summary, &state, m.problem.dim())
                .expect("a run's own summary has its figures");
            row.wall_s = t0.elapsed().as_secs_f64();
            row
        };
        if !row.cached || seen.iter().all(|(k, _)| *k != key) {
            seen.push((key, i));
        }
        if row.cached {
            // Its steps count as done (reported with the next computed step: the progress
            // hook counts computed steps).
            done += m.problem.steps;
        }
        row.member = i;
        row.values = spec.values_of(m);
        rows.push(row);
    }
    Ok(spec.result(rows, computed, started.elapsed().as_secs_f64()))
}

/// One member's run: its summary (JSON) and its state after the last step.
fn run_member<const D: usize>(
    m: &Member,
    exec: Execution,
    done: &mut usize,
    total: usize,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
) -> Result<(Value, State), StudyError> {
    struct Progress<'a> {
        done: &'a mut usize,
        total: usize,
        progress: &'a (dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    }
    impl<const D: usize> Hooks<D> for Progress<'_> {
        type Stop = ();
        fn after_step(
            &mut self,
            _run: &Run<D>,
            _r: &crate::solve::stepper::StepReport,
        ) -> ControlFlow<()> {
            *self.done += 1;
            (self.progress)(*self.done, self.total)
        }
    }
    let settings = crate::solve::SolverSettings {
        threads: exec.threads,
        ..exec.settings
    };
    let mut run = Run::<D>::new(m.problem.clone(), settings).map_err(RunError::from)?;
    let mut hooks = Progress {
        done,
        total,
        progress,
    };
    if run.drive(&mut hooks).map_err(RunError::from)?.is_break() {
        return Err(StudyError::Cancelled);
    }
    let state = run.sim().checkpoint_state();
    let summary = serde_json::to_value(run.summary()).expect("a summary serialises");
    Ok((summary, state))
}

impl SweepResult {
    /// The table as CSV: member, one column per varied pointer, then the figures.
    pub fn csv(&self) -> String {
        let pointers: Vec<&str> = self
            .vary
            .iter()
            .filter_map(|v| v["pointer"].as_str())
            .collect();
        let quote = |s: &str| {
            if s.contains([',', '"', '\n']) {
                format!("\"{}\"", s.replace('"', "\"\""))
            } else {
                s.to_string()
            }
        };
        let mut out = String::from("member");
        for p in &pointers {
            out.push(',');
            out.push_str(&quote(p));
        }
        out.push_str(
            ",w_V,u_V,zeta_L2,zeta_min,min_zeta,slip_nodes,max_slip_speed,steps,wall_s,cached\n",
        );
        for r in &self.rows {
            let _ = write!(out, "{}", r.member);
            for p in &pointers {
                let v = r.values.get(*p).map_or(String::new(), |v| match v {
                    Value::String(s) => s.clone(),
                    other => other.to_string(),
                });
                out.push(',');
                out.push_str(&quote(&v));
            }
            let _ = writeln!(
                out,
                ",{},{},{},{},{},{},{},{},{},{}",
                r.w_v,
                r.u_v,
                r.zeta_l2,
                r.zeta_min,
                r.min_zeta,
                r.slip_nodes,
                r.max_slip_speed,
                r.steps,
                r.wall_s,
                r.cached
            );
        }
        out
    }

    /// The table as aligned text.
    pub fn text_table(&self) -> String {
        let mut out = format!("Sweep {} ({} members)\n", self.name, self.rows.len());
        for line in self.csv().lines() {
            let cells: Vec<String> = line.split(',').map(|c| format!("{c:>14}")).collect();
            out.push_str(cells.join(" ").trim_end());
            out.push('\n');
        }
        out
    }
}

/// An SVG plot of `quantity` (one of [`QUANTITIES`]) against the varied `against` pointer
/// (numeric values), one line per combination of the other pointers' values; None when the
/// quantity or pointer is unknown.
pub fn plot_svg(result: &SweepResult, quantity: &str, against: &str) -> Option<String> {
    if !QUANTITIES.contains(&quantity) {
        return None;
    }
    let pointers: Vec<&str> = result
        .vary
        .iter()
        .filter_map(|v| v["pointer"].as_str())
        .collect();
    if !pointers.contains(&against) {
        return None;
    }
    // Lines: the rows grouped by the other pointers' values, in the rows' order.
    let mut lines: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for r in &result.rows {
        let label = pointers
            .iter()
            .filter(|p| **p != against)
            .map(|p| format!("{p} = {}", r.values.get(*p).unwrap_or(&Value::Null)))
            .collect::<Vec<_>>()
            .join(", ");
        let x = r
            .values
            .get(against)
            .and_then(|v| scene::parse_ratio(v).ok());
        let (Some(x), Some(y)) = (x, r.quantity(quantity)) else {
            continue;
        };
        match lines.iter_mut().find(|(l, _)| *l == label) {
            Some((_, pts)) => pts.push((x, y)),
            None => lines.push((label, vec![(x, y)])),
        }
    }
    for (_, pts) in &mut lines {
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    let all: Vec<(f64, f64)> = lines.iter().flat_map(|(_, p)| p.iter().copied()).collect();
    let (w, h, left, right, top, bottom) = (640.0, 400.0, 70.0, 200.0, 30.0, 50.0);
    let range = |v: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
        if !lo.is_finite() {
            (0.0, 1.0)
        } else if hi - lo <= f64::EPSILON * hi.abs().max(1.0) {
            (
                lo - 0.5 * lo.abs().max(1e-12),
                hi + 0.5 * hi.abs().max(1e-12),
            )
        } else {
            (lo, hi)
        }
    };
    let (x0, x1) = range(&mut all.iter().map(|p| p.0));
    let (y0, y1) = range(&mut all.iter().map(|p| p.1));
    let px = |x: f64| left + (x - x0) / (x1 - x0) * (w - left - right);
    let py = |y: f64| h - bottom - (y - y0) / (y1 - y0) * (h - top - bottom);
    const COLOURS: &[&str] = &[
        "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
    ];
    let esc = |s: &str| {
        s.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
            .replace('"', "&quot;")
    };
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <title>{} against {} ({})</title>\n<rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\n",
        esc(quantity),
        esc(against),
        esc(&result.name)
    );
    let (ax0, ax1, ay0, ay1) = (left, w - right, h - bottom, top);
    let _ = writeln!(
        svg,
        "<path d=\"M{ax0} {ay1}V{ay0}H{ax1}\" fill=\"none\" stroke=\"#333\"/>"
    );
    for i in 0..=4 {
        let fx = x0 + (x1 - x0) * i as f64 / 4.0;
        let fy = y0 + (y1 - y0) * i as f64 / 4.0;
        let _ = writeln!(
            svg,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\n<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            px(fx),
            ay0 + 16.0,
            short(fx),
            ax0 - 6.0,
            py(fy) + 4.0,
            short(fy)
        );
    }
    let _ = writeln!(
        svg,
        "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\n<text x=\"14\" y=\"{:.1}\" text-anchor=\"middle\" transform=\"rotate(-90 14 {:.1})\">{}</text>",
        (ax0 + ax1) / 2.0,
        h - 10.0,
        esc(against),
        (ay0 + ay1) / 2.0,
        (ay0 + ay1) / 2.0,
        esc(quantity)
    );
    for (i, (label, pts)) in lines.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        let d: Vec<String> = pts
            .iter()
            .enumerate()
            .map(|(j, &(x, y))| {
                format!(
                    "{}{:.2} {:.2}",
                    if j == 0 { 'M' } else { 'L' },
                    px(x),
                    py(y)
                )
            })
            .collect();
        let _ = writeln!(
            svg,
            "<g class=\"line\"><title>{}</title><path d=\"{}\" fill=\"none\" stroke=\"{c}\" stroke-width=\"2\"/>",
            esc(label),
            d.join("")
        );
        for &(x, y) in pts {
            let _ = writeln!(
                svg,
                "<circle cx=\"{:.2}\" cy=\"{:.2}\" r=\"3\" fill=\"{c}\"/>",
                px(x),
                py(y)
            );
        }
        let ly = top + 16.0 * i as f64;
        let _ = writeln!(
            svg,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"12\" height=\"3\" fill=\"{c}\"/><text x=\"{:.1}\" y=\"{:.1}\">{}</text></g>",
            ax1 + 12.0,
            ly - 4.0,
            ax1 + 28.0,
            ly,
            esc(if label.is_empty() { quantity } else { label })
        );
    }
    svg.push_str("</svg>\n");
    Some(svg)
}

/// A tick label: 4 significant digits.
fn short(x: f64) -> String {
    let s = format!("{:.4}", x);
    if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e5) {
        format!("{x:.3e}")
    } else {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

#[cfg(test)]
mod tests;
