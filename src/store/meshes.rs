//! The files of uploaded meshes, `<data_dir>/meshes/<id>.msh`, stored like results
//! ([`super::results`]): written atomically (temporary file, fsync, rename, fsync of the
//! directory), temporary files hidden and cleaned at start. A mesh's id is the lowercase hex
//! SHA-256 of its bytes, so the name is its checksum: every read is verified against it, and a
//! file that does not match (a disk or a copy gone wrong) is reported, never parsed.
//!
//! File names are formatted only from ids checked by [`is_mesh_id`] (64 lowercase hex
//! digits): no separators, nothing that could address a path outside the directory.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::results::{remove_temp_files, sync_dir, write_atomic_in, STALE_TEMP, TEMP_PREFIX};

/// Whether `s` is a mesh id: 64 lowercase hexadecimal digits (a SHA-256).
pub fn is_mesh_id(s: &str) -> bool {
    s.len() == 64 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// The id of a mesh file: the lowercase hex SHA-256 of its bytes.
pub fn mesh_id(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn invalid_id(id: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("invalid mesh id {id:?}"),
    )
}

/// The uploaded mesh files, rooted at `<data_dir>/meshes`.
#[derive(Debug, Clone)]
pub struct MeshBlobs {
    root: PathBuf,
}

impl MeshBlobs {
    /// Creates `<data_dir>/meshes` if needed and removes the temporary files an interrupted
    /// write left there.
    pub fn new(data_dir: &Path) -> io::Result<MeshBlobs> {
        MeshBlobs::open(data_dir, std::time::Duration::ZERO)
    }

    /// As [`MeshBlobs::new`] for a directory shared by several nodes: only temporary files
    /// older than an hour are removed (another node may be writing right now).
    pub fn shared(data_dir: &Path) -> io::Result<MeshBlobs> {
        MeshBlobs::open(data_dir, STALE_TEMP)
    }

    fn open(data_dir: &Path, min_temp_age: std::time::Duration) -> io::Result<MeshBlobs> {
        let root = data_dir.join("meshes");
        if !root.is_dir() {
            fs::create_dir_all(&root)?;
            sync_dir(data_dir)?;
        }
        remove_temp_files(&root, min_temp_age)?;
        Ok(MeshBlobs { root })
    }

    /// `<data_dir>/meshes`.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The path of mesh `id`'s file (whether or not it exists); None for an invalid id.
    pub fn path(&self, id: &str) -> Option<PathBuf> {
        is_mesh_id(id).then(|| self.root.join(format!("{id}.msh")))
    }

    /// Writes the file of mesh `id`, atomically replacing any previous one. `bytes` must be
    /// the mesh whose SHA-256 is `id` ([`io::ErrorKind::InvalidInput`] otherwise).
    pub fn write(&self, id: &str, bytes: &[u8]) -> io::Result<()> {
        if !is_mesh_id(id) || mesh_id(bytes) != id {
            return Err(invalid_id(id));
        }
        write_atomic_in(&self.root, &format!("{id}.msh"), bytes)
    }

    /// Whether the file of mesh `id` exists (not verified; see [`MeshBlobs::read`]).
    pub fn exists(&self, id: &str) -> bool {
        self.path(id).is_some_and(|p| p.is_file())
    }

    /// The bytes of mesh `id`, checked against the id; None if there is no such file (or the
    /// id is invalid). A file whose SHA-256 is not its id is [`io::ErrorKind::InvalidData`].
    pub fn read(&self, id: &str) -> io::Result<Option<Vec<u8>>> {
        let Some(path) = self.path(id) else {
            return Ok(None);
        };
        let bytes = match fs::read(path) {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e),
        };
        if mesh_id(&bytes) != id {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!(
                    "the stored file of mesh {id} does not match its checksum (it is damaged); upload the .msh again"
                ),
            ));
        }
        Ok(Some(bytes))
    }

    /// Writes `bytes`, the mesh whose SHA-256 is `id`, to a temporary file (fsynced) for
    /// [`Staged::place`] to rename into place: the slow part of a write, done before the
    /// store's transaction (see `Store::add_mesh_with_file`), the rename inside it.
    pub fn stage(&self, id: &str, bytes: &[u8]) -> io::Result<Staged> {
        if !is_mesh_id(id) || mesh_id(bytes) != id {
            return Err(invalid_id(id));
        }
        let temp = self.temp_path(id, "upload");
        let written = (|| {
            let mut f = fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&temp)?;
            f.write_all(bytes)?;
            f.sync_all()
        })();
        if let Err(e) = written {
            let _ = fs::remove_file(&temp);
            return Err(e);
        }
        Ok(Staged {
            temp,
            target: self.root.join(format!("{id}.msh")),
            root: self.root.clone(),
        })
    }

    /// A temporary name in the directory for mesh `id` (removed at start, as every
    /// temporary file; see [`MeshBlobs::shared`]).
    fn temp_path(&self, id: &str, what: &str) -> PathBuf {
        self.root.join(format!(
            "{TEMP_PREFIX}{id}.msh-{what}-{}",
            uuid::Uuid::new_v4().simple()
        ))
    }

    /// Moves the file of mesh `id` out of the way (the first step of a deletion, inside the
    /// store's transaction): Some(its new name), for [`Buried::finish`] to remove once the
    /// record's deletion committed or to restore if it did not; None if there is no file.
    pub fn bury(&self, id: &str) -> io::Result<Option<Buried>> {
        let path = self.path(id).ok_or_else(|| invalid_id(id))?;
        let tomb = self.temp_path(id, "deleted");
        match fs::rename(&path, &tomb) {
            Ok(()) => Ok(Some(Buried {
                tomb,
                path,
                root: self.root.clone(),
            })),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Removes the file of mesh `id`; Ok if it does not exist.
    pub fn remove(&self, id: &str) -> io::Result<()> {
        let path = self.path(id).ok_or_else(|| invalid_id(id))?;
        match fs::remove_file(path) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
            _ => sync_dir(&self.root),
        }
    }
}

