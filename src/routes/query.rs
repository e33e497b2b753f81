//! Typed query strings: each route that takes parameters declares them as a struct
//! (`#[serde(deny_unknown_fields)]`, its values typed and checked as they are decoded), and
//! [`Params`] extracts it. Anything wrong — an unknown parameter, a value out of range — is
//! a 400 problem+json naming the parameter, never a plain-text rejection. A parameter given
//! twice counts with its last value.

use crate::problem::Problem;
use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use serde::de::DeserializeOwned;

/// The query string of a request, decoded into `T`.
pub struct Params<T>(pub T);

impl<S: Send + Sync, T: DeserializeOwned> FromRequestParts<S> for Params<T> {
    type Rejection = Problem;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, Problem> {
        decode(parts.uri.query().unwrap_or("")).map(Params)
    }
}

/// Decodes `query` (application/x-www-form-urlencoded, invalid UTF-8 replaced) into `T`.
pub fn decode<T: DeserializeOwned>(query: &str) -> Result<T, Problem> {
    let pairs: Vec<(String, String)> =
        serde_urlencoded::from_str(query).map_err(|e| Problem::bad_request(e.to_string()))?;
    // The last value of a repeated parameter wins; the others are dropped here, since
    // decoding into a struct refuses duplicates.
    let mut last: Vec<(String, String)> = Vec::with_capacity(pairs.len());
    for (k, v) in pairs {
        match last.iter_mut().find(|(seen, _)| *seen == k) {
            Some(slot) => slot.1 = v,
            None => last.push((k, v)),
        }
    }
    let query = serde_urlencoded::to_string(&last).map_err(|e| Problem::internal(e.to_string()))?;
    serde_urlencoded::from_str(&query).map_err(|e| Problem::bad_request(detail(&e.to_string())))
}

/// The detail of a refused query: serde's "unknown field `x`, expected one of `a`, `b`"
/// in this API's words; the checks of the parameter types say what is wrong themselves.
fn detail(message: &str) -> String {
    let Some(rest) = message.strip_prefix("unknown field `") else {
        return message.to_string();
    };
    let mut quoted = rest.split('`').step_by(2);
    let name = quoted.next().unwrap_or("");
    let allowed: Vec<&str> = quoted.collect();
    format!(
        "unknown query parameter {name:?} (allowed: {})",
        allowed.join(", ")
    )
}

/// `cursor`: a page position as the store writes it (the `next` of the previous page of a
/// listing: jobs, meshes).
#[derive(serde::Deserialize)]
#[serde(try_from = "String")]
pub struct Cursor(pub String);

impl TryFrom<String> for Cursor {
    type Error = String;
    fn try_from(c: String) -> Result<Self, String> {
        match crate::store::parse_cursor(&c) {
            Some(_) => Ok(Cursor(c)),
            None => Err(format!("invalid cursor {c:?}")),
        }
    }
}

/// `limit`: items per page, an integer in 1..=500.
#[derive(serde::Deserialize)]
#[serde(try_from = "String")]
pub struct Limit(pub usize);

impl TryFrom<String> for Limit {
    type Error = &'static str;
    fn try_from(l: String) -> Result<Self, &'static str> {
        l.parse::<usize>()
            .ok()
            .filter(|n| (1..=500).contains(n))
            .map(Limit)
            .ok_or("limit must be an integer in 1..=500")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Q {
        a: Option<String>,
        b: Option<String>,
    }

    #[test]
    fn unknown_parameters_are_named_and_repeats_keep_the_last_value() {
        let e = decode::<Q>("a=1&colour=red").unwrap_err();
        assert_eq!(e.status, 400);
        assert_eq!(
            e.detail,
            "unknown query parameter \"colour\" (allowed: a, b)"
        );
        let q: Q = decode("a=1&b=%FF&a=2").unwrap();
        assert_eq!(q.a.as_deref(), Some("2"));
        assert_eq!(q.b.as_deref(), Some("\u{fffd}"));
        assert_eq!(decode::<Q>("").unwrap(), Q { a: None, b: None });
        assert!(decode::<Q>("&&&=&=").is_err());
    }
}
