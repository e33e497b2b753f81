//! `contact-sim run`: one simulation, its summary on stdout, its files with --out.

use super::mesh_files::SceneDir;
use super::{fail, preset, pretty, progress};
use clap::Args;
use contact_core::admission::{self, Limits, Pointers};
use contact_core::mesh::AnyMesh;
use contact_core::output::fields::MeshJson;
use contact_core::output::Summary;
use contact_core::problem::Problem;
use contact_core::run::RunError;
use contact_core::scene::{self, presets, Overrides};
use contact_core::solve::{SolveError, SolverSettings};
use serde_json::Value;
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
    /// Directory for summary.json, mesh.json and fields/step_NNNNN.json.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Relative optimality residual of the sub-problem solvers.
    #[arg(long, default_value_t = SolverSettings::default().tolerance)]
    pub tol: f64,
    /// Linear solver path, overriding the scene's `solver.linear`: auto, direct or multigrid.
    #[arg(long = "linear-solver", value_parser = ["auto", "direct", "multigrid"])]
    pub linear_solver: Option<String>,
    /// Per-job memory limit in bytes (suffixes K, M, G, T): the run is refused before any
    /// numeric work if its predicted peak exceeds it. Default: 80 % of physical memory.
    #[arg(long = "max-job-memory", value_parser = contact_core::memory::parse_bytes)]
    pub max_job_memory: Option<u64>,
}

pub fn main(args: RunArgs) -> ExitCode {
    let mut doc = match load_scene(args.scene.as_deref(), args.preset.as_deref()) {
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
    if let (Some(path), Some(top)) = (&args.linear_solver, doc.as_object_mut()) {
        let solver = top.entry("solver").or_insert_with(|| serde_json::json!({}));
        if let Some(s) = solver.as_object_mut() {
            s.insert("linear".into(), Value::String(path.clone()));
        }
    }
    // Mesh files are looked up next to the scene file (the working directory for a preset).
    let dir = args
        .scene
        .as_deref()
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .unwrap_or_default();
    let problem = match scene::validate_with(&doc, &SceneDir(dir)) {
        Ok(p) => p,
        Err(errors) => {
            eprintln!(
                "{}",
                pretty(&serde_json::json!({"title": "invalid scene", "errors": errors}))
            );
            return ExitCode::from(2);
        }
    };
    let fields_dir = args.out.as_ref().map(|d| d.join("fields"));
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
    let bar = progress::bar(problem.steps as u64, "steps");
    let (result, io_error) = match problem.dim() {
        2 => run_writing::<2>(problem, settings, fields_dir.as_deref(), &bar),
        _ => run_writing::<3>(problem, settings, fields_dir.as_deref(), &bar),
    };
    bar.finish_and_clear();
    match result {
        Ok(summary) => {
            let text = pretty(&summary);
            if let Some(dir) = &args.out {
                if let Err(e) = std::fs::write(dir.join("summary.json"), &text) {
                    return fail(1, &format!("cannot write summary.json: {e}"));
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

/// Runs the problem (of dimension D), writing `mesh.json` and the stored steps' JSON into
/// `fields_dir`'s parent and `fields_dir` when given; the error of a failed write, if any.
fn run_writing<const D: usize>(
    problem: Problem,
    settings: SolverSettings,
    fields_dir: Option<&Path>,
    bar: &indicatif::ProgressBar,
) -> (Result<Summary, RunError>, Option<String>) {
    let mut io_error = None;
    let mut wrote_mesh = false;
    let result = contact_core::run::run::<D>(problem, settings, |sim, r| {
        bar.inc(1);
        let Some(dir) = fields_dir else {
            return ControlFlow::Continue(());
        };
        let mut write = |path: PathBuf, json: String| match std::fs::write(&path, json) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                io_error = Some(format!("cannot write {}: {e}", path.display()));
                ControlFlow::Break(())
            }
        };
        if !wrote_mesh {
            wrote_mesh = true;
            let mesh = AnyMesh::from_mesh(sim.mesh.clone());
            write(
                dir.parent().unwrap().join("mesh.json"),
                to_json(&MeshJson::new(&mesh, &sim.problem.boundary)),
            )?;
        }
        if sim.problem.output.stores(r.n, sim.problem.steps) {
            write(
                dir.join(format!("step_{:05}.json", r.n)),
                to_json(&sim.fields()),
            )?;
        }
        ControlFlow::Continue(())
    });
    (result, io_error)
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
