//! Result files of jobs (summary, stored steps, …) under `<data_dir>/results/<uuid>/`.
//!
//! * **Atomic replacement.** [`ResultFiles::write_atomic`] writes a temporary file in the
//!   same directory, fsyncs it, renames it over the target and fsyncs the directory. A
//!   reader therefore sees either the old or the new complete file, never a partial one,
//!   and after a crash the target holds the old or the new content. Left-over temporary
//!   files (crash between create and rename) start with [`TEMP_PREFIX`], are never listed
//!   or readable through this API, and are removed by [`ResultFiles::new`] (at start) and
//!   [`ResultFiles::remove_job`].
//! * **Path safety.** A job directory name is always formatted from a [`Uuid`] (hyphenated
//!   lowercase), never taken from a string, and file names must match
//!   `^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$` without `..`: no separators, no leading dot, no
//!   NUL, nothing that could address a path outside the results directory.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use uuid::Uuid;

/// Prefix of temporary files; such names are invalid result names (leading dot).
pub const TEMP_PREFIX: &str = ".tmp-";

/// Longest accepted result file name.
pub const MAX_NAME_LEN: usize = 64;

/// Whether `name` is an acceptable result file name: 1 to 64 bytes, first
/// `[A-Za-z0-9_]`, then `[A-Za-z0-9_.-]`, and no `..` anywhere.
pub fn valid_name(name: &str) -> bool {
    let b = name.as_bytes();
    let Some((&first, rest)) = b.split_first() else {
        return false;
    };
    b.len() <= MAX_NAME_LEN
        && (first.is_ascii_alphanumeric() || first == b'_')
        && rest
            .iter()
            .all(|&c| c.is_ascii_alphanumeric() || matches!(c, b'_' | b'.' | b'-'))
        && !name.contains("..")
}

fn invalid_name(name: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("invalid result file name {name:?}"),
    )
}

/// Makes a directory's entries (creations, renames) durable. On platforms where a
/// directory cannot be opened for syncing this is a no-op.
pub(super) fn sync_dir(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        File::open(dir)?.sync_all()
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

/// Writes `bytes` as `dir/name` atomically: a temporary file ([`TEMP_PREFIX`]) in `dir`,
/// fsynced, renamed over the target, then the directory fsynced. `name` is trusted (the
/// callers check it).
pub(super) fn write_atomic_in(dir: &Path, name: &str, bytes: &[u8]) -> io::Result<()> {
    let target = dir.join(name);
    let temp = dir.join(format!("{TEMP_PREFIX}{name}-{}", Uuid::new_v4().simple()));
    let written = (|| {
        let mut f = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&temp, &target)
    })();
    if let Err(e) = written {
        let _ = fs::remove_file(&temp);
        return Err(e);
    }
    sync_dir(dir)
}

/// Age beyond which a temporary file in a shared result directory is certainly abandoned
/// (a write takes from its creation to its rename milliseconds, seconds at worst).
pub(super) const STALE_TEMP: std::time::Duration = std::time::Duration::from_secs(3600);

