//! Free space of the data directory, and the floor below which a node takes no new work
//! (`--min-free-disk`): `POST /jobs` and `POST /meshes` answer 507, workers claim nothing,
//! `/healthz` is degraded. A job that finds the disk full while writing anyway (ENOSPC,
//! EDQUOT) is put back in the queue (see `crate::jobs`).

use std::io;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use axum::http::StatusCode;

use crate::problem::Problem;

/// The least free space of the data directory for the node to take work: bytes, or a
/// percentage of the file system's size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MinFreeDisk {
    Bytes(u64),
    Percent(f64),
}

impl Default for MinFreeDisk {
    /// 1 GiB.
    fn default() -> Self {
        MinFreeDisk::Bytes(1 << 30)
    }
}

impl FromStr for MinFreeDisk {
    type Err = String;

    /// `1073741824`, `512MiB`, `2GB`, `1G` (binary multiples for K, M, G, T with or without
    /// `iB`; decimal for `kB`, `MB`, `GB`, `TB`), or `5%`; `0` turns the check off.
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.trim();
        let bad = || {
            format!("{s:?}: give bytes (e.g. 1073741824, 512MiB, 2GB) or a percentage of the disk (e.g. 5%)")
        };
        if let Some(p) = s.strip_suffix('%') {
            let p: f64 = p.trim().parse().map_err(|_| bad())?;
            if !(0.0..=100.0).contains(&p) {
                return Err(format!("{s:?}: a percentage must be between 0 and 100"));
            }
            return Ok(MinFreeDisk::Percent(p));
        }
        let split = s
            .find(|c: char| !c.is_ascii_digit() && c != '.')
            .unwrap_or(s.len());
        let (number, unit) = s.split_at(split);
        let number: f64 = number.parse().map_err(|_| bad())?;
        let factor: f64 = match unit.trim() {
            "" | "B" => 1.0,
            "K" | "KiB" | "k" => 1024.0,
            "M" | "MiB" => 1024f64.powi(2),
            "G" | "GiB" => 1024f64.powi(3),
            "T" | "TiB" => 1024f64.powi(4),
            "kB" | "KB" => 1e3,
            "MB" => 1e6,
            "GB" => 1e9,
            "TB" => 1e12,
            _ => return Err(bad()),
        };
        let bytes = number * factor;
        if !bytes.is_finite() || bytes >= u64::MAX as f64 {
            return Err(bad());
        }
        Ok(MinFreeDisk::Bytes(bytes as u64))
    }
}

impl std::fmt::Display for MinFreeDisk {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MinFreeDisk::Bytes(b) => write!(f, "{b} bytes"),
            MinFreeDisk::Percent(p) => write!(f, "{p}%"),
        }
    }
}

impl MinFreeDisk {
    /// The floor in bytes on a file system of `total` bytes.
    pub fn bytes(self, total: u64) -> u64 {
        match self {
            MinFreeDisk::Bytes(b) => b,
            MinFreeDisk::Percent(p) => (total as f64 * p / 100.0).ceil() as u64,
        }
    }
}

/// Free and total bytes of a file system (free: what an unprivileged writer may use).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Space {
    pub free: u64,
    pub total: u64,
}

/// The space of the file system that holds `path`.
pub fn space(path: &Path) -> io::Result<Space> {
    let s = rustix::fs::statvfs(path)?;
    Ok(Space {
        free: s.f_bavail.saturating_mul(s.f_frsize),
        total: s.f_blocks.saturating_mul(s.f_frsize),
    })
}

/// Whether a write failed because the disk (ENOSPC) or the user's quota (EDQUOT) is full.
pub fn is_full(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::StorageFull | io::ErrorKind::QuotaExceeded
    )
}

/// How long a measurement is reused: requests and idle workers ask often.
const FRESH: Duration = Duration::from_millis(500);

/// Retry-After of a 507: space comes back when an operator acts, not in a second.
pub const RETRY_AFTER_S: u32 = 30;

/// How long the node takes no work after a write found the disk full although the free
/// space was above the floor (the floor is too low for the jobs running): without the
/// pause a worker would claim the requeued job again at once and fill the disk again.
pub const FULL_PAUSE: Duration = Duration::from_secs(5);

/// The data directory's space against the node's floor, measured at most every [`FRESH`].
pub struct DiskGuard {
    dir: PathBuf,
    min: MinFreeDisk,
    last: Mutex<Option<(Instant, Result<Space, String>)>>,
    /// Until when the node pauses after a write found the disk full ([`FULL_PAUSE`]).
    paused_until: Mutex<Option<Instant>>,
}

/// Why the node takes no work now.
#[derive(Debug, Clone, PartialEq)]
pub enum Low {
    /// Below the floor.
    Full { space: Space, min: u64 },
    /// A write found the disk full a moment ago (see [`FULL_PAUSE`]).
    JustFull,
    /// The file system cannot be asked.
    Unknown(String),
}

