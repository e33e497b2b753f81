//! What both job-store backends share: the row as read before validation, its conversion
//! into a [`JobRecord`], and list cursors.

use super::{
    JobRecord, JobStatus, MemoryPrediction, MeshPage, MeshRecord, Page, Progress, StoreError,
};
use contact_core::linalg::LinearPath;
use uuid::Uuid;

/// Parses a list cursor produced by [`Store::list`] (`"s<seq>"`, seq > 0).
///
/// Cursors are opaque to clients; the API should call this to reject a malformed cursor
/// with a 400 before calling `list`, which treats an unparsable cursor as "past the end"
/// and returns an empty page.
pub fn parse_cursor(s: &str) -> Option<i64> {
    let digits = s.strip_prefix('s')?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse::<i64>().ok().filter(|&v| v > 0)
}

fn make_cursor(seq: i64) -> String {
    format!("s{seq}")
}

pub(super) fn to_i64(v: usize, what: &str) -> Result<i64, StoreError> {
    i64::try_from(v).map_err(|_| StoreError::Db(format!("{what} {v} out of range")))
}

pub(super) fn to_usize(v: i64, what: &str) -> Result<usize, StoreError> {
    usize::try_from(v).map_err(|_| StoreError::Corrupt(format!("{what} = {v}")))
}

pub(super) fn check_lease(lease_s: f64) -> Result<(), StoreError> {
    if lease_s.is_finite() && lease_s >= 0.0 {
        Ok(())
    } else {
        Err(StoreError::Db(format!(
            "invalid lease duration {lease_s} s"
        )))
    }
}

/// A [`MemoryPrediction`] as the `linear_path` and `predicted_bytes` columns.
pub(super) fn memory_columns(
    m: Option<MemoryPrediction>,
) -> Result<(Option<&'static str>, Option<i64>), StoreError> {
    match m {
        Some(m) => Ok((
            Some(m.linear_path.name()),
            Some(i64::try_from(m.predicted_bytes).map_err(|_| {
                StoreError::Db(format!(
                    "predicted_bytes {} out of range",
                    m.predicted_bytes
                ))
            })?),
        )),
        None => Ok((None, None)),
    }
}

pub(super) fn json_text(v: &serde_json::Value) -> Result<String, StoreError> {
    serde_json::to_string(v).map_err(|e| StoreError::Db(format!("cannot serialise JSON: {e}")))
}

/// A `jobs` row as read, before validation.
pub(super) struct RawJob {
    pub(super) id: String,
    pub(super) status: String,
    pub(super) scene: String,
    pub(super) scene_hash: String,
    pub(super) idempotency_key: Option<String>,
    pub(super) request_hash: Option<String>,
    pub(super) created_at: f64,
    pub(super) started_at: Option<f64>,
    pub(super) finished_at: Option<f64>,
    pub(super) step: i64,
    pub(super) steps: i64,
    pub(super) last_residual: Option<f64>,
    pub(super) error: Option<String>,
    pub(super) cancel_requested: bool,
    pub(super) attempt: i64,
    pub(super) worker: Option<String>,
    pub(super) lease_until: Option<f64>,
    pub(super) checkpoint_step: Option<i64>,
    pub(super) seq: i64,
    pub(super) owner: String,
    pub(super) linear_path: Option<String>,
    pub(super) predicted_bytes: Option<i64>,
    pub(super) sweep: Option<String>,
    pub(super) members: Option<String>,
}

impl RawJob {
    /// Validates and converts; any malformed value is [`StoreError::Corrupt`].
    pub(super) fn into_record(self) -> Result<JobRecord, StoreError> {
        let id = Uuid::parse_str(&self.id)
            .map_err(|e| StoreError::Corrupt(format!("job id {:?}: {e}", self.id)))?;
        let status = JobStatus::parse(&self.status)
            .ok_or_else(|| StoreError::Corrupt(format!("job {id}: status {:?}", self.status)))?;
        let scene = serde_json::from_str(&self.scene)
            .map_err(|e| StoreError::Corrupt(format!("job {id}: scene JSON: {e}")))?;
        let error = match self.error {
            Some(text) => Some(
                serde_json::from_str(&text)
                    .map_err(|e| StoreError::Corrupt(format!("job {id}: error JSON: {e}")))?,
            ),
            None => None,
        };
        let attempt = u32::try_from(self.attempt)
            .map_err(|_| StoreError::Corrupt(format!("job {id}: attempt = {}", self.attempt)))?;
        let last_checkpoint_step = match self.checkpoint_step {
            Some(s) => Some(to_usize(s, "checkpoint_step")?),
            None => None,
        };
        let memory = match (self.linear_path, self.predicted_bytes) {
            (Some(path), Some(bytes)) => Some(MemoryPrediction {
                linear_path: LinearPath::parse(&path)
                    .filter(|p| *p != LinearPath::Auto)
                    .ok_or_else(|| {
                        StoreError::Corrupt(format!("job {id}: linear_path {path:?}"))
                    })?,
                predicted_bytes: u64::try_from(bytes).map_err(|_| {
                    StoreError::Corrupt(format!("job {id}: predicted_bytes = {bytes}"))
                })?,
            }),
            (None, None) => None,
            (path, bytes) => {
                return Err(StoreError::Corrupt(format!(
                    "job {id}: linear_path {path:?} and predicted_bytes {bytes:?}, one without the other"
                )))
            }
        };
        let sweep = match self.sweep {
            Some(s) => Some(
                Uuid::parse_str(&s)
                    .map_err(|e| StoreError::Corrupt(format!("job {id}: sweep {s:?}: {e}")))?,
            ),
            None => None,
        };
        let members = match self.members {
            Some(text) => serde_json::from_str(&text)
                .map_err(|e| StoreError::Corrupt(format!("job {id}: members JSON: {e}")))?,
            None => Vec::new(),
        };
        Ok(JobRecord {
            id,
            status,
            scene,
            scene_hash: self.scene_hash,
            idempotency_key: self.idempotency_key,
            request_hash: self.request_hash,
            created_at: self.created_at,
            started_at: self.started_at,
            finished_at: self.finished_at,
            progress: Progress {
                step: to_usize(self.step, "step")?,
                steps: to_usize(self.steps, "steps")?,
                last_residual: self.last_residual,
            },
            error,
            cancel_requested: self.cancel_requested,
            attempt,
            worker: self.worker,
            lease_until: self.lease_until,
            last_checkpoint_step,
            owner: self.owner,
            memory,
            sweep,
            members,
        })
    }
}

