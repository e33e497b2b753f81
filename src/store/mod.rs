//! The durable job store behind a narrow interface: enqueue, claim with a lease, heartbeat,
//! progress, checkpoint, finish, fetch. The embedded default is SQLite in the data directory
//! ([`sqlite::SqliteStore`]); results (summary, stored steps) are files written atomically
//! ([`results::ResultFiles`]). Many nodes share one PostgreSQL database instead
//! ([`postgres::PgStore`]) and a result directory on a shared filesystem.
//!
//! Uploaded meshes are stored the same way: a row per mesh (id, size, upload time, summary)
//! in the job store, and the file under `<data_dir>/meshes/` ([`meshes::MeshBlobs`]). A job
//! records the uploaded mesh its scene uses, so that a mesh is not deleted under a job that
//! still needs it.
//!
//! Jobs and meshes have owners (the API key that created them, empty without
//! authentication); keys, quotas, measured use and mesh ownership are [`owners::Owners`],
//! which every store implements too. Claims are fair across owners.
//!
//! All methods are blocking (call them from worker threads or `spawn_blocking`).

mod claim;
pub mod meshes;
pub mod owners;
mod pg_owners;
pub mod postgres;
pub mod postgres_tls;
pub mod results;
mod row;
pub mod sqlite;

pub use row::parse_cursor;

use serde::{Deserialize, Serialize};
use uuid::Uuid;

/// Job lifecycle: queued → running → succeeded | failed | cancelled
/// (queued → cancelled directly when cancelled before it ran).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobStatus {
    pub const ALL: [JobStatus; 5] = [
        JobStatus::Queued,
        JobStatus::Running,
        JobStatus::Succeeded,
        JobStatus::Failed,
        JobStatus::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Succeeded => "succeeded",
            JobStatus::Failed => "failed",
            JobStatus::Cancelled => "cancelled",
        }
    }

    pub fn parse(s: &str) -> Option<JobStatus> {
        JobStatus::ALL.into_iter().find(|x| x.as_str() == s)
    }

    pub fn is_finished(self) -> bool {
        matches!(
            self,
            JobStatus::Succeeded | JobStatus::Failed | JobStatus::Cancelled
        )
    }
}

/// Progress of a running job (persisted at every checkpoint and on finish, kept in memory
/// between).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Progress {
    pub step: usize,
    pub steps: usize,
    /// Worst of the two sub-problem residuals at the last step.
    pub last_residual: Option<f64>,
}

/// A job as stored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobRecord {
    pub id: Uuid,
    pub status: JobStatus,
    /// The submitted scene after preset expansion and overrides (what was validated).
    pub scene: serde_json::Value,
    /// Hex SHA-256 of the canonical scene JSON plus crate version and solver settings.
    pub scene_hash: String,
    pub idempotency_key: Option<String>,
    /// Hex SHA-256 of the request body the idempotency key was first used with.
    pub request_hash: Option<String>,
    /// Unix times in seconds (fractional).
    pub created_at: f64,
    pub started_at: Option<f64>,
    pub finished_at: Option<f64>,
    pub progress: Progress,
    /// RFC 9457 problem+json object for failed jobs.
    pub error: Option<serde_json::Value>,
    pub cancel_requested: bool,
    pub attempt: u32,
    pub worker: Option<String>,
    pub lease_until: Option<f64>,
    pub last_checkpoint_step: Option<usize>,
    /// The name of the key that submitted it; empty when submitted anonymously
    /// (authentication off). See [`owners`].
    #[serde(default)]
    pub owner: String,
    /// A simulation's peak memory as predicted at submission; None for a study (its levels
    /// differ) and for jobs stored before predictions were kept.
    #[serde(default)]
    pub memory: Option<MemoryPrediction>,
    /// A sweep's member job: the sweep that created it (and is cancelled with it).
    #[serde(default)]
    pub sweep: Option<Uuid>,
    /// A sweep: its members' job ids in member order (equal members share one job), empty
    /// before the sweep first looked at them ([`Store::set_members`]).
    #[serde(default)]
    pub members: Vec<Uuid>,
}

