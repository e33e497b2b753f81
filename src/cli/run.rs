//! `contact-sim run`: one simulation, its summary on stdout, its files with --out; or the
//! continuation of a finished run (`--continue DIR --t-end T2`) from the state its --out kept.

use super::mesh_files::SceneDir;
use super::{fail, preset, pretty, progress};
use clap::Args;
use contact_core::admission::{self, Limits, Pointers};
use contact_core::mesh::AnyMesh;
use contact_core::output::fields::MeshJson;
use contact_core::output::stored::{decode_state, encode_state};
use contact_core::output::Summary;
use contact_core::problem::{FieldSet, Problem};
use contact_core::run::{Hooks, Run, RunError};
use contact_core::scene::{self, presets, Overrides};
use contact_core::solve::stepper::{State, StepReport};
use contact_core::solve::{SolveError, SolverSettings};
use serde_json::{json, Value};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Args)]
pub struct RunArgs {
    /// Scene file (JSON); omit when using --preset.
    pub scene: Option<PathBuf>,
    /// A built-in scene instead of a file (see `contact-sim presets`).
    #[arg(long)]
    pub preset: Option<String>,
    /// Mesh size: a number or a fraction like 1/32.
    #[arg(long)]
    pub h: Option<String>,
    /// Time step: a number or a fraction like 1/32.
    #[arg(long)]
    pub k: Option<String>,
    /// Final time T.
    #[arg(long = "t-end")]
    pub t_end: Option<String>,
    /// Directory for summary.json, mesh.json and fields/step_NNNNN.json, and what a
    /// continuation needs: scene.json (the scene as run) and state.bin (the last state).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Continue the finished run whose --out folder is DIR to --t-end, with its step k: the
    /// same steps as one run to --t-end (bit for bit on the direct path), numbered from the
    /// parent's start. Takes no scene, --preset, --h or --k.
    #[arg(
        long = "continue",
        value_name = "DIR",
        conflicts_with_all = ["scene", "preset", "h", "k"],
        requires = "t_end"
    )]
    pub continue_from: Option<PathBuf>,
    /// Relative optimality residual of the sub-problem solvers.
    #[arg(long, default_value_t = SolverSettings::default().tolerance)]
    pub tol: f64,
    /// Linear solver path, overriding the scene's `solver.linear`: auto, direct or multigrid.
    #[arg(long = "linear-solver", value_parser = ["auto", "direct", "multigrid"])]
    pub linear_solver: Option<String>,
    /// Precision of the multigrid path's level operators, overriding the scene's
    /// `solver.precision`: auto (mixed in 3D), double or mixed.
    #[arg(long, value_parser = ["auto", "double", "mixed"])]
    pub precision: Option<String>,
    /// Threads of the run (default: all cores). The numbers are the same bits for every
    /// count.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub threads: Option<u64>,
    /// Per-job memory limit in bytes (suffixes K, M, G, T): the run is refused before any
    /// numeric work if its predicted peak exceeds it. Default: 80 % of physical memory.
    #[arg(long = "max-job-memory", value_parser = contact_core::memory::parse_bytes)]
    pub max_job_memory: Option<u64>,
}

