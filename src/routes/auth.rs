//! The layer in front of every route: resolves the [`Caller`] (401 without a valid key
//! where one is needed), keeps admin-only routes to admins, limits submissions per key,
//! hides other owners' jobs (404 on every `/jobs/{id}…` route, exactly the answer of a job
//! that does not exist), and writes the audit log line of every change.
//!
//! Meshes are checked by their handlers, which answer with the owner's view of a mesh.

use crate::auth::keys::{authenticate, bearer};
use crate::auth::{AuthMode, Caller};
use crate::limits::is_submission;
use crate::problem::Problem;
use crate::state::AppState;
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, HeaderValue, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::net::SocketAddr;
use std::sync::Arc;
use uuid::Uuid;

/// Routes served without a key: the browser client (it asks for the key), the API
/// description and its rendered reference, the presets, and `/healthz` (bare liveness without an admin key).
fn is_public(path: &str) -> bool {
    matches!(
        path,
        "/" | "/docs"
            | "/docs/"
            | "/favicon.ico"
            | "/openapi.yaml"
            | "/scene.schema.json"
            | "/presets"
            | "/healthz"
    ) || path.starts_with("/client/")
        || path == "/guide"
        || path.starts_with("/guide/")
        || path.starts_with("/presets/")
}

/// The job id of a `/jobs/{id}` or `/jobs/{id}/…` path (None for others, and for ids that
/// are not UUIDs: those are unknown jobs to the handler already). Percent-decoded as the
/// handlers' `Path` extractor decodes it: `%2D` for `-` must not slip past the owner check.
fn job_id(path: &str) -> Option<Uuid> {
    let rest = path.strip_prefix("/jobs/")?;
    let id = rest.split('/').next()?;
    let id = percent_encoding::percent_decode_str(id)
        .decode_utf8()
        .ok()?;
    Uuid::parse_str(&id).ok()
}

/// 401: no key, or one that is unknown or revoked (the same answer for all three).
pub fn unauthorized() -> Response {
    let mut r = Problem::new(
        StatusCode::UNAUTHORIZED,
        "unauthorized",
        "this service needs an API key: send Authorization: Bearer <key> (an administrator \
         makes one with contact-sim keys add NAME)",
    )
    .with_type("/problems/unauthorized")
    .into_response();
    r.headers_mut().insert(
        header::WWW_AUTHENTICATE,
        HeaderValue::from_static("Bearer realm=\"contact-sim\""),
    );
    r
}

/// The middleware (see the module documentation).
pub async fn layer(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    let path = req.uri().path().to_owned();
    let caller = match state.auth {
        AuthMode::Off | AuthMode::OffExposed => Caller::Anonymous,
        AuthMode::Required => {
            let token = token_of(&req);
            let presented = req.headers().contains_key(header::AUTHORIZATION);
            let malformed = presented && token.is_none();
            match resolve(&state, token).await {
                Ok(Some(c)) => c,
                Ok(None) => {
                    let public = is_public(&path);
                    if presented || !public {
                        let reason = if malformed {
                            "malformed Authorization header (not Bearer <key>)"
                        } else if presented {
                            "unknown or revoked key"
                        } else {
                            "no key"
                        };
                        audit_failure(&req, &path, reason, public);
                    }
                    if public {
                        Caller::Public
                    } else {
                        return unauthorized();
                    }
                }
                Err(p) => return p.into_response(),
            }
        }
    };
    if !caller.sees_all() {
        if path == "/healthz" {
            // Liveness for load balancers (ok, or degraded with its status code); the node's
            // details and the reason are for admins — but before the first key exists there
            // is no admin to tell, and the reason (create a key) is what the operator of a
            // fresh container needs to read.
            let resp = next.run(req).await;
            if resp.status().is_success() {
                return axum::Json(serde_json::json!({"status": "ok"})).into_response();
            }
            let store = state.store().clone();
            let keyless =
                super::blocking(move || Ok(!crate::auth::has_active_key(store.as_ref())?)).await;
            if keyless.unwrap_or(false) {
                return resp;
            }
            return super::misc::degraded("the node cannot take work now".into()).into_response();
        }
        if path == "/metrics" {
            return Problem::new(
                StatusCode::FORBIDDEN,
                "forbidden",
                "the metrics are for admin keys (contact-sim keys add NAME --admin)",
            )
            .into_response();
        }
    }
    if let Caller::Key(key) = &caller {
        if is_submission(&req) {
            let limiter = &state.key_limiter;
            if let Err(wait) = limiter.take(key.name.clone()) {
                return Problem::new(
                    StatusCode::TOO_MANY_REQUESTS,
                    "too many requests",
                    format!(
                        "more than {} submissions per second (bursts of {}) with this key; retry in {wait} s",
                        limiter.rate, limiter.burst
                    ),
                )
                .with_type("/problems/rate-limited")
                .retry_after(wait)
                .into_response();
            }
        }
        if let Some(id) = job_id(&path).filter(|_| !caller.sees_all()) {
            let store = state.store().clone();
            let owner = super::blocking(move || Ok(store.get(id)?.map(|r| r.owner))).await;
            match owner {
                Ok(Some(owner)) if !caller.sees(&owner) => {
                    return Problem::not_found(format!("no job with id {id}")).into_response()
                }
                Ok(_) => {}
                Err(p) => return p.into_response(),
            }
        }
    }
    let audited = matches!(*req.method(), Method::POST | Method::DELETE)
        && (path.starts_with("/jobs") || path.starts_with("/meshes"));
    let from = req
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map(|ConnectInfo(a)| a.to_string())
        .unwrap_or_default();
    let method = req.method().clone();
    let who = caller.who().to_string();
    req.extensions_mut().insert(caller);
    let resp = next.run(req).await;
    if audited {
        audit(&who, &method, &path, &from, &resp);
    }
    resp
}

