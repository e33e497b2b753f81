//! Request limits that sit in front of the handlers: a per-client token bucket on
//! submissions (429 + `Retry-After`), a cap on the nesting depth of submitted JSON, and the
//! rewriting of every error response that did not come from [`ApiError`] (axum's extractor
//! rejections: bad path encoding, bad query, body too large, …) into problem+json.
//!
//! Clients are told apart by peer IP address (IPv6 by /64 prefix: one host usually owns a
//! whole /64), which needs `ConnectInfo<SocketAddr>` (the server is started with
//! `into_make_service_with_connect_info`, see `app::serve`). A request without that
//! information (a router driven in-process) is not rate-limited.

use super::error::ApiError;
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::collections::HashMap;
use std::net::{IpAddr, Ipv6Addr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Above this many tracked clients, buckets that have refilled completely are forgotten
/// (a full bucket carries no information), so memory stays bounded by the number of
/// clients active within one refill period.
const PRUNE_AT: usize = 10_000;

#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    at: Instant,
}

/// Token buckets per client: `burst` submissions at once, refilled at `rate` per second.
#[derive(Debug)]
pub struct RateLimiter {
    rate: f64,
    burst: f64,
    buckets: Mutex<HashMap<IpAddr, Bucket>>,
}

impl RateLimiter {
    /// `rate` ≤ 0 (or not finite) disables the limiter; `burst` is at least 1.
    pub fn new(rate: f64, burst: u32) -> RateLimiter {
        RateLimiter {
            rate: if rate.is_finite() { rate.max(0.0) } else { 0.0 },
            burst: f64::from(burst.max(1)),
            buckets: Mutex::new(HashMap::new()),
        }
    }

    pub fn enabled(&self) -> bool {
        self.rate > 0.0
    }

    /// Takes one token for `client` at time `now`; on refusal, the whole seconds until a
    /// token is available (at least 1).
    pub fn take_at(&self, client: IpAddr, now: Instant) -> Result<(), u32> {
        if !self.enabled() {
            return Ok(());
        }
        let mut map = self.buckets.lock().unwrap_or_else(|e| e.into_inner());
        if map.len() >= PRUNE_AT && !map.contains_key(&client) {
            let (rate, burst) = (self.rate, self.burst);
            map.retain(|_, b| b.tokens + rate * now.duration_since(b.at).as_secs_f64() < burst);
        }
        let b = map.entry(client).or_insert(Bucket {
            tokens: self.burst,
            at: now,
        });
        let elapsed = now.saturating_duration_since(b.at).as_secs_f64();
        b.tokens = (b.tokens + elapsed * self.rate).min(self.burst);
        b.at = now;
        if b.tokens >= 1.0 {
            b.tokens -= 1.0;
            Ok(())
        } else {
            let wait = ((1.0 - b.tokens) / self.rate).ceil();
            Err(wait.clamp(1.0, f64::from(u32::MAX)) as u32)
        }
    }

    /// Number of clients currently tracked.
    pub fn tracked(&self) -> usize {
        self.buckets.lock().map_or(0, |m| m.len())
    }
}

/// The client key of a peer address: the IPv4 address, or the /64 prefix of an IPv6 one
/// (IPv4-mapped IPv6 addresses count as IPv4).
pub fn client_key(addr: IpAddr) -> IpAddr {
    match addr.to_canonical() {
        IpAddr::V6(v6) => {
            let s = v6.segments();
            IpAddr::V6(Ipv6Addr::new(s[0], s[1], s[2], s[3], 0, 0, 0, 0))
        }
        v4 => v4,
    }
}

/// Whether a request submits work: any POST except a cancellation.
fn is_submission(req: &Request) -> bool {
    req.method() == Method::POST && !req.uri().path().ends_with("/cancel")
}

/// Middleware: 429 with `Retry-After` when a client exceeds its submission rate.
pub async fn rate_limit(
    State(limiter): State<Arc<RateLimiter>>,
    req: Request,
    next: Next,
) -> Response {
    if limiter.enabled() && is_submission(&req) {
        if let Some(ConnectInfo(peer)) = req.extensions().get::<ConnectInfo<SocketAddr>>() {
            if let Err(wait) = limiter.take_at(client_key(peer.ip()), Instant::now()) {
                let mut e = ApiError::new(
                    StatusCode::TOO_MANY_REQUESTS,
                    "too many requests",
                    format!(
                        "more than {} submissions per second (bursts of {}) from this client; retry in {wait} s",
                        limiter.rate, limiter.burst
                    ),
                );
                e.type_ = "/problems/rate-limited";
                e.retry_after = Some(wait);
                return e.into_response();
            }
        }
    }
    next.run(req).await
}

/// Depth of the deepest array/object nesting of `v` (a scalar is depth 0) and the JSON
/// pointer of a value at that depth, stopping as soon as `limit` is exceeded.
fn too_deep(v: &serde_json::Value, limit: usize, path: &mut Vec<String>) -> bool {
    let children: Box<dyn Iterator<Item = (String, &serde_json::Value)>> = match v {
        serde_json::Value::Array(a) => {
            Box::new(a.iter().enumerate().map(|(i, x)| (i.to_string(), x)))
        }
        serde_json::Value::Object(m) => Box::new(
            m.iter()
                .map(|(k, x)| (k.replace('~', "~0").replace('/', "~1"), x)),
        ),
        _ => return false,
    };
    if path.len() >= limit {
        return true;
    }
    for (k, child) in children {
        path.push(k);
        if too_deep(child, limit, path) {
            return true;
        }
        path.pop();
    }
    false
}