/// Removes the temporary files at least `min_age` old left in one job directory.
pub(super) fn remove_temp_files(dir: &Path, min_age: std::time::Duration) -> io::Result<()> {
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    for entry in entries {
        let entry = entry?;
        let is_temp = entry
            .file_name()
            .to_str()
            .is_some_and(|n| n.starts_with(TEMP_PREFIX));
        let old_enough = || -> io::Result<bool> {
            if min_age.is_zero() {
                return Ok(true);
            }
            let modified = entry.metadata()?.modified()?;
            Ok(modified.elapsed().is_ok_and(|age| age >= min_age))
        };
        if is_temp && entry.file_type()?.is_file() && old_enough()? {
            match fs::remove_file(entry.path()) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
    }
    Ok(())
}

/// The result files of all jobs, rooted at `<data_dir>/results`.
#[derive(Debug, Clone)]
pub struct ResultFiles {
    root: PathBuf,
}

impl ResultFiles {
    /// Creates `<data_dir>/results` if needed and removes temporary files left by an
    /// interrupted write in any job directory (only directories named like a UUID are
    /// looked at; anything else in `results/` is left alone).
    pub fn new(data_dir: &Path) -> io::Result<ResultFiles> {
        ResultFiles::open(data_dir, std::time::Duration::ZERO)
    }

    /// As [`ResultFiles::new`] for a directory shared by several nodes (e.g. over NFS):
    /// another node may be writing right now, so only temporary files older than an hour
    /// are removed.
    pub fn shared(data_dir: &Path) -> io::Result<ResultFiles> {
        ResultFiles::open(data_dir, STALE_TEMP)
    }

    fn open(data_dir: &Path, min_temp_age: std::time::Duration) -> io::Result<ResultFiles> {
        let root = data_dir.join("results");
        fs::create_dir_all(&root)?;
        for entry in fs::read_dir(&root)? {
            let entry = entry?;
            let is_job_dir = entry
                .file_name()
                .to_str()
                .and_then(|n| Uuid::try_parse(n).ok().filter(|u| u.to_string() == n))
                .is_some();
            if is_job_dir && entry.file_type()?.is_dir() {
                remove_temp_files(&entry.path(), min_temp_age)?;
            }
        }
        Ok(ResultFiles { root })
    }

    /// `<data_dir>/results`.
    pub fn root(&self) -> &Path {
        &self.root
    }

    fn job_dir(&self, id: Uuid) -> PathBuf {
        self.root.join(id.hyphenated().to_string())
    }

    /// The path of result `name` of job `id` (whether or not it exists), None for an
    /// invalid name.
    pub fn path(&self, id: Uuid, name: &str) -> Option<PathBuf> {
        valid_name(name).then(|| self.job_dir(id).join(name))
    }

    /// Writes `bytes` as result `name` of job `id`, atomically replacing any previous
    /// content (see the module documentation). Creates the job directory if needed.
    /// An invalid name is [`io::ErrorKind::InvalidInput`].
    pub fn write_atomic(&self, id: Uuid, name: &str, bytes: &[u8]) -> io::Result<()> {
        if !valid_name(name) {
            return Err(invalid_name(name));
        }
        let dir = self.job_dir(id);
        if !dir.is_dir() {
            fs::create_dir_all(&dir)?;
            // Make the new directory's entry in `results/` durable too.
            sync_dir(&self.root)?;
        }
        write_atomic_in(&dir, name, bytes)
    }

    /// The content of result `name` of job `id`; None if it does not exist or the name is
    /// invalid.
    pub fn read(&self, id: Uuid, name: &str) -> io::Result<Option<Vec<u8>>> {
        let Some(path) = self.path(id, name) else {
            return Ok(None);
        };
        match fs::read(path) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Names of the job's result files, sorted; empty if the job has none. Temporary files
    /// and anything that is not a regular file with a valid name are skipped.
    pub fn list(&self, id: Uuid) -> io::Result<Vec<String>> {
        let entries = match fs::read_dir(self.job_dir(id)) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(e),
        };
        let mut names = Vec::new();
        for entry in entries {
            let entry = entry?;
            let Ok(name) = entry.file_name().into_string() else {
                continue;
            };
            if valid_name(&name) && entry.file_type()?.is_file() {
                names.push(name);
            }
        }
        names.sort();
        Ok(names)
    }

    /// Removes the job's directory with everything in it (temporary files included); Ok
    /// if it does not exist.
    pub fn remove_job(&self, id: Uuid) -> io::Result<()> {
        match fs::remove_dir_all(self.job_dir(id)) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    /// Removes the job's files for which `remove(name)` is true, and its temporary files;
    /// then the directory if nothing is left in it. Ok if it does not exist.
    pub fn remove_where(&self, id: Uuid, remove: impl Fn(&str) -> bool) -> io::Result<()> {
        let dir = self.job_dir(id);
        let entries = match fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(e),
        };
        for entry in entries {
            let entry = entry?;
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if entry.file_type()?.is_file() && (name.starts_with(TEMP_PREFIX) || remove(&name)) {
                match fs::remove_file(entry.path()) {
                    Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
                    _ => {}
                }
            }
        }
        match fs::remove_dir(&dir) {
            // Not empty: files were kept.
            Err(e) if e.kind() == io::ErrorKind::NotFound || dir.read_dir()?.next().is_some() => {
                Ok(())
            }
            other => other,
        }
    }

    /// Total size in bytes of the regular files in the job's directory (temporary files
    /// included: they occupy disk too); 0 if it does not exist.
    pub fn bytes_used(&self, id: Uuid) -> io::Result<u64> {
        let entries = match fs::read_dir(self.job_dir(id)) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
            Err(e) => return Err(e),
        };
        let mut total = 0u64;
        for entry in entries {
            let meta = entry?.metadata()?;
            if meta.is_file() {
                total = total.saturating_add(meta.len());
            }
        }
        Ok(total)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A directory under the system temp dir, removed on drop.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new() -> TempDir {
            let p = std::env::temp_dir().join(format!("contact-sim-results-{}", Uuid::new_v4()));
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
    fn write_read_list_remove() {
        let dir = TempDir::new();
        let files = ResultFiles::new(&dir.0).unwrap();
        let id = Uuid::new_v4();
        assert_eq!(files.list(id).unwrap(), Vec::<String>::new());
        assert_eq!(files.bytes_used(id).unwrap(), 0);
        assert_eq!(files.read(id, "summary.json").unwrap(), None);
        files.write_atomic(id, "summary.json", b"{}").unwrap();
        files
            .write_atomic(id, "step-000001.bin", &[1, 2, 3])
            .unwrap();
        files.write_atomic(id, "a_b-c.d", b"").unwrap();
        assert_eq!(
            files.list(id).unwrap(),
            vec!["a_b-c.d", "step-000001.bin", "summary.json"]
        );
        assert_eq!(files.read(id, "summary.json").unwrap().unwrap(), b"{}");
        assert_eq!(files.read(id, "a_b-c.d").unwrap().unwrap(), b"");
        assert_eq!(files.bytes_used(id).unwrap(), 5);
        let p = files.path(id, "summary.json").unwrap();
        assert_eq!(
            p,
            dir.0
                .join("results")
                .join(id.to_string())
                .join("summary.json")
        );
        assert!(p.is_file());
        // Another job is unaffected.
        assert!(files.list(Uuid::new_v4()).unwrap().is_empty());
        files.remove_job(id).unwrap();
        assert!(files.list(id).unwrap().is_empty());
        assert!(!dir.0.join("results").join(id.to_string()).exists());
        files.remove_job(id).unwrap();
    }

    #[test]
    fn hostile_names_are_rejected() {
        let dir = TempDir::new();
        let files = ResultFiles::new(&dir.0).unwrap();
        let id = Uuid::new_v4();
        let long = "a".repeat(MAX_NAME_LEN + 1);
        let hostile = [
            "../x",
            "..",
            ".",
            "a/b",
            "/etc/passwd",
            "a\\b",
            "C:x",
            "",
            ".hidden",
            ".tmp-summary.json",
            "x\0y",
            "a..b",
            "-rf",
            "é",
            "a b",
            "a\nb",
            long.as_str(),
        ];
        for name in hostile {
            let err = files.write_atomic(id, name, b"x").unwrap_err();
            assert_eq!(err.kind(), io::ErrorKind::InvalidInput, "{name:?}");
            assert_eq!(files.read(id, name).unwrap(), None, "{name:?}");
            assert_eq!(files.path(id, name), None, "{name:?}");
        }
        // Nothing was created anywhere.
        assert!(!dir.0.join("results").join(id.to_string()).exists());
        assert_eq!(fs::read_dir(&dir.0).unwrap().count(), 1);
        // The longest valid name works.
        let max = "b".repeat(MAX_NAME_LEN);
        files.write_atomic(id, &max, b"ok").unwrap();
        assert_eq!(files.list(id).unwrap(), vec![max]);
    }

    #[test]
    fn a_shared_directory_keeps_other_nodes_fresh_temp_files() {
        let d = TempDir::new();
        let files = ResultFiles::new(&d.0).unwrap();
        let id = Uuid::new_v4();
        files.write_atomic(id, "a.bin", b"a").unwrap();
        let dir = d.0.join("results").join(id.to_string());
        // Another node's write in flight, and one abandoned two hours ago.
        let fresh = dir.join(format!("{TEMP_PREFIX}b.bin-1"));
        let stale = dir.join(format!("{TEMP_PREFIX}c.bin-2"));
        fs::write(&fresh, b"partial").unwrap();
        fs::write(&stale, b"partial").unwrap();
        let old = std::time::SystemTime::now() - std::time::Duration::from_secs(7200);
        File::options()
            .write(true)
            .open(&stale)
            .unwrap()
            .set_modified(old)
            .unwrap();
        ResultFiles::shared(&d.0).unwrap();
        assert!(
            fresh.exists(),
            "a starting node removed another node's write in flight"
        );
        assert!(!stale.exists(), "an abandoned temporary file was kept");
        // A single node's own directory: every temporary file is its own, left by a crash.
        ResultFiles::new(&d.0).unwrap();
        assert!(!fresh.exists());
        assert_eq!(files.read(id, "a.bin").unwrap().unwrap(), b"a");
    }

    #[test]
    fn overwrite_is_whole_and_temp_files_are_hidden_and_cleaned() {
        let dir = TempDir::new();
        let files = ResultFiles::new(&dir.0).unwrap();
        let id = Uuid::new_v4();
        files
            .write_atomic(id, "out.bin", &vec![1u8; 100_000])
            .unwrap();
        files.write_atomic(id, "out.bin", b"short").unwrap();
        assert_eq!(files.read(id, "out.bin").unwrap().unwrap(), b"short");
        files
            .write_atomic(id, "out.bin", &vec![2u8; 50_000])
            .unwrap();
        assert_eq!(
            files.read(id, "out.bin").unwrap().unwrap(),
            vec![2u8; 50_000]
        );
        assert_eq!(files.list(id).unwrap(), vec!["out.bin"]);

        // A crash between create and rename leaves a temp file: hidden, then cleaned.
        let job_dir = dir.0.join("results").join(id.to_string());
        let stale = job_dir.join(format!("{TEMP_PREFIX}out.bin-deadbeef"));
        fs::write(&stale, b"partial").unwrap();
        // A foreign directory in results/ is left alone by the cleanup.
        let foreign = dir.0.join("results").join("not-a-job");
        fs::create_dir_all(&foreign).unwrap();
        fs::write(foreign.join(format!("{TEMP_PREFIX}keep")), b"k").unwrap();
        assert_eq!(files.list(id).unwrap(), vec!["out.bin"]);
        assert_eq!(files.bytes_used(id).unwrap(), 50_000 + 7);
        let files = ResultFiles::new(&dir.0).unwrap();
        assert!(!stale.exists());
        assert!(foreign.join(format!("{TEMP_PREFIX}keep")).exists());
        assert_eq!(
            files.read(id, "out.bin").unwrap().unwrap(),
            vec![2u8; 50_000]
        );
        assert_eq!(fs::read_dir(&job_dir).unwrap().count(), 1);
    }

    #[test]
    fn concurrent_reader_never_sees_partial_file() {
        let dir = TempDir::new();
        let files = ResultFiles::new(&dir.0).unwrap();
        let id = Uuid::new_v4();
        let a = vec![b'a'; 300_000];
        let b = vec![b'b'; 200_000];
        files.write_atomic(id, "x", &a).unwrap();
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let reader = {
            let files = files.clone();
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut reads = 0;
                while !stop.load(std::sync::atomic::Ordering::Relaxed) || reads == 0 {
                    let got = files.read(id, "x").unwrap().unwrap();
                    let ok = (got.len() == 300_000 && got.iter().all(|&c| c == b'a'))
                        || (got.len() == 200_000 && got.iter().all(|&c| c == b'b'));
                    assert!(ok, "partial read of {} bytes", got.len());
                    reads += 1;
                }
                reads
            })
        };
        for i in 0..20 {
            files
                .write_atomic(id, "x", if i % 2 == 0 { &b } else { &a })
                .unwrap();
        }
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        assert!(reader.join().unwrap() > 0);
        assert_eq!(files.list(id).unwrap(), vec!["x"]);
    }
}
