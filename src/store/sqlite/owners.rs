//! [`Owners`] on the embedded store: keys, usage and mesh owners in the tables of
//! migration 4.

use rusqlite::{params, OptionalExtension, Row, TransactionBehavior};

use super::{select_mesh, SqliteStore};
use crate::store::owners::{KeyAdded, KeyRecord, Owners, Quotas, Usage, KEY_COLS};
use crate::store::row::{into_mesh_page, page_bounds, RawMesh, UNFINISHED};
use crate::store::{now, MeshDeletion, MeshFileStep, MeshPage, MeshRecord, StoreError};

fn key_from_row(r: &Row<'_>) -> rusqlite::Result<(KeyRecord, String)> {
    Ok((
        KeyRecord {
            name: r.get(0)?,
            admin: r.get::<_, i64>(1)? != 0,
            created_at: r.get(2)?,
            last_used_at: r.get(3)?,
            revoked_at: r.get(4)?,
            quotas: Quotas::from_columns(r.get(5)?, r.get(6)?, r.get(7)?),
        },
        r.get(8)?,
    ))
}

impl Owners for SqliteStore {
    fn add_key(
        &self,
        name: &str,
        token_hash: &str,
        admin: bool,
        quotas: Quotas,
    ) -> Result<KeyAdded, StoreError> {
        let (active, stored, compute) = quotas.columns();
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        let revoked: Option<Option<f64>> = tx
            .query_row(
                "SELECT revoked_at FROM api_keys WHERE name = ?1",
                params![name],
                |r| r.get(0),
            )
            .optional()?;
        if let Some(None) = revoked {
            return Ok(KeyAdded::Exists);
        }
        tx.execute(
            "INSERT INTO api_keys (name, token_hash, admin, created_at, max_active_jobs,
                                   max_stored_bytes, max_compute_s)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)
             ON CONFLICT (name) DO UPDATE SET token_hash = ?2, admin = ?3, created_at = ?4,
                 last_used_at = NULL, revoked_at = NULL, max_active_jobs = ?5,
                 max_stored_bytes = ?6, max_compute_s = ?7",
            params![name, token_hash, admin, now(), active, stored, compute],
        )?;
        let (rec, _) = tx.query_row(
            &format!("SELECT {KEY_COLS} FROM api_keys WHERE name = ?1"),
            params![name],
            key_from_row,
        )?;
        tx.commit()?;
        Ok(KeyAdded::Added(rec))
    }

    fn keys(&self) -> Result<Vec<KeyRecord>, StoreError> {
        let conn = self.lock();
        let mut stmt = conn.prepare(&format!("SELECT {KEY_COLS} FROM api_keys ORDER BY name"))?;
        let rows = stmt.query_map([], key_from_row)?;
        Ok(rows
            .map(|r| r.map(|(k, _)| k))
            .collect::<rusqlite::Result<_>>()?)
    }

    fn revoke_key(&self, name: &str) -> Result<bool, StoreError> {
        let n = self.lock().execute(
            "UPDATE api_keys SET revoked_at = ?2 WHERE name = ?1 AND revoked_at IS NULL",
            params![name, now()],
        )?;
        Ok(n > 0)
    }

    fn set_quotas(&self, name: &str, quotas: Quotas) -> Result<bool, StoreError> {
        let (active, stored, compute) = quotas.columns();
        let n = self.lock().execute(
            "UPDATE api_keys SET max_active_jobs = ?2, max_stored_bytes = ?3, max_compute_s = ?4
             WHERE name = ?1",
            params![name, active, stored, compute],
        )?;
        Ok(n > 0)
    }

    fn key_by_hash(&self, token_hash: &str) -> Result<Option<(KeyRecord, String)>, StoreError> {
        Ok(self
            .lock()
            .query_row(
                &format!(
                    "SELECT {KEY_COLS} FROM api_keys WHERE token_hash = ?1 AND revoked_at IS NULL"
                ),
                params![token_hash],
                key_from_row,
            )
            .optional()?)
    }

    fn touch_key(&self, name: &str, now: f64) -> Result<(), StoreError> {
        self.lock().execute(
            "UPDATE api_keys SET last_used_at = ?2 WHERE name = ?1",
            params![name, now],
        )?;
        Ok(())
    }

    fn usage(&self, owner: &str, day: i64) -> Result<Usage, StoreError> {
        let conn = self.lock();
        let (active, job_bytes): (i64, i64) = conn.query_row(
            &format!(
                "SELECT COALESCE(SUM(status IN {UNFINISHED}), 0), COALESCE(SUM(stored_bytes), 0)
                 FROM jobs WHERE owner = ?1"
            ),
            params![owner],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )?;
        let mesh_bytes: i64 = conn.query_row(
            "SELECT COALESCE(SUM(m.bytes), 0) FROM mesh_owners o JOIN meshes m ON m.id = o.id
             WHERE o.owner = ?1",
            params![owner],
            |r| r.get(0),
        )?;
        let compute: f64 = conn
            .query_row(
                "SELECT compute_s FROM usage WHERE owner = ?1 AND day = ?2",
                params![owner, day],
                |r| r.get(0),
            )
            .optional()?
            .unwrap_or(0.0);
        Ok(Usage {
            active_jobs: active.max(0) as u64,
            stored_bytes: job_bytes.max(0) as u64 + mesh_bytes.max(0) as u64,
            compute_s_today: compute,
        })
    }

    fn add_compute(&self, owner: &str, day: i64, seconds: f64) -> Result<(), StoreError> {
        self.lock().execute(
            "INSERT INTO usage (owner, day, compute_s) VALUES (?1, ?2, ?3)
             ON CONFLICT (owner, day) DO UPDATE SET compute_s = compute_s + ?3",
            params![owner, day, seconds],
        )?;
        Ok(())
    }

    fn add_mesh_owner(&self, owner: &str, id: &str) -> Result<Option<bool>, StoreError> {
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        if select_mesh(&tx, id)?.is_none() {
            return Ok(None);
        }
        let n = tx.execute(
            "INSERT INTO mesh_owners (owner, id, created_at) VALUES (?1, ?2, ?3)
             ON CONFLICT (owner, id) DO NOTHING",
            params![owner, id, now()],
        )?;
        tx.commit()?;
        Ok(Some(n > 0))
    }

    fn owned_mesh(&self, owner: &str, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        let conn = self.lock();
        let raw = conn
            .query_row(
                "SELECT m.id, m.bytes, o.created_at, m.summary, o.seq
                 FROM mesh_owners o JOIN meshes m ON m.id = o.id
                 WHERE o.owner = ?1 AND o.id = ?2",
                params![owner, id],
                RawMesh::from_row,
            )
            .optional()?;
        raw.map(RawMesh::into_record).transpose()
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
        let conn = self.lock();
        let mut stmt = conn.prepare_cached(
            "SELECT m.id, m.bytes, o.created_at, m.summary, o.seq
             FROM mesh_owners o JOIN meshes m ON m.id = o.id
             WHERE o.owner = ?1 AND o.seq < ?2 ORDER BY o.seq DESC LIMIT ?3",
        )?;
        let raws: Vec<RawMesh> = stmt
            .query_map(params![owner, before, fetch], RawMesh::from_row)?
            .collect::<rusqlite::Result<_>>()?;
        drop(stmt);
        drop(conn);
        into_mesh_page(raws, limit)
    }

    fn release_mesh_with_file(
        &self,
        owner: &str,
        id: &str,
        file: MeshFileStep<'_>,
    ) -> Result<(MeshDeletion, bool), StoreError> {
        let mut conn = self.lock();
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        let owned: Option<i64> = tx
            .query_row(
                "SELECT seq FROM mesh_owners WHERE owner = ?1 AND id = ?2",
                params![owner, id],
                |r| r.get(0),
            )
            .optional()?;
        if owned.is_none() {
            return Ok((MeshDeletion::Absent, false));
        }
        let user = super::select_one(
            &tx,
            &format!("owner = ?1 AND mesh = ?2 AND status IN {UNFINISHED} ORDER BY seq"),
            params![owner, id],
        )?;
        if let Some(job) = user {
            return Ok((MeshDeletion::InUse(Box::new(job)), false));
        }
        tx.execute(
            "DELETE FROM mesh_owners WHERE owner = ?1 AND id = ?2",
            params![owner, id],
        )?;
        let others: i64 = tx.query_row(
            "SELECT COUNT(*) FROM mesh_owners WHERE id = ?1",
            params![id],
            |r| r.get(0),
        )?;
        let used: i64 = tx.query_row(
            &format!("SELECT COUNT(*) FROM jobs WHERE mesh = ?1 AND status IN {UNFINISHED}"),
            params![id],
            |r| r.get(0),
        )?;
        let orphan = others == 0 && used == 0;
        if orphan {
            tx.execute("DELETE FROM meshes WHERE id = ?1", params![id])?;
            file()?;
        }
        tx.commit()?;
        Ok((MeshDeletion::Deleted, orphan))
    }
}
