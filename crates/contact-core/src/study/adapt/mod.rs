//! An adaptive study (docs/src/explanation/a-posteriori.md#adaptive-studies): the scene's
//! run repeated on meshes refined where its a posteriori estimate ([`crate::a_posteriori`])
//! says the error is, until the estimate meets a target.
//!
//! ```json
//! {"name": "...", "scene": {...} | "l-bracket",
//!  "adapt": {"target": 0.01, "quantity": "w", "theta": 0.5, "max_nodes": 20000,
//!            "max_cycles": 12, "uniform": true},
//!  "reference": {"refine": 3}}
//! ```
//!
//! ```text
//! M_0 = the scene's mesh
//! for i = 0, 1, …:
//!     run the scene on M_i to t = T, estimating every step          (3.10) ∥ (3.13)
//!     a_T = k Σ_n η_{T,n}²   the velocity's spatial indicators over the run
//!     η = the velocity's whole estimate (time part too) / (k Σ_n |w_n|²_V)^½
//!     stop if η ≤ target, or i = max_cycles, or the time part dominates η (its square more
//!         than half of η²: only a smaller k reduces it)
//!     M = Dörfler(a, θ)                                              [`dorfler`]
//!     M_{i+1} = bisection of M_i refining M, closed                  [`crate::mesh::bisect`]
//!     stop (M_i final) if M_{i+1} has more than max_nodes nodes or does not fit the memory limit
//! ```
//!
//! The time step is the scene's throughout: the study adapts the mesh. Cells are marked by
//! the spatial indicators (element, jump, traction, friction), which refinement reduces;
//! the estimate compared with the target carries the time part too (each row gives its
//! share), so a target below what k allows is not reached (the cycles then stop at the node
//! budget, and the result says so).
//!
//! Beside the cycles, the **uniform line**: the initial mesh with every cell bisected d, 2d, …
//! times (h/2, h/4, …), run while it has fewer nodes than the last cycle, so that the
//! estimate (and the true error) can be compared at equal unknowns. With a **reference**
//! (`"refine": r`: the initial mesh's cells bisected r·d times, h/2^r), each run's true error
//! (k Σ_n |w(t_n) − w_h(t_n)|²_V)^½ / (k Σ_n |w(t_n)|²_V)^½ is measured on it ([`nested`]):
//! bisection meshes of one initial mesh are nested in the uniform bisection of the same
//! depth, so a cycle whose cells are bisected at most r·d times is interpolated onto the
//! reference exactly. A cycle refined deeper than the reference has no true error (None).
//!
//! The last cycle is the study's run: its stored steps go to the [`Sink`] (each cycle
//! restarts it), its summary is the result's, and its mesh is [`AdaptResult::final_msh`].

pub mod dorfler;
mod nested;
mod result;

pub use result::{AdaptResult, Row, Stop};

use super::spec::{field_error, given_scene, scene_document, study_name};
use super::target::Sink;
use super::{Execution, StudyError};
use crate::admission::{self, Fit, LimitError, Limits, Pointers};
use crate::mesh::bisect::Bisection;
use crate::mesh::{AnyMesh, Mesh};
use crate::problem::{Body, Problem};
use crate::run::{Hooks, Run, RunError};
use crate::scene::{self, ValidationErrors};
use crate::solve::stepper::StepReport;
use nested::Reference;
use serde_json::{json, Map, Value};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

const FIELDS: &[&str] = &["name", "scene", "adapt", "reference"];
const ADAPT_FIELDS: &[&str] = &[
    "target",
    "quantity",
    "theta",
    "max_nodes",
    "max_cycles",
    "uniform",
];
/// Dörfler's θ when the request gives none.
pub const DEFAULT_THETA: f64 = 0.5;
/// Cycles at most when the request gives no `max_cycles`.
pub const DEFAULT_MAX_CYCLES: usize = 12;
/// Nodes at most when the request gives no `max_nodes`.
pub const DEFAULT_MAX_NODES: usize = 100_000;
/// `reference.refine` at most (h/2^r; the node budget bounds it further).
pub const MAX_REFERENCE_REFINE: usize = 8;

/// A study document is an adaptive study when it has `adapt`.
pub fn is_adapt(doc: &Value) -> bool {
    doc.get("adapt").is_some()
}

