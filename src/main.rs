//! The `contact-sim` command line: a thin front end over the library.

use clap::{Parser, Subcommand};
use contact_sim::scene::{self, presets, Overrides};
use contact_sim::solve::SolverSettings;
use contact_sim::{bench, run};
use serde_json::Value;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "contact-sim",
    version,
    about = "Quasistatic frictional contact of a viscoelastic body with damage (Han, Jureczka & Ochal 2020)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene (a JSON file or a preset) and print the summary JSON.
    Run {
        /// Scene file (JSON); omit when using --preset.
        scene: Option<PathBuf>,
        #[arg(long)]
        preset: Option<String>,
        /// Mesh size: a number or a fraction like 1/32.
        #[arg(long)]
        h: Option<String>,
        /// Time step: a number or a fraction like 1/32.
        #[arg(long)]
        k: Option<String>,
        /// Final time T.
        #[arg(long = "t-end")]
        t_end: Option<String>,
        /// Directory for summary.json, mesh.json and fields/step_NNNNN.json.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Relative optimality residual of the sub-problem solvers.
        #[arg(long, default_value_t = 1e-10)]
        tol: f64,
    },
    /// List the presets.
    Presets,
    /// Print a preset as a scene file.
    Preset { name: String },
    /// Convergence study presets: paper-table-1 (k = 1/128, h = 1/2 … 1/32) and
    /// paper-table-2 (h = 1/128, k = 1/2 … 1/32), reference h = k = 1/128.
    Study {
        #[arg(long)]
        preset: String,
        /// json (default) or text (the paper's table layout).
        #[arg(long, default_value = "json")]
        format: String,
    },
    /// Speed figures: paper-convergence at h = k = 1/16 … 1/128 (and more with --levels).
    Bench {
        /// Levels 1/h = 1/k to run.
        #[arg(long, value_delimiter = ',', default_value = "16,32,64,128")]
        levels: Vec<usize>,
        /// Repetitions per level (the fastest is reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
    },
}

fn main() -> ExitCode {
    match Cli::parse().command {
        Command::Run {
            scene,
            preset,
            h,
            k,
            t_end,
            out,
            tol,
        } => {
            let doc = match load_scene(scene.as_deref(), preset.as_deref()) {
                Ok(d) => d,
                Err(e) => return fail(2, &e),
            };
            let to_value = |s: Option<String>| {
                s.map(|s| {
                    s.parse::<f64>()
                        .map(Value::from)
                        .unwrap_or(Value::String(s))
                })
            };
            let overrides = Overrides {
                h: to_value(h),
                k: to_value(k),
                t_end: to_value(t_end),
            };
            cmd_run(doc, &overrides, out.as_deref(), tol)
        }
        Command::Presets => {
            for name in presets::names() {
                println!("{name:20} {}", presets::description(name).unwrap_or(""));
            }
            ExitCode::SUCCESS
        }
        Command::Preset { name } => match presets::get(&name) {
            Some(doc) => {
                println!("{}", serde_json::to_string_pretty(&doc).expect("JSON"));
                ExitCode::SUCCESS
            }
            None => fail(
                2,
                &format!(
                    "unknown preset {name:?}; known: {}",
                    presets::names().join(", ")
                ),
            ),
        },
        Command::Study { preset, format } => cmd_study(&preset, &format),
        Command::Bench { levels, repeat } => match bench::run(&levels, repeat.max(1)) {
            Ok(report) => {
                eprintln!("{}", report.table());
                println!("{}", serde_json::to_string_pretty(&report).expect("JSON"));
                ExitCode::SUCCESS
            }
            Err(e) => fail(1, &e.to_string()),
        },
    }
}

fn load_scene(path: Option<&Path>, preset: Option<&str>) -> Result<Value, String> {
    match (path, preset) {
        (Some(_), Some(_)) => Err("give either a scene file or --preset, not both".into()),
        (None, None) => {
            Err("give a scene file or --preset NAME (see `contact-sim presets`)".into())
        }
        (None, Some(name)) => presets::get(name).ok_or_else(|| {
            format!(
                "unknown preset {name:?}; known: {}",
                presets::names().join(", ")
            )
        }),
        (Some(p), None) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| format!("cannot read {}: {e}", p.display()))?;
            serde_json::from_str(&text).map_err(|e| format!("{}: invalid JSON: {e}", p.display()))
        }
    }
}

