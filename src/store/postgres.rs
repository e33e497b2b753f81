//! The shared job store: one PostgreSQL database for many nodes (API nodes and worker
//! nodes), so that a sweep or a fine study can use more than one machine.
//!
//! # Design
//!
//! * **Jobs are rows of a state machine** (`queued → running → succeeded | failed |
//!   cancelled`) with `attempt`, `worker_id`, `lease_until` and `last_checkpoint_step`; the
//!   checkpoint blob lives in its own table (`checkpoints`), so the heartbeats that rewrite a
//!   job row every few seconds never copy it.
//! * **Claiming is `SELECT … FOR UPDATE SKIP LOCKED`** on the oldest claimable row of the
//!   owners with the fewest running jobs, least recently served first (fair across owners): workers of any number of processes never wait on each other's claims and never claim the same
//!   row (the row lock is held until the claiming transaction commits). What becomes of the
//!   claimed row (cancelled, dead letter, running) is both stores' one claim policy
//!   (`super::claim`, see [`Store::claim`]).
//! * **One clock.** Leases and timestamps use the database server's clock
//!   (`clock_timestamp()`), so nodes with skewed clocks still agree on whose lease expired.
//! * **Wake-ups by LISTEN/NOTIFY.** A submission runs `NOTIFY contact_sim_jobs` inside its
//!   transaction (delivered at commit); every worker node keeps one connection that
//!   `LISTEN`s and wakes its idle workers ([`Store::watch_for_work`]). Idle workers otherwise
//!   only look again when a lease could have expired (see `jobs::Runtime`), not in a loop.
//! * **Reconnection.** A lost connection (database restarted, network) is reported as
//!   [`StoreError::Unavailable`] and dropped; the next call connects again. Reads are retried
//!   once on a fresh connection; mutations are not (their outcome is unknown), callers decide:
//!   the worker retries idempotent ones (finish, checkpoint) and the API answers 503 with
//!   `Retry-After` (a client retrying with its `Idempotency-Key` cannot create a second job).
//! * **Versioned migrations** in [`MIGRATIONS`], recorded in `contact_sim_schema` and
//!   applied at connect under a session advisory lock, so nodes starting together migrate
//!   once; a database migrated by a newer build is refused.
//! * **TLS** as libpq's `sslmode` and `sslrootcert` in the URL (`super::postgres_tls`).
//!
//! All calls block (the `postgres` crate drives `tokio-postgres` on a private runtime):
//! call them from worker threads or `spawn_blocking`, never from an async task.

use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use postgres::error::SqlState;
use postgres::fallible_iterator::FallibleIterator;
use postgres::{Client, Config, GenericClient, Row};
use tokio_postgres_rustls::MakeRustlsConnect;
use uuid::Uuid;

use super::claim::{verdict, Candidate, Verdict};
use super::row::{
    check_lease, into_mesh_page, into_page, json_text, memory_columns, page_bounds, status_counts,
    to_i64, to_usize, RawJob, RawMesh, FINISHED, UNFINISHED,
};
use super::{
    Enqueued, JobRecord, JobStatus, MeshDeletion, MeshFileStep, MeshPage, MeshRecord, NewJob, Page,
    Progress, Store, StoreError, Wake,
};

