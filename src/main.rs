//! The `contact-sim` command line: a thin front end over the library.

use clap::{Args, Parser, Subcommand};
use contact_core::scene::{self, presets, Overrides};
use contact_core::solve::SolverSettings;
use contact_core::{bench, run};
use contact_sim::Config;
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
    /// Without a subcommand: `serve` with its defaults.
    #[command(subcommand)]
    command: Option<Command>,
}

/// How a node joins the job store (flags of `serve` and `worker`).
#[derive(Args)]
struct NodeArgs {
    /// Job store: a `postgres://user@host/db` URL shared by many nodes, or omitted for
    /// the embedded SQLite database in the data directory (single node).
    #[arg(long)]
    store: Option<String>,
    /// This node's name, the prefix of its worker names; a restarted node with the same
    /// name takes its interrupted jobs back at once. Must differ between live nodes
    /// (default: "local" for the embedded store, host-pid for a shared one).
    #[arg(long)]
    node: Option<String>,
    /// Seconds a job's lease lasts: a dead worker's job is claimed by another this long
    /// after its last renewal.
    #[arg(long = "lease-seconds", default_value_t = 30.0)]
    lease_seconds: f64,
}

impl NodeArgs {
    /// Sets the store, node name and lease of `config`; an error names the bad flag.
    fn apply(self, config: Config) -> Result<Config, String> {
        let seconds = self.lease_seconds;
        if !(seconds.is_finite() && (0.3..=86_400.0).contains(&seconds)) {
            return Err(format!(
                "--lease-seconds {seconds}: must be between 0.3 and 86400"
            ));
        }
        Ok(Config {
            node: node_name(self.node, self.store.is_some()),
            store: self.store,
            lease_s: seconds,
            ..config
        })
    }
}

#[derive(Subcommand)]
enum Command {
    /// Run the HTTP job service (the default).
    Serve {
        #[arg(long, default_value = "127.0.0.1:8080")]
        addr: String,
        /// Result files (and the embedded store); with --store, a directory shared by all
        /// nodes.
        #[arg(long = "data-dir", default_value = "./data")]
        data_dir: PathBuf,
        /// Worker threads (default: number of cores; 0: an API-only node).
        #[arg(long)]
        workers: Option<usize>,
        #[command(flatten)]
        node: NodeArgs,
        /// Maximum queued jobs before POST /jobs answers 503.
        #[arg(long = "queue-capacity", default_value_t = 1000)]
        queue_capacity: usize,
        /// Per-job limit on mesh nodes.
        #[arg(long = "max-nodes", default_value_t = 300_000)]
        max_nodes: usize,
        /// Per-job limit on time steps.
        #[arg(long = "max-steps", default_value_t = 100_000)]
        max_steps: usize,
        /// Per-job limit on stored result bytes.
        #[arg(long = "max-stored-bytes", default_value_t = 2 << 30)]
        max_stored_bytes: u64,
        /// Request body limit in bytes (413 beyond).
        #[arg(long = "max-body-bytes", default_value_t = 1 << 20)]
        max_body_bytes: usize,
        /// Deepest array/object nesting of a submitted document (422 beyond).
        #[arg(long = "max-json-depth", default_value_t = 32)]
        max_json_depth: usize,
        /// Submissions (POST) per second per client IP, refill rate of a token bucket
        /// (429 + Retry-After beyond); 0 disables the limit.
        #[arg(long = "submit-rate", default_value_t = 10.0)]
        submit_rate: f64,
        /// Submissions a client may make in one burst (token bucket size).
        #[arg(long = "submit-burst", default_value_t = 50)]
        submit_burst: u32,
        /// Seconds a client has to send a complete request head (then disconnected).
        #[arg(long = "header-timeout", default_value_t = 30.0)]
        header_timeout: f64,
    },
    /// A compute-only node: workers that claim jobs from a shared store (no HTTP). Stops on
    /// SIGINT or SIGTERM; its running jobs are checkpointed and resumed by any node.
    Worker {
        /// The directory of result files, shared with every other node.
        #[arg(long = "data-dir", default_value = "./data")]
        data_dir: PathBuf,
        /// Worker threads (default: number of cores).
        #[arg(long)]
        workers: Option<usize>,
        #[command(flatten)]
        node: NodeArgs,
    },
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
    /// Convergence studies: study files (JSON, `{"study": {...}}` or the study object) and/or
    /// presets (paper-table-1, paper-table-2). Studies of one scene share their reference run.
    /// Prints the result JSON (an array for several studies) or the paper-style tables.
    Study {
        files: Vec<PathBuf>,
        #[arg(long)]
        preset: Vec<String>,
        /// json (default) or text (the paper's table layout).
        #[arg(long, default_value = "json")]
        format: String,
        /// Runs computed at once (default: number of cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Also write NAME.json, NAME.txt and NAME.svg (the report plots) per study here.
        #[arg(long = "report-dir")]
        report_dir: Option<PathBuf>,
    },
    /// Speed figures: paper-convergence at h = k = 1/16 … 1/128 (and more with --levels).
    Bench {
        /// Levels 1/h = 1/k to run.
        #[arg(long, value_delimiter = ',', default_value = "16,32,64,128")]
        levels: Vec<usize>,
        /// Repetitions per level (the fastest is reported).
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Instead: Tables 1 and 2 together (one shared reference) against the reference
        /// run alone.
        #[arg(long)]
        tables: bool,
    },
    /// The stability suite: hard scenes (friction, non-convexity, damage, extreme h and k, a
    /// slender beam, load jumps) run with every invariant checked, or refused with a reason.
    /// Exit code 1 if any case does not do what it must.
    Stress {
        /// The coarse subset (what tests/stability.rs runs).
        #[arg(long)]
        quick: bool,
        /// text (default) or json.
        #[arg(long, default_value = "text")]
        format: String,
    },
}

