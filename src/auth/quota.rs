//! Per-key quotas, checked where work or data is added: a submission against the active
//! jobs, the compute of the day and the stored bytes; a mesh upload against the stored
//! bytes. Over quota is a problem+json naming the quota, its limit, the use and when it
//! resets: 429 (with `Retry-After`) for jobs and compute, 413 for bytes (a size, reset by
//! deleting jobs or meshes).
//!
//! The check and the insert are two store calls: concurrent submissions of one key may go
//! over the active-jobs quota by the number in flight, which the per-key submission rate
//! keeps small.

use super::Caller;
use crate::problem::Problem;
use crate::store::owners::{day_of, Usage};
use crate::store::Store;
use axum::http::StatusCode;
use serde_json::json;

/// Refuses a submission whose results are estimated at `stored_bytes` when it would take
/// the caller over one of its key's quotas. Blocking.
pub fn check_submission(
    store: &dyn Store,
    caller: &Caller,
    stored_bytes: u64,
) -> Result<(), Problem> {
    let Some(key) = caller.key() else {
        return Ok(());
    };
    let q = key.quotas;
    if q.active_jobs.is_none() && q.stored_bytes.is_none() && q.compute_s_per_day.is_none() {
        return Ok(());
    }
    let now = crate::store::now();
    let usage = store.usage(&key.name, day_of(now))?;
    if let Some(limit) = q.active_jobs {
        if usage.active_jobs >= limit {
            return Err(over(
                StatusCode::TOO_MANY_REQUESTS,
                "active_jobs",
                limit as f64,
                usage.active_jobs as f64,
                None,
                format!(
                    "{} of your jobs are queued or running, the limit of this key; submit again when one has finished",
                    usage.active_jobs
                ),
            )
            .retry_after(5));
        }
    }
    if let Some(limit) = q.compute_s_per_day {
        if usage.compute_s_today >= limit {
            let reset = (day_of(now) + 1) as f64 * 86_400.0;
            let wait = (reset - now).ceil().clamp(1.0, 86_400.0) as u32;
            return Err(over(
                StatusCode::TOO_MANY_REQUESTS,
                "compute_s_per_day",
                limit,
                usage.compute_s_today,
                Some(reset),
                format!(
                    "your jobs used {:.0} worker-seconds today (UTC), the daily limit of this key is {limit:.0}; it resets at midnight UTC",
                    usage.compute_s_today
                ),
            )
            .retry_after(wait));
        }
    }
    check_bytes(
        q.stored_bytes,
        &usage,
        stored_bytes,
        "job's estimated results",
    )
}

/// Refuses an upload of `bytes` that would take the caller over its stored-bytes quota.
/// Blocking.
pub fn check_upload(store: &dyn Store, caller: &Caller, bytes: u64) -> Result<(), Problem> {
    let Some(key) = caller.key() else {
        return Ok(());
    };
    if key.quotas.stored_bytes.is_none() {
        return Ok(());
    }
    let usage = store.usage(&key.name, day_of(crate::store::now()))?;
    check_bytes(key.quotas.stored_bytes, &usage, bytes, "mesh")
}

fn check_bytes(limit: Option<u64>, usage: &Usage, more: u64, what: &str) -> Result<(), Problem> {
    match limit {
        Some(limit) if usage.stored_bytes.saturating_add(more) > limit => Err(over(
            StatusCode::PAYLOAD_TOO_LARGE,
            "stored_bytes",
            limit as f64,
            usage.stored_bytes as f64,
            None,
            format!(
                "you store {} bytes; this {what} ({more} bytes) would go over the {limit} bytes of this key; delete finished jobs or meshes",
                usage.stored_bytes
            ),
        )),
        _ => Ok(()),
    }
}

/// RFC 3339 UTC time of a Unix time in whole seconds (a quota's reset).
fn rfc3339(unix: f64) -> String {
    jiff::Timestamp::from_second(unix as i64)
        .unwrap_or(jiff::Timestamp::UNIX_EPOCH)
        .strftime("%Y-%m-%dT%H:%M:%SZ")
        .to_string()
}

/// The problem of a quota: `/problems/quota-exceeded` with a `quota` member.
fn over(
    status: StatusCode,
    name: &str,
    limit: f64,
    used: f64,
    reset: Option<f64>,
    detail: String,
) -> Problem {
    let mut p =
        Problem::new(status, "quota exceeded", detail).with_type("/problems/quota-exceeded");
    p.quota = Some(Box::new(json!({
        "name": name,
        "limit": limit,
        "used": used,
        "reset": reset.map(rfc3339),
    })));
    p
}
