//! The embedded job store: one SQLite database file in the data directory.
//!
//! # Design
//!
//! * **One connection behind a mutex.** The store is shared by the async API (through
//!   `spawn_blocking`) and the worker threads. Every operation is short (a few indexed
//!   statements), so serialising them through one [`Connection`] in a [`Mutex`] is simple,
//!   correct and fast enough for an embedded store; it also means no `SQLITE_BUSY` between
//!   our own threads. `busy_timeout` (5 s) still covers a second process opening the same
//!   file (e.g. an admin tool); past it, as when the file cannot be opened or written, the
//!   store is [`StoreError::Unavailable`].
//! * **Every mutation is one committed transaction.** Read-modify-write sequences (enqueue
//!   with an idempotency key, claim, heartbeat, cancel) run in `BEGIN IMMEDIATE`
//!   transactions, which take the write lock up front, so they are atomic even against
//!   another process; single-statement updates are atomic by themselves. A process killed
//!   at any point leaves the database at the last committed state (SQLite's journal
//!   guarantees this).
//! * **WAL, `synchronous=FULL`.** WAL lets readers of other processes proceed during
//!   writes and makes commits cheap. With WAL, `synchronous=NORMAL` is also
//!   *consistent* after a power loss, but may lose the last commits; we chose `FULL`
//!   because the API acknowledges a submission (202 with a job id) right after `enqueue`
//!   commits, and that acknowledgement must survive a power cut. The cost is one fsync
//!   per commit, which is negligible at this store's write rate (submissions,
//!   heartbeats every few seconds, checkpoints).
//! * **Versioned migrations** in [`MIGRATIONS`], tracked by `PRAGMA user_version` and
//!   applied at open in a single transaction (all or nothing). A database written by a
//!   newer build (higher version) is refused rather than misread.
//! * **Leases instead of orphan sweeps.** A claimed job carries `worker` and
//!   `lease_until`; the worker extends the lease with [`Store::heartbeat`]. When a worker
//!   dies its lease runs out and [`Store::claim`] hands the job to another worker (which
//!   resumes from the last checkpoint). A restarted single-node server calls
//!   [`SqliteStore::release_worker_leases`] so its previous run's jobs are claimable at
//!   once instead of after the lease expires.
//!
//! The checkpoint blob lives in the `jobs` row as its last column: queries never select
//! it except [`Store::load_checkpoint`], and SQLite does not read a row's trailing
//! overflow pages for columns it is not asked for.

use std::path::Path;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use rusqlite::{params, Connection, OptionalExtension, Params, Row, TransactionBehavior};
use uuid::Uuid;

use super::claim::{verdict, Candidate, Verdict};
use super::row::{
    check_lease, into_mesh_page, into_page, json_text, memory_columns, page_bounds, status_counts,
    to_i64, to_usize, RawJob, RawMesh, FINISHED, UNFINISHED,
};
use super::{
    now, Enqueued, JobRecord, JobStatus, MeshDeletion, MeshFileStep, MeshPage, MeshRecord, NewJob,
    Page, Progress, Store, StoreError,
};

