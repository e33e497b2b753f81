//! /jobs: submit (validated by [`crate::submission`], deduplicated, enqueued), list, get (ETag, Retry-After),
//! cancel, delete, and the Server-Sent Events progress stream.

use super::query::{Cursor, Limit, Params};
use super::{blocking, load_job, parse_id, rfc3339};
use crate::auth::Caller;
use crate::jobs::{is_study, JobEvent};
use crate::problem::Problem;
use crate::state::AppState;
use crate::store::{Enqueued, JobRecord, JobStatus, NewJob};
use crate::submission::Validated;
use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::Extension;
use contact_core::scene::hex_sha256;
use serde_json::{json, Value};
use std::convert::Infallible;
use std::time::Duration;

/// The job resource as served.
pub fn job_view(rec: &JobRecord, state: &AppState) -> Value {
    let id = rec.id;
    let (progress, eta) = match state.rt.live_progress(id) {
        Some((p, eta)) if rec.status == JobStatus::Running => (p, eta),
        _ => (rec.progress, None),
    };
    let percent = if progress.steps > 0 {
        100.0 * progress.step as f64 / progress.steps as f64
    } else {
        0.0
    };
    let base = format!("/jobs/{id}");
    let mut links = json!({"self": base, "events": format!("{base}/events")});
    if !rec.status.is_finished() {
        links["cancel"] = json!(format!("{base}/cancel"));
    }
    let study = is_study(&rec.scene);
    if rec.status == JobStatus::Succeeded && study {
        links["summary"] = json!(format!("{base}/summary"));
        links["table"] = json!(format!("{base}/summary?format=text"));
        links["report"] = json!(format!("{base}/report.svg"));
        if crate::jobs::is_sweep(&rec.scene) {
            links["table_csv"] = json!(format!("{base}/table.csv"));
            links["plot"] = json!(format!("{base}/plot.svg"));
        }
        if crate::jobs::has_chosen_run(&rec.scene) {
            // The chosen run's results, served as a simulation's.
            links["fields"] = json!(format!("{base}/fields?step=last"));
            links["mesh"] = json!(format!("{base}/mesh"));
            links["pvd"] = json!(format!("{base}/result.pvd"));
            links["archive"] = json!(format!("{base}/archive.tar"));
        }
    } else if rec.status == JobStatus::Succeeded {
        links["summary"] = json!(format!("{base}/summary"));
        links["fields"] = json!(format!("{base}/fields?step=last"));
        links["mesh"] = json!(format!("{base}/mesh"));
        links["pvd"] = json!(format!("{base}/result.pvd"));
        links["archive"] = json!(format!("{base}/archive.tar"));
    }
    let mut view = json!({
        "id": id,
        "kind": if study { "study" } else { "simulation" },
        "scene": if study {
            let st = rec.scene.get("sweep").unwrap_or(&rec.scene["study"]);
            st.get("name").or_else(|| st["scene"].get("name"))
        } else {
            rec.scene.get("name")
        }
        .cloned()
        .unwrap_or(Value::Null),
        "status": rec.status,
        "progress": {
            "step": progress.step,
            "steps": progress.steps,
            "percent": (percent * 10.0).round() / 10.0,
            "eta_s": eta,
            "last_residual": progress.last_residual,
        },
        "created_at": rfc3339(rec.created_at),
        "started_at": rec.started_at.map(rfc3339),
        "finished_at": rec.finished_at.map(rfc3339),
        "error": rec.error,
        "attempt": rec.attempt,
        "worker": rec.worker,
        "last_checkpoint_step": rec.last_checkpoint_step,
        "scene_hash": rec.scene_hash,
        "memory": rec.memory.map(|m| json!({
            "predicted_bytes": m.predicted_bytes,
            "limit_bytes": state.rt.config.max_job_memory,
            "linear_path": m.linear_path,
        })),
        "resolution": (!study).then(|| {
            let (mesh, time) = (&rec.scene["mesh"], &rec.scene["time"]);
            json!({
                "h": mesh.get("h"),
                "refine": mesh.get("refine"),
                "k": time.get("k"),
                "steps": progress.steps,
                "t_end": time.get("t_end"),
            })
        }),
        "links": links,
    });
    if let Some(link) = crate::continuation::parent_of(&rec.scene) {
        // A continuation: the parent's id, computation hash and last step.
        view["continued_from"] = link.clone();
        if let Some(parent) = link["job"].as_str() {
            view["links"]["parent"] = json!(format!("/jobs/{parent}"));
        }
    }
    if let Some(sweep) = rec.sweep {
        // A sweep's member: the sweep that created it (and cancels it with itself).
        view["sweep"] = json!(sweep);
        view["links"]["sweep"] = json!(format!("/jobs/{sweep}"));
    }
    if crate::jobs::is_sweep(&rec.scene) {
        // Its members' jobs in member order (equal members share one); empty until the
        // sweep was first claimed.
        view["members"] = json!(rec.members);
    }
    if !rec.owner.is_empty() {
        view["owner"] = json!(rec.owner);
    }
    view
}

