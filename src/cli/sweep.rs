//! `contact-sim sweep FILE`: a parameter sweep (`{"sweep": {...}}` or the sweep object), read,
//! limited and run by the core's [`contact_core::study::sweep`] as the service runs one: the
//! table of members as JSON, CSV or text, and with --plot an SVG of a quantity against one
//! varied parameter.

use super::{fail, pretty, progress};
use clap::{Args, ValueEnum};
use contact_core::admission::Limits;
use contact_core::study;
use contact_core::study::request::{self, Outcome};
use contact_core::study::sweep::{plot_svg, QUANTITIES};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args)]
pub struct SweepArgs {
    /// The sweep file: `{"sweep": {"scene", "vary", "mode"}}` or the sweep object.
    pub file: PathBuf,
    /// json (the result document), csv (the table) or text.
    #[arg(long, value_enum, default_value_t = SweepFormat::Json)]
    pub format: SweepFormat,
    /// Also write an SVG plot of --quantity against --against here.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// The plotted quantity: w_V, u_V, zeta_L2, zeta_min, min_zeta, slip_nodes,
    /// max_slip_speed or wall_s.
    #[arg(long, default_value = "w_V")]
    pub quantity: String,
    /// The varied pointer on the plot's horizontal axis (default: the first).
    #[arg(long)]
    pub against: Option<String>,
    /// Threads of each member's run (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub threads: Option<u64>,
    /// Per-job memory limit in bytes (suffixes K, M, G, T), as for `run`: the largest member
    /// decides. Default: 80 % of physical memory.
    #[arg(long = "max-job-memory", value_parser = contact_core::memory::parse_bytes)]
    pub max_job_memory: Option<u64>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SweepFormat {
    Json,
    Csv,
    Text,
}

pub fn main(args: SweepArgs) -> ExitCode {
    let text = match std::fs::read_to_string(&args.file) {
        Ok(t) => t,
        Err(e) => return fail(2, &format!("cannot read {}: {e}", args.file.display())),
    };
    let mut doc = match contact_sim::json_body::parse(text.as_bytes()) {
        Ok(d) => d,
        Err(e) => return fail(2, &format!("{}: {e}", args.file.display())),
    };
    let at = if doc.get("sweep").is_some() {
        doc = doc["sweep"].take();
        "/sweep"
    } else {
        ""
    };
    if !QUANTITIES.contains(&args.quantity.as_str()) {
        return fail(
            2,
            &format!(
                "--quantity must be one of {}, not {:?}",
                QUANTITIES.join(", "),
                args.quantity
            ),
        );
    }
    let r = match request::parse_sweep(&doc, at, &super::mesh_files::SceneDir(dir(&args))) {
        Ok((r, _)) => r,
        Err(e) => {
            eprintln!(
                "{}",
                pretty(&serde_json::json!({"title": "invalid sweep", "errors": e}))
            );
            return ExitCode::from(2);
        }
    };
    let limits = Limits {
        max_memory: args
            .max_job_memory
            .or_else(|| contact_core::memory::default_limit(1)),
        ..Limits::default()
    };
    if let Err(e) = r.admit(&limits) {
        return fail(2, &format!("{}: {} (at {})", r.name(), e, e.pointer));
    }
    let threads = args
        .threads
        .map_or_else(|| study::Execution::default().threads, |t| t as usize);
    let bar = progress::bar(0, "steps");
    let progress = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
        ControlFlow::Continue(())
    };
    let outcome = r.execute(request::Context {
        cache: &study::ReferenceCache::new(1),
        threads,
        settings: Default::default(),
        limits,
        progress: &progress,
        sink: &mut study::target::Discard,
    });
    bar.finish_and_clear();
    let result = match outcome {
        Ok(Outcome::Sweep(r)) => r,
        Ok(_) => unreachable!("a sweep request gives a sweep"),
        Err(e) => return fail(1, &format!("{}: {e}", r.name())),
    };
    if let Some(path) = &args.plot {
        let against = args.against.clone().unwrap_or_else(|| {
            result.vary[0]["pointer"]
                .as_str()
                .unwrap_or_default()
                .to_string()
        });
        let Some(svg) = plot_svg(&result, &args.quantity, &against) else {
            return fail(
                2,
                &format!("--against must be a varied pointer, not {against:?}"),
            );
        };
        if let Err(e) = std::fs::write(path, svg) {
            return fail(1, &format!("cannot write {}: {e}", path.display()));
        }
    }
    match args.format {
        SweepFormat::Json => outln!("{}", pretty(&*result)),
        SweepFormat::Csv => outln!("{}", result.csv().trim_end()),
        SweepFormat::Text => outln!("{}", result.text_table().trim_end()),
    }
    ExitCode::SUCCESS
}

/// Mesh files a scene names are looked up next to the sweep file.
fn dir(args: &SweepArgs) -> PathBuf {
    args.file
        .parent()
        .map(std::path::Path::to_path_buf)
        .unwrap_or_default()
}