/// The linear path a simulation takes and its peak memory, as predicted at submission from
/// the count model before any numeric work (`contact_core::memory::choose`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MemoryPrediction {
    /// Direct or multigrid, never `auto`: the path `auto` resolved to.
    pub linear_path: contact_core::linalg::LinearPath,
    /// Peak bytes of the run on that path.
    pub predicted_bytes: u64,
}

/// What `enqueue` needs.
#[derive(Debug, Clone)]
pub struct NewJob {
    pub scene: serde_json::Value,
    pub scene_hash: String,
    pub steps: usize,
    pub idempotency_key: Option<String>,
    pub request_hash: Option<String>,
    /// The id of the uploaded mesh the scene uses (`domain.mesh`), if any: the job is only
    /// enqueued if that mesh is stored, and the mesh cannot be deleted while the job is
    /// queued or running.
    pub mesh: Option<String>,
    /// See [`JobRecord::memory`].
    pub memory: Option<MemoryPrediction>,
}

/// Outcome of `enqueue` with an idempotency key.
#[derive(Debug, Clone, PartialEq)]
pub enum Enqueued {
    /// A new job.
    New(JobRecord),
    /// The key was used before with the same request: that job.
    Existing(JobRecord),
    /// The key was used before with a different request body.
    KeyConflict(JobRecord),
    /// The uploaded mesh of [`NewJob::mesh`] is not stored (deleted meanwhile): nothing was
    /// enqueued.
    NoMesh(String),
}

/// An uploaded mesh as stored (its file is in [`meshes::MeshBlobs`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshRecord {
    /// Lowercase hex SHA-256 of the file.
    pub id: String,
    /// Size of the file in bytes.
    pub bytes: u64,
    /// Unix time in seconds of the first upload.
    pub created_at: f64,
    /// What `contact_core::mesh::import::summarize` reported (JSON).
    pub summary: serde_json::Value,
}

/// A page of meshes, newest first.
#[derive(Debug, Clone)]
pub struct MeshPage {
    pub meshes: Vec<MeshRecord>,
    /// Opaque cursor for the next page (as for jobs), None on the last page.
    pub next: Option<String>,
}

/// Outcome of [`Store::delete_mesh`].
#[derive(Debug, Clone, PartialEq)]
pub enum MeshDeletion {
    Deleted,
    /// No mesh with that id.
    Absent,
    /// Not deleted: this job, queued or running, uses it.
    InUse(Box<JobRecord>),
}

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("database error: {0}")]
    Db(String),
    #[error("I/O error: {0}")]
    Io(#[from] std::io::Error),
    #[error("corrupt record: {0}")]
    Corrupt(String),
    /// The database cannot be reached (down, restarting, connection lost). Transient: the
    /// operation may be retried; whether a failed mutation took effect is unknown.
    #[error("database unavailable: {0}")]
    Unavailable(String),
}

/// What changes a mesh's file together with its record: called inside the store's
/// transaction, after the record changed and before the commit, while every other change of
/// that mesh's record — on any node sharing the store — waits (SQLite: the database's write
/// lock; PostgreSQL: a transaction advisory lock on the mesh id). An error rolls the change
/// back. So an upload and a delete of the same mesh at the same instant run one after the
/// other, file and record together, and never leave a record without its file.
pub type MeshFileStep<'a> = &'a mut dyn FnMut() -> std::io::Result<()>;

/// Wakes a process's idle workers; returns false once nobody needs waking any more (the
/// watcher then stops).
pub type Wake = std::sync::Arc<dyn Fn() -> bool + Send + Sync>;

/// A page of jobs, newest first.
#[derive(Debug, Clone)]
pub struct Page {
    pub jobs: Vec<JobRecord>,
    /// Opaque cursor for the next page, None on the last page.
    pub next: Option<String>,
}

