//! Results of succeeded jobs, rendered on request from the compact stored steps: summary,
//! mesh, fields as JSON, VTK (.vtu per step, .pvd collection) and one tar archive. Bodies are
//! streamed from the blocking pool.
//!
//! Step 0 is the initial state (t = 0): u_0, w_0 = 0, ζ_0 and σ_0 = B(ε(u_0), ζ_0)
//! ([`initial_fields`]). It is not stored but derived from the stored scene, like the mesh,
//! and served with the stored steps everywhere (fields, N.vtu, the PVD, the archive), so a
//! ParaView time series starts at t = 0.

use super::query::Params;
use super::{blocking, load_job, parse_id};
use crate::jobs::{
    has_chosen_run, is_study, is_sweep, parse_step_file, step_file, CHOSEN_SCENE_FILE, REPORT_FILE,
    SUMMARY_FILE, TABLE_CSV_FILE, TABLE_FILE,
};
use crate::meshes::Meshes;
use crate::problem::Problem;
use crate::state::AppState;
use crate::store::{JobRecord, JobStatus};
use crate::stream::{blocking_body, blocking_body_or_length, rendered_len};
use axum::extract::{Path, State};
use axum::http::{header, HeaderValue, Method};
use axum::response::{IntoResponse, Response};
use contact_core::mesh::AnyMesh;
use contact_core::output::fields::MeshJson;
use contact_core::output::stored::decode_step;
use contact_core::output::surface::Surface;
use contact_core::output::vtk::{write_mesh_vtu, write_pvd, Compression};
use contact_core::solve::stepper::{initial_fields_of, StepFields};
use std::io::Write as _;
use uuid::Uuid;

const FIELD_NAMES: [&str; 7] = [
    "u",
    "w",
    "zeta",
    "sigma",
    "von_mises",
    "contact",
    "estimate",
];

