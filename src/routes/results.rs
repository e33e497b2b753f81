//! Results of succeeded jobs, rendered on request from the compact stored steps: summary,
//! mesh, fields as JSON, VTK (.vtu per step, .pvd collection) and one tar archive. Bodies are
//! streamed from the blocking pool.

use super::{blocking, load_job, only_params, parse_id};
use crate::error::ApiError;
use crate::jobs::{is_study, parse_step_file, step_file, REPORT_FILE, SUMMARY_FILE, TABLE_FILE};
use crate::state::AppState;
use crate::store::{JobRecord, JobStatus};
use crate::stream::blocking_body;
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};
use contact_core::mesh::Mesh;
use contact_core::output::fields::MeshJson;
use contact_core::output::stored::decode_step;
use contact_core::output::vtk::{write_pvd, write_vtu};
use contact_core::solve::stepper::StepFields;
use std::collections::HashMap;
use std::io::Write;
use uuid::Uuid;

const FIELD_NAMES: [&str; 6] = ["u", "w", "zeta", "sigma", "von_mises", "contact"];

fn require_succeeded(rec: &JobRecord) -> Result<(), ApiError> {
    match rec.status {
        JobStatus::Succeeded => Ok(()),
        s => Err(ApiError::conflict(format!(
            "job {} is {}; results are available once it has succeeded{}",
            rec.id,
            s.as_str(),
            if s.is_finished() {
                ""
            } else {
                " (poll GET /jobs/{id} or follow /events)"
            }
        ))),
    }
}

async fn succeeded(state: &AppState, id: &str) -> Result<JobRecord, ApiError> {
    let rec = load_job(state, parse_id(id)?).await?;
    require_succeeded(&rec)?;
    Ok(rec)
}

/// A succeeded simulation (the per-step results of a study are its table, not fields).
async fn simulation(state: &AppState, id: &str) -> Result<JobRecord, ApiError> {
    let rec = load_job(state, parse_id(id)?).await?;
    if is_study(&rec.scene) {
        return Err(ApiError::not_found(format!(
            "job {} is a convergence study: it has no fields; see /jobs/{}/summary and /jobs/{}/report.svg",
            rec.id, rec.id, rec.id
        )));
    }
    require_succeeded(&rec)?;
    Ok(rec)
}

/// Reads a result file of a succeeded job on the blocking pool.
async fn result_file(
    state: &AppState,
    rec: &JobRecord,
    file: &'static str,
) -> Result<Vec<u8>, ApiError> {
    let results = state.rt.results.clone();
    let id = rec.id;
    blocking(move || {
        results
            .read(id, file)
            .map_err(|e| ApiError::internal(e.to_string()))?
            .ok_or_else(|| ApiError::internal(format!("{file} missing")))
    })
    .await
}

/// A stored result file as the response, with its SHA-256 as `Repr-Digest` (RFC 9530) and
/// as the `ETag`, so a client can check what it downloaded from whichever node wrote it.
/// (Stored steps carry their own checksum; the views streamed from them are derived.)
fn with_type(bytes: Vec<u8>, content_type: &'static str) -> Response {
    use base64::Engine as _;
    use sha2::{Digest, Sha256};
    let digest = Sha256::digest(&bytes);
    let b64 = base64::engine::general_purpose::STANDARD.encode(digest);
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    let mut r = bytes.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    if let Ok(v) = HeaderValue::from_str(&format!("sha-256=:{b64}:")) {
        h.insert("repr-digest", v);
    }
    if let Ok(v) = HeaderValue::from_str(&format!("\"{hex}\"")) {
        h.insert(header::ETAG, v);
    }
    r
}

/// The mesh is not stored: it is regenerated (deterministically) from the stored scene.
fn mesh_of(rec: &JobRecord) -> Result<(Mesh, f64), ApiError> {
    let p = contact_core::scene::validate(&rec.scene)
        .map_err(|e| ApiError::internal(format!("stored scene: {e}")))?;
    let (nx, ny) = p.cells();
    let mut mesh = Mesh::rectangle(p.width, p.height, nx, ny, p.pattern);
    mesh.tag_boundary(&p.boundary.iter().map(|b| b.segment).collect::<Vec<_>>());
    Ok((mesh, p.k()))
}

fn stored_steps(state: &AppState, id: Uuid) -> Result<Vec<usize>, ApiError> {
    let mut steps: Vec<usize> = state
        .rt
        .results
        .list(id)
        .map_err(|e| ApiError::internal(e.to_string()))?
        .iter()
        .filter_map(|n| parse_step_file(n))
        .collect();
    steps.sort_unstable();
    Ok(steps)
}