/// A sweep's record with its progress as its members' now (they run as jobs of their own,
/// possibly on other nodes); any other record as it is. Blocking.
fn with_member_progress(mut rec: JobRecord, state: &AppState) -> JobRecord {
    if crate::jobs::is_sweep(&rec.scene) && !rec.status.is_finished() {
        if let Some(p) = state.rt.sweep_members_progress(&rec) {
            rec.progress = p;
        }
    }
    rec
}

fn json_response(status: StatusCode, body: &Value) -> Response {
    let mut r = (status, serde_json::to_vec(body).unwrap_or_default()).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r
}

pub async fn submit(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, Problem> {
    if let Some(ct) = headers.get(header::CONTENT_TYPE) {
        let ct = ct.to_str().unwrap_or("");
        if !ct.starts_with("application/json") && !ct.contains("+json") {
            return Err(Problem::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported media type",
                format!("send the scene as application/json, not {ct:?}"),
            ));
        }
    }
    // A full disk is the node's condition: 507 before anything is stored.
    state.rt.disk.check().map_err(|low| low.problem())?;
    let doc: Value = crate::json_body::parse(&body)?;
    crate::limits::check_depth(&doc, state.rt.config.max_json_depth)?;
    // Validation meshes the body (and reads an uploaded mesh): on the blocking pool. Another
    // owner's mesh is unknown before it is read (nothing about it may leak).
    let st = state.clone();
    let who = caller.clone();
    let Validated {
        doc: scene_doc,
        steps,
        stored_bytes,
        memory,
    } = blocking(move || {
        if doc.get("continue").is_some() {
            return crate::continuation::validated(doc, &st, &who);
        }
        crate::meshes::check_owner(&doc, st.store().as_ref(), &who)?;
        crate::submission::validated(doc, &st)
    })
    .await?;
    let hash = crate::submission::scene_hash(&scene_doc);
    let mesh = crate::meshes::mesh_ref(&scene_doc);
    let key = match headers.get("idempotency-key") {
        Some(v) => Some(
            v.to_str()
                .ok()
                .filter(|s| !s.is_empty() && s.len() <= 255)
                .ok_or_else(|| {
                    Problem::bad_request("Idempotency-Key must be 1–255 visible ASCII characters")
                })?
                .to_string(),
        ),
        None => None,
    };
    let request_hash = key.as_ref().map(|_| hex_sha256(&body));
    let store = state.store().clone();
    let capacity = state.rt.config.queue_capacity;
    let outcome = blocking(move || {
        let owner = caller.owner();
        if key.is_none() {
            // An identical scene already computed by this version for this owner: answer
            // from the store.
            if let Some(done) = store.find_succeeded_for(owner, &hash)? {
                return Ok(Enqueued::Existing(done));
            }
        }
        // A retry with an Idempotency-Key gets its job back whatever the quotas say now.
        let retry = match &key {
            Some(k) => store.find_by_idempotency_key(owner, k)?.is_some(),
            None => false,
        };
        if !retry {
            crate::auth::quota::check_submission(store.as_ref(), &caller, stored_bytes)?;
        }
        let queued = store
            .counts()?
            .into_iter()
            .find(|(s, _)| *s == JobStatus::Queued)
            .map_or(0, |(_, n)| n);
        if queued >= capacity {
            return Err(Problem::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "queue full",
                format!("{queued} jobs are queued (limit {capacity}); retry later"),
            )
            .retry_after(5));
        }
        let job = NewJob {
            scene: scene_doc,
            scene_hash: hash,
            steps,
            idempotency_key: key,
            request_hash,
            mesh,
            memory,
        };
        Ok(store.enqueue_for(owner, stored_bytes, job)?)
    })
    .await?;
    let (status, rec) = match outcome {
        Enqueued::New(rec) => {
            state.rt.notify();
            (StatusCode::ACCEPTED, rec)
        }
        Enqueued::Existing(rec)
            if rec.status == JobStatus::Succeeded && rec.idempotency_key.is_none() =>
        {
            (StatusCode::OK, rec)
        }
        Enqueued::Existing(rec) => (StatusCode::ACCEPTED, rec),
        // The mesh was deleted between validation and enqueueing.
        Enqueued::NoMesh(id) => {
            return Err(Problem::invalid_field(
                "/domain/mesh",
                crate::meshes::unknown_mesh(&id),
            ))
        }
        Enqueued::KeyConflict(rec) => {
            return Err(Problem::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "idempotency key reused",
                format!(
                    "this Idempotency-Key was used for job {} with a different request body",
                    rec.id
                ),
            ))
        }
    };
    let mut resp = json_response(status, &job_view(&rec, &state));
    resp.headers_mut().insert(
        header::LOCATION,
        HeaderValue::from_str(&format!("/jobs/{}", rec.id)).expect("uuid is ASCII"),
    );
    Ok(resp)
}

