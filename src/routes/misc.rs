//! Presets, health, Prometheus metrics, the OpenAPI document and the scene schema it
//! references.

use crate::problem::Problem;
use crate::state::AppState;
use crate::store::JobStatus;
use axum::extract::{Path, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use contact_core::scene::presets;
use contact_core::study::presets as study_presets;
use serde_json::{json, Value};
use std::sync::atomic::Ordering;

pub const OPENAPI: &str = include_str!("../../api/openapi.yaml");

/// The scene format. The OpenAPI document references it by the relative URL
/// `scene.schema.json`, which resolves to this route next to `/openapi.yaml` as it does to the
/// file next to `api/openapi.yaml` in the repository.
pub const SCENE_SCHEMA: &str = include_str!("../../api/scene.schema.json");

/// The built-in scenes, and the built-in convergence studies (the paper's Tables 1 and 2)
/// under `studies`: both are read from `/presets/{name}`.
pub async fn presets() -> Json<Value> {
    let list: Vec<Value> = presets::names()
        .iter()
        .map(|n| json!({"name": n, "description": presets::description(n), "href": format!("/presets/{n}")}))
        .collect();
    let studies: Vec<Value> = study_presets::names()
        .iter()
        .map(|n| json!({"name": n, "description": study_presets::description(n), "href": format!("/presets/{n}")}))
        .collect();
    Json(json!({"presets": list, "studies": studies}))
}

/// A scene preset as its scene document; a study preset as the `{"study": {...}}` body that
/// `POST /jobs` runs (so either can be edited and submitted as it is).
pub async fn preset(Path(name): Path<String>) -> Result<Json<Value>, Problem> {
    if let Some(doc) = presets::get(&name) {
        return Ok(Json(doc));
    }
    if let Some(doc) = study_presets::get(&name) {
        return Ok(Json(json!({ "study": doc })));
    }
    Err(Problem::not_found(format!(
        "unknown preset {name:?}; known: {}",
        presets::names()
            .iter()
            .chain(study_presets::names())
            .copied()
            .collect::<Vec<_>>()
            .join(", ")
    )))
}

/// The 503 problem of a node that cannot take work now, with why.
pub fn degraded(reason: String) -> Problem {
    Problem::new(StatusCode::SERVICE_UNAVAILABLE, "degraded", reason)
        .with_type("/problems/degraded")
        .retry_after(crate::disk::RETRY_AFTER_S)
}

/// 200 `ok`; 503 problem+json of type `/problems/degraded` with the reason when the node
/// cannot take work (its disk below `--min-free-disk`, or `--auth required` and no API key
/// yet); a store that cannot be read is the 503 problem of the store.
pub async fn healthz(State(state): State<AppState>) -> Result<Response, Problem> {
    let store = state.store().clone();
    let required = state.auth == crate::auth::AuthMode::Required;
    let keyless = super::blocking(move || {
        store.counts()?;
        Ok(required && !crate::auth::has_active_key(store.as_ref())?)
    })
    .await?;
    if keyless {
        return Err(degraded(crate::auth::NO_KEY_YET.to_string()));
    }
    let rt = state.rt.clone();
    let (low, space) =
        super::blocking(move || Ok((rt.disk.check().err(), rt.disk.space().ok()))).await?;
    let mut health = json!({
        "status": "ok",
        "workers": state.rt.config.workers,
        "node": state.rt.config.node,
        "store": if state.rt.config.store.is_some() { "postgres" } else { "sqlite" },
        "version": env!("CARGO_PKG_VERSION"),
    });
    if let Some(w) = state.auth.warning() {
        health["warning"] = json!(w);
    }
    if let Some(s) = space {
        health["disk"] = json!({"free_bytes": s.free, "total_bytes": s.total, "min_free_bytes": state.rt.config.min_free_disk.bytes(s.total)});
    }
    if let Some(low) = low {
        return Err(degraded(low.reason()));
    }
    Ok(Json(health).into_response())
}

pub async fn metrics(State(state): State<AppState>) -> Result<Response, Problem> {
    let store = state.store().clone();
    let counts = super::blocking(move || Ok(store.counts()?)).await?;
    let count = |s: JobStatus| counts.iter().find(|(x, _)| *x == s).map_or(0, |(_, n)| *n);
    let mut out = String::new();
    out += "# HELP contact_sim_queue_depth Jobs waiting for a worker.\n# TYPE contact_sim_queue_depth gauge\n";
    out += &format!("contact_sim_queue_depth {}\n", count(JobStatus::Queued));
    out += "# HELP contact_sim_running_jobs Jobs being computed by this node.\n# TYPE contact_sim_running_jobs gauge\n";
    out += &format!(
        "contact_sim_running_jobs {}\n",
        state.rt.running.load(Ordering::Relaxed)
    );
    out += "# HELP contact_sim_jobs Jobs in the store by status.\n# TYPE contact_sim_jobs gauge\n";
    for s in JobStatus::ALL {
        out += &format!(
            "contact_sim_jobs{{status=\"{}\"}} {}\n",
            s.as_str(),
            count(s)
        );
    }
    out += "# HELP contact_sim_steps_total Time steps computed by this process.\n# TYPE contact_sim_steps_total counter\n";
    out += &format!(
        "contact_sim_steps_total {}\n",
        state.rt.steps_done.load(Ordering::Relaxed)
    );
    out += "# HELP contact_sim_workers Worker threads of this node.\n# TYPE contact_sim_workers gauge\n";
    out += &format!("contact_sim_workers {}\n", state.rt.config.workers);
    let rt = state.rt.clone();
    if let Ok(s) = super::blocking(move || rt.disk.space().map_err(Problem::internal)).await {
        out += "# HELP contact_sim_disk_free_bytes Free bytes of the data directory's disk.\n# TYPE contact_sim_disk_free_bytes gauge\n";
        out += &format!("contact_sim_disk_free_bytes {}\n", s.free);
        out += "# HELP contact_sim_disk_min_free_bytes The --min-free-disk floor in bytes (below it the node takes no work).\n# TYPE contact_sim_disk_min_free_bytes gauge\n";
        out += &format!(
            "contact_sim_disk_min_free_bytes {}\n",
            state.rt.config.min_free_disk.bytes(s.total)
        );
    }
    let mut r = out.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; version=0.0.4"),
    );
    Ok(r)
}

pub async fn openapi() -> Response {
    let mut r = OPENAPI.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/yaml"),
    );
    r
}

pub async fn scene_schema() -> Response {
    let mut r = SCENE_SCHEMA.into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/schema+json"),
    );
    r
}