fn pick_step(steps: &[usize], spec: &str) -> Result<usize, ApiError> {
    let want = if spec == "last" {
        *steps.last().ok_or_else(|| {
            ApiError::not_found("this job stored no steps (see the scene's output selection)")
        })?
    } else {
        spec.parse::<usize>().map_err(|_| {
            ApiError::bad_request(format!(
                "step must be a step number or \"last\", not {spec:?}"
            ))
        })?
    };
    if steps.binary_search(&want).is_err() {
        let shown: Vec<String> = steps.iter().take(20).map(|s| s.to_string()).collect();
        return Err(ApiError::not_found(format!(
            "step {want} is not stored; stored steps: {}{}",
            shown.join(", "),
            if steps.len() > 20 { ", …" } else { "" }
        )));
    }
    Ok(want)
}

fn load_step(state: &AppState, id: Uuid, n: usize) -> Result<StepFields, ApiError> {
    let bytes = state
        .rt
        .results
        .read(id, &step_file(n))
        .map_err(|e| ApiError::internal(e.to_string()))?
        .ok_or_else(|| ApiError::not_found(format!("step {n} is not stored")))?;
    decode_step(&bytes).map_err(|e| ApiError::internal(format!("stored step {n} is corrupt: {e}")))
}

/// `?format=json` (default) or, for studies, `?format=text` (the paper's table layout).
pub async fn summary(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_params(&q, &["format"])?;
    let text = match q.get("format").map(String::as_str) {
        None | Some("json") => false,
        Some("text") => true,
        Some(o) => {
            return Err(ApiError::bad_request(format!(
                "format must be json or text, not {o:?}"
            )))
        }
    };
    let rec = succeeded(&state, &id).await?;
    if text && !is_study(&rec.scene) {
        return Err(ApiError::bad_request(
            "format=text is the error table of a study; a simulation's summary is JSON",
        ));
    }
    Ok(if text {
        with_type(
            result_file(&state, &rec, TABLE_FILE).await?,
            "text/plain; charset=utf-8",
        )
    } else {
        with_type(
            result_file(&state, &rec, SUMMARY_FILE).await?,
            "application/json",
        )
    })
}

/// `/jobs/{id}/report.svg`: a study's error and work–precision plots.
pub async fn report(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let rec = succeeded(&state, &id).await?;
    if !is_study(&rec.scene) {
        return Err(ApiError::not_found(format!(
            "job {} is a simulation; reports are drawn for convergence studies (POST /jobs with {{\"study\": ...}}, or a scene with \"error_estimate\": true for an error bar)",
            rec.id
        )));
    }
    Ok(with_type(
        result_file(&state, &rec, REPORT_FILE).await?,
        "image/svg+xml",
    ))
}

pub async fn mesh(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let rec = simulation(&state, &id).await?;
    Ok(blocking_body("application/json", move |w| {
        let (mesh, _) = mesh_of(&rec).map_err(|e| std::io::Error::other(e.detail))?;
        serde_json::to_writer(w, &MeshJson::new(&mesh)).map_err(std::io::Error::other)
    }))
}

#[derive(serde::Serialize)]
struct FieldsDoc<'a> {
    job: Uuid,
    #[serde(skip_serializing_if = "Option::is_none")]
    mesh: Option<MeshJson<'a>>,
    #[serde(flatten)]
    fields: &'a StepFields,
}

/// `?step=N|last&fields=u,w,zeta,sigma,von_mises,contact&mesh=1`.
pub async fn fields(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_params(&q, &["step", "fields", "mesh"])?;
    let wanted: Vec<String> = match q.get("fields") {
        Some(list) => list
            .split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect(),
        None => FIELD_NAMES.iter().map(|s| s.to_string()).collect(),
    };
    if let Some(bad) = wanted.iter().find(|f| !FIELD_NAMES.contains(&f.as_str())) {
        return Err(ApiError::bad_request(format!(
            "unknown field {bad:?}; fields are {}",
            FIELD_NAMES.join(", ")
        )));
    }
    let with_mesh = match q.get("mesh").map(String::as_str) {
        None | Some("0") | Some("false") => false,
        Some("1") | Some("true") => true,
        Some(o) => {
            return Err(ApiError::bad_request(format!(
                "mesh must be 1 or 0, not {o:?}"
            )))
        }
    };
    let rec = simulation(&state, &id).await?;
    let spec = q.get("step").cloned().unwrap_or_else(|| "last".into());
    let st = state.clone();
    let job = rec.id;
    let mut f = blocking(move || {
        let n = pick_step(&stored_steps(&st, job)?, &spec)?;
        load_step(&st, job, n)
    })
    .await?;
    let keep = |name: &str| wanted.iter().any(|w| w == name);
    if !keep("u") {
        f.u = None
    }
    if !keep("w") {
        f.w = None
    }
    if !keep("zeta") {
        f.zeta = None
    }
    if !keep("sigma") {
        f.sigma = None
    }
    if !keep("von_mises") {
        f.von_mises = None
    }
    if !keep("contact") {
        f.contact = None
    }
    Ok(blocking_body("application/json", move |w| {
        let mesh = if with_mesh {
            Some(
                mesh_of(&rec)
                    .map_err(|e| std::io::Error::other(e.detail))?
                    .0,
            )
        } else {
            None
        };
        let doc = FieldsDoc {
            job: rec.id,
            mesh: mesh.as_ref().map(MeshJson::new),
            fields: &f,
        };
        serde_json::to_writer(w, &doc).map_err(std::io::Error::other)
    }))
}

