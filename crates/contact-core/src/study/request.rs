//! A study request, read, limited and executed in one place: the service's route (at
//! submission), its worker (the run) and `contact-sim study` call this, so a study meets the
//! same limits wherever it is submitted and run.
//!
//! - [`parse`]: the study document into a [`Request`] — a ladder ([`super::spec`]) or a
//!   target ([`super::target`]) — and the expanded document a job stores;
//! - [`Request::admit`]: every run the study will make against the host's per-job
//!   [`Limits`] ([`crate::admission`]), before any run: nodes, memory on the linear path each
//!   run takes, and steps; a run that does not fit is refused at the member that sets its size
//!   (`/study/reference/h`, `/study/h/2`, `/study/scene` for a target's pilots);
//! - [`Request::execute`]: the study under the same limits (each run's set-up refuses a path
//!   that does not fit; concurrent runs share the memory limit, [`super::schedule`]).

use super::adapt::{self, AdaptResult, AdaptSpec};
use super::sweep::{self, Known, SweepResult, SweepSpec};
use super::target::{self, Sink, TargetSpec};
use super::{Execution, Plan, ReferenceCache, StudyError, StudyResult, TargetResult};
use crate::admission::{self, Fit, Limit, LimitError, Limits, Pointers};
use crate::scene::{MeshFiles, ValidationErrors};
use crate::solve::SolverSettings;
use serde_json::Value;
use std::ops::ControlFlow;

/// A validated study request.
#[derive(Debug, Clone)]
pub enum Request {
    /// Levels compared with a reference run.
    Ladder(Plan),
    /// The cheapest run meeting a target error. `at` is the request's pointer to the study
    /// (its pilots are refused at `{at}/scene`).
    Target { spec: TargetSpec, at: String },
    /// Members of one scene with values substituted at JSON pointers ([`super::sweep`]).
    Sweep(Box<SweepSpec>),
    /// Cycles of run, estimate, mark and refine to a target estimate ([`super::adapt`]).
    /// `at` as for a target.
    Adapt { spec: Box<AdaptSpec>, at: String },
}

/// Reads the sweep object `doc` at `at` (`/sweep`), as [`parse`] reads a study.
pub fn parse_sweep(
    doc: &Value,
    at: &str,
    files: &dyn MeshFiles,
) -> Result<(Request, Value), ValidationErrors> {
    let (spec, expanded) = sweep::parse_with(doc, at, files)?;
    Ok((Request::Sweep(Box::new(spec)), expanded))
}

/// Reads the study object `doc`, located at JSON pointer `at` in the request (errors point
/// there), with the meshes a scene names looked up in `files`. Returns the request and the
/// expanded document (presets resolved), which is what a job stores.
pub fn parse(
    doc: &Value,
    at: &str,
    files: &dyn MeshFiles,
) -> Result<(Request, Value), ValidationErrors> {
    // A preset of any kind is read as its document.
    if let Some(name) = doc.get("preset").and_then(Value::as_str) {
        if let (Some(expanded), 1) = (
            super::presets::get(name),
            doc.as_object().map_or(0, |o| o.len()),
        ) {
            return parse(&expanded, at, files);
        }
    }
    if adapt::is_adapt(doc) {
        let (spec, expanded) = adapt::parse_with(doc, at, files)?;
        return Ok((
            Request::Adapt {
                spec: Box::new(spec),
                at: at.to_string(),
            },
            expanded,
        ));
    }
    if target::is_target(doc) {
        let (spec, expanded) = target::parse_with(doc, at, files)?;
        Ok((
            Request::Target {
                spec,
                at: at.to_string(),
            },
            expanded,
        ))
    } else {
        let (plan, expanded) = super::spec::parse_with(doc, at, files)?;
        Ok((Request::Ladder(plan), expanded))
    }
}

/// What admission found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Admission {
    /// Time steps of the runs known before the study starts (its progress scale; a target
    /// study's first pilots).
    pub steps: usize,
    /// The run with the largest predicted peak: its path and bytes.
    pub largest: Fit,
}

/// How a study is run: where its reference runs are cached, its threads and solver settings
/// (the memory limit of `settings` is replaced by the limits'), the host's limits, the
/// progress hook (steps done, steps in all; `Break` cancels) and where a target study's chosen
/// run writes its stored steps.
pub struct Context<'a> {
    pub cache: &'a ReferenceCache,
    pub threads: usize,
    pub settings: SolverSettings,
    pub limits: Limits,
    pub progress: &'a (dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    pub sink: &'a mut dyn Sink,
}