pub fn main(args: RunArgs) -> ExitCode {
    let parent = match args.continue_from.as_deref().map(Parent::read) {
        None => None,
        Some(Ok(p)) => Some(p),
        Some(Err(e)) => return fail(2, &e),
    };
    let loaded = match &parent {
        Some(p) => Ok(p.scene.clone()),
        None => load_scene(args.scene.as_deref(), args.preset.as_deref()),
    };
    let mut doc = match loaded {
        Ok(d) => d,
        Err(e) => return fail(2, &e),
    };
    // A number stays a number; anything else ("1/32") is for the scene's ratio parser.
    let to_value = |s: Option<String>| {
        s.map(|s| {
            s.parse::<f64>()
                .map(Value::from)
                .unwrap_or(Value::String(s))
        })
    };
    let overrides = Overrides {
        h: to_value(args.h),
        k: to_value(args.k),
        t_end: to_value(args.t_end),
    };
    scene::apply_overrides(&mut doc, &overrides);
    if let (Some(p), Some(time)) = (&parent, doc.get_mut("time")) {
        // The parent's step k, exactly: the number of steps follows from --t-end.
        *time = json!({"t_end": time["t_end"], "k": p.k});
    }
    for (key, value) in [
        ("linear", &args.linear_solver),
        ("precision", &args.precision),
    ] {
        if let (Some(value), Some(top)) = (value, doc.as_object_mut()) {
            let solver = top.entry("solver").or_insert_with(|| serde_json::json!({}));
            if let Some(s) = solver.as_object_mut() {
                s.insert(key.into(), Value::String(value.clone()));
            }
        }
    }
    // Mesh files are looked up next to the scene file (the working directory for a preset; a
    // continued run's scene names its mesh file by an absolute path).
    let dir = args
        .scene
        .as_deref()
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .unwrap_or_default();
    let scene_as_run = with_absolute_mesh(&doc, &dir);
    let mut problem = match scene::validate_with(&doc, &SceneDir(dir)) {
        Ok(p) => p,
        Err(errors) => {
            eprintln!(
                "{}",
                pretty(&serde_json::json!({"title": "invalid scene", "errors": errors}))
            );
            return ExitCode::from(2);
        }
    };
    if let Some(p) = &parent {
        if let Err(e) = p.check(&problem) {
            return fail(2, &e);
        }
    }
    let fields_dir = args.out.as_ref().map(|d| d.join("fields"));
    if fields_dir.is_none() {
        // Nothing stores the steps' fields, so the run keeps nothing for them.
        problem.output.fields = FieldSet::default();
    }
    if let Some(dir) = &fields_dir {
        if let Err(e) = std::fs::create_dir_all(dir) {
            return fail(1, &format!("cannot create {}: {e}", dir.display()));
        }
    }
    let settings = SolverSettings {
        tolerance: args.tol,
        memory_limit: args
            .max_job_memory
            .or_else(|| contact_core::memory::default_limit(1)),
        threads: args
            .threads
            .map_or_else(contact_core::linalg::par::Threads::available, |t| {
                t as usize
            }),
        ..Default::default()
    };
    // The per-job limits the service admits a job under, here the memory limit alone.
    let limits = Limits {
        max_memory: settings.memory_limit,
        ..Limits::default()
    };
    let at = Pointers {
        mesh: "/mesh".into(),
        ..Pointers::scene()
    };
    if let Err(e) = admission::check_run(&problem, &limits, &at) {
        return refused(&e.pointer, &e.message);
    }
    let done = parent.as_ref().map_or(0, |p| p.state.step);
    let bar = progress::bar((problem.steps - done) as u64, "steps");
    let start = parent.map(|p| (p.state, p.reports));
    let (result, io_error) = match problem.dim() {
        2 => run_writing::<2>(problem, settings, start, fields_dir.as_deref(), &bar),
        _ => run_writing::<3>(problem, settings, start, fields_dir.as_deref(), &bar),
    };
    bar.finish_and_clear();
    match result {
        Ok((summary, state)) => {
            let mut summary = serde_json::to_value(&summary).expect("JSON");
            if let Some(from) = &args.continue_from {
                summary["continued_from"] =
                    json!({"dir": from.display().to_string(), "step": done});
            }
            let text = pretty(&summary);
            if let Some(dir) = &args.out {
                let files = [
                    ("summary.json", text.clone().into_bytes()),
                    (SCENE_FILE, pretty(&scene_as_run).into_bytes()),
                    (STATE_FILE, encode_state(&state)),
                ];
                for (name, bytes) in files {
                    if let Err(e) = std::fs::write(dir.join(name), bytes) {
                        return fail(1, &format!("cannot write {name}: {e}"));
                    }
                }
            }
            outln!("{text}");
            ExitCode::SUCCESS
        }
        Err(RunError::Solve(SolveError::Memory(e))) => refused(e.pointer(), &e.to_string()),
        Err(e) => fail(1, &io_error.unwrap_or_else(|| e.to_string())),
    }
}