/// Schema migrations; entry `i` brings the schema from version `i` to `i + 1`.
/// Append only: never edit a released migration.
const MIGRATIONS: &[&str] = &[
    // Version 1: jobs and their checkpoints.
    "
    CREATE TABLE jobs (
        id               uuid PRIMARY KEY,
        seq              bigint GENERATED ALWAYS AS IDENTITY UNIQUE,
        status           text NOT NULL
                         CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
        scene            text NOT NULL,
        scene_hash       text NOT NULL,
        idempotency_key  text UNIQUE,
        request_hash     text,
        created_at       float8 NOT NULL,
        started_at       float8,
        finished_at      float8,
        step             bigint NOT NULL DEFAULT 0,
        steps            bigint NOT NULL DEFAULT 0,
        last_residual    float8,
        error            text,
        cancel_requested boolean NOT NULL DEFAULT false,
        attempt          integer NOT NULL DEFAULT 0,
        worker_id        text,
        lease_until      float8,
        last_checkpoint_step bigint,
        -- Dead-lettering counts only interrupted attempts that made no progress: the
        -- checkpoint step the job was last claimed at, and the claims in a row without a
        -- new checkpoint.
        claim_step       bigint,
        stalls           integer NOT NULL DEFAULT 0
    );
    CREATE INDEX jobs_status_seq ON jobs (status, seq);
    CREATE INDEX jobs_claimable ON jobs (seq) WHERE status IN ('queued', 'running');
    CREATE INDEX jobs_scene_hash ON jobs (scene_hash);

    CREATE TABLE checkpoints (
        job   uuid PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
        step  bigint NOT NULL,
        state bytea NOT NULL
    );
    ",
    // Version 2: uploaded meshes, and the one a job uses (deleting a mesh is refused while
    // a queued or running job uses it).
    "
    CREATE TABLE meshes (
        id         text PRIMARY KEY,
        seq        bigint GENERATED ALWAYS AS IDENTITY UNIQUE,
        bytes      bigint NOT NULL,
        created_at float8 NOT NULL,
        summary    text NOT NULL
    );
    ALTER TABLE jobs ADD COLUMN mesh text;
    CREATE INDEX jobs_mesh ON jobs (mesh) WHERE mesh IS NOT NULL;
    ",
    // Version 3: owners (see `super::owners`): a job's owner and estimated stored bytes,
    // idempotency keys unique per owner; API keys by token hash, compute per owner and UTC
    // day, and the owners of meshes.
    "
    ALTER TABLE jobs ADD COLUMN owner text NOT NULL DEFAULT '';
    ALTER TABLE jobs ADD COLUMN stored_bytes bigint NOT NULL DEFAULT 0;
    ALTER TABLE jobs DROP CONSTRAINT jobs_idempotency_key_key;
    ALTER TABLE jobs ADD CONSTRAINT jobs_owner_idempotency_key UNIQUE (owner, idempotency_key);
    CREATE INDEX jobs_owner_status ON jobs (owner, status, seq);

    CREATE TABLE api_keys (
        name             text PRIMARY KEY,
        token_hash       text NOT NULL UNIQUE,
        admin            boolean NOT NULL DEFAULT false,
        created_at       float8 NOT NULL,
        last_used_at     float8,
        revoked_at       float8,
        max_active_jobs  bigint,
        max_stored_bytes bigint,
        max_compute_s    float8
    );
    CREATE TABLE usage (
        owner     text NOT NULL,
        day       bigint NOT NULL,
        compute_s float8 NOT NULL DEFAULT 0,
        PRIMARY KEY (owner, day)
    );
    CREATE TABLE mesh_owners (
        seq        bigint GENERATED ALWAYS AS IDENTITY UNIQUE,
        owner      text NOT NULL,
        id         text NOT NULL,
        created_at float8 NOT NULL,
        PRIMARY KEY (owner, id)
    );
    CREATE INDEX mesh_owners_id ON mesh_owners (id);
    CREATE TABLE owner_turns (
        owner      text PRIMARY KEY,
        last_claim float8 NOT NULL
    );
    INSERT INTO mesh_owners (owner, id, created_at) SELECT '', id, created_at FROM meshes;
    ",
    // Version 4: a simulation's linear path and peak memory as predicted at submission
    // (both null for studies and for jobs stored before).
    "
    ALTER TABLE jobs ADD COLUMN linear_path text
        CHECK (linear_path IN ('direct', 'multigrid'));
    ALTER TABLE jobs ADD COLUMN predicted_bytes bigint CHECK (predicted_bytes >= 0);
    ALTER TABLE jobs ADD CONSTRAINT jobs_memory_prediction
        CHECK ((linear_path IS NULL) = (predicted_bytes IS NULL));
    ",
    // Version 5: sweeps whose members are jobs. A member job names the sweep that created it
    // (`sweep`); a sweep lists its members' job ids in member order (`members`, JSON). A
    // queued sweep is claimable only while none of its members is queued or running, or once
    // one of them failed or was cancelled.
    "
    ALTER TABLE jobs ADD COLUMN sweep uuid;
    ALTER TABLE jobs ADD COLUMN members text;
    CREATE INDEX jobs_sweep ON jobs (sweep) WHERE sweep IS NOT NULL;
    ",
];

/// Columns of a [`MeshRecord`] (plus `seq`), in the order [`raw_mesh`] reads them.
const MESH_COLS: &str = "id, bytes, created_at, summary, seq";

/// The number of migrations applied.
const SCHEMA_VERSION: &str = "SELECT COALESCE(MAX(version), 0) FROM contact_sim_schema";

/// Key of the session advisory lock held while migrating ("contact" in ASCII).
const MIGRATION_LOCK: i64 = 0x0063_6f6e_7461_6374;

/// The notification channel of new work.
const CHANNEL: &str = "contact_sim_jobs";

/// Columns of a [`JobRecord`] (plus `seq`), in the order [`raw_job`] reads them.
const COLS: &str = "id, status, scene, scene_hash, idempotency_key, request_hash, created_at, \
     started_at, finished_at, step, steps, last_residual, error, cancel_requested, attempt, \
     worker_id, lease_until, last_checkpoint_step, seq, owner, linear_path, predicted_bytes, \
     sweep, members";

/// The database server's time in Unix seconds.
pub(super) const NOW_S: &str = "extract(epoch from clock_timestamp())::float8";

/// Longest a statement may run (ms): every one here is a few indexed row operations or one
/// checkpoint blob.
const STATEMENT_TIMEOUT_MS: u64 = 30_000;

/// How long a connection attempt may take before the store reports the database unavailable.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

fn raw_job(r: &Row) -> Result<RawJob, postgres::Error> {
    Ok(RawJob {
        id: r.try_get::<_, Uuid>(0)?.to_string(),
        status: r.try_get(1)?,
        scene: r.try_get(2)?,
        scene_hash: r.try_get(3)?,
        idempotency_key: r.try_get(4)?,
        request_hash: r.try_get(5)?,
        created_at: r.try_get(6)?,
        started_at: r.try_get(7)?,
        finished_at: r.try_get(8)?,
        step: r.try_get(9)?,
        steps: r.try_get(10)?,
        last_residual: r.try_get(11)?,
        error: r.try_get(12)?,
        cancel_requested: r.try_get(13)?,
        attempt: i64::from(r.try_get::<_, i32>(14)?),
        worker: r.try_get(15)?,
        lease_until: r.try_get(16)?,
        checkpoint_step: r.try_get(17)?,
        seq: r.try_get(18)?,
        owner: r.try_get(19)?,
        linear_path: r.try_get(20)?,
        predicted_bytes: r.try_get(21)?,
        sweep: r.try_get::<_, Option<Uuid>>(22)?.map(|s| s.to_string()),
        members: r.try_get(23)?,
    })
}

