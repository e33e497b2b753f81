//! HTTP handlers, one file per resource family.

pub mod client;
pub mod jobs;
pub mod misc;
pub mod results;

use super::error::ApiError;
use super::store::JobRecord;
use uuid::Uuid;

/// Parses a job id from the path; malformed ids are unknown jobs (404).
pub fn parse_id(s: &str) -> Result<Uuid, ApiError> {
    Uuid::parse_str(s).map_err(|_| ApiError::not_found(format!("no job with id {s:?}")))
}

/// Fetches a job record on the blocking pool; 404 when absent.
pub async fn load_job(state: &crate::state::AppState, id: Uuid) -> Result<JobRecord, ApiError> {
    let store = state.store().clone();
    tokio::task::spawn_blocking(move || store.get(id))
        .await
        .map_err(|e| ApiError::internal(e.to_string()))??
        .ok_or_else(|| ApiError::not_found(format!("no job with id {id}")))
}

/// Refuses query parameters other than `allowed` (a typo must not be silently ignored).
pub fn only_params(
    q: &std::collections::HashMap<String, String>,
    allowed: &[&str],
) -> Result<(), ApiError> {
    match q.keys().find(|k| !allowed.contains(&k.as_str())) {
        Some(k) => Err(ApiError::bad_request(format!(
            "unknown query parameter {k:?} (allowed: {})",
            allowed.join(", ")
        ))),
        None => Ok(()),
    }
}

/// Runs blocking store/file work off the async runtime.
pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::internal(e.to_string()))?
}

/// RFC 3339 UTC time of a Unix time in seconds (civil-from-days, no time-zone database).
pub fn rfc3339(unix: f64) -> String {
    let secs = unix.floor() as i64;
    let millis = ((unix - secs as f64) * 1000.0).floor() as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{millis:03}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
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
