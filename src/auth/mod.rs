//! Who may do what. With authentication required, every request but the public ones (the
//! browser client, the API description, presets, bare liveness) carries an API key
//! (`Authorization: Bearer <token>`); a job or mesh belongs to the key that created it and
//! is invisible (404) to every other key but an admin's. Without authentication (the
//! default on a loopback address) there is one anonymous user who sees everything, as a
//! laptop's service always did.
//!
//! * [`keys`]: tokens (256 random bits, shown once, stored as SHA-256) and their check.
//! * [`quota`]: per-key quotas at submission and upload.
//! * The layer in front of the routes that resolves the caller, refuses (401, 404, 429) and
//!   writes the audit log is `crate::routes::auth`.

pub mod keys;
pub mod quota;

use crate::store::owners::KeyRecord;
use std::sync::Arc;

/// Whether requests need a key.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum AuthMode {
    /// No keys: one anonymous user (listening on loopback addresses only, by default).
    #[default]
    Off,
    /// No keys although the service listens on a non-loopback address (`--auth off`
    /// given explicitly): warned about at start and on `/healthz`.
    OffExposed,
    /// Every non-public request needs an active key.
    Required,
}

impl AuthMode {
    /// The mode of `serve --auth` (`required`, `off`, or none given) on `addrs`: without
    /// the flag, off on loopback addresses only; anything else must say so.
    pub fn resolve(flag: Option<&str>, addrs: &[std::net::SocketAddr]) -> Result<AuthMode, String> {
        let loopback = !addrs.is_empty() && addrs.iter().all(|a| a.ip().is_loopback());
        match flag {
            Some("required") => Ok(AuthMode::Required),
            Some("off") if loopback => Ok(AuthMode::Off),
            Some("off") => Ok(AuthMode::OffExposed),
            Some(other) => Err(format!("--auth {other:?}: must be required or off")),
            None if loopback => Ok(AuthMode::Off),
            None => Err(
                "listening on a non-loopback address needs --auth required (and a key: \
                 contact-sim keys add NAME), or --auth off to serve everyone without keys"
                    .into(),
            ),
        }
    }

    /// The warning of [`AuthMode::OffExposed`] (at start and on `/healthz`).
    pub fn warning(self) -> Option<&'static str> {
        (self == AuthMode::OffExposed).then_some(
            "authentication is off on a non-loopback address: anyone who can reach this \
             port can submit, read, cancel and delete every job (serve --auth required)",
        )
    }
}

/// Why a node with `--auth required` is not ready while its store has no active key (its
/// start-up log, its `/healthz`).
pub const NO_KEY_YET: &str = "--auth required, but the store has no active API key yet: \
    every request but the public ones is 401 until one is created with \
    contact-sim keys add NAME --admin (same --data-dir or --store; in a container, \
    docker exec CONTAINER contact-sim keys add NAME --admin --data-dir /data)";

/// Whether the store has a key that is not revoked.
pub fn has_active_key(store: &dyn crate::store::Store) -> Result<bool, crate::store::StoreError> {
    Ok(store.keys()?.iter().any(|k| k.revoked_at.is_none()))
}

/// Who is asking, as the middleware resolved it (a request extension every handler of a
/// non-public route finds).
#[derive(Debug, Clone)]
pub enum Caller {
    /// Authentication off: the one user, who sees everything.
    Anonymous,
    /// Authentication required, no valid key, a public route.
    Public,
    /// An active key.
    Key(Arc<KeyRecord>),
}

impl Caller {
    /// The owner recorded on what this caller creates (`""`: anonymous).
    pub fn owner(&self) -> &str {
        match self {
            Caller::Key(k) => &k.name,
            _ => "",
        }
    }

    /// Sees and manages everything: the anonymous user or an admin key.
    pub fn sees_all(&self) -> bool {
        match self {
            Caller::Anonymous => true,
            Caller::Public => false,
            Caller::Key(k) => k.admin,
        }
    }

    /// Whether a job or mesh of `owner` exists for this caller.
    pub fn sees(&self, owner: &str) -> bool {
        self.sees_all() || matches!(self, Caller::Key(k) if k.name == owner)
    }

    /// The owner a listing is narrowed to: `asked` (the `owner` query parameter) for
    /// whoever sees everything, the key's own name otherwise. Err when a key that is not an
    /// admin asks for another owner.
    pub fn list_scope(&self, asked: Option<String>) -> Result<Option<String>, String> {
        match self {
            _ if self.sees_all() => Ok(asked),
            Caller::Key(k) => match asked {
                Some(o) if o != k.name => {
                    Err("only an admin key lists another owner's jobs and meshes".into())
                }
                _ => Ok(Some(k.name.clone())),
            },
            _ => Err("no key".into()),
        }
    }

    /// The name for the audit log.
    pub fn who(&self) -> &str {
        match self {
            Caller::Anonymous => "anonymous",
            Caller::Public => "nobody",
            Caller::Key(k) => &k.name,
        }
    }

    /// The per-key quotas of a key; none for the anonymous user.
    pub fn key(&self) -> Option<&KeyRecord> {
        match self {
            Caller::Key(k) => Some(k),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auth_defaults_off_only_on_loopback() {
        let lo: Vec<std::net::SocketAddr> = vec!["127.0.0.1:8080".parse().unwrap()];
        let lo6: Vec<std::net::SocketAddr> = vec!["[::1]:8080".parse().unwrap()];
        let any: Vec<std::net::SocketAddr> = vec!["0.0.0.0:8080".parse().unwrap()];
        let mixed = [lo[0], any[0]];
        assert_eq!(AuthMode::resolve(None, &lo), Ok(AuthMode::Off));
        assert_eq!(AuthMode::resolve(None, &lo6), Ok(AuthMode::Off));
        assert!(AuthMode::resolve(None, &any)
            .unwrap_err()
            .contains("--auth"));
        assert!(AuthMode::resolve(None, &mixed).is_err());
        assert!(AuthMode::resolve(None, &[]).is_err());
        assert_eq!(
            AuthMode::resolve(Some("off"), &any),
            Ok(AuthMode::OffExposed)
        );
        assert_eq!(AuthMode::resolve(Some("off"), &lo), Ok(AuthMode::Off));
        assert_eq!(
            AuthMode::resolve(Some("required"), &lo),
            Ok(AuthMode::Required)
        );
        assert!(AuthMode::resolve(Some("maybe"), &lo).is_err());
        assert!(AuthMode::OffExposed.warning().is_some());
        assert!(AuthMode::Off.warning().is_none());
    }

    #[test]
    fn owners_see_their_own_admins_everything() {
        let key = |name: &str, admin| {
            Caller::Key(Arc::new(KeyRecord {
                name: name.into(),
                admin,
                created_at: 0.0,
                last_used_at: None,
                revoked_at: None,
                quotas: Default::default(),
            }))
        };
        let (alice, root) = (key("alice", false), key("root", true));
        assert!(alice.sees("alice") && !alice.sees("bob") && !alice.sees(""));
        assert!(root.sees("bob") && root.sees(""));
        assert!(Caller::Anonymous.sees("bob"));
        assert!(!Caller::Public.sees(""));
        assert_eq!(alice.list_scope(None), Ok(Some("alice".into())));
        assert!(alice.list_scope(Some("bob".into())).is_err());
        assert_eq!(root.list_scope(Some("bob".into())), Ok(Some("bob".into())));
        assert_eq!(root.list_scope(None), Ok(None));
        assert_eq!(alice.owner(), "alice");
        assert_eq!(Caller::Anonymous.owner(), "");
    }
}