impl Low {
    /// The sentence `/healthz` and the 507 give.
    pub fn reason(&self) -> String {
        match self {
            Low::Full { space, min } => format!(
                "the data directory's disk has {} bytes free, below the --min-free-disk floor of {min} bytes; free space (delete finished jobs with DELETE /jobs/{{id}}) or grow the disk",
                space.free
            ),
            Low::Unknown(e) => format!("the free space of the data directory cannot be read: {e}"),
            Low::JustFull => format!(
                "a write found the data directory's disk full less than {} s ago (raise --min-free-disk above what running jobs write); free space or grow the disk",
                FULL_PAUSE.as_secs()
            ),
        }
    }

    /// 507 Insufficient Storage with Retry-After.
    pub fn problem(&self) -> Problem {
        Problem::new(
            StatusCode::INSUFFICIENT_STORAGE,
            "insufficient storage",
            format!("{}; retry later", self.reason()),
        )
        .with_type("/problems/insufficient-storage")
        .retry_after(RETRY_AFTER_S)
    }
}

impl DiskGuard {
    pub fn new(dir: PathBuf, min: MinFreeDisk) -> DiskGuard {
        DiskGuard {
            dir,
            min,
            last: Mutex::new(None),
            paused_until: Mutex::new(None),
        }
    }

    /// The current space (cached for [`FRESH`]).
    pub fn space(&self) -> Result<Space, String> {
        let mut last = self.last.lock().unwrap();
        if let Some((at, s)) = &*last {
            if at.elapsed() < FRESH {
                return s.clone();
            }
        }
        let s = space(&self.dir).map_err(|e| format!("{}: {e}", self.dir.display()));
        *last = Some((Instant::now(), s.clone()));
        s
    }

    /// The floor in bytes, if the file system can be asked.
    pub fn min_bytes(&self) -> Option<u64> {
        self.space().ok().map(|s| self.min.bytes(s.total))
    }

    /// Ok while the data directory has at least the floor free (always with a floor of 0).
    pub fn check(&self) -> Result<(), Low> {
        if self
            .paused_until
            .lock()
            .unwrap()
            .is_some_and(|t| Instant::now() < t)
        {
            return Err(Low::JustFull);
        }
        if self.min == MinFreeDisk::Bytes(0) || self.min == MinFreeDisk::Percent(0.0) {
            return Ok(());
        }
        match self.space() {
            Ok(space) => {
                let min = self.min.bytes(space.total);
                if space.free < min {
                    Err(Low::Full { space, min })
                } else {
                    Ok(())
                }
            }
            Err(e) => Err(Low::Unknown(e)),
        }
    }

    /// A write found the disk full: measure afresh, and take no work for [`FULL_PAUSE`].
    pub fn note_full(&self) {
        *self.last.lock().unwrap() = None;
        *self.paused_until.lock().unwrap() = Some(Instant::now() + FULL_PAUSE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floors_parse_as_bytes_or_percentages() {
        for (s, want) in [
            ("1073741824", MinFreeDisk::Bytes(1 << 30)),
            ("1GiB", MinFreeDisk::Bytes(1 << 30)),
            ("1G", MinFreeDisk::Bytes(1 << 30)),
            ("512MiB", MinFreeDisk::Bytes(512 << 20)),
            ("2GB", MinFreeDisk::Bytes(2_000_000_000)),
            ("0", MinFreeDisk::Bytes(0)),
            ("5%", MinFreeDisk::Percent(5.0)),
            ("0.5 %", MinFreeDisk::Percent(0.5)),
        ] {
            assert_eq!(s.parse::<MinFreeDisk>(), Ok(want), "{s}");
        }
        for s in ["", "-1", "1XB", "150%", "-3%", "x%", "1e400"] {
            assert!(s.parse::<MinFreeDisk>().is_err(), "{s}");
        }
        assert_eq!(MinFreeDisk::Percent(10.0).bytes(1001), 101);
        assert_eq!(MinFreeDisk::default(), MinFreeDisk::Bytes(1 << 30));
    }

    #[test]
    fn the_guard_compares_free_space_with_the_floor() {
        let dir = std::env::temp_dir();
        let s = space(&dir).unwrap();
        assert!(s.total > 0 && s.free <= s.total);
        assert_eq!(
            DiskGuard::new(dir.clone(), MinFreeDisk::Bytes(0)).check(),
            Ok(())
        );
        assert_eq!(
            DiskGuard::new(dir.clone(), MinFreeDisk::Bytes(1)).check(),
            Ok(())
        );
        let low = DiskGuard::new(dir.clone(), MinFreeDisk::Bytes(s.total + 1))
            .check()
            .unwrap_err();
        assert!(matches!(low, Low::Full { .. }), "{low:?}");
        let p = low.problem();
        assert_eq!(p.status, 507);
        assert_eq!(p.retry_after, Some(RETRY_AFTER_S));
        let missing = DiskGuard::new(dir.join("no/such/dir"), MinFreeDisk::Bytes(1)).check();
        assert!(matches!(missing, Err(Low::Unknown(_))));
    }

    #[test]
    fn enospc_and_edquot_are_a_full_disk() {
        assert!(is_full(&io::Error::from_raw_os_error(28)));
        assert!(is_full(&io::Error::from_raw_os_error(
            rustix::io::Errno::DQUOT.raw_os_error()
        )));
        assert!(!is_full(&io::Error::from_raw_os_error(13)));
        assert!(!is_full(&io::Error::other("x")));
    }
}