/// A run over the memory limit, whether the cheap check or the set-up's exact one found it:
/// the field and both figures on stderr, exit code 2.
fn refused(pointer: &str, message: &str) -> ExitCode {
    eprintln!(
        "{}",
        pretty(
            &serde_json::json!({"title": "the run does not fit the memory limit", "errors": [{"pointer": pointer, "message": message}]})
        )
    );
    ExitCode::from(2)
}

/// What `--out` keeps for a continuation: the scene as run and the state after its last step.
const SCENE_FILE: &str = "scene.json";
const STATE_FILE: &str = "state.bin";

/// A finished run to continue, read from its --out folder: its scene, its last state (with
/// the solvers' warm starts, as a checkpoint carries them), the reports of its steps and its
/// step k.
struct Parent {
    scene: Value,
    state: State,
    reports: Vec<StepReport>,
    k: f64,
}

impl Parent {
    fn read(dir: &Path) -> Result<Parent, String> {
        let read = |name: &str| {
            std::fs::read(dir.join(name)).map_err(|e| {
                format!(
                    "cannot continue from {}: {name}: {e} (the folder a finished `contact-sim run --out` wrote)",
                    dir.display()
                )
            })
        };
        let scene = contact_sim::json_body::parse(&read(SCENE_FILE)?)
            .map_err(|e| format!("{}: {e}", dir.join(SCENE_FILE).display()))?;
        let state = decode_state(&read(STATE_FILE)?)
            .map_err(|e| format!("{}: {e}", dir.join(STATE_FILE).display()))?;
        let summary: Value = serde_json::from_slice(&read("summary.json")?)
            .map_err(|e| format!("{}: {e}", dir.join("summary.json").display()))?;
        let reports: Vec<StepReport> = serde_json::from_value(summary["steps"].clone())
            .map_err(|e| format!("{}: steps: {e}", dir.join("summary.json").display()))?;
        let problem = scene::validate_with(&scene, &SceneDir(dir.to_path_buf()))
            .map_err(|e| format!("{}: {e}", dir.join(SCENE_FILE).display()))?;
        if problem.error_estimate {
            return Err("a run with an error estimate cannot be continued: its (2h, 2k) companion runs are not kept".into());
        }
        if state.step != problem.steps || reports.len() != problem.steps {
            return Err(format!(
                "{}: the run did not finish (state after step {} of {})",
                dir.display(),
                state.step,
                problem.steps
            ));
        }
        Ok(Parent {
            scene,
            state,
            reports,
            k: problem.k(),
        })
    }

    /// The continuation `child` goes on from this run's last step with its very step k.
    fn check(&self, child: &Problem) -> Result<(), String> {
        let t1 = self.state.step as f64 * self.k;
        if child.k().to_bits() != self.k.to_bits() {
            return Err(format!(
                "--t-end {} is not a whole number of the parent's steps k = {} from t = 0",
                child.t_end, self.k
            ));
        }
        if child.steps <= self.state.step {
            return Err(format!(
                "--t-end {} must come after the parent's final time {t1}",
                child.t_end
            ));
        }
        Ok(())
    }
}

/// The scene document as it ran, to be continued from anywhere: a mesh file named relative
/// to the scene's folder is named by its absolute path.
fn with_absolute_mesh(doc: &Value, dir: &Path) -> Value {
    let mut doc = doc.clone();
    if let Some(mesh) = doc.pointer_mut("/domain/mesh") {
        if let Some(path) = mesh
            .as_str()
            .and_then(|name| std::fs::canonicalize(dir.join(name)).ok())
        {
            *mesh = Value::String(path.display().to_string());
        }
    }
    doc
}