fn cmd_run(mut doc: Value, overrides: &Overrides, out: Option<&Path>, tol: f64) -> ExitCode {
    scene::apply_overrides(&mut doc, overrides);
    let problem = match scene::validate(&doc) {
        Ok(p) => p,
        Err(errors) => {
            eprintln!(
                "{}",
                serde_json::to_string_pretty(
                    &serde_json::json!({"title": "invalid scene", "errors": errors})
                )
                .expect("JSON")
            );
            return ExitCode::from(2);
        }
    };
    let fields_dir = out.map(|d| d.join("fields"));
    if let Some(dir) = &fields_dir {
        if let Err(e) = std::fs::create_dir_all(dir) {
            return fail(1, &format!("cannot create {}: {e}", dir.display()));
        }
    }
    let mut io_error = None;
    let mut wrote_mesh = false;
    let settings = SolverSettings {
        tolerance: tol,
        ..Default::default()
    };
    let result = run::run(problem, settings, |sim, r| {
        let Some(dir) = &fields_dir else {
            return ControlFlow::Continue(());
        };
        let mut write = |path: PathBuf, v: &dyn erased::Json| -> ControlFlow<()> {
            match std::fs::write(&path, v.to_json()) {
                Ok(()) => ControlFlow::Continue(()),
                Err(e) => {
                    io_error = Some(format!("cannot write {}: {e}", path.display()));
                    ControlFlow::Break(())
                }
            }
        };
        if !wrote_mesh {
            wrote_mesh = true;
            write(
                dir.parent().unwrap().join("mesh.json"),
                &contact_sim::output::fields::MeshJson::new(&sim.mesh),
            )?;
        }
        if sim.problem.output.stores(r.n, sim.problem.steps) {
            write(dir.join(format!("step_{:05}.json", r.n)), &sim.fields())?;
        }
        ControlFlow::Continue(())
    });
    match result {
        Ok(summary) => {
            let text = serde_json::to_string_pretty(&summary).expect("JSON");
            if let Some(dir) = out {
                if let Err(e) = std::fs::write(dir.join("summary.json"), &text) {
                    return fail(1, &format!("cannot write summary.json: {e}"));
                }
            }
            println!("{text}");
            ExitCode::SUCCESS
        }
        Err(e) => fail(1, &io_error.unwrap_or_else(|| e.to_string())),
    }
}

fn cmd_study(preset: &str, format: &str) -> ExitCode {
    let ladder = [2, 4, 8, 16, 32];
    let (levels, vary): (Vec<(usize, usize)>, &str) = match preset {
        "paper-table-1" => (ladder.iter().map(|&n| (n, 128)).collect(), "h"),
        "paper-table-2" => (ladder.iter().map(|&n| (128, n)).collect(), "k"),
        _ => {
            return fail(
                2,
                &format!("unknown study preset {preset:?}; known: paper-table-1, paper-table-2"),
            )
        }
    };
    let doc = presets::get("paper-convergence").expect("preset exists");
    let base = match scene::validate(&doc) {
        Ok(p) => p,
        Err(e) => return fail(1, &e.to_string()),
    };
    match contact_sim::study::run_ladder(&base, &levels, (128, 128)) {
        Ok(result) => {
            if format == "text" {
                print!("{}", result.text_table(vary));
            } else {
                println!("{}", serde_json::to_string_pretty(&result).expect("JSON"));
            }
            ExitCode::SUCCESS
        }
        Err(e) => fail(1, &e.to_string()),
    }
}

fn fail(code: u8, msg: &str) -> ExitCode {
    eprintln!("contact-sim: {msg}");
    ExitCode::from(code)
}

/// Serialise values of different types through one closure.
mod erased {
    pub trait Json {
        fn to_json(&self) -> String;
    }
    impl<T: serde::Serialize> Json for T {
        fn to_json(&self) -> String {
            serde_json::to_string(self).expect("JSON")
        }
    }
}