/// `/jobs/{id}/fields/{N|last}.vtu`.
pub async fn vtu(
    State(state): State<AppState>,
    Path((id, file)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let spec = file
        .strip_suffix(".vtu")
        .ok_or_else(|| {
            ApiError::not_found(format!(
                "{file:?}: fields files are named N.vtu or last.vtu"
            ))
        })?
        .to_string();
    let rec = simulation(&state, &id).await?;
    let st = state.clone();
    let id = rec.id;
    let (f, rec) = blocking(move || {
        let n = pick_step(&stored_steps(&st, id)?, &spec)?;
        Ok((load_step(&st, id, n)?, rec))
    })
    .await?;
    Ok(blocking_body("application/xml", move |w| {
        let (mesh, _) = mesh_of(&rec).map_err(|e| std::io::Error::other(e.detail))?;
        write_vtu(w, &mesh.nodes, &mesh.triangles, &f)
    }))
}

pub async fn pvd(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let rec = simulation(&state, &id).await?;
    let st = state.clone();
    let id = rec.id;
    let steps = blocking(move || stored_steps(&st, id)).await?;
    let (_, k) = mesh_of(&rec)?;
    let entries: Vec<(f64, String)> = steps
        .iter()
        .map(|&n| (n as f64 * k, format!("/jobs/{id}/fields/{n}.vtu")))
        .collect();
    Ok(blocking_body("application/xml", move |w| {
        write_pvd(w, &entries)
    }))
}

/// One uncompressed tar (POSIX ustar) with scene.json, summary.json, result.pvd and
/// fields/step_NNNNNN.vtu for every stored step; each member is rendered just before it is
/// written.
pub async fn archive(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let rec = simulation(&state, &id).await?;
    let st = state.clone();
    let mut resp = blocking_body("application/x-tar", move |w| {
        let io = |e: ApiError| std::io::Error::other(e.detail);
        let id = rec.id;
        let steps = stored_steps(&st, id).map_err(io)?;
        let (mesh, k) = mesh_of(&rec).map_err(io)?;
        tar_member(
            w,
            "scene.json",
            &serde_json::to_vec_pretty(&rec.scene).unwrap_or_default(),
        )?;
        let summary = st.rt.results.read(id, SUMMARY_FILE)?.unwrap_or_default();
        tar_member(w, "summary.json", &summary)?;
        let name = |n: usize| format!("fields/step_{n:06}.vtu");
        let mut pvd = Vec::new();
        write_pvd(
            &mut pvd,
            &steps
                .iter()
                .map(|&n| (n as f64 * k, name(n)))
                .collect::<Vec<_>>(),
        )?;
        tar_member(w, "result.pvd", &pvd)?;
        for n in steps {
            let f = load_step(&st, id, n).map_err(io)?;
            let mut buf = Vec::new();
            write_vtu(&mut buf, &mesh.nodes, &mesh.triangles, &f)?;
            tar_member(w, &name(n), &buf)?;
        }
        w.write_all(&[0u8; 1024])
    });
    let disp = format!(
        "attachment; filename=\"contact-sim-{}.tar\"",
        parse_id(&id)?
    );
    resp.headers_mut().insert(
        header::CONTENT_DISPOSITION,
        HeaderValue::from_str(&disp).expect("ASCII"),
    );
    Ok(resp)
}

/// Writes one regular-file member of a ustar archive (names < 100 bytes).
fn tar_member(w: &mut dyn Write, name: &str, data: &[u8]) -> std::io::Result<()> {
    let mut h = [0u8; 512];
    h[..name.len()].copy_from_slice(name.as_bytes());
    h[100..108].copy_from_slice(b"0000644\0");
    h[108..116].copy_from_slice(b"0000000\0");
    h[116..124].copy_from_slice(b"0000000\0");
    h[124..136].copy_from_slice(format!("{:011o}\0", data.len()).as_bytes());
    let mtime = crate::store::now() as u64;
    h[136..148].copy_from_slice(format!("{mtime:011o}\0").as_bytes());
    h[156] = b'0';
    h[257..263].copy_from_slice(b"ustar\0");
    h[263..265].copy_from_slice(b"00");
    h[148..156].copy_from_slice(b"        ");
    let sum: u32 = h.iter().map(|&b| b as u32).sum();
    h[148..156].copy_from_slice(format!("{sum:06o}\0 ").as_bytes());
    w.write_all(&h)?;
    w.write_all(data)?;
    let pad = (512 - data.len() % 512) % 512;
    w.write_all(&vec![0u8; pad])
}