pub(super) fn raw_mesh(r: &Row) -> Result<RawMesh, postgres::Error> {
    Ok(RawMesh {
        id: r.try_get(0)?,
        bytes: r.try_get(1)?,
        created_at: r.try_get(2)?,
        summary: r.try_get(3)?,
        seq: r.try_get(4)?,
    })
}

/// The mesh row `id`; `lock` is appended to the query (`""`, `FOR SHARE`, `FOR UPDATE`).
pub(super) fn select_mesh(
    c: &mut impl GenericClient,
    id: &str,
    lock: &str,
) -> Result<Option<RawMesh>, postgres::Error> {
    let sql = format!("SELECT {MESH_COLS} FROM meshes WHERE id = $1 {lock}");
    c.query_opt(sql.as_str(), &[&id])?
        .map(|r| raw_mesh(&r))
        .transpose()
}

/// Class of the transaction advisory locks that serialise the changes of one mesh's record
/// and file ("mesh" in ASCII; two-key advisory locks do not share the migration lock's
/// key space).
const MESH_LOCK: i32 = 0x6d65_7368;

/// Takes the transaction advisory lock of mesh `id`: held until the transaction ends, so
/// the uploads, deletions and releases of one mesh run one after the other on every node.
/// The key is the id's first 8 hex digits (two meshes sharing them merely wait for each
/// other).
pub(super) fn lock_mesh(c: &mut impl GenericClient, id: &str) -> Result<(), postgres::Error> {
    let key = u32::from_str_radix(id.get(..8).unwrap_or("0"), 16).unwrap_or(0);
    let key = i32::from_ne_bytes(key.to_ne_bytes());
    c.execute("SELECT pg_advisory_xact_lock($1, $2)", &[&MESH_LOCK, &key])?;
    Ok(())
}

/// Whether the error means "the database is not reachable right now" rather than "this
/// statement is wrong": no server error code (I/O, closed connection, connect failure), or a
/// code of class 08 (connection exception) or 57P (operator intervention: shutdown, restart).
fn is_unavailable(e: &postgres::Error) -> bool {
    match e.code() {
        None => e.as_db_error().is_none(),
        Some(code) => {
            let c = code.code();
            c.starts_with("08") || c.starts_with("57P")
        }
    }
}

/// The error with its causes (`postgres::Error`'s own text is only the kind, e.g. "db
/// error" or "error performing TLS handshake"; the server's message or the certificate
/// problem is in the source chain).
pub fn describe(e: &postgres::Error) -> String {
    let mut text = e.to_string();
    let mut cause = std::error::Error::source(e);
    while let Some(c) = cause {
        text.push_str(": ");
        text.push_str(&c.to_string());
        cause = c.source();
    }
    text
}

pub(super) fn classify(e: postgres::Error) -> StoreError {
    if super::postgres_tls::is_tls_refusal(&e) {
        // Not transient: waiting does not make a certificate trusted.
        StoreError::Db(super::postgres_tls::explain(&describe(&e)))
    } else if is_unavailable(&e) {
        StoreError::Unavailable(describe(&e))
    } else if e.code() == Some(&SqlState::UNDEFINED_TABLE) {
        StoreError::Db(format!("{} (is the schema migrated?)", describe(&e)))
    } else {
        StoreError::Db(describe(&e))
    }
}

/// Reads at most one job matching `where_clause` (a constant SQL fragment from this file,
/// never user input; values go through `params`).
pub(super) fn select_one(
    c: &mut impl GenericClient,
    where_clause: &str,
    params: &[&(dyn postgres::types::ToSql + Sync)],
) -> Result<Option<RawJob>, postgres::Error> {
    let sql = format!("SELECT {COLS} FROM jobs WHERE {where_clause} LIMIT 1");
    c.query_opt(sql.as_str(), params)?
        .map(|r| raw_job(&r))
        .transpose()
}

/// Applies the pending migrations, each in its own transaction, under the advisory lock.
fn migrate(client: &mut Client) -> Result<(), StoreError> {
    client
        .execute("SELECT pg_advisory_lock($1)", &[&MIGRATION_LOCK])
        .map_err(classify)?;
    let result = (|| {
        client
            .batch_execute(
                "CREATE TABLE IF NOT EXISTS contact_sim_schema (
                     version    integer PRIMARY KEY,
                     applied_at timestamptz NOT NULL DEFAULT now()
                 )",
            )
            .map_err(classify)?;
        let current: i32 = client
            .query_one(SCHEMA_VERSION, &[])
            .map_err(classify)?
            .get(0);
        let current = usize::try_from(current)
            .map_err(|_| StoreError::Corrupt(format!("schema version {current}")))?;
        if current > MIGRATIONS.len() {
            return Err(StoreError::Corrupt(format!(
                "database schema version {current} is newer than this build supports ({})",
                MIGRATIONS.len()
            )));
        }
        for (i, sql) in MIGRATIONS.iter().enumerate().skip(current) {
            let version = i32::try_from(i + 1).expect("few migrations");
            let mut tx = client.transaction().map_err(classify)?;
            tx.batch_execute(sql).map_err(classify)?;
            tx.execute(
                "INSERT INTO contact_sim_schema (version) VALUES ($1)",
                &[&version],
            )
            .map_err(classify)?;
            tx.commit().map_err(classify)?;
        }
        Ok(())
    })();
    // Also released when the session ends, should this fail.
    let _ = client.execute("SELECT pg_advisory_unlock($1)", &[&MIGRATION_LOCK]);
    result
}

