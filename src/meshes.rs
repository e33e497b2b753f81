//! Uploaded meshes: what `POST /meshes` stores (the file in [`MeshBlobs`], a row with its
//! summary in the job store) and how the service resolves a scene's `domain.mesh`
//! ([`Meshes`] is the service's [`MeshFiles`]).
//!
//! A scene names an uploaded mesh by its id, the lowercase hex SHA-256 of the file, so the
//! scene's content hash covers the mesh's bytes: identical requests are answered from the
//! store, and a different file (a different id) never is. Besides ids, only the names of
//! the meshes bundled with the presets are known (`plate-with-hole.msh`); anything else — a
//! path in particular — is refused.
//!
//! Parsed meshes are kept in a small LRU cache by id (parsing is deterministic and the id
//! fixes the bytes), shared by the submissions, the workers and the result routes of one
//! node. The cache is only consulted once the store says the mesh exists, so a mesh deleted
//! through another node is not found here either.
//!
//! Everything here blocks (store, files, parsing): call it from worker threads or the
//! blocking pool, never on the async runtime's threads.

use crate::auth::Caller;
use crate::problem::Problem;
use crate::store::meshes::{is_mesh_id, mesh_id, MeshBlobs};
use crate::store::{MeshDeletion, MeshRecord, Store, StoreError};
use axum::http::StatusCode;
use contact_core::mesh::import::{import_any, summarize};
use contact_core::mesh::AnyMesh;
use contact_core::scene::{presets, Bundled, MeshFiles};
use serde_json::Value;
use std::sync::{Arc, Mutex};

/// Parsed meshes kept in memory per node.
const CACHED: usize = 4;
/// Uploads parsed at once per node.
const PARSES: usize = 2;

/// The uploaded-mesh id a job document uses: `domain.mesh` of a scene, or of a study's
/// scene object, when it has the form of an id (bundled names are not uploads).
pub fn mesh_ref(doc: &Value) -> Option<String> {
    let scene = match doc.get("study").or_else(|| doc.get("sweep")) {
        Some(study) => study.get("scene")?,
        None => doc,
    };
    scene
        .get("domain")?
        .get("mesh")?
        .as_str()
        .filter(|s| is_mesh_id(s))
        .map(str::to_string)
}

/// Refuses a job document whose uploaded mesh is not the caller's (422 at `domain.mesh`,
/// the answer for a mesh that does not exist), before anything reads it. Blocking.
pub fn check_owner(doc: &Value, store: &dyn Store, caller: &Caller) -> Result<(), Problem> {
    let Some(id) = mesh_ref(doc) else {
        return Ok(());
    };
    if caller.sees_all() || store.owned_mesh(caller.owner(), &id)?.is_some() {
        return Ok(());
    }
    let pointer = if doc.get("study").is_some() {
        "/study/scene/domain/mesh"
    } else if doc.get("sweep").is_some() {
        "/sweep/scene/domain/mesh"
    } else {
        "/domain/mesh"
    };
    Err(Problem::invalid_field(pointer, unknown_mesh(&id)))
}

/// What a mesh lookup says when the store cannot be read: a submission that meets it is
/// answered 503 (retry), not 422 (the scene is not at fault).
pub const STORE_UNREADABLE: &str = "the job store cannot be read";

/// The 503 of a validation that could not read the store, if that is why it failed.
pub fn store_outage(errors: &contact_core::scene::ValidationErrors) -> Option<Problem> {
    errors.to_string().contains(STORE_UNREADABLE).then(|| {
        Problem::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "job store unavailable",
            format!("{errors}; retry shortly"),
        )
        .retry_after(2)
    })
}

/// The sentence for a `domain.mesh` the service does not know.
pub fn unknown_mesh(name: &str) -> String {
    if is_mesh_id(name) {
        format!("no uploaded mesh with id {name}; upload the .msh with POST /meshes")
    } else {
        format!(
            "no uploaded mesh with id {name:?}; upload the .msh with POST /meshes and give the id it answers (64 hex digits; file paths are not read by the service)"
        )
    }
}