/// Schema migrations; entry `i` brings the database from `user_version` `i` to `i + 1`.
/// Append only: never edit a released migration.
const MIGRATIONS: &[&str] = &[
    // Version 1: jobs and a monotonic counter for `seq`.
    "
    CREATE TABLE meta (
        key   TEXT PRIMARY KEY NOT NULL,
        value INTEGER NOT NULL
    );
    INSERT INTO meta (key, value) VALUES ('next_seq', 1);

    CREATE TABLE jobs (
        id               TEXT PRIMARY KEY NOT NULL,
        seq              INTEGER NOT NULL UNIQUE,
        status           TEXT NOT NULL
                         CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
        scene            TEXT NOT NULL,
        scene_hash       TEXT NOT NULL,
        idempotency_key  TEXT UNIQUE,
        request_hash     TEXT,
        created_at       REAL NOT NULL,
        started_at       REAL,
        finished_at      REAL,
        step             INTEGER NOT NULL DEFAULT 0,
        steps            INTEGER NOT NULL DEFAULT 0,
        last_residual    REAL,
        error            TEXT,
        cancel_requested INTEGER NOT NULL DEFAULT 0,
        attempt          INTEGER NOT NULL DEFAULT 0,
        worker           TEXT,
        lease_until      REAL,
        checkpoint_step  INTEGER,
        checkpoint       BLOB
    );
    CREATE INDEX jobs_status_seq ON jobs (status, seq);
    CREATE INDEX jobs_scene_hash ON jobs (scene_hash);
    ",
    // Version 2: dead-lettering counts only interrupted attempts that made no progress.
    // `claim_step` is the checkpoint step the job was last claimed at; `stalls` the number
    // of claims in a row with no new checkpoint in between.
    "
    ALTER TABLE jobs ADD COLUMN claim_step INTEGER;
    ALTER TABLE jobs ADD COLUMN stalls INTEGER NOT NULL DEFAULT 0;
    ",
    // Version 3: uploaded meshes, and the one a job uses (deleting a mesh is refused while
    // a queued or running job uses it).
    "
    CREATE TABLE meshes (
        seq        INTEGER PRIMARY KEY AUTOINCREMENT,
        id         TEXT NOT NULL UNIQUE,
        bytes      INTEGER NOT NULL,
        created_at REAL NOT NULL,
        summary    TEXT NOT NULL
    );
    ALTER TABLE jobs ADD COLUMN mesh TEXT;
    CREATE INDEX jobs_mesh ON jobs (mesh) WHERE mesh IS NOT NULL;
    ",
    // Version 4: owners (see `super::owners`). A job's owner and estimated stored bytes;
    // idempotency keys unique per owner, which takes rebuilding the table (SQLite cannot
    // drop a column's UNIQUE constraint); the checkpoint blob moves to the end of the row.
    // API keys by token hash, compute per owner and UTC day, and the owners of meshes.
    "
    CREATE TABLE jobs_v4 (
        id               TEXT PRIMARY KEY NOT NULL,
        seq              INTEGER NOT NULL UNIQUE,
        status           TEXT NOT NULL
                         CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
        scene            TEXT NOT NULL,
        scene_hash       TEXT NOT NULL,
        owner            TEXT NOT NULL DEFAULT '',
        idempotency_key  TEXT,
        request_hash     TEXT,
        created_at       REAL NOT NULL,
        started_at       REAL,
        finished_at      REAL,
        step             INTEGER NOT NULL DEFAULT 0,
        steps            INTEGER NOT NULL DEFAULT 0,
        last_residual    REAL,
        error            TEXT,
        cancel_requested INTEGER NOT NULL DEFAULT 0,
        attempt          INTEGER NOT NULL DEFAULT 0,
        worker           TEXT,
        lease_until      REAL,
        checkpoint_step  INTEGER,
        claim_step       INTEGER,
        stalls           INTEGER NOT NULL DEFAULT 0,
        mesh             TEXT,
        stored_bytes     INTEGER NOT NULL DEFAULT 0,
        checkpoint       BLOB,
        UNIQUE (owner, idempotency_key)
    );
    INSERT INTO jobs_v4 (id, seq, status, scene, scene_hash, idempotency_key, request_hash,
                         created_at, started_at, finished_at, step, steps, last_residual, error,
                         cancel_requested, attempt, worker, lease_until, checkpoint_step,
                         claim_step, stalls, mesh, checkpoint)
        SELECT id, seq, status, scene, scene_hash, idempotency_key, request_hash,
               created_at, started_at, finished_at, step, steps, last_residual, error,
               cancel_requested, attempt, worker, lease_until, checkpoint_step,
               claim_step, stalls, mesh, checkpoint
        FROM jobs;
    DROP TABLE jobs;
    ALTER TABLE jobs_v4 RENAME TO jobs;
    CREATE INDEX jobs_status_seq ON jobs (status, seq);
    CREATE INDEX jobs_scene_hash ON jobs (scene_hash);
    CREATE INDEX jobs_mesh ON jobs (mesh) WHERE mesh IS NOT NULL;
    CREATE INDEX jobs_owner_status ON jobs (owner, status, seq);

    CREATE TABLE api_keys (
        name             TEXT PRIMARY KEY NOT NULL,
        token_hash       TEXT NOT NULL UNIQUE,
        admin            INTEGER NOT NULL DEFAULT 0,
        created_at       REAL NOT NULL,
        last_used_at     REAL,
        revoked_at       REAL,
        max_active_jobs  INTEGER,
        max_stored_bytes INTEGER,
        max_compute_s    REAL
    );
    CREATE TABLE usage (
        owner     TEXT NOT NULL,
        day       INTEGER NOT NULL,
        compute_s REAL NOT NULL DEFAULT 0,
        PRIMARY KEY (owner, day)
    );
    CREATE TABLE mesh_owners (
        seq        INTEGER PRIMARY KEY AUTOINCREMENT,
        owner      TEXT NOT NULL,
        id         TEXT NOT NULL,
        created_at REAL NOT NULL,
        UNIQUE (owner, id)
    );
    CREATE INDEX mesh_owners_id ON mesh_owners (id);
    CREATE TABLE owner_turns (
        owner      TEXT PRIMARY KEY NOT NULL,
        last_claim REAL NOT NULL
    );
    INSERT INTO mesh_owners (owner, id, created_at) SELECT '', id, created_at FROM meshes;
    ",
    // Version 5: a simulation's linear path and peak memory as predicted at submission
    // (both null for studies and for jobs stored before). Rebuilt rather than altered so
    // that the checkpoint blob stays the row's last column.
    "
    CREATE TABLE jobs_v5 (
        id               TEXT PRIMARY KEY NOT NULL,
        seq              INTEGER NOT NULL UNIQUE,
        status           TEXT NOT NULL
                         CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
        scene            TEXT NOT NULL,
        scene_hash       TEXT NOT NULL,
        owner            TEXT NOT NULL DEFAULT '',
        idempotency_key  TEXT,
        request_hash     TEXT,
        created_at       REAL NOT NULL,
        started_at       REAL,
        finished_at      REAL,
        step             INTEGER NOT NULL DEFAULT 0,
        steps            INTEGER NOT NULL DEFAULT 0,
        last_residual    REAL,
        error            TEXT,
        cancel_requested INTEGER NOT NULL DEFAULT 0,
        attempt          INTEGER NOT NULL DEFAULT 0,
        worker           TEXT,
        lease_until      REAL,
        checkpoint_step  INTEGER,
        claim_step       INTEGER,
        stalls           INTEGER NOT NULL DEFAULT 0,
        mesh             TEXT,
        stored_bytes     INTEGER NOT NULL DEFAULT 0,
        linear_path      TEXT CHECK (linear_path IN ('direct', 'multigrid')),
        predicted_bytes  INTEGER CHECK (predicted_bytes >= 0),
        checkpoint       BLOB,
        UNIQUE (owner, idempotency_key),
        CHECK ((linear_path IS NULL) = (predicted_bytes IS NULL))
    );
    INSERT INTO jobs_v5 (id, seq, status, scene, scene_hash, owner, idempotency_key,
                         request_hash, created_at, started_at, finished_at, step, steps,
                         last_residual, error, cancel_requested, attempt, worker, lease_until,
                         checkpoint_step, claim_step, stalls, mesh, stored_bytes, checkpoint)
        SELECT id, seq, status, scene, scene_hash, owner, idempotency_key,
               request_hash, created_at, started_at, finished_at, step, steps,
               last_residual, error, cancel_requested, attempt, worker, lease_until,
               checkpoint_step, claim_step, stalls, mesh, stored_bytes, checkpoint
        FROM jobs;
    DROP TABLE jobs;
    ALTER TABLE jobs_v5 RENAME TO jobs;
    CREATE INDEX jobs_status_seq ON jobs (status, seq);
    CREATE INDEX jobs_scene_hash ON jobs (scene_hash);
    CREATE INDEX jobs_mesh ON jobs (mesh) WHERE mesh IS NOT NULL;
    CREATE INDEX jobs_owner_status ON jobs (owner, status, seq);
    ",
    // Version 6: sweeps whose members are jobs. A member job names the sweep that created it
    // (`sweep`); a sweep lists its members' job ids in member order (`members`, JSON). A
    // queued sweep is claimable only while none of its members is queued or running, or once
    // one of them failed or was cancelled. Rebuilt so that the checkpoint blob stays last.
    "
    CREATE TABLE jobs_v6 (
        id               TEXT PRIMARY KEY NOT NULL,
        seq              INTEGER NOT NULL UNIQUE,
        status           TEXT NOT NULL
                         CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
        scene            TEXT NOT NULL,
        scene_hash       TEXT NOT NULL,
        owner            TEXT NOT NULL DEFAULT '',
        idempotency_key  TEXT,
        request_hash     TEXT,
        created_at       REAL NOT NULL,
        started_at       REAL,
        finished_at      REAL,
        step             INTEGER NOT NULL DEFAULT 0,
        steps            INTEGER NOT NULL DEFAULT 0,
        last_residual    REAL,
        error            TEXT,
        cancel_requested INTEGER NOT NULL DEFAULT 0,
        attempt          INTEGER NOT NULL DEFAULT 0,
        worker           TEXT,
        lease_until      REAL,
        checkpoint_step  INTEGER,
        claim_step       INTEGER,
        stalls           INTEGER NOT NULL DEFAULT 0,
        mesh             TEXT,
        stored_bytes     INTEGER NOT NULL DEFAULT 0,
        linear_path      TEXT CHECK (linear_path IN ('direct', 'multigrid')),
        predicted_bytes  INTEGER CHECK (predicted_bytes >= 0),
        sweep            TEXT,
        members          TEXT,
        checkpoint       BLOB,
        UNIQUE (owner, idempotency_key),
        CHECK ((linear_path IS NULL) = (predicted_bytes IS NULL))
    );
    INSERT INTO jobs_v6 (id, seq, status, scene, scene_hash, owner, idempotency_key,
                         request_hash, created_at, started_at, finished_at, step, steps,
                         last_residual, error, cancel_requested, attempt, worker, lease_until,
                         checkpoint_step, claim_step, stalls, mesh, stored_bytes, linear_path,
                         predicted_bytes, checkpoint)
        SELECT id, seq, status, scene, scene_hash, owner, idempotency_key,
               request_hash, created_at, started_at, finished_at, step, steps,
               last_residual, error, cancel_requested, attempt, worker, lease_until,
               checkpoint_step, claim_step, stalls, mesh, stored_bytes, linear_path,
               predicted_bytes, checkpoint
        FROM jobs;
    DROP TABLE jobs;
    ALTER TABLE jobs_v6 RENAME TO jobs;
    CREATE INDEX jobs_status_seq ON jobs (status, seq);
    CREATE INDEX jobs_scene_hash ON jobs (scene_hash);
    CREATE INDEX jobs_mesh ON jobs (mesh) WHERE mesh IS NOT NULL;
    CREATE INDEX jobs_owner_status ON jobs (owner, status, seq);
    CREATE INDEX jobs_sweep ON jobs (sweep) WHERE sweep IS NOT NULL;
    ",
];

