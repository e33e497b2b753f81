//! A throwaway PostgreSQL server from Debian's packages (`/usr/lib/postgresql/<v>/bin`):
//! `initdb` into a temporary directory, `pg_ctl start` on a free loopback port with trust
//! authentication, stopped and removed on drop. As root (CI containers) the server runs as
//! the `postgres` system user, since `initdb` refuses to run as root.
//!
//! Without the binaries, [`Postgres::start`] returns None (the caller skips) unless `CI` is
//! set, in which case it panics: CI must not pass by skipping.

use super::{try_http, Proc, Resp};
use serde_json::Value;
use std::collections::HashMap;
use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

pub struct Postgres {
    bin: PathBuf,
    dir: PathBuf,
    pub port: u16,
    as_postgres: bool,
    /// Server settings beyond the common ones (`-c name=value …`).
    extra_opts: String,
}

/// A server certificate chain and key (PEM) for [`Postgres::start_tls`].
pub struct ServerCert<'a> {
    pub chain: &'a str,
    pub key: &'a str,
}

/// The newest installed server's binary directory.
fn find_bin() -> Option<PathBuf> {
    let mut versions: Vec<(u32, PathBuf)> = std::fs::read_dir("/usr/lib/postgresql")
        .ok()?
        .flatten()
        .filter_map(|e| {
            let v = e.file_name().to_str()?.parse::<u32>().ok()?;
            let bin = e.path().join("bin");
            bin.join("pg_ctl").is_file().then_some((v, bin))
        })
        .collect();
    versions.sort();
    versions.pop().map(|(_, b)| b)
}

fn is_root() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Uid:"))
                .and_then(|r| r.split_whitespace().next().map(|u| u == "0"))
        })
        .unwrap_or(false)
}

impl Postgres {
    /// Starts a fresh server, or None (skip) when PostgreSQL is not installed and `CI` is
    /// not set.
    pub fn start(tag: &str) -> Option<Postgres> {
        Postgres::start_with(tag, None)
    }

    /// As [`Postgres::start`], with TLS on (`ssl=on`, the given certificate) and every TCP
    /// connection without TLS refused (`hostnossl … reject` first in `pg_hba.conf`), so that
    /// a connection that succeeds is encrypted; the role `scram`, if created, authenticates
    /// with SCRAM-SHA-256.
    pub fn start_tls(tag: &str, cert: ServerCert) -> Option<Postgres> {
        Postgres::start_with(tag, Some(cert))
    }