pub trait Store: owners::Owners + Send + Sync + 'static {
    /// Adds a queued job (or returns the existing one for a known idempotency key), as
    /// the anonymous owner.
    fn enqueue(&self, job: NewJob) -> Result<Enqueued, StoreError> {
        self.enqueue_for("", 0, job)
    }
    /// [`Store::enqueue`] for `owner`, whose idempotency keys are its own (two owners
    /// using the same key get two jobs); `stored_bytes` is the job's estimated result
    /// size, counted against the owner's quota while the job exists.
    fn enqueue_for(
        &self,
        owner: &str,
        stored_bytes: u64,
        job: NewJob,
    ) -> Result<Enqueued, StoreError> {
        self.enqueue_in(owner, stored_bytes, job, None)
    }
    /// [`Store::enqueue_for`] of a sweep's member: the new job names `sweep` as the sweep
    /// that created it. While a queued sweep has a member that is queued or running, and none
    /// that failed or was cancelled, the sweep is not claimed ([`Store::claim`]).
    fn enqueue_in(
        &self,
        owner: &str,
        stored_bytes: u64,
        job: NewJob,
        sweep: Option<Uuid>,
    ) -> Result<Enqueued, StoreError>;
    /// The jobs `sweep` created as its members, oldest first.
    fn sweep_members(&self, sweep: Uuid) -> Result<Vec<JobRecord>, StoreError>;
    /// Records a sweep's members' job ids, in member order ([`JobRecord::members`]).
    fn set_members(&self, id: Uuid, members: &[Uuid]) -> Result<(), StoreError>;
    fn get(&self, id: Uuid) -> Result<Option<JobRecord>, StoreError>;
    /// Newest first; optional status filter; `cursor` from a previous page.
    fn list(
        &self,
        status: Option<JobStatus>,
        cursor: Option<&str>,
        limit: usize,
    ) -> Result<Page, StoreError> {
        self.list_for(None, status, cursor, limit)
    }
    /// [`Store::list`] of one owner's jobs (None: everybody's).
    fn list_for(
        &self,
        owner: Option<&str>,
        status: Option<JobStatus>,
        cursor: Option<&str>,
        limit: usize,
    ) -> Result<Page, StoreError>;
    /// Claims the oldest queued job, or a running job whose lease expired (a dead worker's:
    /// its attempt counter is incremented), for `worker` until now + `lease_s`; fair
    /// across owners: the oldest job of the owner with the fewest running, and of those the
    /// one served least recently. A queued sweep waiting for its members (see
    /// [`Store::enqueue_in`]) is not claimable.
    /// Jobs whose last `max_attempts` attempts all died without saving a new checkpoint are
    /// failed instead of claimed (dead letter); attempts that made progress do not count.
    fn claim(
        &self,
        worker: &str,
        lease_s: f64,
        max_attempts: u32,
    ) -> Result<Option<JobRecord>, StoreError>;
    /// Extends the lease; false if the job is no longer this worker's (or was cancelled).
    fn heartbeat(&self, id: Uuid, worker: &str, lease_s: f64) -> Result<bool, StoreError>;
    fn set_progress(&self, id: Uuid, progress: Progress) -> Result<(), StoreError>;
    /// Saves the state after `step` (opaque bytes, see `output::stored`), atomically with
    /// the step number.
    fn checkpoint(&self, id: Uuid, step: usize, state: &[u8]) -> Result<(), StoreError>;
    fn load_checkpoint(&self, id: Uuid) -> Result<Option<(usize, Vec<u8>)>, StoreError>;
    /// Final status (succeeded, failed with `error`, or cancelled); clears the lease.
    fn finish(
        &self,
        id: Uuid,
        status: JobStatus,
        error: Option<serde_json::Value>,
    ) -> Result<(), StoreError>;
    /// Puts `worker`'s running job back in the queue without counting the attempt: its
    /// worker found the disk full, a condition of the node and not a fault of the job. The
    /// checkpoint is kept, so the next claim resumes from it; a job whose cancel was
    /// requested meanwhile is cancelled instead. False if the job is not `worker`'s.
    fn requeue(&self, id: Uuid, worker: &str) -> Result<bool, StoreError>;
    /// Marks cancellation: a queued job becomes cancelled at once; a running job gets
    /// `cancel_requested` (its worker stops within one step). Returns the updated record.
    fn request_cancel(&self, id: Uuid) -> Result<Option<JobRecord>, StoreError>;
    /// Removes a finished job's record; false if absent or not finished.
    fn delete(&self, id: Uuid) -> Result<bool, StoreError>;
    /// Number of jobs per status.
    fn counts(&self) -> Result<Vec<(JobStatus, usize)>, StoreError>;
    /// Latest finished job with this scene hash that succeeded (repeat requests answered
    /// from the store), among the anonymous owner's.
    fn find_succeeded_by_hash(&self, scene_hash: &str) -> Result<Option<JobRecord>, StoreError> {
        self.find_succeeded_for("", scene_hash)
    }
    /// `owner`'s job submitted with this idempotency key, if any.
    fn find_by_idempotency_key(
        &self,
        owner: &str,
        key: &str,
    ) -> Result<Option<JobRecord>, StoreError>;
    /// [`Store::find_succeeded_by_hash`] among `owner`'s jobs only: another owner's job id
    /// is never handed out.
    fn find_succeeded_for(
        &self,
        owner: &str,
        scene_hash: &str,
    ) -> Result<Option<JobRecord>, StoreError>;
    /// Makes the running jobs of workers whose name starts with `worker_prefix` claimable
    /// at once (their lease is set to 0). A restarted node calls this at start with its own
    /// worker-name prefix: its previous process's workers are dead, so there is no point
    /// waiting for their leases to expire. The claim still counts as a new attempt. An
    /// empty prefix releases every running job (single node only). Returns the number of
    /// jobs released.
    fn release_worker_leases(&self, worker_prefix: &str) -> Result<usize, StoreError>;
    /// Records an uploaded mesh unless one with this id is stored already. Returns the
    /// stored record (the first upload's, for a repeated one) and whether it is new.
    fn add_mesh(
        &self,
        id: &str,
        bytes: u64,
        summary: &serde_json::Value,
    ) -> Result<(MeshRecord, bool), StoreError> {
        self.add_mesh_with_file(id, bytes, summary, &mut || Ok(()))
    }
    /// [`Store::add_mesh`] that puts the mesh's file in place with `file`, inside the
    /// transaction (see [`MeshFileStep`]).
    fn add_mesh_with_file(
        &self,
        id: &str,
        bytes: u64,
        summary: &serde_json::Value,
        file: MeshFileStep<'_>,
    ) -> Result<(MeshRecord, bool), StoreError>;
    fn get_mesh(&self, id: &str) -> Result<Option<MeshRecord>, StoreError>;
    /// Newest first, with cursors as [`Store::list`]'s.
    fn list_meshes(&self, cursor: Option<&str>, limit: usize) -> Result<MeshPage, StoreError>;
    /// Removes a mesh's record unless a queued or running job uses it (atomically with
    /// `enqueue`: a job is never enqueued on a mesh being deleted). Its file is the caller's
    /// to remove.
    fn delete_mesh(&self, id: &str) -> Result<MeshDeletion, StoreError> {
        self.delete_mesh_with_file(id, &mut || Ok(()))
    }
    /// [`Store::delete_mesh`] that takes the mesh's file away with `file`, inside the
    /// transaction (see [`MeshFileStep`]); `file` runs only when the record is deleted.
    fn delete_mesh_with_file(
        &self,
        id: &str,
        file: MeshFileStep<'_>,
    ) -> Result<MeshDeletion, StoreError>;
    /// Calls `wake` whenever another process may have made a job claimable (a submission
    /// on another node), until `wake` returns false. A backend only ever written by this
    /// process (SQLite: the API wakes its own workers) does nothing.
    fn watch_for_work(&self, wake: Wake) -> Result<(), StoreError> {
        let _ = wake;
        Ok(())
    }
}

/// Current Unix time in seconds.
pub fn now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}