/// Columns of a [`MeshRecord`] (plus `seq`), in the order [`RawMesh::from_row`] reads them.
const MESH_COLS: &str = "id, bytes, created_at, summary, seq";

/// Columns of a [`JobRecord`] (plus `seq`), in the order [`RawJob::from_row`] reads them.
/// The checkpoint blob is deliberately absent.
const COLS: &str = "id, status, scene, scene_hash, idempotency_key, request_hash, created_at, \
     started_at, finished_at, step, steps, last_residual, error, cancel_requested, attempt, \
     worker, lease_until, checkpoint_step, seq, owner, linear_path, predicted_bytes, sweep, \
     members";

impl From<rusqlite::Error> for StoreError {
    fn from(e: rusqlite::Error) -> StoreError {
        match e {
            // A column holding something of the wrong type is bad data, not a DB failure.
            rusqlite::Error::InvalidColumnType(..)
            | rusqlite::Error::FromSqlConversionFailure(..)
            | rusqlite::Error::IntegralValueOutOfRange(..)
            | rusqlite::Error::Utf8Error(..) => StoreError::Corrupt(e.to_string()),
            // The database's disk is full: an I/O condition of the node (see `crate::disk`).
            rusqlite::Error::SqliteFailure(f, _) if f.code == rusqlite::ErrorCode::DiskFull => {
                StoreError::Io(std::io::Error::new(
                    std::io::ErrorKind::StorageFull,
                    e.to_string(),
                ))
            }
            // Another process holds the database's write lock past `busy_timeout`, or the
            // file cannot be opened, written or read just now: the store is out, not the
            // request at fault (the API answers 503 with Retry-After, workers retry).
            rusqlite::Error::SqliteFailure(f, _)
                if matches!(
                    f.code,
                    rusqlite::ErrorCode::DatabaseBusy
                        | rusqlite::ErrorCode::DatabaseLocked
                        | rusqlite::ErrorCode::ReadOnly
                        | rusqlite::ErrorCode::CannotOpen
                        | rusqlite::ErrorCode::SystemIoFailure
                ) =>
            {
                StoreError::Unavailable(e.to_string())
            }
            other => StoreError::Db(other.to_string()),
        }
    }
}