fn require_succeeded(rec: &JobRecord) -> Result<(), Problem> {
    match rec.status {
        JobStatus::Succeeded => Ok(()),
        s => Err(Problem::conflict(format!(
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

async fn succeeded(state: &AppState, id: &str) -> Result<JobRecord, Problem> {
    let rec = load_job(state, parse_id(id)?).await?;
    require_succeeded(&rec)?;
    Ok(rec)
}

/// A succeeded simulation (the per-step results of a study are its table, not fields). A
/// target study's are those of its chosen run: the record is returned with the chosen run's
/// scene in place of the study, so that everything drawn from it (mesh, step 0, k) is that
/// run's.
async fn simulation(state: &AppState, id: &str) -> Result<JobRecord, Problem> {
    let mut rec = load_job(state, parse_id(id)?).await?;
    if has_chosen_run(&rec.scene) {
        require_succeeded(&rec)?;
        let bytes = result_file(state, &rec, CHOSEN_SCENE_FILE).await?;
        rec.scene = serde_json::from_slice(&bytes)
            .map_err(|e| Problem::internal(format!("{CHOSEN_SCENE_FILE}: {e}")))?;
        return Ok(rec);
    }
    if is_study(&rec.scene) {
        return Err(Problem::not_found(format!(
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
) -> Result<Vec<u8>, Problem> {
    let results = state.rt.results.clone();
    let id = rec.id;
    blocking(move || {
        results
            .read(id, file)
            .map_err(|e| Problem::internal(e.to_string()))?
            .ok_or_else(|| Problem::internal(format!("{file} missing")))
    })
    .await
}

/// A stored result file as the response, with its SHA-256 as `Repr-Digest` (RFC 9530) and
/// as the `ETag`, so a client can check what it downloaded from whichever node wrote it.
/// (Stored steps carry their own checksum; the views streamed from them are derived.)
pub(super) fn with_type(bytes: Vec<u8>, content_type: &'static str) -> Response {
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

/// The stored scene, validated again. An imported mesh is read from the uploaded file the
/// scene names; once that file is deleted (allowed when no unfinished job uses it), the
/// results drawn on it are 409 until the same file is uploaded again (it gets the same id).
/// Blocking.
fn problem_of(meshes: &Meshes, rec: &JobRecord) -> Result<contact_core::problem::Problem, Problem> {
    let scene = crate::continuation::scene_of(&rec.scene);
    contact_core::scene::validate_with(&scene, meshes).map_err(|e| {
        match e.0.iter().find(|f| f.pointer == "/domain/mesh") {
            Some(f) if crate::meshes::mesh_ref(&rec.scene).is_some() => Problem::conflict(format!(
                "job {}: its mesh is no longer stored ({}); upload the same .msh again (POST /meshes gives it the same id) to read these results",
                rec.id, f.message
            )),
            _ => Problem::internal(format!("stored scene: {e}")),
        }
    })
}

/// [`problem_of`] and the mesh the results are drawn on. The mesh is not stored: it is
/// regenerated (deterministically) from the scene, refined and renumbered as the run's was.
/// Blocking.
fn scene_of(
    meshes: &Meshes,
    rec: &JobRecord,
) -> Result<(contact_core::problem::Problem, AnyMesh), Problem> {
    let p = problem_of(meshes, rec)?;
    let mesh = p
        .any_mesh()
        .map_err(|e| Problem::internal(format!("stored scene: {e}")))?;
    Ok((p, mesh))
}

/// The steps that can be served, in order: 0 (the initial state, derived from the scene)
/// and the stored ones.
fn available_steps(state: &AppState, id: Uuid) -> Result<Vec<usize>, Problem> {
    let mut steps: Vec<usize> = state
        .rt
        .results
        .list(id)
        .map_err(|e| Problem::internal(e.to_string()))?
        .iter()
        .filter_map(|n| parse_step_file(n))
        .chain([0])
        .collect();
    steps.sort_unstable();
    steps.dedup();
    Ok(steps)
}

fn pick_step(steps: &[usize], spec: &str) -> Result<usize, Problem> {
    let want = if spec == "last" {
        *steps
            .last()
            .ok_or_else(|| Problem::not_found("this job has no steps to show"))?
    } else {
        spec.parse::<usize>().map_err(|_| {
            Problem::bad_request(format!(
                "step must be a step number or \"last\", not {spec:?}"
            ))
        })?
    };
    if steps.binary_search(&want).is_err() {
        let shown: Vec<String> = steps.iter().take(20).map(|s| s.to_string()).collect();
        return Err(Problem::not_found(format!(
            "step {want} is not stored; available steps (0 is the initial state): {}{}",
            shown.join(", "),
            if steps.len() > 20 { ", …" } else { "" }
        )));
    }
    Ok(want)
}

/// Step n of a simulation: the initial state derived from the scene for n = 0, a stored
/// step otherwise.
fn load_step(state: &AppState, rec: &JobRecord, n: usize) -> Result<StepFields, Problem> {
    let id = rec.id;
    if n == 0 {
        let (p, mesh) = scene_of(&state.rt.meshes, rec)?;
        return initial_fields_of(&p, &mesh)
            .map_err(|e| Problem::internal(format!("initial state of the stored scene: {e}")));
    }
    let bytes = state
        .rt
        .results
        .read(id, &step_file(n))
        .map_err(|e| Problem::internal(e.to_string()))?
        .ok_or_else(|| Problem::not_found(format!("step {n} is not stored")))?;
    decode_step(&bytes).map_err(|e| Problem::internal(format!("stored step {n} is corrupt: {e}")))
}

/// The query of `/jobs/{id}/summary`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SummaryQuery {
    /// `json` (the default) or, for studies, `text` (the paper's table layout).
    format: Option<SummaryFormat>,
}

#[derive(Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(try_from = "String")]
enum SummaryFormat {
    Json,
    Text,
}

impl TryFrom<String> for SummaryFormat {
    type Error = String;
    fn try_from(o: String) -> Result<Self, String> {
        match o.as_str() {
            "json" => Ok(SummaryFormat::Json),
            "text" => Ok(SummaryFormat::Text),
            _ => Err(format!("format must be json or text, not {o:?}")),
        }
    }
}

/// `?format=json` (default) or, for studies, `?format=text` (the paper's table layout).
pub async fn summary(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Params(q): Params<SummaryQuery>,
) -> Result<Response, Problem> {
    let text = q.format == Some(SummaryFormat::Text);
    let rec = succeeded(&state, &id).await?;
    if text && !is_study(&rec.scene) {
        return Err(Problem::bad_request(
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
) -> Result<Response, Problem> {
    let rec = succeeded(&state, &id).await?;
    if !is_study(&rec.scene) {
        return Err(Problem::not_found(format!(
            "job {} is a simulation; reports are drawn for convergence studies (POST /jobs with {{\"study\": ...}}, or a scene with \"error_estimate\": true for an error bar)",
            rec.id
        )));
    }
    Ok(with_type(
        result_file(&state, &rec, REPORT_FILE).await?,
        "image/svg+xml",
    ))
}

/// A succeeded sweep (404 for any other job: only a sweep has a table of members).
async fn sweep(state: &AppState, id: &str) -> Result<JobRecord, Problem> {
    let rec = succeeded(state, id).await?;
    if !is_sweep(&rec.scene) {
        return Err(Problem::not_found(format!(
            "job {} is not a sweep; tables of members and their plots are made by sweeps (POST /jobs with {{\"sweep\": ...}})",
            rec.id
        )));
    }
    Ok(rec)
}

/// `/jobs/{id}/table.csv`: a sweep's table, one row per member.
pub async fn table_csv(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let rec = sweep(&state, &id).await?;
    Ok(with_type(
        result_file(&state, &rec, TABLE_CSV_FILE).await?,
        "text/csv; charset=utf-8",
    ))
}

/// The query of `/jobs/{id}/plot.svg`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlotQuery {
    /// The quantity on the vertical axis (default `w_V`).
    quantity: Option<String>,
    /// The varied pointer on the horizontal axis (default: the first).
    against: Option<String>,
}

/// `/jobs/{id}/plot.svg?quantity=Q&against=POINTER`: a sweep's quantity against one varied
/// parameter, one line per value of the others.
pub async fn plot(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Params(q): Params<PlotQuery>,
) -> Result<Response, Problem> {
    use contact_core::study::sweep::{plot_svg, SweepResult, QUANTITIES};
    let rec = sweep(&state, &id).await?;
    let bytes = result_file(&state, &rec, SUMMARY_FILE).await?;
    let result: SweepResult = serde_json::from_slice(&bytes)
        .map_err(|e| Problem::internal(format!("{SUMMARY_FILE}: {e}")))?;
    let quantity = q.quantity.unwrap_or_else(|| "w_V".into());
    if !QUANTITIES.contains(&quantity.as_str()) {
        return Err(Problem::bad_request(format!(
            "quantity must be one of {}, not {quantity:?}",
            QUANTITIES.join(", ")
        )));
    }
    let pointers: Vec<String> = result
        .vary
        .iter()
        .filter_map(|v| v["pointer"].as_str().map(String::from))
        .collect();
    let against = match q.against {
        Some(a) => a,
        None => pointers.first().cloned().unwrap_or_default(),
    };
    let svg = plot_svg(&result, &quantity, &against).ok_or_else(|| {
        Problem::bad_request(format!(
            "against must be one of the varied pointers {}, not {against:?}",
            pointers.join(", ")
        ))
    })?;
    Ok(with_type(svg.into_bytes(), "image/svg+xml"))
}

/// The query of `/jobs/{id}/mesh`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshQuery {
    /// `1`/`true`: a 3D mesh's boundary surface instead of the whole mesh (a 2D mesh is
    /// served whole either way).
    surface: Option<SurfaceFlag>,
}

/// `?surface=1`: the boundary surface of a 3D job's mesh (its nodes, triangles and the
/// nodes' ids in the whole mesh); a 2D job's mesh whole, with or without it.
pub async fn mesh(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Params(q): Params<MeshQuery>,
) -> Result<Response, Problem> {
    let with_surface = q.surface.is_some_and(|s| s.0);
    let rec = simulation(&state, &id).await?;
    // Built before the answer starts, so that a missing mesh is a 409, not a cut body.
    let meshes = state.rt.meshes.clone();
    let (p, mesh, surface) = blocking(move || {
        let (p, mesh) = scene_of(&meshes, &rec)?;
        let surface = with_surface.then(|| Surface::of(&mesh)).flatten();
        Ok((p, mesh, surface))
    })
    .await?;
    Ok(blocking_body("application/json", move |w| {
        serde_json::to_writer(w, &mesh_json(&mesh, surface.as_ref(), &p.boundary))
            .map_err(std::io::Error::other)
    }))
}

/// The mesh as served: its surface when there is one, else all of it.
fn mesh_json<'a>(
    mesh: &'a AnyMesh,
    surface: Option<&'a Surface>,
    parts: &'a [contact_core::problem::BoundaryPart],
) -> MeshJson<'a> {
    match (mesh, surface) {
        (AnyMesh::Solid(m), Some(s)) => MeshJson::surface(m, s, parts),
        _ => MeshJson::new(mesh, parts),
    }
}

#[derive(serde::Serialize)]
struct FieldsDoc<'a> {
    job: Uuid,
    #[serde(skip_serializing_if = "Option::is_none")]
    mesh: Option<MeshJson<'a>>,
    #[serde(flatten)]
    fields: &'a StepFields,
}

/// The query of `/jobs/{id}/fields`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldsQuery {
    /// A stored step's number, 0 (the initial state) or `last` (the default). Checked once
    /// the job is known to be a succeeded simulation: an unknown job is 404 whatever the
    /// step says.
    step: Option<String>,
    /// A comma-separated subset of [`FIELD_NAMES`] (default: all; empty items are skipped).
    fields: Option<FieldList>,
    /// `1`/`true` adds the mesh, `0`/`false` (the default) does not.
    mesh: Option<MeshFlag>,
    /// `1`/`true`: a 3D job's fields on its boundary surface only (and, with `mesh`, the
    /// surface instead of the mesh); a 2D job's are served whole either way.
    surface: Option<SurfaceFlag>,
}

#[derive(serde::Deserialize)]
#[serde(try_from = "String")]
struct FieldList(Vec<String>);

impl TryFrom<String> for FieldList {
    type Error = String;
    fn try_from(list: String) -> Result<Self, String> {
        let wanted: Vec<String> = list
            .split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect();
        match wanted.iter().find(|f| !FIELD_NAMES.contains(&f.as_str())) {
            Some(bad) => Err(format!(
                "unknown field {bad:?}; fields are {}",
                FIELD_NAMES.join(", ")
            )),
            None => Ok(FieldList(wanted)),
        }
    }
}

/// A yes/no query parameter: `1`/`true` or `0`/`false`.
fn flag(name: &str, o: &str) -> Result<bool, String> {
    match o {
        "0" | "false" => Ok(false),
        "1" | "true" => Ok(true),
        _ => Err(format!("{name} must be 1 or 0, not {o:?}")),
    }
}

#[derive(serde::Deserialize)]
#[serde(try_from = "String")]
struct MeshFlag(bool);

impl TryFrom<String> for MeshFlag {
    type Error = String;
    fn try_from(o: String) -> Result<Self, String> {
        flag("mesh", &o).map(MeshFlag)
    }
}

#[derive(serde::Deserialize)]
#[serde(try_from = "String")]
struct SurfaceFlag(bool);

impl TryFrom<String> for SurfaceFlag {
    type Error = String;
    fn try_from(o: String) -> Result<Self, String> {
        flag("surface", &o).map(SurfaceFlag)
    }
}

/// `?step=N|last&fields=u,w,zeta,sigma,von_mises,contact,estimate&mesh=1&surface=1`.
pub async fn fields(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Params(q): Params<FieldsQuery>,
) -> Result<Response, Problem> {
    let wanted: Vec<String> = match q.fields {
        Some(list) => list.0,
        None => FIELD_NAMES.iter().map(|s| s.to_string()).collect(),
    };
    let with_mesh = q.mesh.is_some_and(|m| m.0);
    let with_surface = q.surface.is_some_and(|s| s.0);
    let rec = simulation(&state, &id).await?;
    let spec = q.step.unwrap_or_else(|| "last".into());
    let st = state.clone();
    let (f, rec, scene, surface) = blocking(move || {
        let n = pick_step(&available_steps(&st, rec.id)?, &spec)?;
        let scene = match with_mesh || with_surface {
            true => Some(scene_of(&st.rt.meshes, &rec)?),
            false => None,
        };
        let mut f = load_step(&st, &rec, n)?;
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
        if !keep("estimate") {
            f.estimate = None
        }
        let surface = match (&scene, with_surface) {
            (Some((_, mesh)), true) => Surface::of(mesh),
            _ => None,
        };
        if let (Some(s), Some((_, mesh))) = (&surface, &scene) {
            f = s
                .restrict(f, mesh.n_nodes(), mesh.n_cells())
                .map_err(|e| Problem::internal(format!("stored step {n}: {e}")))?;
        }
        // The whole mesh is only kept to be served.
        Ok((f, rec, scene.filter(|_| with_mesh), surface))
    })
    .await?;
    Ok(blocking_body("application/json", move |w| {
        let doc = FieldsDoc {
            job: rec.id,
            mesh: scene
                .as_ref()
                .map(|(p, mesh)| mesh_json(mesh, surface.as_ref(), &p.boundary)),
            fields: &f,
        };
        serde_json::to_writer(w, &doc).map_err(std::io::Error::other)
    }))
}

/// A step as its VTU shows it. Step 0, the initial state, has no contact state (stick and slip
/// are decided by the first step) and no a posteriori estimate (no step was made); for a job
/// that stores them its VTU still has the arrays, every node with `contact_state` 0 and
/// `slip_velocity` 0 (w_0 = 0) and every cell with `estimate` 0, so that all files of the
/// time series have the same arrays (ParaView keeps an array over time only when every step
/// has it).
fn vtu_step(mut f: StepFields, p: &contact_core::problem::Problem, mesh: &AnyMesh) -> StepFields {
    if f.n == 0 && f.contact.is_none() && p.output.fields.contact {
        f.contact = Some(Vec::new());
    }
    if f.n == 0 && f.estimate.is_none() && p.output.estimate {
        f.estimate = Some(vec![0.0; mesh.n_cells()]);
    }
    f
}

/// The query of the routes that write VTU files (`/jobs/{id}/fields/N.vtu`,
/// `/jobs/{id}/archive.tar`).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VtuQuery {
    /// `zlib` (the default) or `none`: the data arrays' encoding.
    compression: Option<CompressionParam>,
}

impl VtuQuery {
    fn compression(&self) -> Compression {
        self.compression.map_or_else(Compression::default, |c| c.0)
    }
}

/// `?compression=zlib|none`.
#[derive(Clone, Copy, serde::Deserialize)]
#[serde(try_from = "String")]
struct CompressionParam(Compression);

impl TryFrom<String> for CompressionParam {
    type Error = String;
    fn try_from(c: String) -> Result<Self, String> {
        match c.as_str() {
            "zlib" => Ok(CompressionParam(Compression::Zlib)),
            "none" => Ok(CompressionParam(Compression::None)),
            _ => Err(format!("compression must be zlib or none, not {c:?}")),
        }
    }
}

/// `/jobs/{id}/fields/{N|last}.vtu` (0.vtu: the initial state), its arrays zlib-compressed
/// unless `?compression=none`; HEAD answers its length.
pub async fn vtu(
    State(state): State<AppState>,
    Path((id, file)): Path<(String, String)>,
    Params(q): Params<VtuQuery>,
    method: Method,
) -> Result<Response, Problem> {
    let compression = q.compression();
    let spec = file
        .strip_suffix(".vtu")
        .ok_or_else(|| {
            Problem::not_found(format!(
                "{file:?}: fields files are named N.vtu or last.vtu"
            ))
        })?
        .to_string();
    let rec = simulation(&state, &id).await?;
    let st = state.clone();
    let id = rec.id;
    let (f, mesh) = blocking(move || {
        let n = pick_step(&available_steps(&st, id)?, &spec)?;
        let (p, mesh) = scene_of(&st.rt.meshes, &rec)?;
        Ok((vtu_step(load_step(&st, &rec, n)?, &p, &mesh), mesh))
    })
    .await?;
    // HEAD says the file's length (the browser shows it beside the link).
    blocking_body_or_length(&method, "application/xml", move |w| {
        write_mesh_vtu(w, &mesh, &f, compression)
    })
    .await
}

/// `/jobs/{id}/result.pvd`: step 0 (t = 0) and every stored step, each referencing its VTU by
/// the relative name `fields/N.vtu`: read from the service it resolves to
/// `/jobs/{id}/fields/N.vtu`, and a saved copy opens beside a `fields/` folder of those files.
pub async fn pvd(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let rec = simulation(&state, &id).await?;
    let st = state.clone();
    let id = rec.id;
    let (steps, k) = blocking(move || {
        let steps = available_steps(&st, id)?;
        // Only k: the scene, not its mesh (a refined body's mesh is refined and renumbered
        // again each time it is built).
        Ok((steps, problem_of(&st.rt.meshes, &rec)?.k()))
    })
    .await?;
    let entries: Vec<(f64, String)> = steps
        .iter()
        .map(|&n| (n as f64 * k, format!("fields/{n}.vtu")))
        .collect();
    Ok(blocking_body("application/xml", move |w| {
        write_pvd(w, &entries)
    }))
}

/// One uncompressed tar (POSIX ustar) whose members all sit in one folder named after the
/// job: `<id>/scene.json`, `<id>/summary.json`, `<id>/result.pvd` and
/// `<id>/fields/step_NNNNNN.vtu` for step 0 (the initial state) and every stored step. The
/// archive is streamed, never held whole, and so is each VTU member: a tar header states its
/// member's length, so a VTU is rendered twice, once into a byte counter for the header and
/// once into the body (a 1/64 box's VTU is some hundreds of MB; held in memory it would come
/// on top of the job's own peak). The VTU files' arrays are zlib-compressed unless
/// `?compression=none`.
pub async fn archive(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Params(q): Params<VtuQuery>,
) -> Result<Response, Problem> {
    let compression = q.compression();
    let rec = simulation(&state, &id).await?;
    let st = state.clone();
    let (p, mesh, rec) = blocking(move || {
        let (p, mesh) = scene_of(&st.rt.meshes, &rec)?;
        Ok((p, mesh, rec))
    })
    .await?;
    let k = p.k();
    let st = state.clone();
    let mut resp = blocking_body("application/x-tar", move |w| {
        let io = |e: Problem| std::io::Error::other(e.detail);
        let id = rec.id;
        let steps = available_steps(&st, id).map_err(io)?;
        let mut tar = tar::Builder::new(w);
        let mtime = crate::store::now() as u64;
        let mut member = |name: &str, data: &[u8]| {
            let mut h = tar::Header::new_ustar();
            h.set_entry_type(tar::EntryType::Regular);
            h.set_mode(0o644);
            h.set_uid(0);
            h.set_gid(0);
            h.set_size(data.len() as u64);
            h.set_mtime(mtime);
            tar.append_data(&mut h, format!("{id}/{name}"), data)
        };
        member(
            "scene.json",
            &serde_json::to_vec_pretty(&rec.scene).unwrap_or_default(),
        )?;
        let summary = st.rt.results.read(id, SUMMARY_FILE)?.unwrap_or_default();
        member("summary.json", &summary)?;
        let name = |n: usize| format!("fields/step_{n:06}.vtu");
        let mut pvd = Vec::new();
        write_pvd(
            &mut pvd,
            &steps
                .iter()
                .map(|&n| (n as f64 * k, name(n)))
                .collect::<Vec<_>>(),
        )?;
        member("result.pvd", &pvd)?;
        for n in steps {
            let f = vtu_step(load_step(&st, &rec, n).map_err(io)?, &p, &mesh);
            let size = rendered_len(|w| write_mesh_vtu(w, &mesh, &f, compression))?;
            let mut h = tar::Header::new_ustar();
            h.set_entry_type(tar::EntryType::Regular);
            h.set_mode(0o644);
            h.set_uid(0);
            h.set_gid(0);
            h.set_size(size);
            h.set_mtime(mtime);
            h.set_path(format!("{id}/{}", name(n)))?;
            h.set_cksum();
            // The header, the body as it is rendered and the padding to the next 512-byte
            // block: what `append_data` writes, without holding the body.
            let out = tar.get_mut();
            out.write_all(h.as_bytes())?;
            let mut body = Counted(&mut *out, 0);
            write_mesh_vtu(&mut body, &mesh, &f, compression)?;
            if body.1 != size {
                return Err(std::io::Error::other(format!(
                    "step {n}: the VTU rendered {} bytes, then {size}",
                    body.1
                )));
            }
            out.write_all(&[0; 512][..(512 - (size % 512) as usize) % 512])?;
        }
        tar.finish()
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

/// A writer that counts what passes through it.
struct Counted<W>(W, u64);

impl<W: std::io::Write> std::io::Write for Counted<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.0.write(buf)?;
        self.1 += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}
