//! `contact-sim study`: convergence studies from files and presets, run as one schedule.

use super::{fail, pretty, progress};
use clap::{Args, ValueEnum};
use contact_core::study::{self, Plan, StudyResult, TargetResult};
use serde_json::Value;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Args)]
pub struct StudyArgs {
    pub files: Vec<PathBuf>,
    #[arg(long)]
    pub preset: Vec<String>,
    /// json (the result documents) or text (the paper's table layout).
    #[arg(long, value_enum, default_value_t = StudyFormat::Json)]
    pub format: StudyFormat,
    /// Runs computed at once (default: number of cores, at most 4).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Also write NAME.json, NAME.txt and NAME.svg (the report plots) per study here.
    #[arg(long = "report-dir")]
    pub report_dir: Option<PathBuf>,
    /// Per-job limit on mesh nodes. A target study whose cheapest run meeting its target has
    /// more is refused after its pilot runs, before that run (exit code 1, naming the best
    /// error reachable and its cost); a ladder study whose reference has more is refused
    /// before any run (exit code 2).
    #[arg(long = "max-nodes")]
    pub max_nodes: Option<usize>,
    /// Per-job memory limit in bytes (suffixes K, M, G, T), as for `run`: refused like
    /// --max-nodes when a run's predicted peak exceeds it on every linear path. Default: 80 %
    /// of physical memory.
    #[arg(long = "max-job-memory", value_parser = contact_core::memory::parse_bytes)]
    pub max_job_memory: Option<u64>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StudyFormat {
    Json,
    Text,
}

pub fn main(args: StudyArgs) -> ExitCode {
    if args.files.is_empty() && args.preset.is_empty() {
        return fail(
            2,
            "give study files and/or --preset NAME (paper-table-1, paper-table-2)",
        );
    }
    let docs = match documents(&args.files, &args.preset) {
        Ok(d) => d,
        Err(e) => return fail(2, &e),
    };
    let (targets, ladders): (Vec<_>, Vec<_>) =
        docs.into_iter().partition(|(_, d)| study::is_target(d));
    if targets.is_empty() {
        return main_ladders(&args, &ladders);
    }
    if !ladders.is_empty() {
        return fail(
            2,
            "give target studies and ladder studies in separate invocations",
        );
    }
    main_targets(&args, &targets)
}

/// How the studies run: --threads, and --max-job-memory (default: 80 % of physical memory,
/// as for `run`).
fn execution(args: &StudyArgs) -> study::Execution {
    let mut exec = study::Execution::default();
    if let Some(t) = args.threads {
        exec.threads = t.max(1);
    }
    exec.settings.memory_limit = args
        .max_job_memory
        .or_else(|| contact_core::memory::default_limit(1));
    exec
}

/// Ladder studies, run as one schedule (studies of one scene share their reference run).
/// A reference beyond --max-nodes or --max-job-memory is exit code 2 before any run.
fn main_ladders(args: &StudyArgs, docs: &[(String, Value)]) -> ExitCode {
    let plans = match plans(docs) {
        Ok(p) => p,
        Err(e) => return fail(2, &e),
    };
    let exec = execution(args);
    for plan in &plans {
        if let Err(e) = check_reference(plan, args.max_nodes, exec.settings.memory_limit) {
            return fail(2, &format!("{}: {e}", plan.name));
        }
    }
    let cache = study::ReferenceCache::new(4);
    // Its length is known once the schedule is: the first call of the hook sets it.
    let bar = progress::bar(0, "steps");
    let progress = |_done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.inc(1);
        ControlFlow::Continue(())
    };
    let results = study::run_many(&plans, &cache, exec, &progress);
    bar.finish_and_clear();
    match results {
        Ok(r) => report(args, &r),
        Err(e) => fail(1, &e.to_string()),
    }
}

/// A ladder study's reference (its largest run) against the node and memory limits.
fn check_reference(
    plan: &Plan,
    max_nodes: Option<usize>,
    memory_limit: Option<u64>,
) -> Result<(), String> {
    let nodes = plan.base.n_nodes();
    if let Some(max) = max_nodes.filter(|&m| nodes > m) {
        return Err(format!(
            "the reference mesh has {nodes} nodes, more than the limit of {max} (--max-nodes)"
        ));
    }
    contact_core::memory::choose(&plan.base, memory_limit)
        .map(|_| ())
        .map_err(|e| format!("the reference run: {e}"))
}