impl RawJob {
    fn from_row(r: &Row<'_>) -> rusqlite::Result<RawJob> {
        Ok(RawJob {
            id: r.get(0)?,
            status: r.get(1)?,
            scene: r.get(2)?,
            scene_hash: r.get(3)?,
            idempotency_key: r.get(4)?,
            request_hash: r.get(5)?,
            created_at: r.get(6)?,
            started_at: r.get(7)?,
            finished_at: r.get(8)?,
            step: r.get(9)?,
            steps: r.get(10)?,
            last_residual: r.get(11)?,
            error: r.get(12)?,
            cancel_requested: r.get::<_, i64>(13)? != 0,
            attempt: r.get(14)?,
            worker: r.get(15)?,
            lease_until: r.get(16)?,
            checkpoint_step: r.get(17)?,
            seq: r.get(18)?,
            owner: r.get(19)?,
            linear_path: r.get(20)?,
            predicted_bytes: r.get(21)?,
            sweep: r.get(22)?,
            members: r.get(23)?,
        })
    }
}

impl RawMesh {
    fn from_row(r: &Row<'_>) -> rusqlite::Result<RawMesh> {
        Ok(RawMesh {
            id: r.get(0)?,
            bytes: r.get(1)?,
            created_at: r.get(2)?,
            summary: r.get(3)?,
            seq: r.get(4)?,
        })
    }
}

fn select_mesh(conn: &Connection, id: &str) -> Result<Option<MeshRecord>, StoreError> {
    let sql = format!("SELECT {MESH_COLS} FROM meshes WHERE id = ?1");
    let raw = conn
        .query_row(&sql, params![id], RawMesh::from_row)
        .optional()?;
    raw.map(RawMesh::into_record).transpose()
}

/// Reads at most one job matching `where_clause` (a constant SQL fragment from this file,
/// never user input; values go through `params`).
fn select_one<P: Params>(
    conn: &Connection,
    where_clause: &str,
    params: P,
) -> Result<Option<JobRecord>, StoreError> {
    let sql = format!("SELECT {COLS} FROM jobs WHERE {where_clause} LIMIT 1");
    let raw = conn.query_row(&sql, params, RawJob::from_row).optional()?;
    raw.map(RawJob::into_record).transpose()
}

fn select_by_id(conn: &Connection, id: Uuid) -> Result<Option<JobRecord>, StoreError> {
    select_one(conn, "id = ?1", params![id.to_string()])
}

/// Applies the pending migrations in one transaction.
fn migrate(conn: &mut Connection) -> Result<(), StoreError> {
    let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
    let version: i64 = tx.pragma_query_value(None, "user_version", |r| r.get(0))?;
    let latest = MIGRATIONS.len();
    let current = usize::try_from(version)
        .map_err(|_| StoreError::Corrupt(format!("schema version {version}")))?;
    if current > latest {
        return Err(StoreError::Corrupt(format!(
            "database schema version {current} is newer than this build supports ({latest})"
        )));
    }
    for (i, sql) in MIGRATIONS.iter().enumerate().skip(current) {
        tx.execute_batch(sql)?;
        tx.pragma_update(None, "user_version", to_i64(i + 1, "schema version")?)?;
    }
    tx.commit()?;
    Ok(())
}

/// The SQLite-backed [`Store`]. See the module documentation for the design.
pub struct SqliteStore {
    conn: Mutex<Connection>,
}

impl std::fmt::Debug for SqliteStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SqliteStore").finish_non_exhaustive()
    }
}

impl SqliteStore {
    /// Opens (creating if needed) the database at `path`, its parent directory, and the
    /// schema; applies pending migrations. Journal mode WAL where the filesystem supports
    /// it (otherwise SQLite keeps its rollback journal, which is equally crash-safe),
    /// `synchronous=FULL`, `busy_timeout` 5 s.
    pub fn open(path: &Path) -> Result<SqliteStore, StoreError> {
        if let Some(parent) = path.parent() {
            if !parent.as_os_str().is_empty() {
                std::fs::create_dir_all(parent)?;
            }
        }
        SqliteStore::init(Connection::open(path)?)
    }

    /// A private in-memory database (tests, throwaway runs). Nothing survives the store.
    pub fn open_in_memory() -> Result<SqliteStore, StoreError> {
        SqliteStore::init(Connection::open_in_memory()?)
    }

    fn init(mut conn: Connection) -> Result<SqliteStore, StoreError> {
        conn.busy_timeout(Duration::from_secs(5))?;
        // Returns the resulting mode ("wal", or "memory" for in-memory databases); any
        // answer is acceptable, see `open`.
        let _mode: String =
            conn.pragma_update_and_check(None, "journal_mode", "WAL", |r| r.get(0))?;
        conn.pragma_update(None, "synchronous", "FULL")?;
        migrate(&mut conn)?;
        Ok(SqliteStore {
            conn: Mutex::new(conn),
        })
    }