/// The PostgreSQL-backed [`Store`]. See the module documentation for the design.
pub struct PgStore {
    config: Config,
    /// TLS of every connection (`sslmode`, `sslrootcert` of the URL; see `postgres_tls`).
    tls: MakeRustlsConnect,
    /// One connection per process, shared by the API and the workers; None after a
    /// connection was lost (the next call connects again).
    conn: Mutex<Option<Client>>,
}

impl std::fmt::Debug for PgStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PgStore").finish_non_exhaustive()
    }
}

impl PgStore {
    /// Connects to `url` (`postgres://user@host:port/db`, or the key=value form), applies
    /// pending migrations and returns the store. Fails if the database cannot be reached.
    pub fn connect(url: &str) -> Result<PgStore, StoreError> {
        let tls = super::postgres_tls::PgTls::parse(url)
            .and_then(|t| Ok((t.connector()?, t.url)))
            .map_err(StoreError::Db);
        let (tls, url) = tls?;
        let mut config: Config = url
            .parse()
            .map_err(|e| StoreError::Db(format!("invalid PostgreSQL URL: {e}")))?;
        config.connect_timeout(CONNECT_TIMEOUT);
        // A database that stops answering without closing the connection (a network
        // partition) must not hold the store's connection, and every caller behind it,
        // forever: TCP keepalives notice a dead peer, the statement timeout a stuck one.
        config.keepalives(true);
        config.keepalives_idle(Duration::from_secs(10));
        let options = match config.get_options() {
            Some(o) => format!("{o} -c statement_timeout={STATEMENT_TIMEOUT_MS}"),
            None => format!("-c statement_timeout={STATEMENT_TIMEOUT_MS}"),
        };
        config.options(&options);
        if config.get_application_name().is_none() {
            config.application_name("contact-sim");
        }
        let mut client = config.connect(tls.clone()).map_err(classify)?;
        migrate(&mut client)?;
        Ok(PgStore {
            config,
            tls,
            conn: Mutex::new(Some(client)),
        })
    }

    /// The schema version of the database (number of migrations applied).
    pub fn schema_version(&self) -> Result<usize, StoreError> {
        self.read(|c| {
            let v: i32 = c.query_one(SCHEMA_VERSION, &[])?.get(0);
            Ok(v)
        })
        .and_then(|v| usize::try_from(v).map_err(|_| StoreError::Corrupt(format!("version {v}"))))
    }

    /// The connection (see `SqliteStore::lock` on poisoning: a panicking holder's open
    /// transaction was rolled back when it was dropped).
    fn lock(&self) -> MutexGuard<'_, Option<Client>> {
        self.conn.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Runs `f` on the connection, connecting first if there is none. A connection-level
    /// failure drops the connection and is [`StoreError::Unavailable`].
    pub(super) fn run<T>(
        &self,
        f: impl FnOnce(&mut Client) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let mut guard = self.lock();
        if guard.as_ref().is_none_or(|c| c.is_closed()) {
            *guard = None;
            *guard = Some(self.config.connect(self.tls.clone()).map_err(classify)?);
        }
        let client = guard.as_mut().expect("connected above");
        let result = f(client);
        if matches!(result, Err(StoreError::Unavailable(_))) || client.is_closed() {
            *guard = None;
        }
        result
    }

    /// Like [`Self::run`] for a closure whose only errors are the database's.
    pub(super) fn exec<T>(
        &self,
        f: impl FnOnce(&mut Client) -> Result<T, postgres::Error>,
    ) -> Result<T, StoreError> {
        self.run(|c| f(c).map_err(classify))
    }

    /// A read-only operation: retried once on a fresh connection if the first connection
    /// turned out to be dead (e.g. the first call after a database restart).
    pub(super) fn read<T>(
        &self,
        f: impl Fn(&mut Client) -> Result<T, postgres::Error>,
    ) -> Result<T, StoreError> {
        match self.exec(&f) {
            Err(StoreError::Unavailable(_)) => self.exec(&f),
            other => other,
        }
    }
}

/// Listens on [`CHANNEL`] on its own connection and calls `wake` for every notification,
/// after every (re)connection (notifications sent while disconnected are lost, so the
/// workers must look for themselves), and once a minute regardless. Stops when `wake`
/// returns false.
fn listen(config: Config, tls: MakeRustlsConnect, wake: Wake) {
    let mut backoff = Duration::from_millis(100);
    loop {
        let mut client = match config.connect(tls.clone()) {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!("job notifications: cannot connect: {}", describe(&e));
                std::thread::sleep(backoff);
                backoff = (backoff * 2).min(Duration::from_secs(5));
                continue;
            }
        };
        if let Err(e) = client.batch_execute(&format!("LISTEN {CHANNEL}")) {
            tracing::warn!("job notifications: LISTEN failed: {}", describe(&e));
            std::thread::sleep(backoff);
            continue;
        }
        backoff = Duration::from_millis(100);
        if !wake() {
            return;
        }
        let mut idle = 0u32;
        loop {
            // A short timeout so that a dead connection is noticed.
            let got = {
                let mut n = client.notifications();
                let mut it = n.timeout_iter(Duration::from_secs(1));
                it.next()
            };
            match got {
                Ok(Some(_)) => {
                    idle = 0;
                    if !wake() {
                        return;
                    }
                }
                Err(e) => {
                    tracing::warn!("job notifications: connection lost: {}", describe(&e));
                    break;
                }
                Ok(None) => {
                    idle += 1;
                    if client.is_closed() {
                        break;
                    }
                    if idle >= 60 {
                        idle = 0;
                        // A cheap round trip also detects a half-open connection.
                        if client.batch_execute("SELECT 1").is_err() || !wake() {
                            break;
                        }
                    }
                }
            }
        }
    }
}

