//! The one error body of the service: an RFC 9457 problem detail. Every error response of
//! the HTTP API (handlers, extractor rejections, limits, unknown routes) and the `error` of
//! a failed job are this type, served as `application/problem+json`.

use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

/// An RFC 9457 problem detail with this service's extension member `errors`.
#[derive(Debug, Clone, Serialize)]
pub struct Problem {
    /// A URI reference naming the kind of problem (`about:blank`: the status says it all).
    #[serde(rename = "type")]
    pub type_: &'static str,
    pub title: &'static str,
    pub status: u16,
    pub detail: String,
    /// What is wrong where: one entry per offending field of the request body.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub errors: Option<Vec<FieldError>>,
    /// The quota a request went over: its name, limit, use and when it resets (see
    /// `crate::auth::quota`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quota: Option<Box<serde_json::Value>>,
    /// The per-job limit a request went over: its name, the member that sets the size, what
    /// the request needs and what the node allows (see [`Problem::over_limit`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit: Option<Box<serde_json::Value>>,
    /// Seconds after which a retry may succeed (the `Retry-After` header, not a member).
    #[serde(skip)]
    pub retry_after: Option<u32>,
}

/// One entry of [`Problem::errors`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FieldError {
    /// RFC 6901 JSON pointer into the request body ("" is the body itself).
    pub pointer: String,
    pub message: String,
}

impl Problem {
    pub fn new(status: StatusCode, title: &'static str, detail: impl Into<String>) -> Problem {
        Problem {
            type_: "about:blank",
            title,
            status: status.as_u16(),
            detail: detail.into(),
            errors: None,
            quota: None,
            limit: None,
            retry_after: None,
        }
    }

    /// The same problem with a `type` of its own (a `/problems/…` path).
    pub fn with_type(mut self, type_: &'static str) -> Problem {
        self.type_ = type_;
        self
    }

    /// The same problem with a `Retry-After` of `seconds`.
    pub fn retry_after(mut self, seconds: u32) -> Problem {
        self.retry_after = Some(seconds);
        self
    }

    pub fn bad_request(detail: impl Into<String>) -> Problem {
        Problem::new(StatusCode::BAD_REQUEST, "bad request", detail)
    }

    pub fn not_found(detail: impl Into<String>) -> Problem {
        Problem::new(StatusCode::NOT_FOUND, "not found", detail)
    }

    pub fn conflict(detail: impl Into<String>) -> Problem {
        Problem::new(StatusCode::CONFLICT, "conflict", detail)
    }

    pub fn internal(detail: impl Into<String>) -> Problem {
        Problem::new(StatusCode::INTERNAL_SERVER_ERROR, "internal error", detail)
    }

    /// 422 with the validation errors of a scene (pointers into the submitted document).
    pub fn invalid_scene(errors: &contact_core::scene::ValidationErrors) -> Problem {
        let n = errors.0.len();
        let mut p = Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid scene",
            format!(
                "the scene has {n} error{}; see `errors` (JSON pointers into the request body)",
                if n == 1 { "" } else { "s" }
            ),
        )
        .with_type("/problems/invalid-scene");
        p.errors = Some(
            errors
                .0
                .iter()
                .map(|e| FieldError {
                    pointer: e.pointer.clone(),
                    message: e.message.clone(),
                })
                .collect(),
        );
        p
    }

    /// 422 for one field (limits, preset names, overrides).
    pub fn invalid_field(pointer: &str, message: impl Into<String>) -> Problem {
        Problem::field(
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid scene",
            pointer,
            message,
        )
        .with_type("/problems/invalid-scene")
    }

    /// A problem about one field: `message` is both the detail and the field's entry.
    pub fn field(
        status: StatusCode,
        title: &'static str,
        pointer: &str,
        message: impl Into<String>,
    ) -> Problem {
        let message = message.into();
        let mut p = Problem::new(status, title, message.clone());
        p.errors = Some(vec![FieldError {
            pointer: pointer.to_string(),
            message,
        }]);
        p
    }

    /// The problem as a JSON document (what a failed job stores as its `error`).
    /// 422 at the member that does not fit, with the limit's name and figures as the
    /// extension member `limit` (what the run needs, what this node allows).
    pub fn over_limit(e: &contact_core::admission::LimitError) -> Problem {
        let mut p = Problem::invalid_field(&e.pointer, e.message.clone());
        p.limit = Some(Box::new(serde_json::json!({
            "name": e.limit,
            "pointer": e.pointer,
            "needed": e.needed,
            "allowed": e.allowed,
        })));
        p
    }

    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self).expect("a problem serialises")
    }
}

impl From<crate::store::StoreError> for Problem {
    fn from(e: crate::store::StoreError) -> Self {
        use crate::store::StoreError;
        match e {
            // The shared database is restarting or unreachable: the client should retry
            // (with its Idempotency-Key, a retried submission cannot create a second job).
            StoreError::Unavailable(_) => Problem::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "job store unavailable",
                format!("store: {e}; retry shortly"),
            )
            .retry_after(2),
            e => Problem::internal(format!("store: {e}")),
        }
    }
}

impl IntoResponse for Problem {
    fn into_response(self) -> Response {
        let status = StatusCode::from_u16(self.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        let body = serde_json::to_vec(&self).unwrap_or_default();
        let mut resp = (status, body).into_response();
        resp.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        if let Some(s) = self.retry_after {
            resp.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        resp
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The members and their order are those of the documents served before this type.
    #[test]
    fn serialises_as_rfc_9457() {
        let p = Problem::invalid_field("/mesh/h", "too fine").retry_after(3);
        assert_eq!(
            serde_json::to_string(&p).unwrap(),
            r#"{"type":"/problems/invalid-scene","title":"invalid scene","status":422,"detail":"too fine","errors":[{"pointer":"/mesh/h","message":"too fine"}]}"#
        );
        let r = Problem::not_found("no").into_response();
        assert_eq!(r.status(), 404);
        assert_eq!(
            r.headers()[header::CONTENT_TYPE],
            "application/problem+json"
        );
        let r = p.into_response();
        assert_eq!(r.headers()[header::RETRY_AFTER], "3");
    }
}