    /// The connection. A poisoned mutex (a thread panicked while holding it) is recovered:
    /// any transaction that thread had open was rolled back when its `Transaction` was
    /// dropped during unwinding, so the connection is in a clean state.
    fn lock(&self) -> MutexGuard<'_, Connection> {
        self.conn.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn claim_at(
        &self,
        worker: &str,
        lease_s: f64,
        max_attempts: u32,
        now: f64,
    ) -> Result<Option<JobRecord>, StoreError> {
        check_lease(lease_s)?;
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        // Each iteration either returns or moves the candidate to a final status, so the
        // loop ends.
        loop {
            let candidate: Option<(String, Candidate)> = tx
                .query_row(
                    "SELECT j.id, j.attempt, j.cancel_requested != 0, j.stalls,
                            COALESCE(j.checkpoint_step, -1) > COALESCE(j.claim_step, -1)
                     FROM jobs j
                     LEFT JOIN (SELECT owner, COUNT(*) AS n FROM jobs
                                WHERE status = 'running' AND COALESCE(lease_until, 0) >= ?1
                                GROUP BY owner) r ON r.owner = j.owner
                     LEFT JOIN owner_turns t ON t.owner = j.owner
                     WHERE (j.status = 'queued' AND j.cancel_requested = 0
                            AND (NOT EXISTS (SELECT 1 FROM jobs m WHERE m.sweep = j.id
                                             AND m.status IN ('queued', 'running'))
                                 OR EXISTS (SELECT 1 FROM jobs m WHERE m.sweep = j.id
                                            AND m.status IN ('failed', 'cancelled'))))
                        OR (j.status = 'running' AND COALESCE(j.lease_until, 0) < ?1)
                     ORDER BY COALESCE(r.n, 0), COALESCE(t.last_claim, 0), j.seq LIMIT 1",
                    params![now],
                    |r| {
                        Ok((
                            r.get(0)?,
                            Candidate {
                                attempt: r.get(1)?,
                                cancel_requested: r.get(2)?,
                                stalls: r.get(3)?,
                                progressed: r.get(4)?,
                            },
                        ))
                    },
                )
                .optional()?;
            let Some((id, candidate)) = candidate else {
                tx.commit()?;
                return Ok(None);
            };
            match verdict(candidate, max_attempts) {
                Verdict::Cancel => {
                    tx.execute(
                        "UPDATE jobs SET status = 'cancelled', finished_at = ?2, lease_until = NULL,
                                checkpoint = NULL, checkpoint_step = NULL
                         WHERE id = ?1",
                        params![id, now],
                    )?;
                    continue;
                }
                Verdict::DeadLetter(error) => {
                    tx.execute(
                        "UPDATE jobs SET status = 'failed', finished_at = ?2, error = ?3,
                                lease_until = NULL, checkpoint = NULL, checkpoint_step = NULL
                         WHERE id = ?1",
                        params![id, now, json_text(&error)?],
                    )?;
                    continue;
                }
                Verdict::Run { stalls } => {
                    tx.execute(
                        "UPDATE jobs SET status = 'running', worker = ?2, lease_until = ?3,
                                attempt = attempt + 1, started_at = COALESCE(started_at, ?4),
                                stalls = ?5, claim_step = checkpoint_step
                         WHERE id = ?1",
                        params![id, worker, now + lease_s, now, stalls],
                    )?;
                    tx.execute(
                        "INSERT INTO owner_turns (owner, last_claim)
                         SELECT owner, ?2 FROM jobs WHERE id = ?1
                         ON CONFLICT (owner) DO UPDATE SET last_claim = excluded.last_claim",
                        params![id, now],
                    )?;
                }
            }
            let job = select_one(&tx, "id = ?1", params![id])?;
            tx.commit()?;
            return Ok(job);
        }
    }

    fn heartbeat_at(
        &self,
        id: Uuid,
        worker: &str,
        lease_s: f64,
        now: f64,
    ) -> Result<bool, StoreError> {
        check_lease(lease_s)?;
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        let cancel_requested: Option<bool> = tx
            .query_row(
                "UPDATE jobs SET lease_until = ?3
                 WHERE id = ?1 AND status = 'running' AND worker = ?2
                 RETURNING cancel_requested != 0",
                params![id.to_string(), worker, now + lease_s],
                |r| r.get(0),
            )
            .optional()?;
        tx.commit()?;
        Ok(cancel_requested == Some(false))
    }

    fn finish_at(
        &self,
        id: Uuid,
        status: JobStatus,
        error: Option<serde_json::Value>,
        now: f64,
    ) -> Result<(), StoreError> {
        if !status.is_finished() {
            return Err(StoreError::Db(format!(
                "finish: {} is not a final status",
                status.as_str()
            )));
        }
        let error = error.as_ref().map(json_text).transpose()?;
        let conn = self.lock();
        conn.execute(
            &format!(
                "UPDATE jobs SET status = ?2, finished_at = ?3, error = ?4, lease_until = NULL,
                        checkpoint = NULL, checkpoint_step = NULL
                 WHERE id = ?1 AND status NOT IN {FINISHED}"
            ),
            params![id.to_string(), status.as_str(), now, error],
        )?;
        Ok(())
    }

    fn request_cancel_at(&self, id: Uuid, now: f64) -> Result<Option<JobRecord>, StoreError> {
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        let key = id.to_string();
        let status: Option<String> = tx
            .query_row("SELECT status FROM jobs WHERE id = ?1", params![key], |r| {
                r.get(0)
            })
            .optional()?;
        match status.as_deref() {
            None => return Ok(None),
            Some("queued") => {
                tx.execute(
                    "UPDATE jobs SET status = 'cancelled', cancel_requested = 1, finished_at = ?2
                     WHERE id = ?1",
                    params![key, now],
                )?;
            }
            Some("running") => {
                tx.execute(
                    "UPDATE jobs SET cancel_requested = 1 WHERE id = ?1",
                    params![key],
                )?;
            }
            Some(_) => {}
        }
        let job = select_by_id(&tx, id)?;
        tx.commit()?;
        Ok(job)
    }
}