/// Refuses a document nested deeper than `limit` arrays/objects (422 at the first value
/// below the limit). Scenes are at most 4 levels deep; anything much deeper is not a scene.
pub fn check_depth(doc: &serde_json::Value, limit: usize) -> Result<(), ApiError> {
    let mut path = Vec::new();
    if too_deep(doc, limit, &mut path) {
        let pointer: String = path.iter().map(|p| format!("/{p}")).collect();
        return Err(ApiError::invalid_field(
            &pointer,
            format!("the document is nested more than {limit} levels deep"),
        ));
    }
    Ok(())
}

/// Middleware: every error response becomes problem+json. Responses built from
/// [`ApiError`] pass unchanged; others (axum's rejections, whose body is a short text)
/// are rewritten with that text as `detail`, keeping their status and headers.
pub async fn problem_json_errors(req: Request, next: Next) -> Response {
    let resp = next.run(req).await;
    let status = resp.status();
    if !(status.is_client_error() || status.is_server_error()) {
        return resp;
    }
    let is_problem = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/problem+json"));
    if is_problem {
        return resp;
    }
    let (parts, body) = resp.into_parts();
    let detail = match axum::body::to_bytes(body, 16 * 1024).await {
        Ok(b) if !b.is_empty() => String::from_utf8_lossy(&b).into_owned(),
        _ => status.canonical_reason().unwrap_or("error").to_string(),
    };
    let title = status.canonical_reason().unwrap_or("error");
    let mut out = ApiError::new(status, title, detail).into_response();
    for (name, value) in &parts.headers {
        if name != header::CONTENT_TYPE && name != header::CONTENT_LENGTH {
            out.headers_mut().insert(name.clone(), value.clone());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn token_bucket_burst_refill_and_retry_after() {
        let l = RateLimiter::new(2.0, 3);
        let ip: IpAddr = "10.0.0.1".parse().unwrap();
        let other: IpAddr = "10.0.0.2".parse().unwrap();
        let t0 = Instant::now();
        for _ in 0..3 {
            assert_eq!(l.take_at(ip, t0), Ok(()));
        }
        assert_eq!(l.take_at(ip, t0), Err(1));
        // Another client has its own bucket.
        assert_eq!(l.take_at(other, t0), Ok(()));
        // Half a second at 2/s refills one token.
        assert_eq!(l.take_at(ip, t0 + Duration::from_millis(500)), Ok(()));
        assert!(l.take_at(ip, t0 + Duration::from_millis(500)).is_err());
        // A long pause refills to the burst, not beyond.
        let t1 = t0 + Duration::from_secs(3600);
        for _ in 0..3 {
            assert_eq!(l.take_at(ip, t1), Ok(()));
        }
        assert!(l.take_at(ip, t1).is_err());
        // Slow rates give a longer Retry-After.
        let slow = RateLimiter::new(0.1, 1);
        assert_eq!(slow.take_at(ip, t0), Ok(()));
        assert_eq!(slow.take_at(ip, t0), Err(10));
        // Disabled.
        let off = RateLimiter::new(0.0, 1);
        for _ in 0..100 {
            assert_eq!(off.take_at(ip, t0), Ok(()));
        }
        assert_eq!(RateLimiter::new(f64::NAN, 1).take_at(ip, t0), Ok(()));
    }

    #[test]
    fn many_clients_are_pruned() {
        let l = RateLimiter::new(1000.0, 2);
        let t0 = Instant::now();
        for i in 0..(PRUNE_AT as u32 + 500) {
            let ip = IpAddr::V4(std::net::Ipv4Addr::from(i));
            let t = t0 + Duration::from_millis(u64::from(i));
            assert!(l.take_at(ip, t).is_ok());
        }
        assert!(l.tracked() <= PRUNE_AT, "{}", l.tracked());
    }

    #[test]
    fn ipv6_clients_are_keyed_by_prefix() {
        let a: IpAddr = "2001:db8:1:2:aaaa::1".parse().unwrap();
        let b: IpAddr = "2001:db8:1:2:bbbb::9".parse().unwrap();
        let c: IpAddr = "2001:db8:1:3::1".parse().unwrap();
        assert_eq!(client_key(a), client_key(b));
        assert_ne!(client_key(a), client_key(c));
        let mapped: IpAddr = "::ffff:192.0.2.7".parse().unwrap();
        assert_eq!(client_key(mapped), "192.0.2.7".parse::<IpAddr>().unwrap());
    }

    #[test]
    fn depth_limit() {
        let ok = serde_json::json!({"a": [[1, 2], {"b": 3}]});
        assert!(check_depth(&ok, 3).is_ok());
        let e = check_depth(&ok, 2).unwrap_err();
        assert_eq!(e.status, 422);
        assert_eq!(e.errors.unwrap()[0]["pointer"], "/a/0");
        let mut deep = serde_json::json!(1);
        for _ in 0..100 {
            deep = serde_json::json!({"x/y": deep});
        }
        let e = check_depth(&deep, 16).unwrap_err();
        assert!(e.errors.unwrap()[0]["pointer"]
            .as_str()
            .unwrap()
            .starts_with("/x~1y/x~1y"));
        assert!(check_depth(&serde_json::json!("scalar"), 0).is_ok());
    }
}