/// The token of a request's `Authorization: Bearer` header, if it has the form of one.
fn token_of(req: &Request) -> Option<String> {
    req.headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(bearer)
        .map(str::to_string)
}

/// The owner a listing (`GET /jobs`, `GET /meshes`) is narrowed to (see
/// [`Caller::list_scope`]); 403 for a key that asks for another owner's.
pub fn list_scope(caller: &Caller, asked: Option<String>) -> Result<Option<String>, Problem> {
    if let Some(name) = &asked {
        crate::auth::keys::check_name(name).map_err(Problem::bad_request)?;
    }
    caller
        .list_scope(asked)
        .map_err(|e| Problem::new(StatusCode::FORBIDDEN, "forbidden", e))
}

/// The caller of a request with authentication required: None without a valid key.
async fn resolve(state: &AppState, token: Option<String>) -> Result<Option<Caller>, Problem> {
    let Some(token) = token else {
        return Ok(None);
    };
    let store = state.store().clone();
    let key = super::blocking(move || Ok(authenticate(&*store, &token)?)).await?;
    Ok(key.map(|k| Caller::Key(Arc::new(k))))
}

/// One line per failed authentication: the request, the reason, whether it went on as a
/// public request, and the peer address. Never the token.
fn audit_failure(req: &Request, path: &str, reason: &str, public: bool) {
    let from = req
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map(|ConnectInfo(a)| a.to_string())
        .unwrap_or_default();
    tracing::warn!(
        target: "contact_sim::audit",
        who = "unauthenticated",
        action = %format!("{} {path}", req.method()),
        outcome = if public { "served as public" } else { "401" },
        reason,
        from,
        "authentication failed"
    );
}

/// One line per change: who (key name, or `anonymous`), what (method, path, and the
/// resource a submission or upload created), the outcome, from where (peer address); the
/// time is the log line's. Never the token.
fn audit(who: &str, method: &Method, path: &str, from: &str, resp: &Response) {
    let created = resp
        .headers()
        .get(header::LOCATION)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    tracing::info!(
        target: "contact_sim::audit",
        who,
        action = %format!("{method} {path}"),
        status = resp.status().as_u16(),
        resource = created,
        from,
        "audit"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn public_routes_and_job_paths() {
        for p in [
            "/",
            "/client/app.js",
            "/openapi.yaml",
            "/docs",
            "/presets",
            "/presets/x",
            "/healthz",
        ] {
            assert!(is_public(p), "{p}");
        }
        for p in ["/jobs", "/meshes", "/metrics", "/jobs/x", "/nope"] {
            assert!(!is_public(p), "{p}");
        }
        let id = Uuid::new_v4();
        assert_eq!(job_id(&format!("/jobs/{id}")), Some(id));
        assert_eq!(job_id(&format!("/jobs/{id}/fields/a.vtu")), Some(id));
        let encoded = id.to_string().replace('-', "%2D").replacen('a', "%61", 1);
        assert_eq!(job_id(&format!("/jobs/{encoded}/events")), Some(id));
        assert_eq!(job_id("/jobs/nope/events"), None);
        assert_eq!(job_id("/jobs"), None);
        assert_eq!(job_id(&format!("/meshes/{id}")), None);
    }
}