/// The uploaded meshes of one node: store rows, files, and the parsed-mesh cache.
pub struct Meshes {
    store: Arc<dyn Store>,
    blobs: MeshBlobs,
    /// Most recently used last.
    cache: Mutex<Vec<(String, Arc<AnyMesh>)>>,
    /// Uploads parsed at the same time (each holds its file and its mesh in memory); the
    /// handler waits for a slot before handing an upload to the blocking pool.
    pub parse_slots: tokio::sync::Semaphore,
}

impl Meshes {
    pub fn new(store: Arc<dyn Store>, blobs: MeshBlobs) -> Meshes {
        Meshes {
            store,
            blobs,
            cache: Mutex::new(Vec::new()),
            parse_slots: tokio::sync::Semaphore::new(PARSES),
        }
    }

    /// Stores an uploaded file: its id, and whether it is new (a repeated upload of the same
    /// bytes is answered with the first upload's record, without parsing it again).
    ///
    /// A file that is not a usable mesh is a 422 whose detail is the reader's or the
    /// checker's message (section and line, or the offending cell). The file is written
    /// under a temporary name first, then renamed into place inside the store's transaction
    /// that records it (`Store::add_mesh_with_file`), which a deletion of the same mesh on
    /// any node cannot interleave with: a record never names a missing file, and a file is
    /// never left without its record (but by a crash between the rename and the commit:
    /// an unlisted file, put back to use by the next upload of the same bytes).
    pub fn upload(&self, bytes: &[u8]) -> Result<(MeshRecord, bool), Problem> {
        if bytes.is_empty() {
            return Err(Problem::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid mesh",
                "the body is empty: send the bytes of a gmsh .msh file (MSH 4.1 or 2.2, ASCII or binary)",
            )
            .with_type("/problems/invalid-mesh"));
        }
        let id = mesh_id(bytes);
        let io = |e: std::io::Error| Problem::internal(format!("mesh file {id}: {e}"));
        let summary = match self.store.get_mesh(&id)? {
            // Stored and whole: nothing to do.
            Some(existing) if matches!(self.blobs.read(&id), Ok(Some(_))) => {
                return Ok((existing, false))
            }
            // Stored, but the file was lost or damaged (a disk gone wrong): the bytes are at
            // hand to repair it, in the same transaction as a new upload.
            Some(existing) => existing.summary,
            None => {
                let summary = summarize(bytes).map_err(|e| {
                    Problem::new(
                        StatusCode::UNPROCESSABLE_ENTITY,
                        "invalid mesh",
                        e.to_string(),
                    )
                    .with_type("/problems/invalid-mesh")
                })?;
                serde_json::to_value(&summary).map_err(|e| Problem::internal(e.to_string()))?
            }
        };
        let staged = self.blobs.stage(&id, bytes).map_err(io)?;
        Ok(self
            .store
            .add_mesh_with_file(&id, bytes.len() as u64, &summary, &mut || staged.place())?)
    }

    /// [`Meshes::upload`] for `owner` (`""`: anonymous): the mesh becomes theirs too. The
    /// record is the owner's view and `new` says whether it is new to them.
    pub fn upload_for(&self, owner: &str, bytes: &[u8]) -> Result<(MeshRecord, bool), Problem> {
        // Released by its last owner between the upload and the ownership: upload again.
        for _ in 0..3 {
            let (rec, new) = self.upload(bytes)?;
            match self.store.add_mesh_owner(owner, &rec.id)? {
                None => continue,
                Some(_) if owner.is_empty() => return Ok((rec, new)),
                Some(new_to_owner) => {
                    let view = self.store.owned_mesh(owner, &rec.id)?.unwrap_or(rec);
                    return Ok((view, new_to_owner));
                }
            }
        }
        Err(Problem::internal(
            "the mesh was deleted while being uploaded, three times in a row",
        ))
    }

    /// Ends `owner`'s ownership of mesh `id` (see `Owners::release_mesh`); the file and the
    /// cached copy go when nobody else has the mesh.
    pub fn release(&self, owner: &str, id: &str) -> Result<MeshDeletion, Problem> {
        if !is_mesh_id(id) {
            return Ok(MeshDeletion::Absent);
        }
        let mut buried = None;
        let released = self.store.release_mesh_with_file(owner, id, &mut || {
            buried = self.blobs.bury(id)?;
            Ok(())
        });
        let deleted = matches!(released, Ok((MeshDeletion::Deleted, true)));
        self.settle(id, buried, deleted)?;
        Ok(released?.0)
    }

    /// After a record's deletion: the file moved aside by [`MeshBlobs::bury`] goes if the
    /// deletion committed and comes back if it did not; the cached copy goes with it.
    fn settle(
        &self,
        id: &str,
        buried: Option<crate::store::meshes::Buried>,
        deleted: bool,
    ) -> Result<(), Problem> {
        if let Some(b) = buried {
            b.finish(deleted)
                .map_err(|e| Problem::internal(format!("mesh file {id}: {e}")))?;
        }
        if deleted {
            self.cache.lock().unwrap().retain(|(k, _)| k != id);
        }
        Ok(())
    }

    pub fn get(&self, id: &str) -> Result<Option<MeshRecord>, StoreError> {
        if !is_mesh_id(id) {
            return Ok(None);
        }
        self.store.get_mesh(id)
    }

    /// The file of a stored mesh (checked against its id), None if there is no such mesh.
    pub fn file(&self, id: &str) -> Result<Option<Vec<u8>>, Problem> {
        if self.get(id)?.is_none() {
            return Ok(None);
        }
        match self.blobs.read(id) {
            Ok(Some(b)) => Ok(Some(b)),
            // Deleted between the two reads: the mesh is gone, not broken.
            Ok(None) if self.get(id)?.is_none() => Ok(None),
            Ok(None) => Err(missing_file(id)),
            Err(e) => Err(Problem::internal(e.to_string())),
        }
    }

    /// Deletes a mesh unless a queued or running job uses it: the record and the file in
    /// one store transaction (`Store::delete_mesh_with_file`), then this node's cached copy.
    pub fn delete(&self, id: &str) -> Result<MeshDeletion, Problem> {
        if !is_mesh_id(id) {
            return Ok(MeshDeletion::Absent);
        }
        let mut buried = None;
        let outcome = self.store.delete_mesh_with_file(id, &mut || {
            buried = self.blobs.bury(id)?;
            Ok(())
        });
        self.settle(
            id,
            buried,
            outcome.as_ref().is_ok_and(|o| *o == MeshDeletion::Deleted),
        )?;
        Ok(outcome?)
    }

    /// The checked 2D mesh of an uploaded id or a bundled name, cached.
    fn load_cached(&self, name: &str) -> Result<Arc<AnyMesh>, String> {
        let uploaded = is_mesh_id(name);
        if uploaded {
            match self.store.get_mesh(name) {
                Ok(Some(_)) => {}
                Ok(None) => return Err(unknown_mesh(name)),
                Err(e) => return Err(format!("mesh {name}: {STORE_UNREADABLE}: {e}")),
            }
        } else if presets::bundled_mesh(name).is_none() {
            return Err(unknown_mesh(name));
        }
        {
            let mut cache = self.cache.lock().unwrap();
            if let Some(i) = cache.iter().position(|(k, _)| k == name) {
                let hit = cache.remove(i);
                let mesh = hit.1.clone();
                cache.push(hit);
                return Ok(mesh);
            }
        }
        let mesh = if uploaded {
            let bytes = match self.blobs.read(name) {
                Ok(Some(b)) => b,
                Ok(None) => return Err(missing_file(name).detail),
                Err(e) => return Err(e.to_string()),
            };
            // 3D meshes are stored, but scenes are 2D: the importer says so.
            import_any(&bytes).map_err(|e| format!("mesh {name}: {e}"))?
        } else {
            Bundled.load(name)?
        };
        let mesh = Arc::new(mesh);
        let mut cache = self.cache.lock().unwrap();
        cache.retain(|(k, _)| k != name);
        if cache.len() >= CACHED {
            cache.remove(0);
        }
        cache.push((name.to_string(), mesh.clone()));
        Ok(mesh)
    }
}