/// A finished study.
#[derive(Debug, Clone)]
pub enum Outcome {
    Ladder(Box<StudyResult>),
    Target(Box<TargetResult>),
    Sweep(Box<SweepResult>),
    Adapt(Box<AdaptResult>),
}

impl Request {
    /// The study's name.
    pub fn name(&self) -> &str {
        match self {
            Request::Ladder(plan) => &plan.name,
            Request::Target { spec, .. } => &spec.name,
            Request::Sweep(spec) => &spec.name,
            Request::Adapt { spec, .. } => &spec.name,
        }
    }

    /// Every run of the study against `limits`, before any of them: the first that does not
    /// fit, or the study's progress scale and its largest run.
    ///
    /// A ladder: the reference, then each level, each alone against the node and memory
    /// limits (they may run at the same time, but the schedule never lets more predicted
    /// bytes run at once than the limit, [`super::schedule`]); all runs' steps together
    /// against the step limit. It stores no steps. A target: its first pilot runs alone
    /// (the runs the plan chooses later are held to the same limits by the plan).
    pub fn admit(&self, limits: &Limits) -> Result<Admission, LimitError> {
        // A study's runs store no steps (a target's chosen run is held to the stored-bytes
        // limit when it is chosen); the step limit counts the whole study.
        let per_run = Limits {
            max_stored_bytes: None,
            max_steps: None,
            ..*limits
        };
        match self {
            Request::Ladder(plan) => {
                let [ref_h, ref_k] = &plan.reference_pointers;
                let mut runs = vec![(plan.reference, ref_h, ref_k, "the reference")];
                for (level, [h, k]) in plan.levels.iter().zip(&plan.level_pointers) {
                    runs.push((*level, h, k, "a level"));
                }
                let mut largest: Option<Fit> = None;
                for (level, h, k, what) in runs {
                    let p = super::with(&plan.base, level);
                    let at = Pointers {
                        mesh: h.clone(),
                        steps: k.clone(),
                        output: String::new(),
                        solver: None,
                    };
                    let fit = admission::check_run(&p, &per_run, &at).map_err(|e| {
                        let h = super::format::fraction(1.0 / level.0 as f64);
                        let k = super::format::fraction(p.t_end / level.1 as f64);
                        let run = match p.body {
                            Some(_) => format!("refine = {}", level.0.trailing_zeros()),
                            None => format!("h = {h}"),
                        };
                        LimitError {
                            message: format!("{what} ({run}, k = {k}): {}", e.message),
                            ..e
                        }
                    })?;
                    if largest.is_none_or(|l| fit.memory_bytes > l.memory_bytes) {
                        largest = Some(fit);
                    }
                }
                let steps = super::total_steps(plan);
                if let Some(max) = limits.max_steps.filter(|&m| steps > m) {
                    return Err(LimitError {
                        pointer: ref_k.clone(),
                        limit: Limit::Steps,
                        needed: steps as u64,
                        allowed: max as u64,
                        message: format!(
                            "the study's runs take {steps} time steps in all, more than the per-job limit of {max}"
                        ),
                    });
                }
                Ok(Admission {
                    steps,
                    largest: largest.expect("a study has a reference"),
                })
            }
            Request::Target { spec, at } => {
                let scene = format!("{at}/scene");
                let pointers = Pointers {
                    mesh: scene.clone(),
                    steps: scene.clone(),
                    output: scene.clone(),
                    solver: None,
                };
                let mut largest: Option<Fit> = None;
                for level in spec.first_pilots() {
                    let p = super::with(&spec.base, level);
                    let fit =
                        admission::check_run(&p, &per_run, &pointers).map_err(|e| LimitError {
                            message: format!(
                                "even the pilot runs of this scene do not fit: {}",
                                e.message
                            ),
                            ..e
                        })?;
                    if largest.is_none_or(|l| fit.memory_bytes > l.memory_bytes) {
                        largest = Some(fit);
                    }
                }
                Ok(Admission {
                    steps: spec.first_pilot_steps(),
                    largest: largest.expect("a target study has pilots"),
                })
            }
            Request::Sweep(spec) => {
                let (steps, largest) = spec.admit(limits)?;
                Ok(Admission { steps, largest })
            }
            Request::Adapt { spec, at } => {
                let (steps, largest) = spec.admit(limits, at)?;
                Ok(Admission { steps, largest })
            }
        }
    }