/// The query of `GET /jobs`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ListQuery {
    /// Only jobs in this status.
    status: Option<StatusParam>,
    /// Where the page starts: the `next` of the previous page.
    cursor: Option<Cursor>,
    /// Jobs per page, 1..=500 (default 50).
    limit: Option<Limit>,
    /// Only this owner's jobs (an admin's choice; a key sees only its own anyway).
    owner: Option<String>,
}

/// `status`: a job status by name.
#[derive(Clone, Copy, serde::Deserialize)]
#[serde(try_from = "String")]
struct StatusParam(JobStatus);

impl TryFrom<String> for StatusParam {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        JobStatus::parse(&s).map(StatusParam).ok_or_else(|| {
            format!(
                "status must be one of queued, running, succeeded, failed, cancelled, not {s:?}"
            )
        })
    }
}

pub async fn list(
    State(state): State<AppState>,
    Extension(caller): Extension<Caller>,
    Params(q): Params<ListQuery>,
) -> Result<Response, Problem> {
    let status = q.status.map(|s| s.0);
    let limit = q.limit.map_or(50, |l| l.0);
    let cursor = q.cursor.map(|c| c.0);
    let asked = q.owner.clone();
    let owner = super::auth::list_scope(&caller, q.owner)?;
    let store = state.store().clone();
    let page =
        blocking(move || Ok(store.list_for(owner.as_deref(), status, cursor.as_deref(), limit)?))
            .await?;
    let next = page.next.map(|c| {
        let mut url = format!("/jobs?cursor={c}&limit={limit}");
        if let Some(s) = status {
            url += &format!("&status={}", s.as_str());
        }
        if let Some(o) = &asked {
            url += &format!("&owner={o}");
        }
        url
    });
    let jobs: Vec<Value> = page.jobs.iter().map(|r| job_view(r, &state)).collect();
    let mut resp = json_response(StatusCode::OK, &json!({"jobs": jobs, "next": next}));
    if let Some(n) = &next {
        if let Ok(v) = HeaderValue::from_str(&format!("<{n}>; rel=\"next\"")) {
            resp.headers_mut().insert(header::LINK, v);
        }
    }
    Ok(resp)
}