/// [`run_writing`]'s hooks: the progress bar, and `mesh.json` and the stored steps' JSON.
struct Writer<'a> {
    fields_dir: Option<&'a Path>,
    bar: &'a indicatif::ProgressBar,
    wrote_mesh: bool,
    io_error: Option<String>,
}

impl<const D: usize> Hooks<D> for Writer<'_> {
    type Stop = usize;

    fn after_step(&mut self, run: &Run<D>, r: &StepReport) -> ControlFlow<usize> {
        self.bar.inc(1);
        let Some(dir) = self.fields_dir else {
            return ControlFlow::Continue(());
        };
        let sim = run.sim();
        let mut write = |path: PathBuf, json: String| match std::fs::write(&path, json) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                self.io_error = Some(format!("cannot write {}: {e}", path.display()));
                ControlFlow::Break(r.n)
            }
        };
        if !self.wrote_mesh {
            let mesh = AnyMesh::from_mesh(sim.output_mesh());
            write(
                dir.parent().unwrap().join("mesh.json"),
                to_json(&MeshJson::new(&mesh, &sim.problem.boundary)),
            )?;
            self.wrote_mesh = true;
        }
        if sim.problem.output.stores(r.n, sim.problem.steps) {
            write(
                dir.join(format!("step_{:05}.json", r.n)),
                to_json(&sim.fields()),
            )?;
        }
        ControlFlow::Continue(())
    }
}

/// Runs the problem (of dimension D), from `start` (a parent's last state and its steps'
/// reports) when given, writing `mesh.json` and the stored steps' JSON into `fields_dir`'s
/// parent and `fields_dir` when given; the summary and the last state, and the error of a
/// failed write, if any.
fn run_writing<const D: usize>(
    problem: Problem,
    settings: SolverSettings,
    start: Option<(State, Vec<StepReport>)>,
    fields_dir: Option<&Path>,
    bar: &indicatif::ProgressBar,
) -> (Result<(Summary, State), RunError>, Option<String>) {
    let mut writer = Writer {
        fields_dir,
        bar,
        wrote_mesh: false,
        io_error: None,
    };
    let result = (|| {
        let mut run = Run::<D>::new(problem, settings)?;
        if let Some((state, reports)) = start {
            let now = &run.sim().state;
            if (state.u.len(), state.zeta.len()) != (now.u.len(), now.zeta.len()) {
                return Err(RunError::Solve(SolveError::Data {
                    pointer: "/domain".into(),
                    message: "the parent's state does not fit the scene's mesh".into(),
                }));
            }
            run.resume(state, reports, Vec::new())?;
        }
        if let ControlFlow::Break(n) = run.drive(&mut writer)? {
            return Err(RunError::Cancelled(n));
        }
        let state = run.sim().checkpoint_state();
        Ok((run.summary(), state))
    })();
    (result, writer.io_error)
}

/// The scene document of a file or a preset (exactly one of them).
fn load_scene(path: Option<&Path>, preset: Option<&str>) -> Result<Value, String> {
    match (path, preset) {
        (Some(_), Some(_)) => Err("give either a scene file or --preset, not both".into()),
        (None, None) => {
            Err("give a scene file or --preset NAME (see `contact-sim presets`)".into())
        }
        (None, Some(name)) => presets::get(name).ok_or_else(|| preset::unknown(name)),
        (Some(p), None) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| format!("cannot read {}: {e}", p.display()))?;
            contact_sim::json_body::parse(text.as_bytes())
                .map_err(|e| format!("{}: {e}", p.display()))
        }
    }
}

/// Field and mesh files are compact JSON.
fn to_json(value: &impl serde::Serialize) -> String {
    serde_json::to_string(value).expect("JSON")
}