/// A validated adaptive study.
#[derive(Debug, Clone)]
pub struct AdaptSpec {
    pub name: String,
    /// The scene document (a preset name expanded).
    pub scene: Value,
    /// The scene as given: its mesh is the first cycle's.
    pub base: Problem,
    /// The relative estimate of w to reach.
    pub target: f64,
    pub theta: f64,
    /// Given: refused at admission above the per-job node limit. None: the smaller of
    /// [`DEFAULT_MAX_NODES`] and that limit.
    pub max_nodes: Option<usize>,
    pub max_cycles: usize,
    /// Run the uniform line beside the cycles.
    pub uniform: bool,
    /// `reference.refine`: the true error is measured on the initial mesh bisected r·d times.
    pub reference: Option<usize>,
    /// The target bounds the estimate's spatial part ([`Row::space_estimate`]), and the
    /// cycles do not stop for a dominant time part: how a target study compares adaptive
    /// meshes with a uniform one at the same k (`crate::study::target`). False for a
    /// request's adaptive study.
    pub spatial: bool,
}

/// Reads an adaptive study (`doc` at JSON pointer `at`), with the meshes a scene names looked
/// up in `files`; the expanded document is what a job stores.
pub fn parse_with(
    doc: &Value,
    at: &str,
    files: &dyn scene::MeshFiles,
) -> Result<(AdaptSpec, Value), ValidationErrors> {
    let err = |p: &str, m: String| field_error(at, p, m);
    let Some(obj) = doc.as_object() else {
        return Err(err("", "a study must be an object".into()));
    };
    for k in obj.keys() {
        if !FIELDS.contains(&k.as_str()) {
            let why = if ["h", "k", "target"].contains(&k.as_str()) {
                format!("an adaptive study refines the scene's mesh itself: remove {k:?}")
            } else {
                format!(
                    "unknown field {k:?} in an adaptive study (allowed: {})",
                    FIELDS.join(", ")
                )
            };
            return Err(err(&format!("/{k}"), why));
        }
    }
    let name = study_name(obj, at)?;
    let Some(adapt) = obj.get("adapt").and_then(Value::as_object) else {
        return Err(err(
            "/adapt",
            "adapt must be an object {\"target\": 0.01, \"theta\": 0.5, \"max_nodes\": 20000}"
                .into(),
        ));
    };
    for k in adapt.keys() {
        if !ADAPT_FIELDS.contains(&k.as_str()) {
            return Err(err(
                &format!("/adapt/{k}"),
                format!("unknown field {k:?} (allowed: {})", ADAPT_FIELDS.join(", ")),
            ));
        }
    }
    let target = match adapt.get("target").and_then(Value::as_f64) {
        Some(e) if e > 0.0 && e < 1.0 => e,
        _ => {
            return Err(err(
                "/adapt/target",
                "target must be a relative estimate between 0 and 1 (exclusive), e.g. 0.01".into(),
            ))
        }
    };
    if let Some(q) = adapt.get("quantity") {
        if q.as_str() != Some("w") {
            return Err(err(
                "/adapt/quantity",
                format!("quantity must be \"w\" (the velocity's estimate in |·|_V; the estimator's damage part has other units and is not targeted), got {q}"),
            ));
        }
    }
    let theta = match adapt.get("theta") {
        None => DEFAULT_THETA,
        Some(v) => match v.as_f64() {
            Some(t) if t > 0.0 && t <= 1.0 => t,
            _ => {
                return Err(err(
                    "/adapt/theta",
                    format!(
                    "theta (Dörfler's share of the estimate to refine) must be in (0, 1], got {v}"
                ),
                ))
            }
        },
    };
    let count = |key: &str, default: usize, min: u64, max: u64| match adapt.get(key) {
        None => Ok(default),
        Some(v) => match v.as_u64() {
            Some(n) if (min..=max).contains(&n) => Ok(n as usize),
            _ => Err(err(
                &format!("/adapt/{key}"),
                format!("{key} must be a whole number from {min} to {max}, got {v}"),
            )),
        },
    };
    let max_nodes = match adapt.get("max_nodes") {
        None => None,
        Some(_) => Some(count(
            "max_nodes",
            DEFAULT_MAX_NODES,
            4,
            crate::mesh::import::MAX_NODES as u64,
        )?),
    };
    let max_cycles = count("max_cycles", DEFAULT_MAX_CYCLES, 1, 40)?;
    let uniform = match adapt.get("uniform") {
        None => true,
        Some(Value::Bool(b)) => *b,
        Some(v) => {
            return Err(err(
                "/adapt/uniform",
                format!("uniform must be true or false, got {v}"),
            ))
        }
    };
    let reference = match obj.get("reference") {
        None => None,
        Some(r) => {
            let Some(o) = r.as_object() else {
                return Err(err(
                    "/reference",
                    "reference must be an object {\"refine\": r}".into(),
                ));
            };
            if let Some(k) = o.keys().find(|k| *k != "refine") {
                return Err(err(
                    &format!("/reference/{k}"),
                    format!("unknown field {k:?}: an adaptive study's reference is the initial mesh refined uniformly (allowed: refine)"),
                ));
            }
            match o.get("refine").and_then(Value::as_u64) {
                Some(n) if (1..=MAX_REFERENCE_REFINE as u64).contains(&n) => Some(n as usize),
                _ => {
                    return Err(err(
                        "/reference/refine",
                        format!("refine must be a whole number from 1 to {MAX_REFERENCE_REFINE} (the reference's h is the initial mesh's ÷ 2^refine)"),
                    ))
                }
            }
        }
    };
    let scene_doc = scene_document(obj, at)?;
    let base = given_scene(&scene_doc, at, files)?;
    let mut expanded = Map::new();
    if let Some(n) = &name {
        expanded.insert("name".into(), json!(n));
    }
    expanded.insert("scene".into(), scene_doc.clone());
    expanded.insert(
        "adapt".into(),
        json!({"target": target, "quantity": "w", "theta": theta,
               "max_cycles": max_cycles, "uniform": uniform}),
    );
    if let Some(n) = max_nodes {
        expanded["adapt"]["max_nodes"] = json!(n);
    }
    if let Some(r) = reference {
        expanded.insert("reference".into(), json!({"refine": r}));
    }
    let spec = AdaptSpec {
        name: name.unwrap_or_else(|| format!("adaptive study of {}", base.name)),
        scene: scene_doc,
        base,
        target,
        theta,
        max_nodes,
        max_cycles,
        uniform,
        reference,
        spatial: false,
    };
    Ok((spec, Value::Object(expanded)))
}