    /// Runs the study under `cx.limits`.
    pub fn execute(&self, cx: Context) -> Result<Outcome, StudyError> {
        self.execute_known(cx, &|_| None)
    }

    /// [`Request::execute`], a sweep taking the members `known` knows from there.
    pub fn execute_known(&self, cx: Context, known: &Known) -> Result<Outcome, StudyError> {
        let exec = Execution {
            threads: cx.threads.max(1),
            settings: SolverSettings {
                memory_limit: cx.limits.max_memory,
                ..cx.settings
            },
        };
        match self {
            Request::Ladder(plan) => {
                super::run(plan, cx.cache, exec, cx.progress).map(|r| Outcome::Ladder(Box::new(r)))
            }
            Request::Target { spec, .. } => {
                target::run(spec, exec, cx.limits, cx.progress, cx.sink)
                    .map(|r| Outcome::Target(Box::new(r)))
            }
            Request::Sweep(spec) => {
                sweep::run(spec, exec, cx.progress, known).map(|r| Outcome::Sweep(Box::new(r)))
            }
            Request::Adapt { spec, .. } => adapt::run(spec, exec, cx.limits, cx.progress, cx.sink)
                .map(|r| Outcome::Adapt(Box::new(r))),
        }
    }
}

impl Outcome {
    pub fn name(&self) -> &str {
        match self {
            Outcome::Ladder(r) => &r.name,
            Outcome::Target(r) => &r.name,
            Outcome::Sweep(r) => &r.name,
            Outcome::Adapt(r) => &r.name,
        }
    }

    /// The result document (the job's summary).
    pub fn to_json(&self) -> Value {
        match self {
            Outcome::Ladder(r) => serde_json::to_value(r),
            Outcome::Target(r) => serde_json::to_value(r),
            Outcome::Sweep(r) => serde_json::to_value(r),
            Outcome::Adapt(r) => serde_json::to_value(r),
        }
        .expect("a study result serialises")
    }

    /// The result as the paper's table layout.
    pub fn text_table(&self) -> String {
        match self {
            Outcome::Ladder(r) => r.text_table(),
            Outcome::Target(r) => r.text_table(),
            Outcome::Sweep(r) => r.text_table(),
            Outcome::Adapt(r) => r.text_table(),
        }
    }

    /// The report plots (SVG).
    pub fn report_svg(&self) -> String {
        match self {
            Outcome::Ladder(r) => super::report_svg::study_report(r),
            Outcome::Target(r) => super::report_svg::target_report(r),
            // w_V against the first varied pointer, one line per value of the others.
            Outcome::Sweep(r) => {
                let first = r.vary[0]["pointer"].as_str().unwrap_or_default();
                sweep::plot_svg(r, "w_V", first).unwrap_or_default()
            }
            Outcome::Adapt(r) => super::report_svg::adapt_report(r),
        }
    }

    /// A target study's chosen run's scene document (None for a ladder; a run on an adaptive
    /// mesh has [`Outcome::scene_on`] that mesh, once it is stored somewhere).
    pub fn chosen_scene(&self) -> Option<&Value> {
        match self {
            Outcome::Ladder(_) | Outcome::Sweep(_) | Outcome::Adapt(_) => None,
            Outcome::Target(r) => Some(&r.scene),
        }
    }

    /// The adaptive mesh the study's run is on (an adaptive study's final mesh, a target
    /// study's when it took an adaptive one) as a gmsh MSH 2.2 file.
    pub fn final_msh(&self) -> Option<String> {
        match self {
            Outcome::Adapt(r) => Some(r.final_msh()),
            Outcome::Target(r) => r.final_msh(),
            Outcome::Ladder(_) | Outcome::Sweep(_) => None,
        }
    }

    /// The scene document of the study's run once [`Outcome::final_msh`] is stored as the
    /// mesh called `mesh` ([`super::spec::scene_on_mesh`]); None without a final mesh.
    pub fn scene_on(&self, mesh: &str) -> Option<Value> {
        match self {
            Outcome::Adapt(r) => Some(super::spec::scene_on_mesh(&r.scene, mesh)),
            Outcome::Target(r) => r
                .final_mesh
                .is_some()
                .then(|| super::spec::scene_on_mesh(&r.scene, mesh)),
            Outcome::Ladder(_) | Outcome::Sweep(_) => None,
        }
    }
}

#[cfg(test)]
mod tests;
