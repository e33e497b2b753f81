//! The router and the server: `app(state)` returns the Router (tests call it on an ephemeral
//! port), `serve` runs it with the worker pool until shutdown.

use super::error::ApiError;
use super::jobs::Runtime;
use super::limits::{self, RateLimiter};
use super::routes::{client, jobs, misc, results};
use super::store::postgres::PgStore;
use super::store::results::ResultFiles;
use super::store::sqlite::SqliteStore;
use super::store::{Store, StoreError};
use super::Config;
use axum::extract::DefaultBodyLimit;
use axum::http::StatusCode;
use axum::routing::{get, post};
use axum::{middleware, Router};
use std::sync::Arc;

/// Shared state of the handlers.
#[derive(Clone)]
pub struct AppState {
    pub rt: Arc<Runtime>,
    /// Turns true when the server starts shutting down (ends open event streams).
    pub closing: tokio::sync::watch::Receiver<bool>,
    closing_tx: Arc<tokio::sync::watch::Sender<bool>>,
    /// Submission rate per client (see `limits`).
    pub limiter: Arc<RateLimiter>,
}

impl AppState {
    pub fn store(&self) -> &Arc<dyn Store> {
        &self.rt.store
    }
}

pub fn app(state: AppState) -> Router {
    let limit = state.rt.config.max_body_bytes;
    let limiter = state.limiter.clone();
    Router::new()
        .route("/jobs", post(jobs::submit).get(jobs::list))
        .route("/jobs/{id}", get(jobs::get_job).delete(jobs::delete_job))
        .route("/jobs/{id}/cancel", post(jobs::cancel))
        .route("/jobs/{id}/events", get(jobs::events))
        .route("/jobs/{id}/summary", get(results::summary))
        .route("/jobs/{id}/mesh", get(results::mesh))
        .route("/jobs/{id}/fields", get(results::fields))
        .route("/jobs/{id}/fields/{file}", get(results::vtu))
        .route("/jobs/{id}/result.pvd", get(results::pvd))
        .route("/jobs/{id}/archive.tar", get(results::archive))
        .route("/jobs/{id}/report.svg", get(results::report))
        .route("/presets", get(misc::presets))
        .route("/presets/{name}", get(misc::preset))
        .route("/healthz", get(misc::healthz))
        .route("/metrics", get(misc::metrics))
        .route("/openapi.yaml", get(misc::openapi))
        .route("/", get(client::index))
        .route("/client/{file}", get(client::file))
        .fallback(|| async { ApiError::not_found("no such route; see GET /openapi.yaml") })
        .method_not_allowed_fallback(|| async {
            ApiError::new(
                StatusCode::METHOD_NOT_ALLOWED,
                "method not allowed",
                "see GET /openapi.yaml for the methods of each route",
            )
        })
        .layer(DefaultBodyLimit::max(limit))
        .layer(middleware::from_fn_with_state(limiter, limits::rate_limit))
        .layer(middleware::from_fn(limits::problem_json_errors))
        .with_state(state)
}

/// Opens the store and the result files and starts the worker pool (see [`open_runtime`]).
///
/// Blocking: with a PostgreSQL store, call it outside the async runtime's threads.
pub fn start(config: Config) -> Result<AppState, String> {
    let limiter = Arc::new(RateLimiter::new(config.submit_rate, config.submit_burst));
    let rt = open_runtime(config)?;
    let (tx, rx) = tokio::sync::watch::channel(false);
    Ok(AppState {
        rt,
        closing: rx,
        closing_tx: Arc::new(tx),
        limiter,
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
    let (store, results): (Arc<dyn Store>, ResultFiles) = match &config.store {
        None => (
            Arc::new(
                SqliteStore::open(&config.data_dir.join("jobs.sqlite3"))
                    .map_err(|e| e.to_string())?,
            ),
            ResultFiles::new(&config.data_dir).map_err(|e| e.to_string())?,
        ),
        Some(url) => (
            Arc::new(connect_waiting(url).map_err(|e| format!("store {}: {e}", redact(url)))?),
            // Other nodes write into the same directory: only stale temporary files are
            // theirs to lose.
            ResultFiles::shared(&config.data_dir).map_err(|e| e.to_string())?,
        ),
    };
    store
        .release_worker_leases(&format!("{}-", config.node))
        .map_err(|e| e.to_string())?;
    Ok(Runtime::start(store, Arc::new(results), config))
}

/// Connects to the shared store, waiting up to a minute for a database that is not up yet
/// (nodes and database started together, e.g. as containers); other errors at once.
fn connect_waiting(url: &str) -> Result<PgStore, StoreError> {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let mut backoff = std::time::Duration::from_millis(250);
    loop {
        match PgStore::connect(url) {
            Err(StoreError::Unavailable(e)) if std::time::Instant::now() < deadline => {
                eprintln!(
                    "contact-sim: waiting for the database at {} ({e})",
                    redact(url)
                );
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

/// Serves until `shutdown` resolves, then stops the workers (running jobs are checkpointed
/// and resume at the next start).
pub async fn serve(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let rt = state.rt.clone();
    let closing = state.closing_tx.clone();
    let signal = async move {
        shutdown.await;
        let _ = closing.send(true);
    };
    // Peer addresses reach the handlers (per-client submission rate); slow clients are
    // disconnected after the header timeout.
    let header_timeout = state.rt.config.header_timeout;
    let r = super::server::run(listener, app(state), header_timeout, signal).await;
    tokio::task::spawn_blocking(move || rt.shutdown())
        .await
        .ok();
    r
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

    /// api/openapi.yaml documents exactly the routes of `app()`.
    #[test]
    fn openapi_lists_every_route() {
        let src = include_str!("app.rs");
        let routes: Vec<&str> = src
            .split(".route(\"")
            .skip(1)
            .map(|s| s.split('"').next().unwrap())
            .collect();
        assert!(routes.len() >= 14);
        let spec = super::super::routes::misc::OPENAPI;
        let documented: Vec<&str> = spec
            .lines()
            .filter(|l| l.starts_with("  /") && l.ends_with(':'))
            .map(|l| l.trim().trim_end_matches(':'))
            .collect();
        for r in &routes {
            assert!(
                documented.contains(r),
                "route {r} missing from api/openapi.yaml"
            );
        }
        for d in &documented {
            assert!(
                routes.contains(d),
                "api/openapi.yaml documents {d}, which the router lacks"
            );
        }
    }
}
