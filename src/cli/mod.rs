//! The command line's parts: the argument types ([`Cli`], [`Command`]) and one module per
//! command, each with its flags and what it does. `main.rs` parses and dispatches.

/// `println!` for a command's output on stdout: a reader that has gone away (`contact-sim … |
/// head`) ends the program quietly, see [`write_stdout`].
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!("{}\n", format_args!($($arg)*)))
    };
}

/// `print!` for a command's output on stdout, see [`outln!`].
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!($($arg)*))
    };
}

pub mod bench;
pub mod keys;
pub mod logging;
pub mod mesh_files;
pub mod node;
pub mod preset;
pub mod progress;
pub mod run;
pub mod serve;
pub mod stress;
pub mod study;
pub mod sweep;
pub mod worker;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "contact-sim",
    version,
    about = "Quasistatic frictional contact of a viscoelastic body with damage (Han, Jureczka & Ochal 2020)"
)]
pub struct Cli {
    /// Without a subcommand: `serve` with its defaults.
    #[command(subcommand)]
    pub command: Option<Command>,
    /// How the log lines on stderr are written: text for people, json (one object a line)
    /// for log collectors. The level comes from RUST_LOG (default info).
    #[arg(long = "log-format", global = true, value_enum, default_value_t)]
    pub log_format: logging::LogFormat,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run the HTTP job service (the default).
    Serve(serve::ServeArgs),
    /// A compute-only node: workers that claim jobs from a shared store (no HTTP). Stops on
    /// SIGINT or SIGTERM; its running jobs are checkpointed and resumed by any node.
    Worker(worker::WorkerArgs),
    /// Run a scene (a JSON file or a preset) and print the summary JSON.
    Run(run::RunArgs),
    /// List the presets.
    Presets,
    /// Print a preset as a scene file.
    Preset(preset::PresetArgs),
    /// Convergence studies: study files (JSON, `{"study": {...}}` or the study object) and/or
    /// presets (paper-table-1, paper-table-2, l-bracket-adaptive, l-bracket-target). Studies of
    /// one scene share their reference run.
    /// Prints the result JSON (an array for several studies) or the paper-style tables.
    Study(study::StudyArgs),
    /// A parameter sweep: a file `{"sweep": {"scene", "vary": {POINTER: [VALUES]}, "mode"}}`;
    /// prints the table of members (JSON, CSV or text), optionally plots one quantity.
    Sweep(sweep::SweepArgs),
    /// Speed figures: paper-convergence at h = k = 1/16 … 1/128 (and more with --levels).
    Bench(bench::BenchArgs),
    /// The stability suite: hard scenes (friction, non-convexity, damage, extreme h and k, a
    /// slender beam, load jumps) run with every invariant checked, or refused with a reason.
    /// Exit code 1 if any case does not do what it must.
    Stress(stress::StressArgs),
    /// API keys of the service: add (prints the token once), list, revoke, set-quota.
    Keys(keys::KeysArgs),
}

impl Default for Command {
    fn default() -> Self {
        Command::Serve(serve::ServeArgs::default())
    }
}

/// Reports `msg` to the user on stderr and exits with `code` (2: bad input, 1: the work
/// failed).
pub fn fail(code: u8, msg: &str) -> ExitCode {
    eprintln!("contact-sim: {msg}");
    ExitCode::from(code)
}

/// A service node that cannot go on: `msg` goes to its log, exit code 1.
pub fn fatal(msg: &str) -> ExitCode {
    tracing::error!("{msg}");
    ExitCode::FAILURE
}

/// Writes a command's output to stdout and flushes it. When the reader has closed the pipe
/// (`contact-sim presets | head -1`) nobody wants the rest: the program ends at once with
/// status 0 and no message, as `head` expects of its writer (Rust ignores SIGPIPE, so without
/// this `println!` would panic). Any other write error ends it with status 1 and the reason.
pub fn write_stdout(args: std::fmt::Arguments) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout.write_fmt(args).and_then(|()| stdout.flush()) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => {
            eprintln!("contact-sim: cannot write to stdout: {e}");
            std::process::exit(1)
        }
    }
}

/// The indented JSON every command prints.
pub fn pretty(value: &impl serde::Serialize) -> String {
    serde_json::to_string_pretty(value).expect("JSON")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_argument_definitions_are_consistent() {
        Cli::command().debug_assert();
    }
}
