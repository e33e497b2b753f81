//! /meshes: upload a gmsh .msh file (checked and summarised on the blocking pool), get its
//! summary or its bytes, list, delete. A scene uses an uploaded mesh by its id,
//! `"domain": {"mesh": "<id>"}` (see `crate::meshes`).

use super::query::{Cursor, Limit, Params};
use super::results::with_type;
use super::{blocking, rfc3339};
use crate::auth::Caller;
use crate::problem::Problem;
use crate::state::AppState;
use crate::store::meshes::is_mesh_id;
use crate::store::{MeshDeletion, MeshRecord};
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use serde_json::{json, Value};

/// The mesh resource as served.
pub fn mesh_view(rec: &MeshRecord) -> Value {
    let base = format!("/meshes/{}", rec.id);
    json!({
        "id": rec.id,
        "bytes": rec.bytes,
        "created_at": rfc3339(rec.created_at),
        "summary": rec.summary,
        "links": {"self": base, "file": format!("{base}/file")},
    })
}

fn json_response(status: StatusCode, body: &Value) -> Response {
    let mut r = (status, serde_json::to_vec(body).unwrap_or_default()).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r
}

/// A mesh id from the path; anything else is an unknown mesh (404).
fn parse_mesh_id(s: &str) -> Result<String, Problem> {
    if is_mesh_id(s) {
        Ok(s.to_string())
    } else {
        Err(not_found(s))
    }
}

fn not_found(id: &str) -> Problem {
    Problem::not_found(format!(
        "no mesh with id {id:?} (ids are the 64 lowercase hex digits POST /meshes answers)"
    ))
}

/// `POST /meshes`: 201 for a new mesh, 200 for bytes uploaded before (the same id and
/// record: uploads are idempotent), both with `Location: /meshes/<id>`.
pub async fn upload(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, Problem> {
    if let Some(ct) = headers.get(header::CONTENT_TYPE) {
        let ct = ct.to_str().unwrap_or("");
        let essence = ct.split(';').next().unwrap_or("").trim();
        if !essence.eq_ignore_ascii_case("application/octet-stream") {
            return Err(Problem::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported media type",
                format!(
                    "send the .msh file's bytes as application/octet-stream (curl --data-binary @plate.msh -H 'Content-Type: application/octet-stream'), not {ct:?}"
                ),
            ));
        }
    }
    state.rt.disk.check().map_err(|low| low.problem())?;
    let meshes = state.rt.meshes.clone();
    // One upload parsed at a time per slot: each holds its file and its mesh in memory.
    let _slot = state
        .rt
        .meshes
        .parse_slots
        .acquire()
        .await
        .map_err(|e| Problem::internal(e.to_string()))?;
    let store = state.store().clone();
    let (rec, new) = blocking(move || {
        let owned = caller.key().is_some()
            && store
                .owned_mesh(caller.owner(), &crate::store::meshes::mesh_id(&body))?
                .is_some();
        if !owned {
            crate::auth::quota::check_upload(store.as_ref(), &caller, body.len() as u64)?;
        }
        meshes.upload_for(caller.owner(), &body)
    })
    .await?;
    let status = if new {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    let mut resp = json_response(status, &mesh_view(&rec));
    resp.headers_mut().insert(
        header::LOCATION,
        HeaderValue::from_str(&format!("/meshes/{}", rec.id)).expect("hex is ASCII"),
    );
    Ok(resp)
}

/// The query of `GET /meshes`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    /// Where the page starts: the `next` of the previous page.
    cursor: Option<Cursor>,
    /// Meshes per page, 1..=500 (default 50).
    limit: Option<Limit>,
    /// Only this owner's meshes (an admin's choice; a key sees only its own anyway).
    owner: Option<String>,
}

