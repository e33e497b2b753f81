//! What `serve` and `worker` share: how a node joins the job store (its flags, turned into
//! the service [`Config`]) and when it stops (SIGINT or SIGTERM).

use clap::Args;
use contact_sim::Config;
use std::path::PathBuf;

/// The flags of every service node. Defaults come from [`Config::default`].
#[derive(Args)]
pub struct NodeArgs {
    /// Result files (and the embedded store); with --store, a directory shared by all nodes.
    #[arg(long = "data-dir", default_value_os_t = Config::default().data_dir)]
    pub data_dir: PathBuf,
    /// Worker threads (default: number of cores; 0 with `serve`: an API-only node).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Threads each job computes with (default: cores ÷ workers, at least 1); a study's
    /// runs computed at once share them.
    #[arg(long = "threads-per-job", value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub threads_per_job: Option<u64>,
    /// Job store: a `postgres://user@host/db` URL shared by many nodes, or omitted for
    /// the embedded SQLite database in the data directory (single node).
    #[arg(long)]
    pub store: Option<String>,
    /// This node's name, the prefix of its worker names; a restarted node with the same
    /// name takes its interrupted jobs back at once. Must differ between live nodes
    /// (default: "local" for the embedded store, host-pid for a shared one).
    #[arg(long)]
    pub node: Option<String>,
    /// Seconds a job's lease lasts: a dead worker's job is claimed by another this long
    /// after its last renewal.
    #[arg(long = "lease-seconds", default_value_t = Config::default().lease_s)]
    pub lease_seconds: f64,
    /// Claims in a row that may end without a new checkpoint (worker crashed, killed or
    /// hung) before a job is failed as abandoned instead of being run again.
    #[arg(long = "max-attempts", default_value_t = Config::default().max_attempts)]
    pub max_attempts: u32,
    /// Per-job memory limit in bytes (suffixes K, M, G, T): a job whose predicted peak
    /// exceeds it on every allowed linear path is refused at submission (422). Default: 80 %
    /// of physical memory divided by the workers.
    #[arg(long = "max-job-memory", value_parser = contact_core::memory::parse_bytes)]
    pub max_job_memory: Option<u64>,
    /// Free space the data directory's disk must keep: bytes (1073741824, 512MiB, 2GB) or
    /// a percentage of the disk (5%); 0 turns the check off. Below it POST /jobs and
    /// POST /meshes answer 507, workers claim nothing and /healthz is degraded.
    #[arg(long = "min-free-disk", default_value = "1GiB")]
    pub min_free_disk: contact_sim::disk::MinFreeDisk,
}

impl NodeArgs {
    /// The node's part of the service settings, the rest at their defaults; an error names
    /// the bad flag.
    pub fn config(self) -> Result<Config, String> {
        let seconds = self.lease_seconds;
        if !(seconds.is_finite() && (0.3..=86_400.0).contains(&seconds)) {
            return Err(format!(
                "--lease-seconds {seconds}: must be between 0.3 and 86400"
            ));
        }
        if self.max_attempts == 0 {
            return Err("--max-attempts 0: must be at least 1".into());
        }
        let defaults = Config::default();
        let workers = self.workers.unwrap_or(defaults.workers);
        Ok(Config {
            data_dir: self.data_dir,
            workers,
            threads_per_job: self.threads_per_job.map_or_else(
                || contact_sim::config::threads_per_job(workers),
                |t| t as usize,
            ),
            max_job_memory: self
                .max_job_memory
                .or_else(|| contact_core::memory::default_limit(workers)),
            node: node_name(self.node, self.store.is_some()),
            store: self.store,
            lease_s: seconds,
            max_attempts: self.max_attempts,
            min_free_disk: self.min_free_disk,
            ..defaults
        })
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
pub async fn shutdown_signal() {
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
