//! Request limits that sit in front of the handlers: a per-client limit on submissions
//! (429 + `Retry-After`), a cap on the nesting depth of submitted JSON, and the rewriting of
//! every error response that is not a [`Problem`] already (axum's extractor rejections: bad
//! path encoding, body too large, …) into problem+json.
//!
//! Clients are told apart by peer IP address (IPv6 by /64 prefix: one host usually owns a
//! whole /64), which needs `ConnectInfo<SocketAddr>` (the accept loop in `server` attaches
//! it to every request). A request without that information (a router driven in-process)
//! is not rate-limited. With authentication on, a request with an API key is limited per
//! key instead, by `crate::routes::auth` (many users may share one address).

use super::problem::Problem;
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use governor::clock::{Clock, MonotonicClock};
use governor::middleware::NoOpMiddleware;
use governor::state::keyed::HashMapStateStore;
use governor::Quota;
use std::net::{IpAddr, Ipv6Addr, SocketAddr};
use std::num::NonZeroU32;
use std::sync::Arc;
use std::time::Duration;

/// Above this many tracked clients, those whose allowance has refilled completely are
/// forgotten (a full allowance carries no information), so memory stays bounded by the
/// number of clients active within one refill period.
const PRUNE_AT: usize = 10_000;

/// The longest a client's whole burst may take to refill: slower configured rates are
/// this slow (governor counts time in u64 nanoseconds, about 584 years).
const LONGEST_REFILL: Duration = Duration::from_secs(100 * 365 * 86_400);

type Keyed<C, K> =
    governor::RateLimiter<K, HashMapStateStore<K>, C, NoOpMiddleware<<C as Clock>::Instant>>;

/// Submissions per client: `burst` at once, one more every 1/`rate` seconds (a token
/// bucket, as governor's GCRA keyed by client address, or by API key: `K`).
pub struct RateLimiter<C: Clock = MonotonicClock, K: std::hash::Hash + Eq + Clone = IpAddr> {
    pub(crate) rate: f64,
    pub(crate) burst: u32,
    /// None: disabled.
    keyed: Option<Keyed<C, K>>,
}

impl RateLimiter {
    /// `rate` ≤ 0 (or not finite) disables the limiter; `burst` is at least 1.
    pub fn new(rate: f64, burst: u32) -> RateLimiter {
        RateLimiter::<MonotonicClock, IpAddr>::with_clock(rate, burst, MonotonicClock)
    }
}

impl RateLimiter<MonotonicClock, String> {
    /// [`RateLimiter::new`] keyed by API key name (see `crate::auth`).
    pub fn per_key(rate: f64, burst: u32) -> RateLimiter<MonotonicClock, String> {
        RateLimiter::<MonotonicClock, String>::with_clock(rate, burst, MonotonicClock)
    }
}

impl<C: Clock, K: std::hash::Hash + Eq + Clone> RateLimiter<C, K> {
    /// [`RateLimiter::new`] reading the time from `clock`.
    pub fn with_clock(rate: f64, burst: u32, clock: C) -> RateLimiter<C, K> {
        let rate = if rate.is_finite() { rate.max(0.0) } else { 0.0 };
        let burst = NonZeroU32::new(burst.max(1)).expect("at least 1");
        let keyed = (rate > 0.0)
            .then(|| {
                let period = Duration::try_from_secs_f64(1.0 / rate)
                    .unwrap_or(Duration::MAX)
                    .min(LONGEST_REFILL / burst.get());
                Quota::with_period(period.max(Duration::from_nanos(1)))
            })
            .flatten()
            .map(|q| {
                governor::RateLimiter::new(
                    q.allow_burst(burst),
                    HashMapStateStore::default(),
                    clock,
                )
            });
        RateLimiter {
            rate,
            burst: burst.get(),
            keyed,
        }
    }

    pub fn enabled(&self) -> bool {
        self.keyed.is_some()
    }

    /// Takes one submission of `client`'s allowance; on refusal, the whole seconds until
    /// the next one is allowed (at least 1).
    pub fn take(&self, client: K) -> Result<(), u32> {
        let Some(keyed) = &self.keyed else {
            return Ok(());
        };
        if keyed.len() >= PRUNE_AT {
            keyed.retain_recent();
        }
        keyed.check_key(&client).map_err(|not_until| {
            not_until
                .wait_time_from(keyed.clock().now())
                .as_secs_f64()
                .ceil()
                .clamp(1.0, f64::from(u32::MAX)) as u32
        })
    }