fn main() -> ExitCode {
    let command = Cli::parse().command.unwrap_or(Command::Serve {
        addr: "127.0.0.1:8080".into(),
        data_dir: PathBuf::from("./data"),
        workers: None,
        queue_capacity: 1000,
        max_nodes: 300_000,
        max_steps: 100_000,
        max_stored_bytes: 2 << 30,
        max_body_bytes: 1 << 20,
        max_json_depth: 32,
        submit_rate: 10.0,
        submit_burst: 50,
        header_timeout: 30.0,
        node: NodeArgs {
            store: None,
            node: None,
            lease_seconds: 30.0,
        },
    });
    match command {
        Command::Serve {
            addr,
            data_dir,
            workers,
            queue_capacity,
            max_nodes,
            max_steps,
            max_stored_bytes,
            max_body_bytes,
            max_json_depth,
            submit_rate,
            submit_burst,
            header_timeout,
            node,
        } => {
            let defaults = Config::default();
            let config = Config {
                data_dir,
                workers: workers.unwrap_or(defaults.workers),
                queue_capacity,
                max_nodes,
                max_steps,
                max_stored_bytes,
                max_body_bytes,
                max_json_depth,
                submit_rate,
                submit_burst,
                header_timeout: if header_timeout.is_finite() && header_timeout > 0.0 {
                    std::time::Duration::from_secs_f64(header_timeout.min(1e6))
                } else {
                    defaults.header_timeout
                },
                ..defaults
            };
            match node.apply(config) {
                Ok(config) => cmd_serve(&addr, config),
                Err(e) => fail(2, &e),
            }
        }
        Command::Worker {
            data_dir,
            workers,
            node,
        } => {
            if node.store.is_none() {
                return fail(
                    2,
                    "a worker node needs the shared store: --store postgres://user@host/db",
                );
            }
            let defaults = Config::default();
            let config = Config {
                data_dir,
                workers: workers.unwrap_or(defaults.workers).max(1),
                ..defaults
            };
            match node.apply(config) {
                Ok(config) => cmd_worker(config),
                Err(e) => fail(2, &e),
            }
        }
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
        Command::Study {
            files,
            preset,
            format,
            threads,
            report_dir,
        } => cmd_study(&files, &preset, &format, threads, report_dir.as_deref()),
        Command::Stress { quick, format } => cmd_stress(quick, &format),
        Command::Bench {
            repeat,
            tables: true,
            ..
        } => {
            let threads = std::thread::available_parallelism().map_or(1, |n| n.get().min(4));
            match bench::tables(repeat.max(1), threads) {
                Ok(r) => {
                    println!("{}", serde_json::to_string_pretty(&r).expect("JSON"));
                    ExitCode::SUCCESS
                }
                Err(e) => fail(1, &e.to_string()),
            }
        }
        Command::Bench { levels, repeat, .. } => match bench::run(&levels, repeat.max(1)) {
            Ok(report) => {
                eprintln!("{}", report.table());
                println!("{}", serde_json::to_string_pretty(&report).expect("JSON"));
                ExitCode::SUCCESS
            }
            Err(e) => fail(1, &e.to_string()),
        },
    }
}