/// Target studies, one after the other. Pilot levels beyond --max-nodes are exit code 2
/// before any run; a target out of reach of --max-nodes or --max-job-memory (or of the
/// study's budget) is exit code 1 after the pilot runs, before the expensive run, with the
/// reason (the best error reachable and its cost).
fn main_targets(args: &StudyArgs, docs: &[(String, Value)]) -> ExitCode {
    let mut specs = Vec::new();
    for (origin, doc) in docs {
        match study::target::parse(doc, "") {
            Ok((spec, _)) => specs.push(spec),
            Err(e) => return fail(2, &format!("{origin}: {e}")),
        }
    }
    for spec in &specs {
        let pilot_nodes = spec.pilot_nodes();
        if let Some(max) = args.max_nodes.filter(|&m| pilot_nodes > m) {
            return fail(
                2,
                &format!(
                    "{}: even the pilot levels need {pilot_nodes} nodes, more than the limit of {max} (--max-nodes)",
                    spec.name
                ),
            );
        }
    }
    let exec = execution(args);
    let limits = study::target::Limits {
        max_nodes: args.max_nodes,
        max_steps: None,
    };
    let mut results = Vec::new();
    for spec in &specs {
        let bar = progress::bar(0, "steps");
        let progress = |done: usize, total: usize| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
            ControlFlow::Continue(())
        };
        let r = study::target::run(spec, exec, limits, &progress, &mut study::target::Discard);
        bar.finish_and_clear();
        match r {
            Ok(r) => results.push(r),
            Err(e) => return fail(1, &format!("{}: {e}", spec.name)),
        }
    }
    report(args, &results)
}

/// What the command prints and writes of a study's result, ladder or target.
trait Report: serde::Serialize {
    fn name(&self) -> &str;
    fn text_table(&self) -> String;
    /// The report plots.
    fn svg(&self) -> String;
}

impl Report for StudyResult {
    fn name(&self) -> &str {
        &self.name
    }
    fn text_table(&self) -> String {
        StudyResult::text_table(self)
    }
    fn svg(&self) -> String {
        study::report_svg::study_report(self)
    }
}

impl Report for TargetResult {
    fn name(&self) -> &str {
        &self.name
    }
    fn text_table(&self) -> String {
        TargetResult::text_table(self)
    }
    fn svg(&self) -> String {
        study::report_svg::target_report(self)
    }
}

/// The results on stdout (JSON, an array for several, or text), and with --report-dir their
/// files.
fn report<R: Report>(args: &StudyArgs, results: &[R]) -> ExitCode {
    if let Some(dir) = &args.report_dir {
        if let Err(e) = write_reports(dir, results) {
            return fail(
                1,
                &format!("cannot write the reports to {}: {e}", dir.display()),
            );
        }
    }
    match (args.format, results) {
        (StudyFormat::Text, _) => {
            for r in results {
                println!("{}", r.text_table());
            }
        }
        (StudyFormat::Json, [one]) => println!("{}", pretty(one)),
        (StudyFormat::Json, _) => println!("{}", pretty(&results)),
    }
    ExitCode::SUCCESS
}

/// The study documents of the files (a request body `{"study": {...}}` or the study
/// object) and of the presets, in that order, each with its origin.
fn documents(files: &[PathBuf], presets: &[String]) -> Result<Vec<(String, Value)>, String> {
    let mut docs: Vec<(String, Value)> = Vec::new();
    for f in files {
        let text =
            std::fs::read_to_string(f).map_err(|e| format!("cannot read {}: {e}", f.display()))?;
        let mut v = contact_sim::json_body::parse(text.as_bytes())
            .map_err(|e| format!("{}: {e}", f.display()))?;
        if let Some(inner) = v.get_mut("study") {
            v = inner.take();
        }
        docs.push((f.display().to_string(), v));
    }
    for p in presets {
        docs.push((p.clone(), serde_json::json!({ "preset": p })));
    }
    Ok(docs)
}

/// The ladder studies' plans; an error names the file or preset.
fn plans(docs: &[(String, Value)]) -> Result<Vec<Plan>, String> {
    docs.iter()
        .map(|(origin, doc)| {
            study::parse(doc, "")
                .map(|(plan, _)| plan)
                .map_err(|e| format!("{origin}: {e}"))
        })
        .collect()
}

/// NAME.json, NAME.txt and NAME.svg per study in `dir`, NAME the study's name with anything
/// but ASCII letters, digits and '-' replaced by '_'.
fn write_reports<R: Report>(dir: &Path, results: &[R]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    for r in results {
        let stem = file_stem(r.name());
        std::fs::write(dir.join(format!("{stem}.json")), pretty(r))?;
        std::fs::write(dir.join(format!("{stem}.txt")), r.text_table())?;
        std::fs::write(dir.join(format!("{stem}.svg")), r.svg())?;
    }
    Ok(())
}

/// A study's name with anything but ASCII letters, digits and '-' replaced by '_'.
fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}