/// SQL list of the final statuses (the same in both dialects).
pub(super) const FINISHED: &str = "('succeeded', 'failed', 'cancelled')";

/// The `seq` bound and row count of a list query: jobs with `seq < before`, `limit + 1` of
/// them (one more than asked tells whether another page follows). None for an unparsable
/// cursor, which yields an empty page (see [`parse_cursor`]). `limit` 0 counts as 1.
pub(super) fn page_bounds(cursor: Option<&str>, limit: usize) -> Option<(i64, i64)> {
    let before = match cursor {
        None => i64::MAX,
        Some(c) => parse_cursor(c)?,
    };
    let fetch = i64::try_from(limit.max(1))
        .unwrap_or(i64::MAX - 1)
        .saturating_add(1);
    Some((before, fetch))
}

/// The page of the rows fetched with [`page_bounds`] (newest first).
pub(super) fn into_page(raws: Vec<RawJob>, limit: usize) -> Result<Page, StoreError> {
    let limit = limit.max(1);
    let more = raws.len() > limit;
    let mut jobs = Vec::with_capacity(raws.len().min(limit));
    let mut last_seq = None;
    for raw in raws.into_iter().take(limit) {
        last_seq = Some(raw.seq);
        jobs.push(raw.into_record()?);
    }
    let next = if more {
        last_seq.map(make_cursor)
    } else {
        None
    };
    Ok(Page { jobs, next })
}

/// Jobs per status from `(status, count)` rows, every status listed (in
/// [`JobStatus::ALL`] order) even when zero.
pub(super) fn status_counts(
    rows: Vec<(String, i64)>,
) -> Result<Vec<(JobStatus, usize)>, StoreError> {
    let mut counts: Vec<(JobStatus, usize)> = JobStatus::ALL.iter().map(|&s| (s, 0)).collect();
    for (status, n) in rows {
        let s = JobStatus::parse(&status)
            .ok_or_else(|| StoreError::Corrupt(format!("status {status:?}")))?;
        let n = to_usize(n, "count")?;
        if let Some(slot) = counts.iter_mut().find(|(k, _)| *k == s) {
            slot.1 = n;
        }
    }
    Ok(counts)
}

/// A `meshes` row as read, before validation.
pub(super) struct RawMesh {
    pub(super) id: String,
    pub(super) bytes: i64,
    pub(super) created_at: f64,
    pub(super) summary: String,
    pub(super) seq: i64,
}

impl RawMesh {
    /// Validates and converts; any malformed value is [`StoreError::Corrupt`].
    pub(super) fn into_record(self) -> Result<MeshRecord, StoreError> {
        let summary = serde_json::from_str(&self.summary)
            .map_err(|e| StoreError::Corrupt(format!("mesh {}: summary JSON: {e}", self.id)))?;
        let bytes = u64::try_from(self.bytes).map_err(|_| {
            StoreError::Corrupt(format!("mesh {}: bytes = {}", self.id, self.bytes))
        })?;
        Ok(MeshRecord {
            id: self.id,
            bytes,
            created_at: self.created_at,
            summary,
        })
    }
}

/// The page of mesh rows fetched with [`page_bounds`] (newest first).
pub(super) fn into_mesh_page(raws: Vec<RawMesh>, limit: usize) -> Result<MeshPage, StoreError> {
    let limit = limit.max(1);
    let more = raws.len() > limit;
    let mut meshes = Vec::with_capacity(raws.len().min(limit));
    let mut last_seq = None;
    for raw in raws.into_iter().take(limit) {
        last_seq = Some(raw.seq);
        meshes.push(raw.into_record()?);
    }
    let next = if more {
        last_seq.map(make_cursor)
    } else {
        None
    };
    Ok(MeshPage { meshes, next })
}

/// SQL list of the statuses of a job that still needs its mesh.
pub(super) const UNFINISHED: &str = "('queued', 'running')";