impl AdaptSpec {
    /// The runs known before the study against `limits`: the first cycle, and the reference
    /// (estimated as the red refinement of the initial mesh r times, which has the uniform
    /// bisection's nodes); the node budget against the node limit. Returns the progress scale
    /// (steps of those runs) and the larger of them.
    pub fn admit(&self, limits: &Limits, at: &str) -> Result<(usize, Fit), LimitError> {
        let per_run = Limits {
            max_stored_bytes: None,
            max_steps: None,
            ..*limits
        };
        let scene = format!("{at}/scene");
        let pointers = |mesh: String| Pointers {
            mesh,
            steps: scene.clone(),
            output: scene.clone(),
            solver: None,
        };
        let mut largest = admission::check_run(&self.base, &per_run, &pointers(scene.clone()))?;
        let mut steps = self.base.steps;
        if let Some(r) = self.reference {
            let fine = self.on_red_refinement(r);
            let fit =
                admission::check_run(&fine, &per_run, &pointers(format!("{at}/reference/refine")))
                    .map_err(|e| LimitError {
                        message: format!("the reference ({r} uniform refinements): {}", e.message),
                        ..e
                    })?;
            steps += fine.steps;
            if fit.memory_bytes > largest.memory_bytes {
                largest = fit;
            }
        }
        if let (Some(n), Some(max)) = (self.max_nodes, limits.max_nodes) {
            if n > max {
                return Err(LimitError {
                    pointer: format!("{at}/adapt/max_nodes"),
                    limit: admission::Limit::Nodes,
                    needed: n as u64,
                    allowed: max as u64,
                    message: format!(
                        "max_nodes is {n}, more than the per-job limit of {max} nodes"
                    ),
                });
            }
        }
        if let Some(max) = limits.max_steps.filter(|&m| steps > m) {
            return Err(LimitError {
                pointer: scene,
                limit: admission::Limit::Steps,
                needed: steps as u64,
                allowed: max as u64,
                message: format!("the first cycle and the reference take {steps} time steps, more than the per-job limit of {max}"),
            });
        }
        Ok((steps, largest))
    }

