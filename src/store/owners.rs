//! Who owns what, in the job store: API keys (stored only as the SHA-256 of the token),
//! their quotas and measured use, and the owners of uploaded meshes. Both backends
//! implement [`Owners`] ([`super::sqlite`] in `sqlite/owners.rs`, PostgreSQL in
//! `pg_owners.rs`), so that every node sees the same keys: a key revoked through one node's
//! database is refused by all of them at their next request.
//!
//! An owner is a key's name. Jobs and mesh records of the anonymous mode (authentication
//! off) have the empty owner `""`, which no key can have.

use super::{MeshDeletion, MeshPage, MeshRecord, StoreError};

/// Per-key limits; None is unlimited.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Quotas {
    /// Queued plus running jobs at once.
    pub active_jobs: Option<u64>,
    /// Bytes stored for the owner: the estimated results of its jobs (the estimate the
    /// per-job limit uses) plus the meshes it uploaded.
    pub stored_bytes: Option<u64>,
    /// Worker-seconds per UTC day, as measured by the workers that ran the owner's jobs.
    pub compute_s_per_day: Option<f64>,
}

impl Quotas {
    /// From the store's columns max_active_jobs, max_stored_bytes, max_compute_s (NULL is
    /// unlimited; a negative count, which no writer stores, reads as 0).
    pub(super) fn from_columns(
        active: Option<i64>,
        stored: Option<i64>,
        compute: Option<f64>,
    ) -> Quotas {
        let count = |v: Option<i64>| v.map(|x| x.max(0) as u64);
        Quotas {
            active_jobs: count(active),
            stored_bytes: count(stored),
            compute_s_per_day: compute,
        }
    }

    /// The values of those columns (counts beyond i64 saturate).
    pub(super) fn columns(&self) -> (Option<i64>, Option<i64>, Option<f64>) {
        let count = |v: Option<u64>| v.map(|x| i64::try_from(x).unwrap_or(i64::MAX));
        (
            count(self.active_jobs),
            count(self.stored_bytes),
            self.compute_s_per_day,
        )
    }
}

/// Columns of a [`KeyRecord`] in both stores, in the order their `key_from_row` reads them,
/// then the token hash.
pub(super) const KEY_COLS: &str = "name, admin, created_at, last_used_at, revoked_at, \
     max_active_jobs, max_stored_bytes, max_compute_s, token_hash";

/// An API key as stored (never its token).
#[derive(Debug, Clone, PartialEq)]
pub struct KeyRecord {
    pub name: String,
    pub admin: bool,
    /// Unix times in seconds.
    pub created_at: f64,
    /// Refreshed at most once a minute (see [`Owners::touch_key`]).
    pub last_used_at: Option<f64>,
    pub revoked_at: Option<f64>,
    pub quotas: Quotas,
}

/// What an owner uses now, measured against its [`Quotas`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Usage {
    pub active_jobs: u64,
    pub stored_bytes: u64,
    pub compute_s_today: f64,
}

/// Outcome of [`Owners::add_key`].
#[derive(Debug, Clone, PartialEq)]
pub enum KeyAdded {
    Added(KeyRecord),
    /// A key of that name is active: revoke it first.
    Exists,
}

/// The UTC day number of a Unix time (days since 1970-01-01), the unit compute is counted in.
pub fn day_of(unix: f64) -> i64 {
    (unix / 86_400.0).floor() as i64
}

pub trait Owners {
    /// Stores a key by the hash of its token. A revoked key's name may be given a new key
    /// (its jobs and meshes stay its owner's: rotation); an active one may not.
    fn add_key(
        &self,
        name: &str,
        token_hash: &str,
        admin: bool,
        quotas: Quotas,
    ) -> Result<KeyAdded, StoreError>;
    /// Every key, revoked ones included, by name.
    fn keys(&self) -> Result<Vec<KeyRecord>, StoreError>;
    /// False if there is no active key of that name.
    fn revoke_key(&self, name: &str) -> Result<bool, StoreError>;
    /// Replaces a key's quotas; false if there is no such key.
    fn set_quotas(&self, name: &str, quotas: Quotas) -> Result<bool, StoreError>;
    /// The active key whose token hashes to `token_hash`, with the stored hash (the caller
    /// compares the two in constant time).
    fn key_by_hash(&self, token_hash: &str) -> Result<Option<(KeyRecord, String)>, StoreError>;
    /// Records a use of the key at `now`.
    fn touch_key(&self, name: &str, now: f64) -> Result<(), StoreError>;
    /// `owner`'s use: unfinished jobs, stored bytes, and compute on UTC day `day`.
    fn usage(&self, owner: &str, day: i64) -> Result<Usage, StoreError>;
    /// Adds worker-seconds to `owner`'s compute of UTC day `day`.
    fn add_compute(&self, owner: &str, day: i64, seconds: f64) -> Result<(), StoreError>;
    /// Makes the stored mesh `id` also `owner`'s. Some(true) if it was not yet, Some(false)
    /// if it was, None if there is no such mesh (deleted meanwhile: upload it again).
    fn add_mesh_owner(&self, owner: &str, id: &str) -> Result<Option<bool>, StoreError>;
    /// The mesh as `owner` sees it (`created_at`: when it became theirs), None unless it
    /// is theirs.
    fn owned_mesh(&self, owner: &str, id: &str) -> Result<Option<MeshRecord>, StoreError>;
    /// `owner`'s meshes, newest first, paged like [`super::Store::list_meshes`].
    fn list_owned_meshes(
        &self,
        owner: &str,
        cursor: Option<&str>,
        limit: usize,
    ) -> Result<MeshPage, StoreError>;
    /// Ends `owner`'s ownership of mesh `id`, unless one of `owner`'s queued or running
    /// jobs uses it. When no owner is left and no unfinished job uses it, the mesh record
    /// goes too and the second value is true: its file is the caller's to remove.
    fn release_mesh(&self, owner: &str, id: &str) -> Result<(MeshDeletion, bool), StoreError> {
        self.release_mesh_with_file(owner, id, &mut || Ok(()))
    }
    /// [`Owners::release_mesh`] that takes the file away with `file` inside the transaction
    /// when the mesh record goes (see [`super::MeshFileStep`]).
    fn release_mesh_with_file(
        &self,
        owner: &str,
        id: &str,
        file: super::MeshFileStep<'_>,
    ) -> Result<(MeshDeletion, bool), StoreError>;
}
