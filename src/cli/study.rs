//! `contact-sim study`: convergence studies from files and presets, run as one schedule.

use super::{fail, pretty, progress};
use clap::{Args, ValueEnum};
use contact_core::study::{self, Plan, StudyResult};
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
    if !targets.is_empty() {
        if !ladders.is_empty() {
            return fail(
                2,
                "give target studies and ladder studies in separate invocations",
            );
        }
        return main_targets(&args, &targets);
    }
    let plans = match plans(&ladders) {
        Ok(p) => p,
        Err(e) => return fail(2, &e),
    };
    let cache = study::ReferenceCache::new(4);
    let mut exec = study::Execution::default();
    if let Some(t) = args.threads {
        exec.threads = t.max(1);
    }
    // Its length is known once the schedule is: the first call of the hook sets it.
    let bar = progress::bar(0, "steps");
    let progress = |_done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.inc(1);
        ControlFlow::Continue(())
    };
    let results = study::run_many(&plans, &cache, exec, &progress);
    bar.finish_and_clear();
    let results = match results {
        Ok(r) => r,
        Err(e) => return fail(1, &e.to_string()),
    };
    if let Some(dir) = &args.report_dir {
        if let Err(e) = write_reports(dir, &results) {
            return fail(
                1,
                &format!("cannot write the reports to {}: {e}", dir.display()),
            );
        }
    }
    match (args.format, results.as_slice()) {
        (StudyFormat::Text, _) => {
            for r in &results {
                println!("{}", r.text_table());
            }
        }
        (StudyFormat::Json, [one]) => println!("{}", pretty(one)),
        (StudyFormat::Json, _) => println!("{}", pretty(&results)),
    }
    ExitCode::SUCCESS
}

/// Target studies, one after the other: the result (JSON or text) of each, and with
/// --report-dir its JSON, text and work–precision SVG. An unreachable target is exit code 1
/// with the reason (the best error reachable and its cost).
fn main_targets(args: &StudyArgs, docs: &[(String, Value)]) -> ExitCode {
    let mut specs = Vec::new();
    for (origin, doc) in docs {
        match study::target::parse(doc, "") {
            Ok((spec, _)) => specs.push(spec),
            Err(e) => return fail(2, &format!("{origin}: {e}")),
        }
    }
    let mut exec = study::Execution::default();
    if let Some(t) = args.threads {
        exec.threads = t.max(1);
    }
    let mut results = Vec::new();
    for spec in &specs {
        let bar = progress::bar(0, "steps");
        let progress = |done: usize, total: usize| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
            ControlFlow::Continue(())
        };
        let r = study::target::run(
            spec,
            exec,
            study::target::Limits::default(),
            &progress,
            &mut study::target::Discard,
        );
        bar.finish_and_clear();
        match r {
            Ok(r) => results.push(r),
            Err(e) => return fail(1, &format!("{}: {e}", spec.name)),
        }
    }
    if let Some(dir) = &args.report_dir {
        let write = || -> std::io::Result<()> {
            std::fs::create_dir_all(dir)?;
            for r in &results {
                let stem = file_stem(&r.name);
                std::fs::write(dir.join(format!("{stem}.json")), pretty(r))?;
                std::fs::write(dir.join(format!("{stem}.txt")), r.text_table())?;
                let svg = study::report_svg::target_report(r);
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
    match (args.format, results.as_slice()) {
        (StudyFormat::Text, _) => {
            for r in &results {
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
fn write_reports(dir: &Path, results: &[StudyResult]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    for r in results {
        let stem = file_stem(&r.name);
        std::fs::write(dir.join(format!("{stem}.json")), pretty(r))?;
        std::fs::write(dir.join(format!("{stem}.txt")), r.text_table())?;
        let svg = study::report_svg::study_report(r);
        std::fs::write(dir.join(format!("{stem}.svg")), svg)?;
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