impl PgStore {
    fn claim_in(
        client: &mut Client,
        worker: &str,
        lease_s: f64,
        max_attempts: u32,
    ) -> Result<Option<RawJob>, postgres::Error> {
        let mut tx = client.transaction()?;
        // Each iteration either returns or moves the candidate to a final status.
        loop {
            let Some(row) = tx.query_opt(
                format!(
                    "SELECT j.id, j.attempt, j.cancel_requested, j.stalls,
                            COALESCE(j.last_checkpoint_step, -1) > COALESCE(j.claim_step, -1)
                     FROM jobs j
                     LEFT JOIN (SELECT owner, count(*) AS n FROM jobs
                                WHERE status = 'running'
                                  AND COALESCE(lease_until, 0) >= {NOW_S}
                                GROUP BY owner) r ON r.owner = j.owner
                     LEFT JOIN owner_turns t ON t.owner = j.owner
                     WHERE j.status IN ('queued', 'running')
                       AND ((j.status = 'queued' AND NOT j.cancel_requested
                             AND (NOT EXISTS (SELECT 1 FROM jobs m WHERE m.sweep = j.id
                                              AND m.status IN ('queued', 'running'))
                                  OR EXISTS (SELECT 1 FROM jobs m WHERE m.sweep = j.id
                                             AND m.status IN ('failed', 'cancelled'))))
                            OR (j.status = 'running' AND COALESCE(j.lease_until, 0) < {NOW_S}))
                     ORDER BY COALESCE(r.n, 0), COALESCE(t.last_claim, 0), j.seq LIMIT 1
                     FOR UPDATE OF j SKIP LOCKED"
                )
                .as_str(),
                &[],
            )?
            else {
                tx.commit()?;
                return Ok(None);
            };
            let id: Uuid = row.try_get(0)?;
            let candidate = Candidate {
                attempt: i64::from(row.try_get::<_, i32>(1)?),
                cancel_requested: row.try_get(2)?,
                stalls: i64::from(row.try_get::<_, i32>(3)?),
                progressed: row.try_get(4)?,
            };
            let stalls = match verdict(candidate, max_attempts) {
                Verdict::Cancel => {
                    tx.execute(
                        format!(
                            "UPDATE jobs SET status = 'cancelled', finished_at = {NOW_S},
                                    lease_until = NULL, last_checkpoint_step = NULL
                             WHERE id = $1"
                        )
                        .as_str(),
                        &[&id],
                    )?;
                    tx.execute("DELETE FROM checkpoints WHERE job = $1", &[&id])?;
                    continue;
                }
                Verdict::DeadLetter(error) => {
                    tx.execute(
                        format!(
                            "UPDATE jobs SET status = 'failed', finished_at = {NOW_S}, error = $2,
                                    lease_until = NULL, last_checkpoint_step = NULL
                             WHERE id = $1"
                        )
                        .as_str(),
                        &[&id, &error.to_string()],
                    )?;
                    tx.execute("DELETE FROM checkpoints WHERE job = $1", &[&id])?;
                    continue;
                }
                Verdict::Run { stalls } => i32::try_from(stalls).unwrap_or(i32::MAX),
            };
            let raw = tx.query_one(
                format!(
                    "UPDATE jobs SET status = 'running', worker_id = $2, lease_until = {NOW_S} + $3,
                            attempt = attempt + 1, started_at = COALESCE(started_at, {NOW_S}),
                            stalls = $4, claim_step = last_checkpoint_step
                     WHERE id = $1
                     RETURNING {COLS}"
                )
                .as_str(),
                &[&id, &worker, &lease_s, &stalls],
            )?;
            let raw = raw_job(&raw)?;
            tx.execute(
                format!(
                    "INSERT INTO owner_turns (owner, last_claim) VALUES ($1, {NOW_S})
                     ON CONFLICT (owner) DO UPDATE SET last_claim = excluded.last_claim"
                )
                .as_str(),
                &[&raw.owner],
            )?;
            tx.commit()?;
            return Ok(Some(raw));
        }
    }
}

