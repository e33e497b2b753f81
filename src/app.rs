//! The router and the server: `app(state)` returns the Router (tests call it on an ephemeral
//! port), `serve` runs it with the worker pool until shutdown.

use crate::limits;
use crate::problem::Problem;
use crate::routes::{auth, client, jobs, meshes, misc, results};
use crate::state::AppState;
use axum::extract::DefaultBodyLimit;
use axum::http::StatusCode;
use axum::routing::{get, post};
use axum::{middleware, Router};

pub fn app(state: AppState) -> Router {
    let limit = state.rt.config.max_body_bytes;
    // Mesh uploads have a limit of their own (this route-level one wins over the router's).
    let big = DefaultBodyLimit::max(state.rt.config.max_mesh_bytes);
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
        .route("/jobs/{id}/table.csv", get(results::table_csv))
        .route("/jobs/{id}/plot.svg", get(results::plot))
        .route("/meshes", post(meshes::upload).get(meshes::list).layer(big))
        .route("/meshes/{id}", get(meshes::get).delete(meshes::delete))
        .route("/meshes/{id}/file", get(meshes::file))
        .route("/presets", get(misc::presets))
        .route("/presets/{name}", get(misc::preset))
        .route("/healthz", get(misc::healthz))
        .route("/metrics", get(misc::metrics))
        .route("/openapi.yaml", get(misc::openapi))
        .route("/scene.schema.json", get(misc::scene_schema))
        .route("/", get(client::index))
        .route("/docs", get(client::docs))
        .route("/docs/", get(client::docs_slash))
        .route("/favicon.ico", get(client::favicon))
        .route("/guide", get(client::guide_root))
        .route("/guide/", get(client::guide_index))
        .route("/guide/{*file}", get(client::guide))
        .route("/client/{*file}", get(client::file))
        .fallback(|| async { Problem::not_found("no such route; see GET /openapi.yaml") })
        .method_not_allowed_fallback(|| async {
            Problem::new(
                StatusCode::METHOD_NOT_ALLOWED,
                "method not allowed",
                "see GET /openapi.yaml for the methods of each route",
            )
        })
        .layer(DefaultBodyLimit::max(limit))
        .layer(middleware::from_fn_with_state(limiter, limits::rate_limit))
        .layer(middleware::from_fn_with_state(state.clone(), auth::layer))
        .layer(middleware::from_fn(limits::problem_json_errors))
        .with_state(state)
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
    let tls = state.rt.config.tls.as_ref().map(|t| t.acceptor());
    let r = crate::server::run(listener, app(state), header_timeout, tls, signal).await;
    tokio::task::spawn_blocking(move || rt.shutdown())
        .await
        .ok();
    r
}
