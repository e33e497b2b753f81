//! `contact-sim keys`: API keys in the job store (the same `--data-dir` or `--store` as the
//! service's nodes). `add` prints the new token once, on stdout and nowhere else; the store
//! keeps only its SHA-256. A revoked key is refused by every node at its next request.

use super::{fail, pretty};
use clap::{Args, Subcommand};
use contact_sim::auth::keys::{check_name, new_token, token_hash};
use contact_sim::store::owners::{KeyAdded, KeyRecord, Quotas};
use contact_sim::store::postgres::PgStore;
use contact_sim::store::sqlite::SqliteStore;
use contact_sim::store::Store;
use contact_sim::Config;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args)]
pub struct KeysArgs {
    #[command(subcommand)]
    pub command: KeysCommand,
    /// The service's data directory (its embedded store).
    #[arg(long = "data-dir", global = true, default_value_os_t = Config::default().data_dir)]
    pub data_dir: PathBuf,
    /// The shared store, `postgres://user@host/db`, instead of the embedded one.
    #[arg(long, global = true)]
    pub store: Option<String>,
}

#[derive(Subcommand)]
pub enum KeysCommand {
    /// Create a key and print its token (shown this once). A revoked key's name may be
    /// given a new key: its jobs and meshes stay the name's.
    Add {
        /// The owner's name: 1 to 64 letters, digits, '.', '_', '-' or '@'.
        name: String,
        /// An admin key sees and manages every owner's jobs and meshes, the metrics and the
        /// node details of /healthz.
        #[arg(long)]
        admin: bool,
        #[command(flatten)]
        quotas: QuotaArgs,
    },
    /// The keys: names, roles, created, last used, revoked, quotas (never tokens).
    List,
    /// Revoke a key (every node refuses it at its next request).
    Revoke { name: String },
    /// Change a key's quotas: the quotas given are replaced, the others kept.
    SetQuota {
        name: String,
        #[command(flatten)]
        quotas: QuotaArgs,
    },
}

/// Quota flags; a number, or `none` for no limit.
#[derive(Args)]
pub struct QuotaArgs {
    /// Queued plus running jobs at once.
    #[arg(long = "max-active-jobs", value_parser = limit)]
    pub active_jobs: Option<Limit>,
    /// Bytes stored: estimated results of the key's jobs plus its meshes.
    #[arg(long = "max-stored-bytes", value_parser = limit)]
    pub stored_bytes: Option<Limit>,
    /// Worker-seconds of compute per UTC day.
    #[arg(long = "max-compute-seconds", value_parser = limit)]
    pub compute_s: Option<Limit>,
}

/// A quota flag's value: a limit, or none.
#[derive(Clone, Copy)]
pub struct Limit(Option<f64>);

fn limit(s: &str) -> Result<Limit, String> {
    if s == "none" {
        return Ok(Limit(None));
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(Limit(Some(v))),
        _ => Err(format!("{s:?}: a number ≥ 0, or none")),
    }
}

impl QuotaArgs {
    /// `base` with the quotas given replaced.
    fn apply(&self, base: Quotas) -> Quotas {
        let whole = |v: Limit| v.0.map(|x| x.min(u64::MAX as f64) as u64);
        Quotas {
            active_jobs: self.active_jobs.map_or(base.active_jobs, whole),
            stored_bytes: self.stored_bytes.map_or(base.stored_bytes, whole),
            compute_s_per_day: self.compute_s.map_or(base.compute_s_per_day, |l| l.0),
        }
    }
}

fn open(args: &KeysArgs) -> Result<Box<dyn Store>, String> {
    match &args.store {
        Some(url) => PgStore::connect(url)
            .map(|s| Box::new(s) as Box<dyn Store>)
            .map_err(|e| format!("store {}: {e}", contact_sim::state::redact(url))),
        None => SqliteStore::open(&args.data_dir.join("jobs.sqlite3"))
            .map(|s| Box::new(s) as Box<dyn Store>)
            .map_err(|e| e.to_string()),
    }
}

fn view(k: &KeyRecord) -> serde_json::Value {
    let time = |t: Option<f64>| t.map(contact_sim::routes::rfc3339);
    json!({
        "name": k.name,
        "role": if k.admin { "admin" } else { "user" },
        "created_at": contact_sim::routes::rfc3339(k.created_at),
        "last_used_at": time(k.last_used_at),
        "revoked_at": time(k.revoked_at),
        "quotas": {
            "max_active_jobs": k.quotas.active_jobs,
            "max_stored_bytes": k.quotas.stored_bytes,
            "max_compute_seconds_per_day": k.quotas.compute_s_per_day,
        },
    })
}

/// The audit line of a key's creation or revocation: who ran the command, from which
/// machine account.
fn audit(action: &str, name: &str) {
    let who = std::env::var("USER").unwrap_or_else(|_| "unknown".into());
    tracing::info!(
        target: "contact_sim::audit",
        who = %format!("cli:{who}"),
        action = %format!("keys {action} {name}"),
        from = "local",
        "audit"
    );
}

pub fn main(args: KeysArgs) -> ExitCode {
    match run(&args) {
        Ok(code) => code,
        Err(e) => fail(1, &e),
    }
}

fn run(args: &KeysArgs) -> Result<ExitCode, String> {
    let store = open(args)?;
    match &args.command {
        KeysCommand::Add {
            name,
            admin,
            quotas,
        } => {
            if let Err(e) = check_name(name) {
                return Ok(fail(2, &e));
            }
            let token = new_token()?;
            match store
                .add_key(
                    name,
                    &token_hash(&token),
                    *admin,
                    quotas.apply(Quotas::default()),
                )
                .map_err(|e| e.to_string())?
            {
                KeyAdded::Exists => Ok(fail(
                    1,
                    &format!(
                        "key {name:?} exists; revoke it first (contact-sim keys revoke {name})"
                    ),
                )),
                KeyAdded::Added(rec) => {
                    audit("add", name);
                    eprintln!(
                        "contact-sim: key {name:?} created ({}); its token follows, shown this once: keep it secret",
                        if rec.admin { "admin" } else { "user" }
                    );
                    outln!("{token}");
                    Ok(ExitCode::SUCCESS)
                }
            }
        }
        KeysCommand::List => {
            let keys = store.keys().map_err(|e| e.to_string())?;
            let list: Vec<_> = keys.iter().map(view).collect();
            outln!("{}", pretty(&json!({ "keys": list })));
            Ok(ExitCode::SUCCESS)
        }
        KeysCommand::Revoke { name } => {
            if store.revoke_key(name).map_err(|e| e.to_string())? {
                audit("revoke", name);
                Ok(ExitCode::SUCCESS)
            } else {
                Ok(fail(1, &format!("no active key named {name:?}")))
            }
        }
        KeysCommand::SetQuota { name, quotas } => {
            let keys = store.keys().map_err(|e| e.to_string())?;
            let Some(key) = keys.iter().find(|k| &k.name == name) else {
                return Ok(fail(1, &format!("no key named {name:?}")));
            };
            let new = quotas.apply(key.quotas);
            store.set_quotas(name, new).map_err(|e| e.to_string())?;
            audit("set-quota", name);
            let updated = KeyRecord {
                quotas: new,
                ..key.clone()
            };
            outln!("{}", pretty(&view(&updated)));
            Ok(ExitCode::SUCCESS)
        }
    }
}