/// `--node`, or a name unique to this process for a shared store (host and pid), "local"
/// for the embedded one.
fn node_name(node: Option<String>, shared: bool) -> String {
    node.unwrap_or_else(|| {
        if shared {
            let host = std::fs::read_to_string("/etc/hostname")
                .ok()
                .map(|h| h.trim().to_string())
                .filter(|h| !h.is_empty())
                .unwrap_or_else(|| "node".into());
            format!("{host}-{}", std::process::id())
        } else {
            "local".into()
        }
    })
}

/// Resolves on SIGINT (Ctrl-C) or SIGTERM (what `docker stop` and service managers send).
async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}

fn cmd_worker(config: Config) -> ExitCode {
    let rt = match contact_sim::state::open_runtime(config.clone()) {
        Ok(rt) => rt,
        Err(e) => return fail(1, &e),
    };
    eprintln!(
        "contact-sim {} worker node {} ({} workers, store {}, results in {})",
        env!("CARGO_PKG_VERSION"),
        config.node,
        config.workers,
        config
            .store
            .as_deref()
            .map_or_else(String::new, contact_sim::state::redact),
        config.data_dir.display()
    );
    match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(signals) => signals.block_on(shutdown_signal()),
        Err(e) => return fail(1, &format!("cannot wait for signals: {e}")),
    }
    eprintln!("contact-sim: worker node stopping (running jobs are checkpointed)");
    rt.shutdown();
    ExitCode::SUCCESS
}

fn cmd_serve(addr: &str, config: Config) -> ExitCode {
    // The async runtime only does I/O; the numerics runs on the worker pool's own threads.
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => return fail(1, &format!("cannot start the async runtime: {e}")),
    };
    if config.workers == 0 && config.store.is_none() {
        eprintln!(
            "contact-sim: warning: --workers 0 with the embedded store: jobs are accepted but \
             nothing runs them (an API-only node needs a shared --store and worker nodes)"
        );
    }
    // Opening a PostgreSQL store blocks: not on the runtime's threads.
    let state = match contact_sim::state::start(config.clone()) {
        Ok(s) => s,
        Err(e) => return fail(1, &e),
    };
    rt.block_on(async {
        let listener = match tokio::net::TcpListener::bind(addr).await {
            Ok(l) => l,
            Err(e) => return fail(1, &format!("cannot listen on {addr}: {e}")),
        };
        eprintln!(
            "contact-sim {} listening on http://{} (data in {}, store {}, node {}, {} workers)",
            env!("CARGO_PKG_VERSION"),
            listener.local_addr().map(|a| a.to_string()).unwrap_or_default(),
            config.data_dir.display(),
            config
                .store
                .as_deref()
                .map_or_else(|| "embedded SQLite".into(), contact_sim::state::redact),
            config.node,
            config.workers
        );
        let shutdown = async {
            shutdown_signal().await;
            eprintln!("contact-sim: shutting down (running jobs are checkpointed and resume at the next start)");
        };
        match contact_sim::app::serve(listener, state, shutdown).await {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => fail(1, &e.to_string()),
        }
    })
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
                &contact_core::output::fields::MeshJson::new(&sim.mesh),
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