    /// Number of clients currently tracked.
    pub fn tracked(&self) -> usize {
        self.keyed.as_ref().map_or(0, |k| k.len())
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
pub(crate) fn is_submission(req: &Request) -> bool {
    req.method() == Method::POST && !req.uri().path().ends_with("/cancel")
}

/// Middleware: 429 with `Retry-After` when a client exceeds its submission rate.
pub async fn rate_limit(
    State(limiter): State<Arc<RateLimiter>>,
    req: Request,
    next: Next,
) -> Response {
    // A request with an API key is limited per key instead (`crate::routes::auth`).
    let keyed = matches!(
        req.extensions().get::<crate::auth::Caller>(),
        Some(crate::auth::Caller::Key(_))
    );
    if limiter.enabled() && is_submission(&req) && !keyed {
        if let Some(ConnectInfo(peer)) = req.extensions().get::<ConnectInfo<SocketAddr>>() {
            if let Err(wait) = limiter.take(client_key(peer.ip())) {
                return Problem::new(
                    StatusCode::TOO_MANY_REQUESTS,
                    "too many requests",
                    format!(
                        "more than {} submissions per second (bursts of {}) from this client; retry in {wait} s",
                        limiter.rate, limiter.burst
                    ),
                )
                .with_type("/problems/rate-limited")
                .retry_after(wait)
                .into_response();
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
pub fn check_depth(doc: &serde_json::Value, limit: usize) -> Result<(), Problem> {
    let mut path = Vec::new();
    if too_deep(doc, limit, &mut path) {
        let pointer: String = path.iter().map(|p| format!("/{p}")).collect();
        return Err(Problem::invalid_field(
            &pointer,
            format!("the document is nested more than {limit} levels deep"),
        ));
    }
    Ok(())
}

/// Middleware: every error response becomes problem+json. Responses built from
/// [`Problem`] pass unchanged; others (axum's rejections, whose body is a short text)
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
    let mut out = Problem::new(status, title, detail).into_response();
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
    use governor::clock::FakeRelativeClock;

    #[test]
    fn token_bucket_burst_refill_and_retry_after() {
        let clock = FakeRelativeClock::default();
        let l = RateLimiter::with_clock(2.0, 3, clock.clone());
        let ip: IpAddr = "10.0.0.1".parse().unwrap();
        let other: IpAddr = "10.0.0.2".parse().unwrap();
        for _ in 0..3 {
            assert_eq!(l.take(ip), Ok(()));
        }
        assert_eq!(l.take(ip), Err(1));
        // Another client has its own bucket.
        assert_eq!(l.take(other), Ok(()));
        // Half a second at 2/s refills one token.
        clock.advance(Duration::from_millis(500));
        assert_eq!(l.take(ip), Ok(()));
        assert!(l.take(ip).is_err());
        // A long pause refills to the burst, not beyond.
        clock.advance(Duration::from_secs(3600));
        for _ in 0..3 {
            assert_eq!(l.take(ip), Ok(()));
        }
        assert!(l.take(ip).is_err());
        // Slow rates give a longer Retry-After.
        let slow = RateLimiter::with_clock(0.1, 1, FakeRelativeClock::default());
        assert_eq!(slow.take(ip), Ok(()));
        assert_eq!(slow.take(ip), Err(10));
        // Disabled.
        let off = RateLimiter::new(0.0, 1);
        for _ in 0..100 {
            assert_eq!(off.take(ip), Ok(()));
        }
        assert_eq!(RateLimiter::new(f64::NAN, 1).take(ip), Ok(()));
        // Absurd rates neither overflow nor divide by zero.
        let glacial = RateLimiter::new(1e-300, u32::MAX);
        assert_eq!(glacial.take(ip), Ok(()));
        assert_eq!(RateLimiter::new(1e300, 1).take(ip), Ok(()));
    }

    #[test]
    fn many_clients_are_pruned() {
        let clock = FakeRelativeClock::default();
        let l = RateLimiter::with_clock(1000.0, 2, clock.clone());
        for i in 0..(PRUNE_AT as u32 + 500) {
            let ip = IpAddr::V4(std::net::Ipv4Addr::from(i));
            clock.advance(Duration::from_millis(1));
            assert!(l.take(ip).is_ok());
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
        assert_eq!(e.errors.unwrap()[0].pointer, "/a/0");
        let mut deep = serde_json::json!(1);
        for _ in 0..100 {
            deep = serde_json::json!({"x/y": deep});
        }
        let e = check_depth(&deep, 16).unwrap_err();
        assert!(e.errors.unwrap()[0].pointer.starts_with("/x~1y/x~1y"));
        assert!(check_depth(&serde_json::json!("scalar"), 0).is_ok());
    }
}