    /// The scene on its initial mesh refined red `r` times (admission's stand-in for the
    /// reference: the same nodes).
    fn on_red_refinement(&self, r: usize) -> Problem {
        let base = match &self.base.body {
            Some(b) => b.base.refined(b.refine),
            None => self
                .base
                .any_mesh()
                .expect("the scene's mesh was tagged at validation"),
        };
        Problem {
            body: Some(Arc::new(Body::new("reference".into(), base, r))),
            ..self.base.clone()
        }
    }

    /// The scene document run on a stored mesh called `mesh` (the final mesh, uploaded):
    /// the same scene with `domain` that mesh, unrefined, its output estimating.
    pub fn scene_on(&self, mesh: &str) -> Value {
        super::spec::scene_on_mesh(&self.scene, mesh)
    }
}

/// The scene on `mesh`, estimating every step, without the (2h, 2k) error estimate.
fn on_mesh<const D: usize>(base: &Problem, mesh: &Mesh<D>, source: String) -> Problem {
    on_any_mesh(base, AnyMesh::from_mesh(mesh.clone()), source)
}

/// [`on_mesh`] for a mesh of either dimension.
pub(crate) fn on_any_mesh(base: &Problem, mesh: AnyMesh, source: String) -> Problem {
    let mut p = base.clone();
    p.body = Some(Arc::new(Body::new(source, mesh, 0)));
    p.cells_per_unit = 0;
    p.output.estimate = true;
    p.error_estimate = false;
    p
}

/// The geometric multigrid levels of the cycle whose mesh has the last of `sizes` nodes:
/// earlier cycles' meshes, each at least 2^d times coarser than the next (as a red
/// refinement is), down to the initial mesh and then its own red refinements' levels. The
/// meshes are nested: bisection keeps every node and appends midpoints (`midpoints[k]` made
/// node n0 + k), so a level is the node count of an earlier cycle and the midpoints since.
/// Empty (smoothed aggregation) while no earlier cycle is coarse enough.
fn levels<const D: usize>(
    initial: &Mesh<D>,
    midpoints: &[[usize; 2]],
    sizes: &[usize],
) -> Vec<crate::mesh::Nesting> {
    let n0 = initial.n_nodes();
    let n = *sizes.last().expect("the cycle's own size");
    let mut chosen = vec![n];
    while let Some(c) = sizes
        .iter()
        .copied()
        .filter(|&c| c << D <= *chosen.last().expect("not empty"))
        .max()
    {
        chosen.push(c);
    }
    if chosen.len() == 1 {
        return Vec::new();
    }
    let mut out = if chosen.last() == Some(&n0) {
        initial.nesting.clone()
    } else {
        Vec::new()
    };
    for pair in chosen.windows(2).rev() {
        let (fine, coarse) = (pair[0], pair[1]);
        out.push(crate::mesh::Nesting {
            coarse_nodes: coarse,
            midpoints: midpoints[coarse - n0..fine - n0].to_vec(),
        });
    }
    out
}

/// What one run gives the study: the velocity's squared indicators over the run per cell,
/// w at the kept steps, and its summary.
struct Ran {
    squares: Vec<f64>,
    w: Vec<Vec<f64>>,
    summary: crate::output::Summary,
    seconds: f64,
}

/// The hooks of one run: accumulate a_T, keep w where asked, stream stored steps to the sink
/// (the cycles), count progress.
struct Collect<'a> {
    squares: Vec<f64>,
    keep: &'a dyn Fn(usize) -> bool,
    w: Vec<Vec<f64>>,
    sink: Option<&'a mut dyn Sink>,
    tick: &'a (dyn Fn() -> ControlFlow<()> + Sync),
}

