//! Helpers of the service's hostile-input, load, crash, PostgreSQL and store tests: the real
//! `contact-sim` binary started on an ephemeral port of 127.0.0.1 (its address read from its
//! start-up line), the tests' HTTP helpers (`tests/common/http.rs`), scenes, the resident
//! memory of a process, throwaway PostgreSQL servers, and the job store's contract.
#![allow(dead_code)]

#[path = "../common/http.rs"]
mod client;
pub mod postgres;
pub mod store_contract;

pub use client::*;
use proptest::prelude::RngExt;
use proptest::test_runner::{RngAlgorithm, TestRng};
use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The server binary running as a child process.
pub struct Proc {
    pub child: Child,
    pub addr: SocketAddr,
    /// Everything the server printed on stderr after its start-up line.
    pub log: Arc<Mutex<String>>,
}

impl Proc {
    /// Starts `contact-sim serve --addr 127.0.0.1:0 --data-dir DIR ARGS…` and waits for its
    /// "listening on http://ADDR" line.
    pub fn start(data_dir: &Path, args: &[&str]) -> Proc {
        let mut full = vec!["serve", "--addr", "127.0.0.1:0", "--data-dir"];
        let dir = data_dir.to_str().expect("UTF-8 path");
        full.push(dir);
        full.extend_from_slice(args);
        Proc::spawn(&full, "listening on http://")
    }

    /// As [`Proc::start`] for a server that serves HTTPS (`ARGS` has `--tls-cert` and
    /// `--tls-key`): waits for its "listening on https://ADDR" line.
    pub fn start_https(data_dir: &Path, args: &[&str]) -> Proc {
        let dir = data_dir.to_str().expect("UTF-8 path");
        let mut full = vec!["serve", "--addr", "127.0.0.1:0", "--data-dir", dir];
        full.extend_from_slice(args);
        Proc::spawn(&full, "listening on https://")
    }

    /// Starts a compute-only node, `contact-sim worker --data-dir DIR ARGS…`, and waits for
    /// its start-up line (`addr` is meaningless for it).
    pub fn worker(data_dir: &Path, args: &[&str]) -> Proc {
        let mut full = vec!["worker", "--data-dir"];
        let dir = data_dir.to_str().expect("UTF-8 path");
        full.push(dir);
        full.extend_from_slice(args);
        Proc::spawn(&full, "worker node ")
    }

    /// Runs `contact-sim ARGS…` and waits for the stderr line containing `ready`; what
    /// follows `ready` up to a space is parsed as the HTTP address if it is one.
    fn spawn(args: &[&str], ready: &str) -> Proc {
        let mut child = Command::new(env!("CARGO_BIN_EXE_contact-sim"))
            .args(args)
            // The start-up lines waited for are logged at info: a quieter RUST_LOG in the
            // caller's environment must not hide them.
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn contact-sim");
        let stderr = child.stderr.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        let log = Arc::new(Mutex::new(String::new()));
        let log2 = log.clone();
        let ready = ready.to_string();
        std::thread::spawn(move || {
            let mut tx = Some(tx);
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if let Some(t) = tx.as_ref() {
                    if let Some(rest) = line.split(ready.as_str()).nth(1) {
                        let addr = rest.split_whitespace().next().unwrap_or("").to_string();
                        let _ = t.send(addr);
                        tx = None;
                        continue;
                    }
                }
                let mut l = log2.lock().unwrap();
                l.push_str(&line);
                l.push('\n');
            }
        });
        let addr = match rx.recv_timeout(Duration::from_secs(60)) {
            Ok(a) => a.parse().unwrap_or(SocketAddr::from(([0, 0, 0, 0], 0))),
            Err(_) => {
                let _ = child.kill();
                panic!(
                    "contact-sim {args:?} did not start: {}",
                    log.lock().unwrap().as_str()
                );
            }
        };
        Proc { child, addr, log }
    }

    /// SIGTERM (a graceful stop), then reap.
    pub fn terminate(mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let _ = self.child.wait();
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// SIGKILL, then reap.
    pub fn kill9(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Whether the process is still running.
    pub fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// VmRSS and VmHWM (peak) of a process in KiB, from /proc (Linux).
pub fn rss_kib(pid: u32) -> Option<(u64, u64)> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| -> Option<u64> {
        s.lines()
            .find_map(|l| l.strip_prefix(name))?
            .split_whitespace()
            .next()?
            .parse()
            .ok()
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

/// A fresh directory under the system temp dir (removed on drop).
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let d = std::env::temp_dir().join(format!(
            "contact-sim-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, std::sync::atomic::Ordering::SeqCst)
        ));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        TempDir(d)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A quick job: paper-exp1 at h = k = 1/4 under a unique name (no deduplication).
pub fn small_scene(name: &str) -> Value {
    let mut s = contact_core::scene::presets::get("paper-exp1").unwrap();
    s["name"] = json!(name);
    s["mesh"]["h"] = json!("1/4");
    s["time"] = json!({"t_end": 1, "k": "1/4"});
    distinct(&mut s, name);
    s
}

/// Makes a scene another computation for each name. A name is a label: the service answers
/// the same computation under another name with the job that already computed it, so the
/// scenes these helpers give distinct names must differ in a number too. The viscosity η is
/// scaled by 1 + 10⁻¹⁵·m, m < 10⁶ a hash of the name: at most 10⁻⁹ relative, far below what
/// any test compares, yet other bits.
fn distinct(s: &mut Value, name: &str) {
    let m = name
        .bytes()
        .fold(0u64, |h, b| h.wrapping_mul(131).wrapping_add(u64::from(b)))
        % 1_000_000;
    let eta = s["material"]["viscosity"]["eta"].as_f64().unwrap();
    s["material"]["viscosity"]["eta"] = json!(eta * (1.0 + 1e-15 * m as f64));
}

/// A job that takes a while: paper-convergence at h = 1/`n` with `steps` steps, storing
/// `stored` evenly spaced steps.
pub fn long_scene(name: &str, n: usize, steps: usize, stored: usize) -> Value {
    let mut s = contact_core::scene::presets::get("paper-convergence").unwrap();
    s["name"] = json!(name);
    s["mesh"]["h"] = json!(format!("1/{n}"));
    s["time"] = json!({"t_end": 1, "N": steps});
    s["output"]["every"] = json!((steps / stored.max(1)).max(1));
    distinct(&mut s, name);
    s
}

/// Deterministic random choices of the service tests, so failures reproduce: proptest's
/// ChaCha generator (the one the unit tests use) seeded from a number.
pub struct Rng(TestRng);

impl Rng {
    pub fn seeded(seed: u64) -> Rng {
        let mut bytes = [0u8; 32];
        bytes[..8].copy_from_slice(&seed.to_le_bytes());
        Rng(TestRng::from_seed(RngAlgorithm::ChaCha, &bytes))
    }
    pub fn next(&mut self) -> u64 {
        self.0.random()
    }
    pub fn below(&mut self, n: usize) -> usize {
        self.0.random_range(0..n)
    }
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.0.random()).collect()
    }
    pub fn pick<'a, T>(&mut self, xs: &'a [T]) -> &'a T {
        &xs[self.below(xs.len())]
    }
}
