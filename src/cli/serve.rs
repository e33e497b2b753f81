//! `contact-sim serve`: the HTTP job service (also what runs without a subcommand).

use super::node::{shutdown_signal, NodeArgs};
use super::{fail, fatal};
use clap::{Args, FromArgMatches};
use contact_sim::Config;
use std::process::ExitCode;

/// The flags of `serve`. Every default but the address comes from [`Config::default`], and
/// [`ServeArgs::config`] of no flags is that default.
#[derive(Args)]
pub struct ServeArgs {
    /// The address to listen on.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: String,
    #[command(flatten)]
    pub node: NodeArgs,
    /// Maximum queued jobs before POST /jobs answers 503.
    #[arg(long = "queue-capacity", default_value_t = Config::default().queue_capacity)]
    pub queue_capacity: usize,
    /// Per-job limit on mesh nodes.
    #[arg(long = "max-nodes", default_value_t = Config::default().max_nodes)]
    pub max_nodes: usize,
    /// Per-job limit on time steps.
    #[arg(long = "max-steps", default_value_t = Config::default().max_steps)]
    pub max_steps: usize,
    /// Per-job limit on stored result bytes.
    #[arg(long = "max-stored-bytes", default_value_t = Config::default().max_stored_bytes)]
    pub max_stored_bytes: u64,
    /// Request body limit in bytes (413 beyond).
    #[arg(long = "max-body-bytes", default_value_t = Config::default().max_body_bytes)]
    pub max_body_bytes: usize,
    /// Body limit of a mesh upload, POST /meshes, in bytes (413 beyond).
    #[arg(long = "max-mesh-bytes", default_value_t = Config::default().max_mesh_bytes)]
    pub max_mesh_bytes: usize,
    /// Deepest array/object nesting of a submitted document (422 beyond).
    #[arg(long = "max-json-depth", default_value_t = Config::default().max_json_depth)]
    pub max_json_depth: usize,
    /// Submissions (POST) per second per client IP, refill rate of a token bucket
    /// (429 + Retry-After beyond); 0 disables the limit.
    #[arg(long = "submit-rate", default_value_t = Config::default().submit_rate)]
    pub submit_rate: f64,
    /// Submissions a client may make in one burst (token bucket size).
    #[arg(long = "submit-burst", default_value_t = Config::default().submit_burst)]
    pub submit_burst: u32,
    /// Seconds a client has to send a complete request head (then disconnected).
    #[arg(
        long = "header-timeout",
        default_value_t = Config::default().header_timeout.as_secs_f64()
    )]
    pub header_timeout: f64,
    /// Serve the user guide built by `mdbook build docs` (its folder, target/book) at /guide/.
    #[arg(long = "guide-dir", value_name = "DIR")]
    pub guide_dir: Option<std::path::PathBuf>,
    /// Serve HTTPS with this PEM certificate chain (server certificate first); needs
    /// --tls-key.
    #[arg(long = "tls-cert", value_name = "PEM", requires = "tls_key")]
    pub tls_cert: Option<std::path::PathBuf>,
    /// The PEM private key of --tls-cert.
    #[arg(long = "tls-key", value_name = "PEM", requires = "tls_cert")]
    pub tls_key: Option<std::path::PathBuf>,
    /// Whether requests need an API key (contact-sim keys add): required, or off. Without
    /// the flag, off when every listening address is loopback; on any other address the
    /// node refuses to start without it.
    #[arg(long, value_parser = ["required", "off"])]
    pub auth: Option<String>,
}

impl Default for ServeArgs {
    /// `serve` without flags.
    fn default() -> Self {
        let matches =
            ServeArgs::augment_args(clap::Command::new("serve")).get_matches_from(["serve"]);
        ServeArgs::from_arg_matches(&matches).expect("serve needs no flags")
    }
}

