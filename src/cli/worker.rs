//! `contact-sim worker`: a compute-only node of a shared store.

use super::node::{shutdown_signal, NodeArgs};
use super::{fail, fatal};
use clap::Args;
use contact_sim::Config;
use std::process::ExitCode;

/// The flags of `worker`: those of every node; the store is required.
#[derive(Args)]
pub struct WorkerArgs {
    #[command(flatten)]
    pub node: NodeArgs,
}

impl WorkerArgs {
    /// The service settings; a worker node runs at least one worker.
    pub fn config(self) -> Result<Config, String> {
        if self.node.store.is_none() {
            return Err(
                "a worker node needs the shared store: --store postgres://user@host/db".into(),
            );
        }
        let config = self.node.config()?;
        Ok(Config {
            workers: config.workers.max(1),
            ..config
        })
    }
}

pub fn main(args: WorkerArgs) -> ExitCode {
    match args.config() {
        Ok(config) => work(config),
        Err(e) => fail(2, &e),
    }
}

fn work(config: Config) -> ExitCode {
    let rt = match contact_sim::state::open_runtime(config.clone()) {
        Ok(rt) => rt,
        Err(e) => return fatal(&e),
    };
    tracing::info!(
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
        Err(e) => return fatal(&format!("cannot wait for signals: {e}")),
    }
    tracing::info!("worker node stopping (running jobs are checkpointed)");
    rt.shutdown();
    ExitCode::SUCCESS
}
