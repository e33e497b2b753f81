//! The node's log: `tracing` events written to stderr, one line each, as text for people or
//! as JSON objects for log collectors (`--log-format`), at the level `RUST_LOG` selects
//! (default `info`). Running jobs log inside a `job` span carrying the job's id, so one
//! job's lines can be picked out of a node's log.

use clap::ValueEnum;
use tracing_subscriber::filter::LevelFilter;
use tracing_subscriber::EnvFilter;

/// How log lines are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    /// `TIME LEVEL span{fields}: target: message`.
    #[default]
    Text,
    /// One JSON object a line (`timestamp`, `level`, `fields.message`, `target`, `span`,
    /// `spans`).
    Json,
}

/// Installs the global subscriber. Directives of `RUST_LOG` that do not parse are skipped.
pub fn init(format: LogFormat) {
    let filter = EnvFilter::builder()
        .with_default_directive(LevelFilter::INFO.into())
        .from_env_lossy();
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    // Err only when a subscriber is installed already: it stays.
    let _ = match format {
        LogFormat::Text => builder.try_init(),
        LogFormat::Json => builder.json().try_init(),
    };
}
