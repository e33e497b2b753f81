//! What the handlers share, and how a node starts: the job store (embedded SQLite or shared
//! PostgreSQL), the result files, the uploaded meshes and the worker pool.

use crate::jobs::Runtime;
use crate::limits::RateLimiter;
use crate::meshes::Meshes;
use crate::store::meshes::MeshBlobs;
use crate::store::postgres::PgStore;
use crate::store::results::ResultFiles;
use crate::store::sqlite::SqliteStore;
use crate::store::{Store, StoreError};
use crate::Config;
use std::sync::Arc;

/// Shared state of the handlers.
#[derive(Clone)]
pub struct AppState {
    pub rt: Arc<Runtime>,
    /// Turns true when the server starts shutting down (ends open event streams).
    pub closing: tokio::sync::watch::Receiver<bool>,
    pub(crate) closing_tx: Arc<tokio::sync::watch::Sender<bool>>,
    /// Submission rate per client (see `limits`).
    pub limiter: Arc<RateLimiter>,
    /// Whether requests need a key (see `auth`).
    pub auth: crate::auth::AuthMode,
    /// Submission rate per API key, with authentication on (see `routes::auth`).
    pub key_limiter: Arc<RateLimiter<governor::clock::MonotonicClock, String>>,
}

impl AppState {
    pub fn store(&self) -> &Arc<dyn Store> {
        &self.rt.store
    }
}

/// Opens the store and the result files and starts the worker pool (see [`open_runtime`]).
///
/// Blocking: with a PostgreSQL store, call it outside the async runtime's threads.
pub fn start(config: Config) -> Result<AppState, String> {
    let limiter = Arc::new(RateLimiter::new(config.submit_rate, config.submit_burst));
    let auth = config.auth;
    let key_limiter = Arc::new(RateLimiter::per_key(
        config.submit_rate,
        config.submit_burst,
    ));
    let rt = open_runtime(config)?;
    let (tx, rx) = tokio::sync::watch::channel(false);
    Ok(AppState {
        rt,
        closing: rx,
        closing_tx: Arc::new(tx),
        limiter,
        auth,
        key_limiter,
    })
}

/// Opens the job store — the embedded SQLite database in `config.data_dir`, or the shared
/// PostgreSQL database of `config.store` — and the result files in `config.data_dir`, and
/// starts `config.workers` workers (none on an API-only node). Leases held by this node's
/// previous run are released, so its interrupted jobs resume at once. Also what a
/// compute-only node (`contact-sim worker`) runs.
pub fn open_runtime(config: Config) -> Result<Arc<Runtime>, String> {
    std::fs::create_dir_all(&config.data_dir)
        .map_err(|e| format!("cannot create {}: {e}", config.data_dir.display()))?;
    let (store, results, blobs): (Arc<dyn Store>, ResultFiles, MeshBlobs) = match &config.store {
        None => (
            Arc::new(
                SqliteStore::open(&config.data_dir.join("jobs.sqlite3"))
                    .map_err(|e| e.to_string())?,
            ),
            ResultFiles::new(&config.data_dir).map_err(|e| e.to_string())?,
            MeshBlobs::new(&config.data_dir).map_err(|e| e.to_string())?,
        ),
        Some(url) => (
            Arc::new(connect_waiting(url).map_err(|e| format!("store {}: {e}", redact(url)))?),
            // Other nodes write into the same directory: only stale temporary files are
            // theirs to lose.
            ResultFiles::shared(&config.data_dir).map_err(|e| e.to_string())?,
            MeshBlobs::shared(&config.data_dir).map_err(|e| e.to_string())?,
        ),
    };
    // A first start (a fresh container) has no key yet: the node starts all the same, so
    // that `contact-sim keys add` can be run beside it; until then /healthz says why it is
    // not ready and every other request is 401.
    if config.auth == crate::auth::AuthMode::Required
        && !crate::auth::has_active_key(store.as_ref()).map_err(|e| e.to_string())?
    {
        tracing::warn!("{}", crate::auth::NO_KEY_YET);
    }
    let meshes = Arc::new(Meshes::new(store.clone(), blobs));
    store
        .release_worker_leases(&format!("{}-", config.node))
        .map_err(|e| e.to_string())?;
    Ok(Runtime::start(store, Arc::new(results), meshes, config))
}

/// Connects to the shared store, waiting up to a minute for a database that is not up yet
/// (nodes and database started together, e.g. as containers); other errors at once.
fn connect_waiting(url: &str) -> Result<PgStore, StoreError> {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let mut backoff = std::time::Duration::from_millis(250);
    loop {
        match PgStore::connect(url) {
            Err(StoreError::Unavailable(e)) if std::time::Instant::now() < deadline => {
                tracing::warn!("waiting for the database at {} ({e})", redact(url));
                std::thread::sleep(backoff);
                backoff = (backoff * 2).min(std::time::Duration::from_secs(5));
            }
            other => return other,
        }
    }
}

/// A store URL without its password (for messages).
pub fn redact(url: &str) -> String {
    match (url.find("://"), url.rfind('@')) {
        (Some(scheme), Some(at)) if at > scheme => {
            let userinfo = &url[scheme + 3..at];
            let user = userinfo.split(':').next().unwrap_or("");
            format!("{}{user}{}", &url[..scheme + 3], &url[at..])
        }
        // The key=value form.
        _ => url
            .split_whitespace()
            .map(|kv| {
                if kv.starts_with("password=") {
                    "password=***"
                } else {
                    kv
                }
            })
            .collect::<Vec<_>>()
            .join(" "),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn store_urls_are_shown_without_passwords() {
        use super::redact;
        assert_eq!(
            redact("postgres://sim:s3cret@db:5432/jobs"),
            "postgres://sim@db:5432/jobs"
        );
        assert_eq!(redact("postgres://sim@db/jobs"), "postgres://sim@db/jobs");
        assert_eq!(redact("postgres://db/jobs"), "postgres://db/jobs");
        assert_eq!(
            redact("host=db user=sim password=s3cret dbname=jobs"),
            "host=db user=sim password=*** dbname=jobs"
        );
    }
}