/// A mesh file written under a temporary name ([`MeshBlobs::stage`]); removed on drop
/// unless placed.
#[derive(Debug)]
pub struct Staged {
    temp: PathBuf,
    target: PathBuf,
    root: PathBuf,
}

impl Staged {
    /// Renames the file into place (atomically replacing a file of the same id, whose
    /// bytes are the same) and fsyncs the directory. Again after a first success, it puts
    /// nothing more in place.
    pub fn place(&self) -> io::Result<()> {
        match fs::rename(&self.temp, &self.target) {
            Err(e) if e.kind() == io::ErrorKind::NotFound && self.target.is_file() => {}
            other => other?,
        }
        sync_dir(&self.root)
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        let _ = fs::remove_file(&self.temp);
    }
}

/// A mesh file moved out of the way by [`MeshBlobs::bury`].
#[derive(Debug)]
pub struct Buried {
    tomb: PathBuf,
    path: PathBuf,
    root: PathBuf,
}

impl Buried {
    /// Removes the file if `deleted` (the record's deletion committed), else puts it back
    /// under its name.
    pub fn finish(self, deleted: bool) -> io::Result<()> {
        if deleted {
            fs::remove_file(&self.tomb)?;
        } else {
            fs::rename(&self.tomb, &self.path)?;
        }
        sync_dir(&self.root)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct TempDir(PathBuf);

    impl TempDir {
        fn new() -> TempDir {
            let p =
                std::env::temp_dir().join(format!("contact-sim-meshes-{}", uuid::Uuid::new_v4()));
            fs::create_dir_all(&p).unwrap();
            TempDir(p)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn ids_are_lowercase_sha256_hex() {
        let id = mesh_id(b"abc");
        assert_eq!(
            id,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert!(is_mesh_id(&id));
        for bad in [
            "",
            &id[..63],
            &id.to_uppercase(),
            &format!("{id}0"),
            "../../../../etc/passwd",
            &format!("{}/", &id[..63]),
            &format!("{}g", &id[..63]),
        ] {
            assert!(!is_mesh_id(bad), "{bad:?}");
        }
    }

    #[test]
    fn write_read_verify_remove() {
        let dir = TempDir::new();
        let blobs = MeshBlobs::new(&dir.0).unwrap();
        let bytes = b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";
        let id = mesh_id(bytes);
        assert_eq!(blobs.read(&id).unwrap(), None);
        assert!(!blobs.exists(&id));
        blobs.write(&id, bytes).unwrap();
        assert!(blobs.exists(&id));
        assert_eq!(blobs.read(&id).unwrap().unwrap(), bytes);
        assert_eq!(
            blobs.path(&id).unwrap(),
            dir.0.join("meshes").join(format!("{id}.msh"))
        );
        // Bytes that are not the id's are refused, whatever the name.
        let other = mesh_id(b"other");
        assert_eq!(
            blobs.write(&other, bytes).unwrap_err().kind(),
            io::ErrorKind::InvalidInput
        );
        assert_eq!(
            blobs.write("../x", bytes).unwrap_err().kind(),
            io::ErrorKind::InvalidInput
        );
        assert_eq!(blobs.read("../x").unwrap(), None);
        // A damaged file is reported, not served.
        fs::write(blobs.path(&id).unwrap(), b"$MeshFormat\n4.1 0 8\n").unwrap();
        assert_eq!(
            blobs.read(&id).unwrap_err().kind(),
            io::ErrorKind::InvalidData
        );
        blobs.remove(&id).unwrap();
        blobs.remove(&id).unwrap();
        assert_eq!(blobs.read(&id).unwrap(), None);
        assert_eq!(fs::read_dir(blobs.root()).unwrap().count(), 0);
    }

    /// The steps of a change made inside a store transaction: staged, placed; buried, then
    /// restored or removed; a staged file never placed leaves nothing.
    #[test]
    fn stage_place_bury_restore_remove() {
        let dir = TempDir::new();
        let blobs = MeshBlobs::new(&dir.0).unwrap();
        let bytes = b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";
        let id = mesh_id(bytes);
        let names = || {
            let mut n: Vec<String> = fs::read_dir(blobs.root())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        };
        assert_eq!(
            blobs.stage(&mesh_id(b"x"), bytes).unwrap_err().kind(),
            io::ErrorKind::InvalidInput
        );
        drop(blobs.stage(&id, bytes).unwrap());
        assert!(names().is_empty());
        let staged = blobs.stage(&id, bytes).unwrap();
        assert!(!blobs.exists(&id));
        assert!(names()[0].starts_with(TEMP_PREFIX));
        staged.place().unwrap();
        staged.place().unwrap();
        drop(staged);
        assert_eq!(names(), vec![format!("{id}.msh")]);
        let buried = blobs.bury(&id).unwrap().unwrap();
        assert!(!blobs.exists(&id));
        assert!(blobs.bury(&id).unwrap().is_none());
        buried.finish(false).unwrap();
        assert_eq!(blobs.read(&id).unwrap().unwrap(), bytes);
        blobs.bury(&id).unwrap().unwrap().finish(true).unwrap();
        assert!(names().is_empty());
    }

    #[test]
    fn temporary_files_are_cleaned_at_start() {
        let dir = TempDir::new();
        let blobs = MeshBlobs::new(&dir.0).unwrap();
        let stale = blobs.root().join(".tmp-x.msh-1");
        fs::write(&stale, b"partial").unwrap();
        // Another node's write in flight survives a shared start, not a single node's.
        MeshBlobs::shared(&dir.0).unwrap();
        assert!(stale.exists());
        MeshBlobs::new(&dir.0).unwrap();
        assert!(!stale.exists());
    }
}