impl Store for PgStore {
    /// As [`super::sqlite::SqliteStore`]'s: one transaction looks up the idempotency key
    /// and inserts; a concurrent insert with the same key (unique constraint) is answered
    /// with the job that won. Notifies the worker nodes at commit.
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
        let raw = self.run(|c| {
            let mut tx = c.transaction().map_err(classify)?;
            if let Some(key) = &job.idempotency_key {
                if let Some(existing) = select_one(
                    &mut tx,
                    "owner = $1 AND idempotency_key = $2",
                    &[&owner, key],
                )
                .map_err(classify)?
                {
                    return Ok(Some((false, existing)));
                }
            }
            // The mesh row stays locked (shared) until the job is committed: `delete_mesh`
            // locks it exclusively first, so it either waits and then sees this job, or
            // deletes first and this finds no row.
            if let Some(mesh) = &job.mesh {
                if select_mesh(&mut tx, mesh, "FOR SHARE")
                    .map_err(classify)?
                    .is_none()
                {
                    return Ok(None);
                }
            }
            let id = Uuid::new_v4();
            let inserted = tx
                .query_opt(
                    format!(
                        "INSERT INTO jobs (id, status, scene, scene_hash, idempotency_key,
                                           request_hash, created_at, steps, mesh, owner,
                                           stored_bytes, linear_path, predicted_bytes, sweep)
                         VALUES ($1, 'queued', $2, $3, $4, $5, {NOW_S}, $6, $7, $8, $9, $10,
                                 $11, $12)
                         ON CONFLICT (owner, idempotency_key) DO NOTHING
                         RETURNING {COLS}"
                    )
                    .as_str(),
                    &[
                        &id,
                        &scene,
                        &job.scene_hash,
                        &job.idempotency_key,
                        &job.request_hash,
                        &steps,
                        &job.mesh,
                        &owner,
                        &stored_bytes,
                        &linear_path,
                        &predicted_bytes,
                        &sweep,
                    ],
                )
                .map_err(classify)?;
            let result = match inserted {
                Some(row) => (true, raw_job(&row).map_err(classify)?),
                None => {
                    // Lost a race for the key: the winner's row is committed now.
                    tx.rollback().map_err(classify)?;
                    let key = job.idempotency_key.as_ref().expect("conflict needs a key");
                    let existing =
                        select_one(c, "owner = $1 AND idempotency_key = $2", &[&owner, key])
                            .map_err(classify)?
                            .ok_or_else(|| StoreError::Db("idempotency key vanished".into()))?;
                    return Ok(Some((false, existing)));
                }
            };
            tx.batch_execute(&format!("NOTIFY {CHANNEL}"))
                .map_err(classify)?;
            tx.commit().map_err(classify)?;
            Ok(Some(result))
        })?;
        let Some((new, raw)) = raw else {
            return Ok(Enqueued::NoMesh(job.mesh.clone().unwrap_or_default()));
        };
        let record = raw.into_record()?;
        Ok(if new {
            Enqueued::New(record)
        } else if record.request_hash == job.request_hash {
            Enqueued::Existing(record)
        } else {
            Enqueued::KeyConflict(record)
        })
    }

    fn sweep_members(&self, sweep: Uuid) -> Result<Vec<JobRecord>, StoreError> {
        let raws = self.read(|c| {
            c.query(
                format!("SELECT {COLS} FROM jobs WHERE sweep = $1 ORDER BY seq").as_str(),
                &[&sweep],
            )?
            .iter()
            .map(raw_job)
            .collect::<Result<Vec<_>, _>>()
        })?;
        raws.into_iter().map(RawJob::into_record).collect()
    }

    fn set_members(&self, id: Uuid, members: &[Uuid]) -> Result<(), StoreError> {
        let members = json_text(&serde_json::json!(members))?;
        self.exec(|c| {
            c.execute(
                "UPDATE jobs SET members = $2 WHERE id = $1",
                &[&id, &members],
            )
        })?;
        Ok(())
    }

    fn get(&self, id: Uuid) -> Result<Option<JobRecord>, StoreError> {
        self.read(|c| select_one(c, "id = $1", &[&id]))?
            .map(RawJob::into_record)
            .transpose()
    }

    /// Newest first by `seq`, with the SQLite store's opaque cursors.
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
        let status = status.map(JobStatus::as_str);
        let raws = self.read(|c| {
            c.query(
                format!(
                    "SELECT {COLS} FROM jobs
                     WHERE ($1::text IS NULL OR status = $1) AND seq < $2
                       AND ($4::text IS NULL OR owner = $4)
                     ORDER BY seq DESC LIMIT $3"
                )
                .as_str(),
                &[&status, &before, &fetch, &owner],
            )?
            .iter()
            .map(raw_job)
            .collect::<Result<Vec<_>, _>>()
        })?;
        into_page(raws, limit)
    }

    /// `FOR UPDATE SKIP LOCKED` on the oldest claimable row of the owner with the fewest
    /// running jobs and the oldest last claim (`owner_turns`); otherwise the rules of
    /// [`Store::claim`] (dead letter after `max_attempts` claims in a row without a new
    /// checkpoint, expired cancel-requested jobs become cancelled).
    fn claim(
        &self,
        worker: &str,
        lease_s: f64,
        max_attempts: u32,
    ) -> Result<Option<JobRecord>, StoreError> {
        check_lease(lease_s)?;
        self.exec(|c| PgStore::claim_in(c, worker, lease_s, max_attempts))?
            .map(RawJob::into_record)
            .transpose()
    }

    fn heartbeat(&self, id: Uuid, worker: &str, lease_s: f64) -> Result<bool, StoreError> {
        check_lease(lease_s)?;
        let cancel_requested: Option<bool> = self.exec(|c| {
            Ok(c.query_opt(
                format!(
                    "UPDATE jobs SET lease_until = {NOW_S} + $3
                     WHERE id = $1 AND status = 'running' AND worker_id = $2
                     RETURNING cancel_requested"
                )
                .as_str(),
                &[&id, &worker, &lease_s],
            )?
            .map(|r| r.get(0)))
        })?;
        Ok(cancel_requested == Some(false))
    }

    fn requeue(&self, id: Uuid, worker: &str) -> Result<bool, StoreError> {
        let n = self.exec(|c| {
            c.execute(
                format!(
                    "UPDATE jobs SET
                         status = CASE WHEN cancel_requested THEN 'cancelled' ELSE 'queued' END,
                         finished_at = CASE WHEN cancel_requested THEN {NOW_S}
                                            ELSE finished_at END,
                         last_checkpoint_step = CASE WHEN cancel_requested THEN NULL
                                                     ELSE last_checkpoint_step END,
                         worker_id = NULL, lease_until = NULL,
                         attempt = GREATEST(attempt - 1, 0), stalls = GREATEST(stalls - 1, 0)
                     WHERE id = $1 AND status = 'running' AND worker_id = $2"
                )
                .as_str(),
                &[&id, &worker],
            )
        })?;
        Ok(n > 0)
    }

    /// A NaN residual is stored as NULL, as in SQLite.
    fn set_progress(&self, id: Uuid, progress: Progress) -> Result<(), StoreError> {
        let step = to_i64(progress.step, "step")?;
        let steps = to_i64(progress.steps, "steps")?;
        let residual = progress.last_residual.filter(|r| !r.is_nan());
        self.exec(|c| {
            c.execute(
                "UPDATE jobs SET step = $2, steps = $3, last_residual = $4 WHERE id = $1",
                &[&id, &step, &steps, &residual],
            )
        })?;
        Ok(())
    }

    /// One statement: the job row's step and the blob change together, and only while the
    /// job is running (a late checkpoint must not resurrect a finished job's).
    fn checkpoint(&self, id: Uuid, step: usize, state: &[u8]) -> Result<(), StoreError> {
        let step = to_i64(step, "checkpoint step")?;
        self.exec(|c| {
            c.execute(
                "WITH j AS (
                     UPDATE jobs SET last_checkpoint_step = $2, step = $2
                     WHERE id = $1 AND status = 'running'
                     RETURNING id
                 )
                 INSERT INTO checkpoints (job, step, state) SELECT id, $2, $3 FROM j
                 ON CONFLICT (job) DO UPDATE SET step = excluded.step, state = excluded.state",
                &[&id, &step, &state],
            )
        })?;
        Ok(())
    }

    fn load_checkpoint(&self, id: Uuid) -> Result<Option<(usize, Vec<u8>)>, StoreError> {
        let row: Option<(i64, Vec<u8>)> = self.read(|c| {
            Ok(c.query_opt(
                "SELECT k.step, k.state FROM checkpoints k JOIN jobs j ON j.id = k.job
                 WHERE k.job = $1 AND j.last_checkpoint_step = k.step",
                &[&id],
            )?
            .map(|r| (r.get(0), r.get(1))))
        })?;
        match row {
            Some((step, blob)) => Ok(Some((to_usize(step, "checkpoint step")?, blob))),
            None => Ok(None),
        }
    }

    /// The first final status wins (a no-op for an absent or finished job), so a worker may
    /// repeat a `finish` whose outcome it did not learn.
    fn finish(
        &self,
        id: Uuid,
        status: JobStatus,
        error: Option<serde_json::Value>,
    ) -> Result<(), StoreError> {
        if !status.is_finished() {
            return Err(StoreError::Db(format!(
                "finish: {} is not a final status",
                status.as_str()
            )));
        }
        let error = error.as_ref().map(json_text).transpose()?;
        self.exec(|c| {
            let mut tx = c.transaction()?;
            let n = tx.execute(
                format!(
                    "UPDATE jobs SET status = $2, finished_at = {NOW_S}, error = $3,
                            lease_until = NULL, last_checkpoint_step = NULL
                     WHERE id = $1 AND status NOT IN {FINISHED}"
                )
                .as_str(),
                &[&id, &status.as_str(), &error],
            )?;
            if n > 0 {
                tx.execute("DELETE FROM checkpoints WHERE job = $1", &[&id])?;
            }
            tx.commit()
        })
    }

    fn request_cancel(&self, id: Uuid) -> Result<Option<JobRecord>, StoreError> {
        self.exec(|c| {
            let mut tx = c.transaction()?;
            let status: Option<String> = tx
                .query_opt("SELECT status FROM jobs WHERE id = $1 FOR UPDATE", &[&id])?
                .map(|r| r.get(0));
            match status.as_deref() {
                None => return Ok(None),
                Some("queued") => {
                    tx.execute(
                        format!(
                            "UPDATE jobs SET status = 'cancelled', cancel_requested = true,
                                    finished_at = {NOW_S}
                             WHERE id = $1"
                        )
                        .as_str(),
                        &[&id],
                    )?;
                }
                Some("running") => {
                    tx.execute(
                        "UPDATE jobs SET cancel_requested = true WHERE id = $1",
                        &[&id],
                    )?;
                }
                Some(_) => {}
            }
            let job = select_one(&mut tx, "id = $1", &[&id])?;
            tx.commit()?;
            Ok(job)
        })?
        .map(RawJob::into_record)
        .transpose()
    }

    fn delete(&self, id: Uuid) -> Result<bool, StoreError> {
        let n = self.exec(|c| {
            c.execute(
                format!("DELETE FROM jobs WHERE id = $1 AND status IN {FINISHED}").as_str(),
                &[&id],
            )
        })?;
        Ok(n > 0)
    }

    fn counts(&self) -> Result<Vec<(JobStatus, usize)>, StoreError> {
        let rows = self.read(|c| {
            Ok(
                c.query("SELECT status, COUNT(*) FROM jobs GROUP BY status", &[])?
                    .iter()
                    .map(|r| (r.get(0), r.get(1)))
                    .collect(),
            )
        })?;
        status_counts(rows)
    }

    fn find_by_idempotency_key(
        &self,
        owner: &str,
        key: &str,
    ) -> Result<Option<JobRecord>, StoreError> {
        self.read(|c| select_one(c, "owner = $1 AND idempotency_key = $2", &[&owner, &key]))?
            .map(RawJob::into_record)
            .transpose()
    }

    fn find_succeeded_for(
        &self,
        owner: &str,
        scene_hash: &str,
    ) -> Result<Option<JobRecord>, StoreError> {
        self.read(|c| {
            let sql = format!(
                "SELECT {COLS} FROM jobs
                 WHERE scene_hash = $1 AND status = 'succeeded' AND owner = $2
                 ORDER BY finished_at DESC, seq DESC LIMIT 1"
            );
            c.query_opt(sql.as_str(), &[&scene_hash, &owner])?
                .map(|r| raw_job(&r))
                .transpose()
        })?
        .map(RawJob::into_record)
        .transpose()
    }

    /// `left(worker_id, length(prefix)) = prefix` rather than LIKE: the prefix may contain `%`
    /// or `_`.
    fn release_worker_leases(&self, worker_prefix: &str) -> Result<usize, StoreError> {
        let n = self.exec(|c| {
            c.execute(
                "UPDATE jobs SET lease_until = 0
                 WHERE status = 'running' AND worker_id IS NOT NULL
                   AND left(worker_id, length($1)) = $1",
                &[&worker_prefix],
            )
        })?;
        usize::try_from(n).map_err(|_| StoreError::Db(format!("{n} rows")))
    }

    /// `ON CONFLICT DO NOTHING`, then the stored row, and the file placed, under the mesh's
    /// advisory lock ([`lock_mesh`]).
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
        let (raw, new) = self.run(|c| {
            let mut tx = c.transaction().map_err(classify)?;
            lock_mesh(&mut tx, id).map_err(classify)?;
            let inserted = tx
                .query_opt(
                    format!(
                        "INSERT INTO meshes (id, bytes, created_at, summary)
                         VALUES ($1, $2, {NOW_S}, $3)
                         ON CONFLICT (id) DO NOTHING
                         RETURNING {MESH_COLS}"
                    )
                    .as_str(),
                    &[&id, &bytes, &summary],
                )
                .map_err(classify)?;
            let got = match inserted {
                Some(row) => (raw_mesh(&row).map_err(classify)?, true),
                None => {
                    let raw = select_mesh(&mut tx, id, "").map_err(classify)?;
                    let raw = raw.ok_or_else(|| {
                        StoreError::Db(format!("mesh {id} missing right after insert"))
                    })?;
                    (raw, false)
                }
            };
            file()?;
            tx.commit().map_err(classify)?;
            Ok(got)
        })?;
        Ok((raw.into_record()?, new))
    }

    fn get_mesh(&self, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        self.read(|c| select_mesh(c, id, ""))?
            .map(RawMesh::into_record)
            .transpose()
    }

    fn list_meshes(&self, cursor: Option<&str>, limit: usize) -> Result<MeshPage, StoreError> {
        let Some((before, fetch)) = page_bounds(cursor, limit) else {
            return Ok(MeshPage {
                meshes: Vec::new(),
                next: None,
            });
        };
        let raws = self.read(|c| {
            c.query(
                format!("SELECT {MESH_COLS} FROM meshes WHERE seq < $1 ORDER BY seq DESC LIMIT $2")
                    .as_str(),
                &[&before, &fetch],
            )?
            .iter()
            .map(raw_mesh)
            .collect::<Result<Vec<_>, _>>()
        })?;
        into_mesh_page(raws, limit)
    }

    /// Takes the mesh's advisory lock ([`lock_mesh`]) and locks its row exclusively, then
    /// looks for a job that needs it (see `enqueue`).
    fn delete_mesh_with_file(
        &self,
        id: &str,
        file: MeshFileStep<'_>,
    ) -> Result<MeshDeletion, StoreError> {
        let outcome = self.run(|c| {
            let mut tx = c.transaction().map_err(classify)?;
            lock_mesh(&mut tx, id).map_err(classify)?;
            if select_mesh(&mut tx, id, "FOR UPDATE")
                .map_err(classify)?
                .is_none()
            {
                return Ok(None);
            }
            let user = select_one(
                &mut tx,
                &format!("mesh = $1 AND status IN {UNFINISHED} ORDER BY seq"),
                &[&id],
            )
            .map_err(classify)?;
            if user.is_none() {
                tx.execute("DELETE FROM meshes WHERE id = $1", &[&id])
                    .map_err(classify)?;
                tx.execute("DELETE FROM mesh_owners WHERE id = $1", &[&id])
                    .map_err(classify)?;
                file()?;
            }
            tx.commit().map_err(classify)?;
            Ok(Some(user))
        })?;
        Ok(match outcome {
            None => MeshDeletion::Absent,
            Some(None) => MeshDeletion::Deleted,
            Some(Some(raw)) => MeshDeletion::InUse(Box::new(raw.into_record()?)),
        })
    }

    /// Starts a thread with its own connection that LISTENs for submissions (see
    /// [`listen`]); it reconnects by itself after the database restarts.
    fn watch_for_work(&self, wake: Wake) -> Result<(), StoreError> {
        let config = self.config.clone();
        let tls = self.tls.clone();
        std::thread::Builder::new()
            .name("pg-listen".into())
            .spawn(move || listen(config, tls, wake))
            .map_err(StoreError::Io)?;
        Ok(())
    }
}