impl<const D: usize> Hooks<D> for Collect<'_> {
    type Stop = Option<std::io::Error>;

    fn stored_step(&mut self, run: &Run<D>, _: &StepReport) -> ControlFlow<Self::Stop> {
        match self.sink.as_mut().map(|s| s.step(&run.sim().fields())) {
            Some(Err(e)) => ControlFlow::Break(Some(e)),
            _ => ControlFlow::Continue(()),
        }
    }

    fn after_step(&mut self, run: &Run<D>, r: &StepReport) -> ControlFlow<Self::Stop> {
        // The cycle's mesh is the bisection's: w and the indicators in its numbering.
        let sim = run.sim();
        if let Some(e) = sim.step_estimate() {
            let k = sim.problem.k();
            if self.squares.is_empty() {
                self.squares = vec![0.0; e.velocity.len()];
            }
            for (a, v) in self.squares.iter_mut().zip(sim.cells_out(&e.velocity)) {
                *a += k * v * v;
            }
        }
        if (self.keep)(r.n) {
            self.w.push(sim.nodes_out(&sim.w, D));
        }
        match (self.tick)() {
            ControlFlow::Break(()) => ControlFlow::Break(None),
            ControlFlow::Continue(()) => ControlFlow::Continue(()),
        }
    }
}

