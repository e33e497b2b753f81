//! API key tokens: `csk_` and 43 base64url characters (256 bits from the operating
//! system's random source), shown once at creation and stored only as their SHA-256. A
//! random 256-bit token needs no slow password hash: there is nothing to guess from its
//! hash. The store finds a key by that hash; the stored and the computed hash are then
//! compared in constant time anyway, so that no timing depends on how much of a guess was
//! right.

use crate::store::owners::KeyRecord;
use crate::store::Store;
use base64::Engine;
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

/// What every token starts with (recognisable in a leaked file or a secret scanner).
pub const PREFIX: &str = "csk_";

/// Length of a token: the prefix and 32 bytes in unpadded base64url.
pub const TOKEN_LEN: usize = 4 + 43;

/// A key's `last_used_at` is rewritten at most this often (seconds): not a write per request.
const TOUCH_EVERY_S: f64 = 60.0;

/// A new token: 256 random bits from the operating system.
pub fn new_token() -> Result<String, String> {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes).map_err(|e| format!("no random source: {e}"))?;
    Ok(format!(
        "{PREFIX}{}",
        base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(bytes)
    ))
}

/// The stored form of a token: lowercase hex SHA-256.
pub fn token_hash(token: &str) -> String {
    Sha256::digest(token.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Whether `s` has the form of a token (checked before any store look-up).
pub fn looks_like_token(s: &str) -> bool {
    s.len() == TOKEN_LEN
        && s.starts_with(PREFIX)
        && s[PREFIX.len()..]
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

/// The token of an `Authorization: Bearer <token>` header value (scheme case-insensitive).
pub fn bearer(header: &str) -> Option<&str> {
    let (scheme, token) = header.trim().split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then(|| token.trim())
        .filter(|t| looks_like_token(t))
}

/// A key name: 1–64 characters of letters, digits, `.`, `_`, `-`, `@` (it appears in logs
/// and in `?owner=`).
pub fn check_name(name: &str) -> Result<(), String> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-' | b'@'));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "key name {name:?}: 1 to 64 letters, digits, '.', '_', '-' or '@'"
        ))
    }
}

/// The active key of `token`, None for an unknown or revoked one (the same answer: nothing
/// tells them apart). Records the use (at most once a minute). Blocking.
pub fn authenticate(
    store: &dyn Store,
    token: &str,
) -> Result<Option<KeyRecord>, crate::store::StoreError> {
    let hash = token_hash(token);
    let Some((key, stored)) = store.key_by_hash(&hash)? else {
        return Ok(None);
    };
    if !bool::from(stored.as_bytes().ct_eq(hash.as_bytes())) {
        return Ok(None);
    }
    let now = crate::store::now();
    if key.last_used_at.is_none_or(|t| now - t >= TOUCH_EVERY_S) {
        // A failed bookkeeping write does not refuse a valid key.
        if let Err(e) = store.touch_key(&key.name, now) {
            tracing::warn!("cannot record the use of key {}: {e}", key.name);
        }
    }
    Ok(Some(key))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_random_and_well_formed() {
        let a = new_token().unwrap();
        let b = new_token().unwrap();
        assert_ne!(a, b);
        assert_eq!(a.len(), TOKEN_LEN);
        assert!(looks_like_token(&a), "{a}");
        assert!(!looks_like_token(&a[..TOKEN_LEN - 1]));
        assert!(!looks_like_token(&format!("x{}", &a[1..])));
        assert_eq!(bearer(&format!("Bearer {a}")), Some(a.as_str()));
        assert_eq!(bearer(&format!("bearer  {a} ")), Some(a.as_str()));
        assert_eq!(bearer(&format!("Basic {a}")), None);
        assert_eq!(bearer("Bearer nope"), None);
    }

    #[test]
    fn the_hash_is_sha256_hex() {
        // SHA-256 of "abc" (FIPS 180-2, appendix B.1).
        assert_eq!(
            token_hash("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn key_names() {
        assert!(check_name("alice").is_ok());
        assert!(check_name("a.b-c_d@lab").is_ok());
        assert!(check_name("").is_err());
        assert!(check_name("a b").is_err());
        assert!(check_name(&"x".repeat(65)).is_err());
    }
}