fn cmd_study(
    files: &[PathBuf],
    presets: &[String],
    format: &str,
    threads: Option<usize>,
    report_dir: Option<&Path>,
) -> ExitCode {
    use contact_core::study;
    if format != "json" && format != "text" {
        return fail(2, &format!("unknown --format {format:?} (json or text)"));
    }
    if files.is_empty() && presets.is_empty() {
        return fail(
            2,
            "give study files and/or --preset NAME (paper-table-1, paper-table-2)",
        );
    }
    let mut docs: Vec<(String, Value)> = Vec::new();
    for f in files {
        let text = match std::fs::read_to_string(f) {
            Ok(t) => t,
            Err(e) => return fail(2, &format!("cannot read {}: {e}", f.display())),
        };
        match serde_json::from_str::<Value>(&text) {
            Ok(mut v) => {
                // Accept the request body form too.
                if let Some(inner) = v.get_mut("study") {
                    v = inner.take();
                }
                docs.push((f.display().to_string(), v));
            }
            Err(e) => return fail(2, &format!("{} is not JSON: {e}", f.display())),
        }
    }
    for p in presets {
        docs.push((p.clone(), serde_json::json!({ "preset": p })));
    }
    let mut plans = Vec::new();
    for (origin, doc) in &docs {
        match study::parse(doc, "") {
            Ok((plan, _)) => plans.push(plan),
            Err(e) => return fail(2, &format!("{origin}: {e}")),
        }
    }
    let cache = study::ReferenceCache::new(4);
    let mut exec = study::Execution::default();
    if let Some(t) = threads {
        exec.threads = t.max(1);
    }
    let results = match study::run_many(&plans, &cache, exec, &|_, _| ControlFlow::Continue(())) {
        Ok(r) => r,
        Err(e) => return fail(1, &e.to_string()),
    };
    if let Some(dir) = report_dir {
        let write = || -> std::io::Result<()> {
            std::fs::create_dir_all(dir)?;
            for r in &results {
                let stem: String = r
                    .name
                    .chars()
                    .map(|c| {
                        if c.is_ascii_alphanumeric() || c == '-' {
                            c
                        } else {
                            '_'
                        }
                    })
                    .collect();
                let json = serde_json::to_string_pretty(r).expect("JSON");
                std::fs::write(dir.join(format!("{stem}.json")), json)?;
                std::fs::write(dir.join(format!("{stem}.txt")), r.text_table())?;
                let svg = contact_core::study::report_svg::study_report(r);
                std::fs::write(dir.join(format!("{stem}.svg")), svg)?;
            }
            Ok(())
        };
        if let Err(e) = write() {
            return fail(
                1,
                &format!("cannot write the reports to {}: {e}", dir.display()),
            );
        }
    }
    if format == "text" {
        for r in &results {
            println!("{}", r.text_table());
        }
    } else if results.len() == 1 {
        println!(
            "{}",
            serde_json::to_string_pretty(&results[0]).expect("JSON")
        );
    } else {
        println!("{}", serde_json::to_string_pretty(&results).expect("JSON"));
    }
    ExitCode::SUCCESS
}

fn cmd_stress(quick: bool, format: &str) -> ExitCode {
    if format != "text" && format != "json" {
        return fail(2, &format!("unknown format {format:?}; use text or json"));
    }
    let report = contact_core::stress::run(quick);
    if format == "json" {
        println!("{}", serde_json::to_string_pretty(&report).expect("JSON"));
    } else {
        print!("{}", report.text_table());
    }
    if report.all_as_expected {
        ExitCode::SUCCESS
    } else {
        fail(1, "some stress cases did not do what they must (marked !)")
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