/// Runs `problem` to t = T with [`Collect`].
fn run_one<'a, const D: usize>(
    problem: Problem,
    exec: Execution,
    keep: &'a dyn Fn(usize) -> bool,
    sink: Option<&'a mut dyn Sink>,
    tick: &'a (dyn Fn() -> ControlFlow<()> + Sync),
) -> Result<Ran, StudyError> {
    let start = Instant::now();
    let settings = crate::solve::SolverSettings {
        threads: exec.threads,
        ..exec.settings
    };
    let mut run = Run::<D>::new(problem, settings).map_err(RunError::from)?;
    let mut hooks = Collect {
        squares: Vec::new(),
        keep,
        w: Vec::new(),
        sink,
        tick,
    };
    match run.drive(&mut hooks).map_err(RunError::from)? {
        ControlFlow::Continue(()) => {}
        ControlFlow::Break(Some(e)) => return Err(StudyError::Output(e)),
        ControlFlow::Break(None) => return Err(StudyError::Cancelled),
    }
    let Collect { squares, w, .. } = hooks;
    Ok(Ran {
        squares,
        w,
        summary: run.summary(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Runs an adaptive study. `progress(done, total)` after every time step of every run (the
/// total grows with the cycles); `Break` cancels. `limits.max_memory` bounds every run: a
/// cycle whose mesh does not fit ends the study at the cycle before.
pub fn run(
    spec: &AdaptSpec,
    exec: Execution,
    limits: Limits,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    sink: &mut dyn Sink,
) -> Result<AdaptResult, StudyError> {
    match spec.base.dim() {
        2 => run_in::<2>(spec, exec, limits, progress, sink),
        _ => run_in::<3>(spec, exec, limits, progress, sink),
    }
}

fn run_in<const D: usize>(
    spec: &AdaptSpec,
    exec: Execution,
    limits: Limits,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    sink: &mut dyn Sink,
) -> Result<AdaptResult, StudyError> {
    let steps = spec.base.steps;
    let done = AtomicUsize::new(0);
    let total = AtomicUsize::new(0);
    let tick = || {
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress(d, total.load(Ordering::Relaxed).max(d))
    };
    let initial: Mesh<D> = spec.base.mesh().map_err(|e| {
        RunError::Solve(crate::solve::SolveError::Data {
            pointer: format!("/boundary/{}", e.part()),
            message: e.to_string(),
        })
    })?;
    let fits = |p: &Problem| crate::memory::choose(p, limits.max_memory).is_ok();
    let max_nodes = spec
        .max_nodes
        .unwrap_or(DEFAULT_MAX_NODES.min(limits.max_nodes.unwrap_or(DEFAULT_MAX_NODES)));

    // The reference first: every cycle's true error is measured on it as the cycle ends.
    let reference = match spec.reference {
        None => None,
        Some(r) => {
            let uniform = nested::uniform(&initial, r * D);
            let problem = on_mesh(
                &spec.base,
                uniform.mesh(),
                format!("reference, h/{}", 1 << r),
            );
            total.fetch_add(steps, Ordering::Relaxed);
            let keep = nested::Kept::within(steps, D * uniform.mesh().n_nodes());
            let ran = run_one::<D>(problem, exec, &|n| keep.has(n), None, &tick)?;
            Some(Reference::new(
                uniform,
                ran.w,
                keep,
                &ran.summary,
                ran.seconds,
            ))
        }
    };
    let keep = |n: usize| reference.as_ref().is_some_and(|r| r.keep.has(n));
    let error = |b: &Bisection<D>, w: &[Vec<f64>]| reference.as_ref().and_then(|r| r.error(b, w));

    let mut bisection = Bisection::new(&initial);
    let mut cycles: Vec<Row> = Vec::new();
    let mut last: Option<(Ran, Mesh<D>)>;
    // The midpoints that made every node after the initial mesh's, in node order, and the
    // node count of each cycle's mesh: the multigrid levels of the next.
    let mut midpoints: Vec<[usize; 2]> = Vec::new();
    let mut sizes: Vec<usize> = Vec::new();
    let stop = loop {
        let i = cycles.len();
        let mut mesh = bisection.mesh().clone();
        sizes.push(mesh.n_nodes());
        mesh.nesting = levels(&initial, &midpoints, &sizes);
        let problem = on_mesh(&spec.base, &mesh, format!("adaptive cycle {i}"));
        sink.restart().map_err(StudyError::Output)?;
        total.fetch_add(steps, Ordering::Relaxed);
        let ran = run_one::<D>(problem, exec, &keep, Some(&mut *sink), &tick)?;
        let generation = (0..mesh.n_cells()).map(|c| bisection.generation(c)).max();
        cycles.push(Row::new(
            &ran.summary,
            generation.unwrap_or(0),
            ran.seconds,
            error(&bisection, &ran.w),
        ));
        let estimate = if spec.spatial {
            cycles[i].space_estimate()
        } else {
            cycles[i].estimate
        };
        let squares = ran.squares.clone();
        last = Some((ran, mesh));
        if estimate <= spec.target {
            break Stop::Target;
        }
        if i + 1 >= spec.max_cycles {
            break Stop::MaxCycles;
        }
        if !spec.spatial && cycles[i].time_share > std::f64::consts::FRAC_1_SQRT_2 {
            break Stop::TimeStep;
        }
        let marked = dorfler::mark(&squares, spec.theta);
        if marked.is_empty() {
            break Stop::NothingToRefine;
        }
        let mut next = bisection.clone();
        let step = next.refine(&marked);
        cycles[i].marked = Some(marked.len());
        if step.mesh.n_nodes() > max_nodes {
            break Stop::MaxNodes;
        }
        if !fits(&on_mesh(&spec.base, &step.mesh, String::new())) {
            break Stop::Memory;
        }
        midpoints.extend(step.midpoints.iter().map(|&(_, ends)| ends));
        bisection = next;
    };
    let (final_run, final_mesh) = last.expect("an adaptive study runs its first cycle");

    // The uniform line up to the last cycle's nodes (the first cycle is its first point).
    let mut uniform = vec![Row {
        marked: None,
        ..cycles[0].clone()
    }];
    if spec.uniform {
        let last_nodes = final_mesh.n_nodes();
        let mut depth = D;
        loop {
            if spec.reference.is_some_and(|r| depth >= r * D) {
                break;
            }
            let b = nested::uniform(&initial, depth);
            let problem = on_mesh(
                &spec.base,
                b.mesh(),
                format!("uniform, h/{}", 1 << (depth / D)),
            );
            if b.mesh().n_nodes() > max_nodes.max(last_nodes) || !fits(&problem) {
                break;
            }
            total.fetch_add(steps, Ordering::Relaxed);
            let ran = run_one::<D>(problem, exec, &keep, None, &tick)?;
            uniform.push(Row::new(
                &ran.summary,
                depth,
                ran.seconds,
                error(&b, &ran.w),
            ));
            if b.mesh().n_nodes() >= last_nodes {
                break;
            }
            depth += D;
        }
    }
    Ok(AdaptResult {
        kind: "adapt",
        name: spec.name.clone(),
        quantity: "w",
        target: spec.target,
        theta: spec.theta,
        max_nodes,
        reached: stop == Stop::Target,
        stopped: stop,
        reference: reference.map(|r| r.row),
        cycles,
        uniform,
        summary: final_run.summary,
        scene: spec.scene.clone(),
        final_mesh: AnyMesh::from_mesh(final_mesh),
    })
}

#[cfg(test)]
mod tests;