impl Store for SqliteStore {
    /// Adds a queued job (attempt 0, progress 0/`steps`) and returns [`Enqueued::New`].
    ///
    /// With an idempotency key that is already stored, nothing is inserted: the stored job
    /// is returned as [`Enqueued::Existing`] if its `request_hash` equals the new one (a
    /// client retry), or as [`Enqueued::KeyConflict`] if it differs (the key was reused for
    /// a different request; the API answers 409/422). The look-up and the insert share one
    /// immediate transaction, so two concurrent submissions with the same key cannot both
    /// insert (the UNIQUE constraint would stop the second one anyway).
    fn enqueue_in(
        &self,
        owner: &str,
        stored_bytes: u64,
        job: NewJob,
        sweep: Option<Uuid>,
    ) -> Result<Enqueued, StoreError> {
        let scene = json_text(&job.scene)?;
        let steps = to_i64(job.steps, "steps")?;
        let stored_bytes = i64::try_from(stored_bytes).unwrap_or(i64::MAX);
        let (linear_path, predicted_bytes) = memory_columns(job.memory)?;
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        if let Some(key) = &job.idempotency_key {
            if let Some(existing) = select_one(
                &tx,
                "owner = ?1 AND idempotency_key = ?2",
                params![owner, key],
            )? {
                return Ok(if existing.request_hash == job.request_hash {
                    Enqueued::Existing(existing)
                } else {
                    Enqueued::KeyConflict(existing)
                });
            }
        }
        if let Some(mesh) = &job.mesh {
            if select_mesh(&tx, mesh)?.is_none() {
                return Ok(Enqueued::NoMesh(mesh.clone()));
            }
        }
        let seq: i64 = tx.query_row("SELECT value FROM meta WHERE key = 'next_seq'", [], |r| {
            r.get(0)
        })?;
        tx.execute(
            "UPDATE meta SET value = ?1 WHERE key = 'next_seq'",
            params![seq + 1],
        )?;
        let id = Uuid::new_v4();
        tx.execute(
            "INSERT INTO jobs (id, seq, status, scene, scene_hash, idempotency_key, request_hash,
                               created_at, step, steps, cancel_requested, attempt, mesh, owner,
                               stored_bytes, linear_path, predicted_bytes, sweep)
             VALUES (?1, ?2, 'queued', ?3, ?4, ?5, ?6, ?7, 0, ?8, 0, 0, ?9, ?10, ?11, ?12, ?13,
                     ?14)",
            params![
                id.to_string(),
                seq,
                scene,
                job.scene_hash,
                job.idempotency_key,
                job.request_hash,
                now(),
                steps,
                job.mesh,
                owner,
                stored_bytes,
                linear_path,
                predicted_bytes,
                sweep.map(|s| s.to_string())
            ],
        )?;
        let record = select_by_id(&tx, id)?
            .ok_or_else(|| StoreError::Db(format!("job {id} missing right after insert")))?;
        tx.commit()?;
        Ok(Enqueued::New(record))
    }

    fn sweep_members(&self, sweep: Uuid) -> Result<Vec<JobRecord>, StoreError> {
        let conn = self.lock();
        let mut stmt = conn.prepare_cached(&format!(
            "SELECT {COLS} FROM jobs WHERE sweep = ?1 ORDER BY seq"
        ))?;
        let raws: Vec<RawJob> = stmt
            .query_map(params![sweep.to_string()], RawJob::from_row)?
            .collect::<rusqlite::Result<_>>()?;
        raws.into_iter().map(RawJob::into_record).collect()
    }

    fn set_members(&self, id: Uuid, members: &[Uuid]) -> Result<(), StoreError> {
        let members = json_text(&serde_json::json!(members))?;
        self.lock().execute(
            "UPDATE jobs SET members = ?2 WHERE id = ?1",
            params![id.to_string(), members],
        )?;
        Ok(())
    }

    /// The full record (without the checkpoint blob), None if absent. Progress comes from
    /// the `step`, `steps`, `last_residual` columns.
    fn get(&self, id: Uuid) -> Result<Option<JobRecord>, StoreError> {
        select_by_id(&self.lock(), id)
    }

    /// Newest first (descending `seq`, the insertion order), optionally only one status.
    ///
    /// `cursor` is the `next` of the previous page: the opaque `"s<seq>"` of its last job;
    /// the page holds the jobs strictly older than it, so deletions and insertions between
    /// requests never duplicate or skip a job that exists throughout. An unparsable cursor
    /// yields an empty page (validate cursors with [`parse_cursor`] first to report 400).
    /// `limit` is at least 1 (0 is treated as 1). `next` is None on the last page.
    /// `owner` (when given) narrows the page to that owner's jobs.
    fn list_for(
        &self,
        owner: Option<&str>,
        status: Option<JobStatus>,
        cursor: Option<&str>,
        limit: usize,
    ) -> Result<Page, StoreError> {
        let Some((before, fetch)) = page_bounds(cursor, limit) else {
            return Ok(Page {
                jobs: Vec::new(),
                next: None,
            });
        };
        let conn = self.lock();
        let status = status.map(JobStatus::as_str);
        let raws: Vec<RawJob> = match (status, owner) {
            (Some(s), None) => {
                let mut stmt = conn.prepare_cached(&format!(
                    "SELECT {COLS} FROM jobs WHERE status = ?1 AND seq < ?2
                     ORDER BY seq DESC LIMIT ?3"
                ))?;
                let rows = stmt.query_map(params![s, before, fetch], RawJob::from_row)?;
                rows.collect::<rusqlite::Result<_>>()?
            }
            (None, None) => {
                let mut stmt = conn.prepare_cached(&format!(
                    "SELECT {COLS} FROM jobs WHERE seq < ?1 ORDER BY seq DESC LIMIT ?2"
                ))?;
                let rows = stmt.query_map(params![before, fetch], RawJob::from_row)?;
                rows.collect::<rusqlite::Result<_>>()?
            }
            (s, Some(o)) => {
                let mut stmt = conn.prepare_cached(&format!(
                    "SELECT {COLS} FROM jobs
                     WHERE owner = ?1 AND (?2 IS NULL OR status = ?2) AND seq < ?3
                     ORDER BY seq DESC LIMIT ?4"
                ))?;
                let rows = stmt.query_map(params![o, s, before, fetch], RawJob::from_row)?;
                rows.collect::<rusqlite::Result<_>>()?
            }
        };
        drop(conn);
        into_page(raws, limit)
    }

    /// In one immediate transaction, takes a job that is either `queued` (and not
    /// cancel-requested) or `running` with an expired lease (`lease_until < now`: its
    /// worker died or hung) — fairly across owners: of the owners with the fewest jobs
    /// running, the one whose last claim is the oldest (`owner_turns`), its oldest job
    /// (lowest `seq`), so that one owner's thousand queued jobs do not starve another's one
    /// even with a single worker (with a single owner, as without authentication, simply
    /// the oldest job) — and applies the claim policy
    /// (`super::claim`, the same for both backends):
    ///
    /// * If that job was already claimed `max_attempts` times in a row without saving a
    ///   new checkpoint in between (and none since), it is marked `failed` with a
    ///   problem+json error (`"title": "job abandoned"`, status 500) and the search goes
    ///   on: a job that kills its worker every time must not loop forever. Attempts that
    ///   made progress (a checkpoint after the step they resumed from) reset that count:
    ///   checkpoints only move forward, so such a job finishes however often the server
    ///   is killed under it.
    /// * An expired running job with a pending cancel request is marked `cancelled`
    ///   instead (its worker can no longer honour the request) and the search goes on.
    /// * Otherwise the job becomes `running` for `worker` until `now + lease_s`, `attempt`
    ///   is incremented, `started_at` is set unless already set (first start is kept), and
    ///   the updated record is returned. The checkpoint is kept, so the new worker resumes.
    ///
    /// Returns None if nothing is claimable. `lease_s` must be finite and ≥ 0.
    fn claim(
        &self,
        worker: &str,
        lease_s: f64,
        max_attempts: u32,
    ) -> Result<Option<JobRecord>, StoreError> {
        self.claim_at(worker, lease_s, max_attempts, now())
    }

    /// Extends the lease to `now + lease_s` if the job is `running` and held by `worker`.
    /// Returns true only if so *and* no cancel was requested; false tells the worker to
    /// stop (the job was cancelled, finished, deleted, or reclaimed by another worker after
    /// this one's lease expired). On a cancel request the lease is still extended so that
    /// the stopping worker can record `cancelled` without being raced by a reclaim.
    fn heartbeat(&self, id: Uuid, worker: &str, lease_s: f64) -> Result<bool, StoreError> {
        self.heartbeat_at(id, worker, lease_s, now())
    }

    fn requeue(&self, id: Uuid, worker: &str) -> Result<bool, StoreError> {
        let n = self.lock().execute(
            "UPDATE jobs SET
                 status = CASE WHEN cancel_requested != 0 THEN 'cancelled' ELSE 'queued' END,
                 finished_at = CASE WHEN cancel_requested != 0 THEN ?3 ELSE finished_at END,
                 checkpoint = CASE WHEN cancel_requested != 0 THEN NULL ELSE checkpoint END,
                 checkpoint_step = CASE WHEN cancel_requested != 0 THEN NULL
                                        ELSE checkpoint_step END,
                 worker = NULL, lease_until = NULL,
                 attempt = MAX(attempt - 1, 0), stalls = MAX(stalls - 1, 0)
             WHERE id = ?1 AND status = 'running' AND worker = ?2",
            params![id.to_string(), worker, now()],
        )?;
        Ok(n > 0)
    }

    /// Records step/steps/last residual (whatever the status; a no-op for an absent job).
    /// A NaN residual is stored as NULL (SQLite has no NaN) and reads back as None.
    fn set_progress(&self, id: Uuid, progress: Progress) -> Result<(), StoreError> {
        let step = to_i64(progress.step, "step")?;
        let steps = to_i64(progress.steps, "steps")?;
        self.lock().execute(
            "UPDATE jobs SET step = ?2, steps = ?3, last_residual = ?4 WHERE id = ?1",
            params![id.to_string(), step, steps, progress.last_residual],
        )?;
        Ok(())
    }

    /// Stores `state` as the checkpoint after `step` and sets the progress step to `step`,
    /// in one statement (so step and blob always agree). Only while the job is `running`:
    /// a late checkpoint from a worker whose job was already finished must not resurrect a
    /// blob that `finish` dropped.
    fn checkpoint(&self, id: Uuid, step: usize, state: &[u8]) -> Result<(), StoreError> {
        let step = to_i64(step, "checkpoint step")?;
        self.lock().execute(
            "UPDATE jobs SET checkpoint_step = ?2, checkpoint = ?3, step = ?2
             WHERE id = ?1 AND status = 'running'",
            params![id.to_string(), step, state],
        )?;
        Ok(())
    }

    /// The last checkpoint (step, state), None if the job is absent, has none yet, or is
    /// finished (the blob is dropped then).
    fn load_checkpoint(&self, id: Uuid) -> Result<Option<(usize, Vec<u8>)>, StoreError> {
        let row: Option<(i64, Vec<u8>)> = self
            .lock()
            .query_row(
                "SELECT checkpoint_step, checkpoint FROM jobs
                 WHERE id = ?1 AND checkpoint_step IS NOT NULL AND checkpoint IS NOT NULL",
                params![id.to_string()],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()?;
        match row {
            Some((step, blob)) => Ok(Some((to_usize(step, "checkpoint_step")?, blob))),
            None => Ok(None),
        }
    }

    /// Sets the final `status` (succeeded, failed or cancelled; anything else is an
    /// error), `finished_at`, and `error` (stored as JSON); clears the lease but keeps the
    /// `worker` name for display; drops the checkpoint (blob and step: no longer needed).
    ///
    /// The first final status wins: finishing an absent or already finished job is a
    /// no-op (e.g. a worker that finishes after its job was abandoned or cancelled).
    fn finish(
        &self,
        id: Uuid,
        status: JobStatus,
        error: Option<serde_json::Value>,
    ) -> Result<(), StoreError> {
        self.finish_at(id, status, error, now())
    }

    /// `queued` → `cancelled` at once (with `finished_at`; it will never be claimed);
    /// `running` → `cancel_requested` is set (the worker sees it at its next heartbeat and
    /// stops); a finished job is unchanged. Returns the record after the change, None if
    /// absent.
    fn request_cancel(&self, id: Uuid) -> Result<Option<JobRecord>, StoreError> {
        self.request_cancel_at(id, now())
    }

    /// Deletes the record of a finished job; false if absent or not finished (a running job
    /// must be cancelled first). Result files are the caller's to remove.
    fn delete(&self, id: Uuid) -> Result<bool, StoreError> {
        let n = self.lock().execute(
            &format!("DELETE FROM jobs WHERE id = ?1 AND status IN {FINISHED}"),
            params![id.to_string()],
        )?;
        Ok(n > 0)
    }

    /// Number of jobs per status, every status listed (in [`JobStatus::ALL`] order) even
    /// when zero.
    fn counts(&self) -> Result<Vec<(JobStatus, usize)>, StoreError> {
        let conn = self.lock();
        let mut stmt = conn.prepare_cached("SELECT status, COUNT(*) FROM jobs GROUP BY status")?;
        let rows: Vec<(String, i64)> = stmt
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?
            .collect::<rusqlite::Result<_>>()?;
        status_counts(rows)
    }

    /// `substr`/`length` rather than LIKE: the prefix may contain `%` or `_`.
    fn release_worker_leases(&self, worker_prefix: &str) -> Result<usize, StoreError> {
        let conn = self.lock();
        let n = conn.execute(
            "UPDATE jobs SET lease_until = 0
             WHERE status = 'running' AND worker IS NOT NULL
               AND substr(worker, 1, length(?1)) = ?1",
            params![worker_prefix],
        )?;
        Ok(n)
    }

    /// The succeeded job with this scene hash that finished last (ties: the newest), None
    /// if there is none.
    fn find_by_idempotency_key(
        &self,
        owner: &str,
        key: &str,
    ) -> Result<Option<JobRecord>, StoreError> {
        select_one(
            &self.lock(),
            "owner = ?1 AND idempotency_key = ?2",
            params![owner, key],
        )
    }

    fn find_succeeded_for(
        &self,
        owner: &str,
        scene_hash: &str,
    ) -> Result<Option<JobRecord>, StoreError> {
        let conn = self.lock();
        let sql = format!(
            "SELECT {COLS} FROM jobs
             WHERE scene_hash = ?1 AND status = 'succeeded' AND owner = ?2
             ORDER BY finished_at DESC, seq DESC LIMIT 1"
        );
        let raw = conn
            .query_row(&sql, params![scene_hash, owner], RawJob::from_row)
            .optional()?;
        raw.map(RawJob::into_record).transpose()
    }

    /// Inserts unless the id is stored, and places the file, in one immediate transaction.
    fn add_mesh_with_file(
        &self,
        id: &str,
        bytes: u64,
        summary: &serde_json::Value,
        file: MeshFileStep<'_>,
    ) -> Result<(MeshRecord, bool), StoreError> {
        let bytes = i64::try_from(bytes)
            .map_err(|_| StoreError::Db(format!("mesh size {bytes} out of range")))?;
        let summary = json_text(summary)?;
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        let inserted = tx.execute(
            "INSERT INTO meshes (id, bytes, created_at, summary) VALUES (?1, ?2, ?3, ?4)
             ON CONFLICT (id) DO NOTHING",
            params![id, bytes, now(), summary],
        )?;
        let record = select_mesh(&tx, id)?
            .ok_or_else(|| StoreError::Db(format!("mesh {id} missing right after insert")))?;
        file()?;
        tx.commit()?;
        Ok((record, inserted > 0))
    }

    fn get_mesh(&self, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        select_mesh(&self.lock(), id)
    }

    fn list_meshes(&self, cursor: Option<&str>, limit: usize) -> Result<MeshPage, StoreError> {
        let Some((before, fetch)) = page_bounds(cursor, limit) else {
            return Ok(MeshPage {
                meshes: Vec::new(),
                next: None,
            });
        };
        let conn = self.lock();
        let mut stmt = conn.prepare_cached(&format!(
            "SELECT {MESH_COLS} FROM meshes WHERE seq < ?1 ORDER BY seq DESC LIMIT ?2"
        ))?;
        let raws: Vec<RawMesh> = stmt
            .query_map(params![before, fetch], RawMesh::from_row)?
            .collect::<rusqlite::Result<_>>()?;
        drop(stmt);
        drop(conn);
        into_mesh_page(raws, limit)
    }

    /// The check, the delete and the file's removal share one immediate transaction, which
    /// `enqueue`'s look-up of the mesh and an upload cannot interleave with.
    fn delete_mesh_with_file(
        &self,
        id: &str,
        file: MeshFileStep<'_>,
    ) -> Result<MeshDeletion, StoreError> {
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        if select_mesh(&tx, id)?.is_none() {
            return Ok(MeshDeletion::Absent);
        }
        let user = select_one(
            &tx,
            &format!("mesh = ?1 AND status IN {UNFINISHED} ORDER BY seq"),
            params![id],
        )?;
        if let Some(job) = user {
            return Ok(MeshDeletion::InUse(Box::new(job)));
        }
        tx.execute("DELETE FROM meshes WHERE id = ?1", params![id])?;
        tx.execute("DELETE FROM mesh_owners WHERE id = ?1", params![id])?;
        file()?;
        tx.commit()?;
        Ok(MeshDeletion::Deleted)
    }
}

mod owners;
#[cfg(test)]
mod tests;