pub async fn get_job(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, Problem> {
    let rec = load_job(&state, parse_id(&id)?).await?;
    let st = state.clone();
    let rec = blocking(move || Ok(with_member_progress(rec, &st))).await?;
    let view = job_view(&rec, &state);
    let body = serde_json::to_vec(&view).unwrap_or_default();
    let etag = format!("\"{}\"", &hex_sha256(&body)[..16]);
    let unfinished = !rec.status.is_finished();
    let not_modified = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag || t.trim() == "*"));
    let mut resp = if not_modified {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        json_response(StatusCode::OK, &view)
    };
    resp.headers_mut()
        .insert(header::ETAG, HeaderValue::from_str(&etag).expect("hex"));
    resp.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    if unfinished {
        resp.headers_mut()
            .insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
    }
    Ok(resp)
}

pub async fn cancel(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let id = parse_id(&id)?;
    let store = state.store().clone();
    let rec = blocking(move || {
        store
            .request_cancel(id)?
            .ok_or_else(|| Problem::not_found(format!("no job with id {id}")))
    })
    .await?;
    state.rt.cancel(id);
    if crate::jobs::is_sweep(&rec.scene) && rec.status == JobStatus::Cancelled {
        // The members the sweep created go with it (a worker that requeues a sweep whose
        // cancel was requested meanwhile cancels them then).
        let rt = state.rt.clone();
        blocking(move || {
            rt.cancel_members(id);
            Ok(())
        })
        .await?;
    }
    let status = if rec.status.is_finished() && rec.status != JobStatus::Cancelled {
        StatusCode::CONFLICT
    } else {
        StatusCode::ACCEPTED
    };
    if status == StatusCode::CONFLICT {
        return Err(Problem::conflict(format!(
            "job {id} already finished ({})",
            rec.status.as_str()
        )));
    }
    Ok(json_response(status, &job_view(&rec, &state)))
}

/// Longest `DELETE /jobs/{id}` waits for a job whose cancel was requested to stop (its
/// worker ends the current time step first; a worker on another node sees the cancel at its
/// next heartbeat, a third of a lease).
const STOP_WAIT: Duration = Duration::from_secs(30);

/// The wait a request asks for with `Prefer: wait=N` (RFC 7240), in seconds, if any.
fn preferred_wait(headers: &HeaderMap) -> Option<Duration> {
    headers
        .get_all("prefer")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split([',', ';']))
        .find_map(|p| {
            let (name, value) = p.split_once('=')?;
            let value = value.trim().trim_matches('"');
            (name.trim().eq_ignore_ascii_case("wait"))
                .then(|| value.parse::<u64>().ok())
                .flatten()
        })
        .map(Duration::from_secs)
}

