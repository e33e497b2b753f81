//! [`Owners`] on the shared PostgreSQL store: keys, usage and mesh owners in the tables of
//! migration 3, so every node sees the same keys at every request.

use postgres::Row;

use super::owners::{KeyAdded, KeyRecord, Owners, Quotas, Usage, KEY_COLS};
use super::postgres::{classify, lock_mesh, raw_mesh, select_mesh, select_one, PgStore, NOW_S};
use super::row::{into_mesh_page, page_bounds, RawJob, RawMesh, UNFINISHED};
use super::{MeshDeletion, MeshFileStep, MeshPage, MeshRecord, StoreError};

/// An owner's view of a mesh: its ownership's time and sequence number.
const OWNED_MESH_COLS: &str = "m.id, m.bytes, o.created_at, m.summary, o.seq";

fn key_from_row(r: &Row) -> Result<(KeyRecord, String), postgres::Error> {
    Ok((
        KeyRecord {
            name: r.try_get(0)?,
            admin: r.try_get(1)?,
            created_at: r.try_get(2)?,
            last_used_at: r.try_get(3)?,
            revoked_at: r.try_get(4)?,
            quotas: Quotas::from_columns(r.try_get(5)?, r.try_get(6)?, r.try_get(7)?),
        },
        r.try_get(8)?,
    ))
}

impl Owners for PgStore {
    /// One upsert that only overwrites a revoked key: two nodes adding the same name cannot
    /// both succeed.
    fn add_key(
        &self,
        name: &str,
        token_hash: &str,
        admin: bool,
        quotas: Quotas,
    ) -> Result<KeyAdded, StoreError> {
        let (active, stored, compute) = quotas.columns();
        self.exec(|c| {
            let mut tx = c.transaction()?;
            let row = tx.query_opt(
                format!(
                    "INSERT INTO api_keys (name, token_hash, admin, created_at, max_active_jobs,
                                           max_stored_bytes, max_compute_s)
                     VALUES ($1, $2, $3, {NOW_S}, $4, $5, $6)
                     ON CONFLICT (name) DO UPDATE SET token_hash = $2, admin = $3,
                         created_at = {NOW_S}, last_used_at = NULL, revoked_at = NULL,
                         max_active_jobs = $4, max_stored_bytes = $5, max_compute_s = $6
                     WHERE api_keys.revoked_at IS NOT NULL
                     RETURNING {KEY_COLS}"
                )
                .as_str(),
                &[&name, &token_hash, &admin, &active, &stored, &compute],
            )?;
            // No row: the name exists and is active (the update's condition failed).
            let Some(row) = row else {
                return Ok(KeyAdded::Exists);
            };
            let (rec, _) = key_from_row(&row)?;
            tx.commit()?;
            Ok(KeyAdded::Added(rec))
        })
    }

    fn keys(&self) -> Result<Vec<KeyRecord>, StoreError> {
        self.read(|c| {
            c.query(
                format!("SELECT {KEY_COLS} FROM api_keys ORDER BY name").as_str(),
                &[],
            )?
            .iter()
            .map(|r| key_from_row(r).map(|(k, _)| k))
            .collect()
        })
    }

    fn revoke_key(&self, name: &str) -> Result<bool, StoreError> {
        let n = self.exec(|c| {
            c.execute(
                format!(
                    "UPDATE api_keys SET revoked_at = {NOW_S}
                     WHERE name = $1 AND revoked_at IS NULL"
                )
                .as_str(),
                &[&name],
            )
        })?;
        Ok(n > 0)
    }

    fn set_quotas(&self, name: &str, quotas: Quotas) -> Result<bool, StoreError> {
        let (active, stored, compute) = quotas.columns();
        let n = self.exec(|c| {
            c.execute(
                "UPDATE api_keys SET max_active_jobs = $2, max_stored_bytes = $3,
                        max_compute_s = $4
                 WHERE name = $1",
                &[&name, &active, &stored, &compute],
            )
        })?;
        Ok(n > 0)
    }

    fn key_by_hash(&self, token_hash: &str) -> Result<Option<(KeyRecord, String)>, StoreError> {
        self.read(|c| {
            c.query_opt(
                format!(
                    "SELECT {KEY_COLS} FROM api_keys WHERE token_hash = $1 AND revoked_at IS NULL"
                )
                .as_str(),
                &[&token_hash],
            )?
            .map(|r| key_from_row(&r))
            .transpose()
        })
    }

    fn touch_key(&self, name: &str, now: f64) -> Result<(), StoreError> {
        self.exec(|c| {
            c.execute(
                "UPDATE api_keys SET last_used_at = $2 WHERE name = $1",
                &[&name, &now],
            )
        })?;
        Ok(())
    }

    fn usage(&self, owner: &str, day: i64) -> Result<Usage, StoreError> {
        let (active, job_bytes, mesh_bytes, compute) = self.read(|c| {
            let row = c.query_one(
                format!(
                    "SELECT
                       (SELECT count(*) FROM jobs WHERE owner = $1 AND status IN {UNFINISHED}),
                       (SELECT COALESCE(SUM(stored_bytes), 0)::bigint FROM jobs WHERE owner = $1),
                       (SELECT COALESCE(SUM(m.bytes), 0)::bigint
                        FROM mesh_owners o JOIN meshes m ON m.id = o.id WHERE o.owner = $1),
                       (SELECT COALESCE(SUM(compute_s), 0)::float8 FROM usage
                        WHERE owner = $1 AND day = $2)"
                )
                .as_str(),
                &[&owner, &day],
            )?;
            Ok((
                row.try_get::<_, i64>(0)?,
                row.try_get::<_, i64>(1)?,
                row.try_get::<_, i64>(2)?,
                row.try_get::<_, f64>(3)?,
            ))
        })?;
        Ok(Usage {
            active_jobs: active.max(0) as u64,
            stored_bytes: job_bytes.max(0) as u64 + mesh_bytes.max(0) as u64,
            compute_s_today: compute,
        })
    }

    fn add_compute(&self, owner: &str, day: i64, seconds: f64) -> Result<(), StoreError> {
        self.exec(|c| {
            c.execute(
                "INSERT INTO usage (owner, day, compute_s) VALUES ($1, $2, $3)
                 ON CONFLICT (owner, day) DO UPDATE SET compute_s = usage.compute_s + $3",
                &[&owner, &day, &seconds],
            )
        })?;
        Ok(())
    }

    /// The mesh row is locked (shared) while the owner is added, as `enqueue` does: a
    /// concurrent release that deletes it waits, then finds the new owner.
    fn add_mesh_owner(&self, owner: &str, id: &str) -> Result<Option<bool>, StoreError> {
        self.exec(|c| {
            let mut tx = c.transaction()?;
            if select_mesh(&mut tx, id, "FOR SHARE")?.is_none() {
                return Ok(None);
            }
            let n = tx.execute(
                format!(
                    "INSERT INTO mesh_owners (owner, id, created_at) VALUES ($1, $2, {NOW_S})
                     ON CONFLICT (owner, id) DO NOTHING"
                )
                .as_str(),
                &[&owner, &id],
            )?;
            tx.commit()?;
            Ok(Some(n > 0))
        })
    }

    fn owned_mesh(&self, owner: &str, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        self.read(|c| {
            c.query_opt(
                format!(
                    "SELECT {OWNED_MESH_COLS} FROM mesh_owners o JOIN meshes m ON m.id = o.id
                     WHERE o.owner = $1 AND o.id = $2"
                )
                .as_str(),
                &[&owner, &id],
            )?
            .map(|r| raw_mesh(&r))
            .transpose()
        })?
        .map(RawMesh::into_record)
        .transpose()
    }

    fn list_owned_meshes(
        &self,
        owner: &str,
        cursor: Option<&str>,
        limit: usize,
    ) -> Result<MeshPage, StoreError> {
        let Some((before, fetch)) = page_bounds(cursor, limit) else {
            return Ok(MeshPage {
                meshes: Vec::new(),
                next: None,
            });
        };
        let raws = self.read(|c| {
            c.query(
                format!(
                    "SELECT {OWNED_MESH_COLS} FROM mesh_owners o JOIN meshes m ON m.id = o.id
                     WHERE o.owner = $1 AND o.seq < $2 ORDER BY o.seq DESC LIMIT $3"
                )
                .as_str(),
                &[&owner, &before, &fetch],
            )?
            .iter()
            .map(raw_mesh)
            .collect::<Result<Vec<_>, _>>()
        })?;
        into_mesh_page(raws, limit)
    }

    /// Takes the mesh's advisory lock and locks its row exclusively first (as
    /// `delete_mesh`), so that an upload, an `enqueue` or an `add_mesh_owner` of the same
    /// mesh either waits or has committed.
    fn release_mesh_with_file(
        &self,
        owner: &str,
        id: &str,
        file: MeshFileStep<'_>,
    ) -> Result<(MeshDeletion, bool), StoreError> {
        let outcome = self.run(|c| {
            let mut tx = c.transaction().map_err(classify)?;
            lock_mesh(&mut tx, id).map_err(classify)?;
            let decided = released(&mut tx, owner, id).map_err(classify)?;
            if let Some((None, true)) = decided {
                file()?;
            }
            if matches!(decided, Some((None, _))) {
                tx.commit().map_err(classify)?;
            }
            // Otherwise dropping the transaction rolls it back.
            Ok(decided)
        })?;
        Ok(match outcome {
            None => (MeshDeletion::Absent, false),
            Some((Some(raw), _)) => (MeshDeletion::InUse(Box::new(raw.into_record()?)), false),
            Some((None, orphan)) => (MeshDeletion::Deleted, orphan),
        })
    }
}