/// `GET /meshes`: newest first, paged like `GET /jobs`.
pub async fn list(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Params(q): Params<ListQuery>,
) -> Result<Response, Problem> {
    let limit = q.limit.map_or(50, |l| l.0);
    let cursor = q.cursor.map(|c| c.0);
    let asked = q.owner.clone();
    let owner = super::auth::list_scope(&caller, q.owner)?;
    let store = state.store().clone();
    let page = blocking(move || {
        Ok(match owner {
            Some(o) => store.list_owned_meshes(&o, cursor.as_deref(), limit)?,
            None => store.list_meshes(cursor.as_deref(), limit)?,
        })
    })
    .await?;
    let next = page.next.map(|c| match &asked {
        Some(o) => format!("/meshes?cursor={c}&limit={limit}&owner={o}"),
        None => format!("/meshes?cursor={c}&limit={limit}"),
    });
    let meshes: Vec<Value> = page.meshes.iter().map(mesh_view).collect();
    let mut resp = json_response(StatusCode::OK, &json!({"meshes": meshes, "next": next}));
    if let Some(n) = &next {
        if let Ok(v) = HeaderValue::from_str(&format!("<{n}>; rel=\"next\"")) {
            resp.headers_mut().insert(header::LINK, v);
        }
    }
    Ok(resp)
}

/// `GET /meshes/{id}`: the summary and metadata.
pub async fn get(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let id = parse_mesh_id(&id)?;
    let meshes = state.rt.meshes.clone();
    let store = state.store().clone();
    let rec = blocking(move || match owner_view(&*store, &caller, &id)? {
        Some(view) => Ok(view),
        None if !caller.sees_all() => Err(not_found(&id)),
        None => meshes.get(&id)?.ok_or_else(|| not_found(&id)),
    })
    .await?;
    Ok(json_response(StatusCode::OK, &mesh_view(&rec)))
}

/// The mesh as a key that does not see everything sees it (None unless it is theirs);
/// None for a caller who sees everything.
fn owner_view(
    store: &dyn crate::store::Store,
    caller: &Caller,
    id: &str,
) -> Result<Option<MeshRecord>, Problem> {
    if caller.sees_all() {
        return Ok(None);
    }
    Ok(store.owned_mesh(caller.owner(), id)?)
}

/// `GET /meshes/{id}/file`: the uploaded bytes, with their SHA-256 (the id) as `ETag` and
/// `Repr-Digest`.
pub async fn file(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let id = parse_mesh_id(&id)?;
    let meshes = state.rt.meshes.clone();
    let store = state.store().clone();
    let name = id.clone();
    let bytes = blocking(move || {
        if !caller.sees_all() && owner_view(&*store, &caller, &name)?.is_none() {
            return Err(not_found(&name));
        }
        meshes.file(&name)?.ok_or_else(|| not_found(&name))
    })
    .await?;
    let mut resp = with_type(bytes, "application/octet-stream");
    let disp = format!("attachment; filename=\"{id}.msh\"");
    resp.headers_mut().insert(
        header::CONTENT_DISPOSITION,
        HeaderValue::from_str(&disp).expect("hex is ASCII"),
    );
    Ok(resp)
}

/// `DELETE /meshes/{id}`: 204; 409 while a queued or running job uses the mesh. A key
/// that does not see everything deletes its own ownership (the file goes with the last
/// owner); an admin or the anonymous user deletes the mesh for everyone.
pub async fn delete(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let id = parse_mesh_id(&id)?;
    let meshes = state.rt.meshes.clone();
    let name = id.clone();
    let outcome = blocking(move || {
        if caller.sees_all() {
            meshes.delete(&name)
        } else {
            meshes.release(caller.owner(), &name)
        }
    })
    .await?;
    match outcome {
        MeshDeletion::Deleted => Ok(StatusCode::NO_CONTENT.into_response()),
        MeshDeletion::Absent => Err(not_found(&id)),
        MeshDeletion::InUse(job) => Err(Problem::conflict(format!(
            "mesh {id} is used by job {} ({}); delete it once the job has finished, or cancel the job",
            job.id,
            job.status.as_str()
        ))),
    }
}