    fn start_with(tag: &str, tls: Option<ServerCert>) -> Option<Postgres> {
        let Some(bin) = find_bin() else {
            if std::env::var_os("CI").is_some() {
                panic!(
                    "PostgreSQL server binaries not found under /usr/lib/postgresql \
                     (.ci/run installs Debian's postgresql package)"
                );
            }
            eprintln!("SKIPPED: PostgreSQL is not installed (apt-get install postgresql)");
            return None;
        };
        let dir = std::env::temp_dir().join(format!("contact-sim-pg-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let as_postgres = is_root();
        if as_postgres {
            let ok = Command::new("chown")
                .args(["-R", "postgres:postgres"])
                .arg(&dir)
                .status()
                .is_ok_and(|s| s.success());
            assert!(ok, "chown to the postgres user failed");
        }
        let port = TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .unwrap()
            .port();
        let mut pg = Postgres {
            bin,
            dir,
            port,
            as_postgres,
            extra_opts: String::new(),
        };
        let data = pg.data_dir();
        pg.run(
            "initdb",
            &[
                "-D",
                data.to_str().unwrap(),
                "-A",
                "trust",
                "-U",
                "contact",
                "-E",
                "UTF8",
                "--no-sync",
            ],
        );
        if let Some(cert) = tls {
            pg.enable_tls(cert);
        }
        pg.ctl_start();
        Some(pg)
    }

    /// Writes the certificate and key next to the data directory (the key readable by the
    /// server's user only, as PostgreSQL demands) and refuses TCP connections without TLS.
    fn enable_tls(&mut self, cert: ServerCert) {
        use std::os::unix::fs::PermissionsExt;
        let crt = self.dir.join("server.crt");
        let key = self.dir.join("server.key");
        std::fs::write(&crt, cert.chain).unwrap();
        std::fs::write(&key, cert.key).unwrap();
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
        let hba = self.data_dir().join("pg_hba.conf");
        let rules = std::fs::read_to_string(&hba).unwrap();
        // The role `scram` (created by the test that uses it) logs in with a password.
        std::fs::write(
            &hba,
            format!("hostnossl all all all reject\nhostssl all scram all scram-sha-256\n{rules}"),
        )
        .unwrap();
        if self.as_postgres {
            for f in [&crt, &key] {
                let ok = Command::new("chown")
                    .arg("postgres:postgres")
                    .arg(f)
                    .status()
                    .is_ok_and(|s| s.success());
                assert!(ok, "chown {} to the postgres user failed", f.display());
            }
        }
        self.extra_opts = format!(
            " -c ssl=on -c ssl_cert_file='{}' -c ssl_key_file='{}'",
            crt.display(),
            key.display()
        );
    }

    /// The server's directory (its data files and log).
    pub fn root(&self) -> &Path {
        &self.dir
    }

    fn data_dir(&self) -> PathBuf {
        self.dir.join("data")
    }

    /// `postgres://contact@127.0.0.1:PORT/postgres`.
    pub fn url(&self) -> String {
        self.url_of("postgres")
    }

    fn url_of(&self, database: &str) -> String {
        format!("postgres://contact@127.0.0.1:{}/{database}", self.port)
    }

    /// Creates the empty database `name` (lower case letters, digits and `_`) and returns
    /// its URL.
    pub fn create_database(&self, name: &str) -> String {
        let mut client = ::postgres::Client::connect(&self.url(), ::postgres::NoTls)
            .unwrap_or_else(|e| panic!("connect to {}: {e}", self.url()));
        client
            .batch_execute(&format!("CREATE DATABASE {name}"))
            .unwrap_or_else(|e| panic!("CREATE DATABASE {name}: {e}"));
        self.url_of(name)
    }

    /// One of the server's programs, run as the `postgres` user when we are root.
    fn command(&self, program: &str) -> Command {
        let exe = self.bin.join(program);
        if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        }
    }

    fn run(&self, program: &str, args: &[&str]) {
        let out = self
            .command(program)
            .args(args)
            .current_dir(&self.dir)
            .output()
            .unwrap_or_else(|e| panic!("{program}: {e}"));
        assert!(
            out.status.success(),
            "{program} {args:?} failed: {}{}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
            std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default()
        );
    }

    fn ctl_start(&self) {
        let data = self.data_dir();
        let opts = format!(
            "-p {} -c listen_addresses=127.0.0.1 -c unix_socket_directories='{}' -c fsync=off \
             -c max_connections=200{}",
            self.port,
            self.dir.display(),
            self.extra_opts
        );
        let log = self.dir.join("server.log");
        self.run(
            "pg_ctl",
            &[
                "-D",
                data.to_str().unwrap(),
                "-o",
                &opts,
                "-l",
                log.to_str().unwrap(),
                "-w",
                "-t",
                "60",
                "start",
            ],
        );
    }

    /// Stops the server (`mode`: "fast" disconnects the clients and shuts down cleanly,
    /// "immediate" is a crash) and starts it again on the same port.
    pub fn restart(&self, mode: &str) {
        self.stop(mode);
        self.ctl_start();
    }

    pub fn stop(&self, mode: &str) {
        let data = self.data_dir();
        self.run(
            "pg_ctl",
            &["-D", data.to_str().unwrap(), "-m", mode, "-w", "stop"],
        );
    }

    pub fn start_again(&self) {
        self.ctl_start();
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        let data = self.data_dir();
        let _ = self
            .command("pg_ctl")
            .args([
                "-D",
                data.to_str().unwrap(),
                "-m",
                "immediate",
                "-w",
                "stop",
            ])
            .output();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

// Nodes of a cluster on one shared store.

/// One node's command-line flags on the shared store.
pub fn node_args<'a>(url: &'a str, node: &'a str, lease: &'a str) -> Vec<&'a str> {
    vec![
        "--store",
        url,
        "--node",
        node,
        "--lease-seconds",
        lease,
        "--workers",
        "1",
    ]
}

/// An API-only node (no workers) on the shared store.
pub fn api_node(data: &std::path::Path, url: &str) -> Proc {
    Proc::start(
        data,
        &[
            "--store",
            url,
            "--node",
            "api",
            "--workers",
            "0",
            "--submit-rate",
            "0",
        ],
    )
}

/// Submits `scene` with an idempotency key, retrying while the service is unavailable
/// (connection refused, 503 during a database restart); returns the job id.
pub fn submit(addr: SocketAddr, scene: &Value, key: &str) -> String {
    let body = scene.to_string();
    let t = Instant::now();
    loop {
        let r = try_http(
            addr,
            "POST",
            "/jobs",
            &[
                ("Content-Type", "application/json"),
                ("Idempotency-Key", key),
            ],
            body.as_bytes(),
            Duration::from_secs(30),
        );
        match r {
            Ok(r) if r.status == 202 || r.status == 200 => {
                return r.json()["id"].as_str().unwrap().to_string()
            }
            Ok(r) if r.status == 503 => {}
            Ok(r) => panic!("submission {key}: {} {}", r.status, r.text()),
            Err(_) => {}
        }
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "submission {key} never accepted"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// GET that retries while the service is unavailable.
pub fn get_retrying(addr: SocketAddr, path: &str) -> Resp {
    let t = Instant::now();
    loop {
        match try_http(addr, "GET", path, &[], b"", Duration::from_secs(30)) {
            Ok(r) if r.status != 503 => return r,
            _ => {}
        }
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "GET {path} unavailable"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Waits until every job is finished; returns the final records.
pub fn wait_all(addr: SocketAddr, ids: &[String], timeout: Duration) -> Vec<Value> {
    let t = Instant::now();
    ids.iter()
        .map(|id| loop {
            let j = get_retrying(addr, &format!("/jobs/{id}")).json();
            if ["succeeded", "failed", "cancelled"].contains(&j["status"].as_str().unwrap_or("")) {
                break j;
            }
            assert!(t.elapsed() < timeout, "job {id} stuck: {j}");
            std::thread::sleep(Duration::from_millis(100));
        })
        .collect()
}

/// How often each job id was reported finished ("job <id> succeeded") in the nodes' logs.
pub fn completions(nodes: &[&Proc]) -> HashMap<String, usize> {
    let mut n = HashMap::new();
    for p in nodes {
        for line in p.log.lock().unwrap().lines() {
            if let Some(rest) = line.split(": job ").nth(1) {
                let mut words = rest.split_whitespace();
                let (id, what) = (words.next().unwrap_or(""), words.next().unwrap_or(""));
                if what == "succeeded" {
                    *n.entry(id.to_string()).or_default() += 1;
                }
            }
        }
    }
    n
}