fn missing_file(id: &str) -> Problem {
    Problem::conflict(format!(
        "the file of mesh {id} is missing from the data directory; upload the .msh again with POST /meshes"
    ))
}

impl MeshFiles for Meshes {
    /// An uploaded mesh by id, or a mesh bundled with the presets by name; anything else is
    /// refused with [`unknown_mesh`]'s sentence.
    fn load(&self, name: &str) -> Result<AnyMesh, String> {
        self.load_cached(name).map(|m| (*m).clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn mesh_references_of_scenes_and_studies() {
        let id = "a".repeat(64);
        assert_eq!(mesh_ref(&json!({"domain": {"mesh": id}})), Some(id.clone()));
        assert_eq!(
            mesh_ref(&json!({"study": {"scene": {"domain": {"mesh": id}}}})),
            Some(id.clone())
        );
        for doc in [
            json!({"domain": {"mesh": "plate-with-hole.msh"}}),
            json!({"domain": {"width": 1, "height": 1}}),
            json!({"domain": {"mesh": id.to_uppercase()}}),
            json!({"study": {"scene": "paper-convergence"}}),
            json!({"domain": {"mesh": 3}}),
            json!([]),
        ] {
            assert_eq!(mesh_ref(&doc), None, "{doc}");
        }
    }

    #[test]
    fn unknown_names_point_to_the_upload() {
        let m = unknown_mesh("../../etc/passwd");
        assert!(
            m.starts_with("no uploaded mesh with id \"../../etc/passwd\""),
            "{m}"
        );
        assert!(m.contains("POST /meshes"), "{m}");
        let id = "0".repeat(64);
        assert_eq!(
            unknown_mesh(&id),
            format!("no uploaded mesh with id {id}; upload the .msh with POST /meshes")
        );
    }

    #[test]
    fn loads_uploads_and_bundled_meshes_and_nothing_else() {
        let dir =
            std::env::temp_dir().join(format!("contact-sim-meshlib-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let store: Arc<dyn Store> =
            Arc::new(crate::store::sqlite::SqliteStore::open_in_memory().unwrap());
        let meshes = Meshes::new(store, MeshBlobs::new(&dir).unwrap());
        let bytes = presets::bundled_mesh("plate-with-hole.msh").unwrap();
        let bundled = meshes.load("plate-with-hole.msh").unwrap();
        let (rec, new) = meshes.upload(bytes).unwrap();
        assert!(new);
        assert_eq!(rec.id, mesh_id(bytes));
        assert_eq!(rec.summary["nodes"], bundled.n_nodes());
        let (again, new) = meshes.upload(bytes).unwrap();
        assert!(!new);
        assert_eq!(again, rec);
        let uploaded = meshes.load(&rec.id).unwrap();
        assert_eq!(uploaded.get::<2>().nodes, bundled.get::<2>().nodes);
        // Served from the cache the second time, the same mesh.
        assert_eq!(
            meshes.load(&rec.id).unwrap().get::<2>().nodes,
            bundled.get::<2>().nodes
        );
        let e = meshes.load("/etc/passwd").unwrap_err();
        assert!(e.starts_with("no uploaded mesh with id"), "{e}");
        let e = meshes
            .upload(b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n")
            .unwrap_err();
        assert_eq!(e.status, 422);
        assert!(e.detail.contains("2.2"), "{}", e.detail);
        assert_eq!(meshes.upload(b"").unwrap_err().status, 422);
        assert_eq!(meshes.delete(&rec.id).unwrap(), MeshDeletion::Deleted);
        let e = meshes.load(&rec.id).unwrap_err();
        assert_eq!(e, unknown_mesh(&rec.id));
        assert_eq!(meshes.delete(&rec.id).unwrap(), MeshDeletion::Absent);
        std::fs::remove_dir_all(&dir).ok();
    }
}
