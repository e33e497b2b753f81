//! `contact-sim study`: convergence, target and adaptive studies from files and presets, each read,
//! limited and run by the core's [`contact_core::study::request`] (as the service does), one
//! after the other; studies of one scene share their reference run through one cache.

use super::{fail, pretty, progress};
use clap::{Args, ValueEnum};
use contact_core::admission::{Limit, LimitError, Limits};
use contact_core::study;
use contact_core::study::request::{self, Outcome};
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
    /// Threads of the study (default: all cores): runs computed at once share them, at
    /// most one run per thread. The numbers are the same bits for every count.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub threads: Option<u64>,
    /// Also write NAME.json, NAME.txt and NAME.svg (the report plots) per study here, and an
    /// adaptive study's final mesh as NAME.msh.
    #[arg(long = "report-dir")]
    pub report_dir: Option<PathBuf>,
    /// Per-job limit on mesh nodes. A study one of whose runs known in advance (a ladder's
    /// reference and levels, a target's first pilots) has more is refused before any run
    /// (exit code 2); a target study whose cheapest run meeting its target has more is refused
    /// after its pilot runs, before that run (exit code 1, naming the best error reachable and
    /// its cost).
    #[arg(long = "max-nodes")]
    pub max_nodes: Option<usize>,
    /// Per-job memory limit in bytes (suffixes K, M, G, T), as for `run`: refused like
    /// --max-nodes when a run's predicted peak exceeds it on the path the run takes (every
    /// path, with `auto`); runs computed at once share it. Default: 80 % of physical memory.
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
            "give study files and/or --preset NAME (paper-table-1, paper-table-2, l-bracket-adaptive, l-bracket-target)",
        );
    }
    let docs = match documents(&args.files, &args.preset) {
        Ok(d) => d,
        Err(e) => return fail(2, &e),
    };
    let mut requests = Vec::with_capacity(docs.len());
    for (origin, doc) in &docs {
        match request::parse(doc, "", &contact_core::scene::Bundled) {
            Ok((r, _)) => requests.push(r),
            Err(e) => return fail(2, &format!("{origin}: {e}")),
        }
    }
    let limits = limits(&args);
    // Every run of every study against the limits before any of them runs.
    for r in &requests {
        if let Err(e) = r.admit(&limits) {
            return fail(2, &format!("{}: {} ({})", r.name(), e, flag(&e)));
        }
    }
    let cache = study::ReferenceCache::new(4);
    let threads = args
        .threads
        .map_or_else(|| study::Execution::default().threads, |t| t as usize);
    let mut outcomes = Vec::with_capacity(requests.len());
    for r in &requests {
        // Its length is known once the schedule is: the hook sets it.
        let bar = progress::bar(0, "steps");
        let progress = |done: usize, total: usize| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
            ControlFlow::Continue(())
        };
        let outcome = r.execute(request::Context {
            cache: &cache,
            threads,
            settings: Default::default(),
            limits,
            progress: &progress,
            sink: &mut study::target::Discard,
        });
        bar.finish_and_clear();
        match outcome {
            Ok(o) => outcomes.push(o),
            Err(e) => return fail(1, &format!("{}: {e}", r.name())),
        }
    }
    report(&args, &outcomes)
}

/// The per-job limits of the command: --max-nodes, and --max-job-memory (default: 80 % of
/// physical memory, as for `run`).
fn limits(args: &StudyArgs) -> Limits {
    Limits {
        max_nodes: args.max_nodes,
        max_memory: args
            .max_job_memory
            .or_else(|| contact_core::memory::default_limit(1)),
        ..Limits::default()
    }
}

/// The option that sets a limit.
fn flag(e: &LimitError) -> &'static str {
    match e.limit {
        Limit::Nodes => "--max-nodes",
        Limit::Memory => "--max-job-memory",
        Limit::Steps | Limit::StoredBytes => "a per-job limit",
    }
}

/// The results on stdout (JSON, an array for several, or text), and with --report-dir their
/// files.
fn report(args: &StudyArgs, results: &[Outcome]) -> ExitCode {
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
                outln!("{}", r.text_table());
            }
        }
        (StudyFormat::Json, [one]) => outln!("{}", pretty(&one.to_json())),
        (StudyFormat::Json, _) => {
            let all: Vec<Value> = results.iter().map(Outcome::to_json).collect();
            outln!("{}", pretty(&all))
        }
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

/// NAME.json, NAME.txt and NAME.svg per study in `dir` (and an adaptive study's final mesh
/// as NAME.msh), NAME the study's name with anything but ASCII letters, digits and '-'
/// replaced by '_'.
fn write_reports(dir: &Path, results: &[Outcome]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    for r in results {
        let stem = file_stem(r.name());
        std::fs::write(dir.join(format!("{stem}.json")), pretty(&r.to_json()))?;
        std::fs::write(dir.join(format!("{stem}.txt")), r.text_table())?;
        std::fs::write(dir.join(format!("{stem}.svg")), r.report_svg())?;
        if let Some(msh) = r.final_msh() {
            std::fs::write(dir.join(format!("{stem}.msh")), msh)?;
        }
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
