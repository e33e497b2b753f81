//! Service settings: what `contact-sim serve` and `contact-sim worker` configure.

use std::path::PathBuf;

/// Service settings (CLI flags of `contact-sim serve`).
#[derive(Debug, Clone)]
pub struct Config {
    /// Result files (and the embedded store's database). With a shared store, a directory
    /// every node mounts at the same contents.
    pub data_dir: PathBuf,
    /// `postgres://…`: the shared job store of many nodes; None: the embedded SQLite store
    /// in `data_dir` (single node, no server needed).
    pub store: Option<String>,
    /// Seconds a claimed job's lease lasts; a dead worker's job is claimed again this long
    /// after its last renewal (renewed every third of it while the job runs).
    pub lease_s: f64,
    /// Claims in a row that may end without a new checkpoint (the worker died, was killed
    /// or hung each time) before the job is failed as abandoned (dead letter).
    pub max_attempts: u32,
    /// Worker threads (jobs run in parallel, each sequentially).
    pub workers: usize,
    /// Prefix of this node's worker names (leases of a previous run are released at start,
    /// so it must differ between nodes sharing a store).
    pub node: String,
    /// Maximum number of queued jobs; beyond it POST /jobs answers 503.
    pub queue_capacity: usize,
    /// Per-job limits, enforced at submission ([`Config::job_limits`]).
    pub max_nodes: usize,
    pub max_steps: usize,
    pub max_stored_bytes: u64,
    /// Predicted peak memory a job may need, in bytes (None: no limit; default 80 % of
    /// physical memory divided by the workers); enforced at submission and when a worker
    /// prepares the job ([`contact_core::memory`]).
    pub max_job_memory: Option<u64>,
    /// Request body limit in bytes.
    pub max_body_bytes: usize,
    /// Body limit of a mesh upload (`POST /meshes`) in bytes; the reader's own limit
    /// (`contact_core::mesh::import::MAX_FILE_BYTES`, 256 MiB) applies above it.
    pub max_mesh_bytes: usize,
    /// Threads each job computes with (`--threads-per-job`; default: cores ÷ workers, at
    /// least 1); a study's runs computed at the same time share them. Not part of any
    /// computation's hash: the numbers are the same bits for every count.
    pub threads_per_job: usize,
    /// Deepest array/object nesting accepted in a submitted document (scenes need 4).
    pub max_json_depth: usize,
    /// Submissions per second per client IP (token bucket refill rate; 0 disables).
    pub submit_rate: f64,
    /// Submissions a client may make at once (token bucket size).
    pub submit_burst: u32,
    /// Time a client has to send a complete request head (slow or silent clients are
    /// disconnected).
    pub header_timeout: std::time::Duration,
    /// Certificate and key of HTTPS (`--tls-cert`, `--tls-key`); None: plain HTTP.
    pub tls: Option<crate::tls::ServerTls>,
    /// Whether requests need an API key (see `crate::auth`); with `Required` and no active
    /// key in the store yet, the node starts but `/healthz` is 503 and everything else 401
    /// until one is added.
    pub auth: crate::auth::AuthMode,
    /// Free space of the data directory below which the node takes no new work
    /// (`--min-free-disk`, see `crate::disk`).
    pub min_free_disk: crate::disk::MinFreeDisk,
    /// The built user guide (the mdBook HTML `mdbook build docs` writes to `target/book`),
    /// served at `/guide/` (`--guide-dir`); None: `/guide/` says how to get it.
    pub guide_dir: Option<std::path::PathBuf>,
}

impl Config {
    /// The per-job limits every job is admitted under at submission and run under by a
    /// worker ([`contact_core::admission`]).
    pub fn job_limits(&self) -> contact_core::admission::Limits {
        contact_core::admission::Limits {
            max_nodes: Some(self.max_nodes),
            max_steps: Some(self.max_steps),
            max_stored_bytes: Some(self.max_stored_bytes),
            max_memory: self.max_job_memory,
        }
    }
}

/// The cores of the machine divided among `workers` jobs (at least one thread each).
pub fn threads_per_job(workers: usize) -> usize {
    (contact_core::linalg::par::Threads::available() / workers.max(1)).max(1)
}

impl Default for Config {
    fn default() -> Self {
        let workers = std::thread::available_parallelism().map_or(2, |n| n.get());
        Config {
            data_dir: PathBuf::from("./data"),
            store: None,
            lease_s: 30.0,
            max_attempts: 3,
            workers,
            node: "local".into(),
            queue_capacity: 1000,
            max_nodes: 300_000,
            max_steps: 100_000,
            max_stored_bytes: 2 << 30,
            max_job_memory: contact_core::memory::default_limit(workers),
            max_body_bytes: 1 << 20,
            max_mesh_bytes: 64 << 20,
            threads_per_job: threads_per_job(workers),
            max_json_depth: 32,
            submit_rate: 10.0,
            submit_burst: 50,
            header_timeout: std::time::Duration::from_secs(30),
            tls: None,
            auth: crate::auth::AuthMode::Off,
            min_free_disk: crate::disk::MinFreeDisk::default(),
            guide_dir: None,
        }
    }
}
