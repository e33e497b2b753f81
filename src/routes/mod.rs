//! HTTP handlers, one file per resource family.

pub mod auth;
pub mod client;
pub mod jobs;
pub mod meshes;
pub mod misc;
pub mod query;
pub mod results;

use super::problem::Problem;
use super::store::JobRecord;
use uuid::Uuid;

/// Parses a job id from the path; malformed ids are unknown jobs (404).
pub fn parse_id(s: &str) -> Result<Uuid, Problem> {
    Uuid::parse_str(s).map_err(|_| Problem::not_found(format!("no job with id {s:?}")))
}

/// Fetches a job record on the blocking pool; 404 when absent.
pub async fn load_job(state: &crate::state::AppState, id: Uuid) -> Result<JobRecord, Problem> {
    let store = state.store().clone();
    tokio::task::spawn_blocking(move || store.get(id))
        .await
        .map_err(|e| Problem::internal(e.to_string()))??
        .ok_or_else(|| Problem::not_found(format!("no job with id {id}")))
}

/// Runs blocking store/file work off the async runtime.
pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, Problem> + Send + 'static,
) -> Result<T, Problem> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| Problem::internal(e.to_string()))?
}

/// RFC 3339 UTC time of a Unix time in seconds, to the millisecond (truncated), with `Z`.
pub fn rfc3339(unix: f64) -> String {
    let secs = unix.floor();
    let millis = ((unix - secs) * 1000.0).floor().clamp(0.0, 999.0) as i32;
    // Stored times come from the system clock: far inside jiff's range (years ±9999).
    jiff::Timestamp::new(secs as i64, millis * 1_000_000)
        .unwrap_or(jiff::Timestamp::UNIX_EPOCH)
        .strftime("%Y-%m-%dT%H:%M:%S%.3fZ")
        .to_string()
}

#[cfg(test)]
mod tests {
    #[test]
    fn rfc3339_known_dates() {
        assert_eq!(super::rfc3339(0.0), "1970-01-01T00:00:00.000Z");
        assert_eq!(super::rfc3339(951_782_400.5), "2000-02-29T00:00:00.500Z");
        assert_eq!(super::rfc3339(1_795_305_600.0), "2026-11-22T00:00:00.000Z");
    }
}