/// `DELETE /jobs/{id}`: removes a finished job and its results (204). A job whose cancel
/// was requested but whose worker is still ending its current step is waited for, up to
/// [`STOP_WAIT`] or the request's `Prefer: wait=N`, then 409 with `Retry-After`; a job
/// running or queued without a cancel is 409 at once.
pub async fn delete_job(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, Problem> {
    let id = parse_id(&id)?;
    let mut rec = load_job(&state, id).await?;
    let wait = preferred_wait(&headers).map_or(STOP_WAIT, |w| w.min(STOP_WAIT));
    let deadline = std::time::Instant::now() + wait;
    while !rec.status.is_finished() && rec.cancel_requested && std::time::Instant::now() < deadline
    {
        tokio::time::sleep(Duration::from_millis(50)).await;
        rec = load_job(&state, id).await?;
    }
    if !rec.status.is_finished() {
        return Err(if rec.cancel_requested {
            Problem::conflict(format!(
                "job {id} is cancelled but its worker is still ending its current time step \
                 (waited {} s); retry after Retry-After seconds",
                wait.as_secs()
            ))
            .retry_after(2)
        } else {
            Problem::conflict(format!(
                "job {id} is {}; cancel it first (POST /jobs/{id}/cancel), then delete it",
                rec.status.as_str()
            ))
        });
    }
    let store = state.store().clone();
    let results = state.rt.results.clone();
    blocking(move || {
        store.delete(id)?;
        results
            .remove_job(id)
            .map_err(|e| Problem::internal(e.to_string()))
    })
    .await?;
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// SSE: the current state first, then every progress event, and the final status; the stream
/// ends when the job is finished.
pub async fn events(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let id = parse_id(&id)?;
    // Unknown ids are refused before a channel is created for them; then subscribe before
    // reading the record again, so no event between the two is lost.
    load_job(&state, id).await?;
    let mut rx = state.rt.subscribe(id);
    let rec = load_job(&state, id).await?;
    let first = JobEvent::from_record(&rec);
    let mut closing = state.closing.clone();
    let store = state.store().clone();
    let rt = state.rt.clone();
    let stream = async_stream(
        move |tx: tokio::sync::mpsc::Sender<Result<Event, Infallible>>| async move {
            let done = first.status.is_finished();
            let _ = tx.send(Ok(to_event(&first))).await;
            let mut last = first;
            if done {
                return;
            }
            loop {
                tokio::select! {
                    ev = rx.recv() => match ev {
                        Ok(ev) => {
                            let fin = ev.status.is_finished();
                            last = ev.clone();
                            if tx.send(Ok(to_event(&ev))).await.is_err() || fin {
                                return;
                            }
                        }
                        Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => continue,
                        Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
                    },
                    _ = closing.changed() => return,
                    // The record now and then: a job run by another node (shared store)
                    // publishes nothing here, and an event may have been published before
                    // the channel existed (e.g. a queued job cancelled).
                    _ = tokio::time::sleep(Duration::from_secs(2)) => {
                        let s = store.clone();
                        if let Ok(Ok(Some(r))) = tokio::task::spawn_blocking(move || s.get(id)).await {
                            let ev = JobEvent::from_record(&r);
                            if r.status.is_finished() {
                                let _ = tx.send(Ok(to_event(&ev))).await;
                                return;
                            }
                            let moved = (ev.status, ev.step) != (last.status, last.step);
                            if moved && rt.live_progress(id).is_none() {
                                if tx.send(Ok(to_event(&ev))).await.is_err() {
                                    return;
                                }
                                last = ev;
                            }
                        }
                    }
                }
            }
            // Channel closed: the job ended; report its final record.
            let s = store.clone();
            if let Ok(Ok(Some(r))) = tokio::task::spawn_blocking(move || s.get(id)).await {
                let ev = JobEvent::from_record(&r);
                let _ = tx.send(Ok(to_event(&ev))).await;
            }
        },
    );
    Ok(Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response())
}

fn to_event(ev: &JobEvent) -> Event {
    let kind = if ev.status.is_finished() {
        "status"
    } else {
        "progress"
    };
    Event::default()
        .event(kind)
        .json_data(ev)
        .unwrap_or_default()
}

/// A stream fed by an async task through a channel.
fn async_stream<T: Send + 'static, F, Fut>(f: F) -> impl futures_util::Stream<Item = T>
where
    F: FnOnce(tokio::sync::mpsc::Sender<T>) -> Fut,
    Fut: std::future::Future<Output = ()> + Send + 'static,
{
    let (tx, mut rx) = tokio::sync::mpsc::channel(16);
    tokio::spawn(f(tx));
    futures_util::stream::poll_fn(move |cx| rx.poll_recv(cx))
}