/// The release of [`Owners::release_mesh`] inside `tx` (not committed): None if `owner` does
/// not have the mesh, `Some((Some(job), _))` if one of `owner`'s unfinished jobs uses it
/// (roll back), `Some((None, orphan))` if released (`orphan`: the mesh record went too).
fn released(
    tx: &mut postgres::Transaction<'_>,
    owner: &str,
    id: &str,
) -> Result<Option<(Option<RawJob>, bool)>, postgres::Error> {
    if select_mesh(tx, id, "FOR UPDATE")?.is_none() {
        return Ok(None);
    }
    let n = tx.execute(
        "DELETE FROM mesh_owners WHERE owner = $1 AND id = $2",
        &[&owner, &id],
    )?;
    if n == 0 {
        return Ok(None);
    }
    let user = select_one(
        tx,
        &format!("owner = $1 AND mesh = $2 AND status IN {UNFINISHED} ORDER BY seq"),
        &[&owner, &id],
    )?;
    if user.is_some() {
        return Ok(Some((user, false)));
    }
    let left: i64 = tx
        .query_one(
            format!(
                "SELECT (SELECT count(*) FROM mesh_owners WHERE id = $1)
                      + (SELECT count(*) FROM jobs WHERE mesh = $1
                         AND status IN {UNFINISHED})"
            )
            .as_str(),
            &[&id],
        )?
        .try_get(0)?;
    let orphan = left == 0;
    if orphan {
        tx.execute("DELETE FROM meshes WHERE id = $1", &[&id])?;
    }
    Ok(Some((None, orphan)))
}