impl ServeArgs {
    /// The service settings; an error names the bad flag. A header timeout that is not a
    /// positive number keeps the default.
    pub fn config(self) -> Result<Config, String> {
        let base = self.node.config()?;
        let addrs: Vec<std::net::SocketAddr> = std::net::ToSocketAddrs::to_socket_addrs(&self.addr)
            .map_err(|e| format!("--addr {}: {e}", self.addr))?
            .collect();
        let auth = contact_sim::auth::AuthMode::resolve(self.auth.as_deref(), &addrs)?;
        let header_timeout = if self.header_timeout.is_finite() && self.header_timeout > 0.0 {
            std::time::Duration::from_secs_f64(self.header_timeout.min(1e6))
        } else {
            base.header_timeout
        };
        Ok(Config {
            queue_capacity: self.queue_capacity,
            max_nodes: self.max_nodes,
            max_steps: self.max_steps,
            max_stored_bytes: self.max_stored_bytes,
            max_body_bytes: self.max_body_bytes,
            max_mesh_bytes: self.max_mesh_bytes,
            max_json_depth: self.max_json_depth,
            submit_rate: self.submit_rate,
            submit_burst: self.submit_burst,
            header_timeout,
            tls: match (&self.tls_cert, &self.tls_key) {
                (Some(cert), Some(key)) => Some(contact_sim::tls::ServerTls::load(cert, key)?),
                _ => None,
            },
            auth,
            guide_dir: self.guide_dir.clone(),
            ..base
        })
    }
}

pub fn main(args: ServeArgs) -> ExitCode {
    let addr = args.addr.clone();
    match args.config() {
        Ok(config) => serve(&addr, config),
        Err(e) => fail(2, &e),
    }
}

fn serve(addr: &str, config: Config) -> ExitCode {
    // The async runtime only does I/O; the numerics runs on the worker pool's own threads.
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => return fatal(&format!("cannot start the async runtime: {e}")),
    };
    if let Some(w) = config.auth.warning() {
        tracing::warn!("{w}");
    }
    if config.workers == 0 && config.store.is_none() {
        tracing::warn!(
            "--workers 0 with the embedded store: jobs are accepted but nothing runs them \
             (an API-only node needs a shared --store and worker nodes)"
        );
    }
    // Opening a PostgreSQL store blocks: not on the runtime's threads.
    let state = match contact_sim::state::start(config.clone()) {
        Ok(s) => s,
        Err(e) => return fatal(&e),
    };
    rt.block_on(async {
        let listener = match tokio::net::TcpListener::bind(addr).await {
            Ok(l) => l,
            Err(e) => return fatal(&format!("cannot listen on {addr}: {e}")),
        };
        tracing::info!(
            "contact-sim {} listening on {}://{} (data in {}, store {}, node {}, {} workers)",
            env!("CARGO_PKG_VERSION"),
            if config.tls.is_some() {
                "https"
            } else {
                "http"
            },
            listener
                .local_addr()
                .map(|a| a.to_string())
                .unwrap_or_default(),
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
            tracing::info!(
                "shutting down (running jobs are checkpointed and resume at the next start)"
            );
        };
        match contact_sim::app::serve(listener, state, shutdown).await {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => fatal(&e.to_string()),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The defaults are written once: `serve` without flags is `Config::default()`.
    #[test]
    fn serve_without_flags_is_the_default_config() {
        let args = ServeArgs::default();
        assert_eq!(args.addr, "127.0.0.1:8080");
        let config = args.config().unwrap();
        assert_eq!(format!("{config:?}"), format!("{:?}", Config::default()));
    }

    #[test]
    fn flags_reach_the_config() {
        let matches = ServeArgs::augment_args(clap::Command::new("serve")).get_matches_from([
            "serve",
            "--max-steps",
            "7",
            "--header-timeout",
            "0.5",
            "--lease-seconds",
            "2",
            "--max-attempts",
            "9",
            "--store",
            "postgres://u@h/db",
            "--node",
            "api",
            "--workers",
            "0",
        ]);
        let config = ServeArgs::from_arg_matches(&matches)
            .unwrap()
            .config()
            .unwrap();
        assert_eq!((config.max_steps, config.workers), (7, 0));
        assert_eq!(config.header_timeout, std::time::Duration::from_millis(500));
        assert_eq!(config.lease_s, 2.0);
        assert_eq!(config.max_attempts, 9);
        assert_eq!(config.store.as_deref(), Some("postgres://u@h/db"));
        assert_eq!(config.node, "api");
        assert_eq!(config.max_nodes, Config::default().max_nodes);
    }

    #[test]
    fn node_flags_out_of_range_are_named() {
        let mut args = ServeArgs::default();
        args.node.lease_seconds = 0.1;
        let err = args.config().unwrap_err();
        assert!(err.contains("--lease-seconds"), "{err}");
        let mut args = ServeArgs::default();
        args.node.max_attempts = 0;
        let err = args.config().unwrap_err();
        assert!(err.contains("--max-attempts"), "{err}");
    }
}
