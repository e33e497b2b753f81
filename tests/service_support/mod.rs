//! Helpers of the service's hostile-input, load, crash, PostgreSQL and store tests: the real
//! `contact-sim` binary started on an ephemeral port of 127.0.0.1 (its address read from its
//! start-up line), a minimal HTTP/1.1 client that never panics and never waits forever,
//! scenes, the resident memory of a process, throwaway PostgreSQL servers, and the job
//! store's contract.
#![allow(dead_code)]

pub mod postgres;
pub mod store_contract;

use serde_json::{json, Value};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

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

#[derive(Debug)]
pub struct Resp {
    pub status: u16,
    pub headers: HashMap<String, String>,
    pub body: Vec<u8>,
}

impl Resp {
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "{}: not JSON ({e}): {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.get(name).map(String::as_str)
    }
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

/// Sends raw bytes as one request (the caller writes the whole request) and reads the
/// response until the server closes the connection or `timeout` passes in total.
pub fn raw(addr: SocketAddr, request: &[u8], timeout: Duration) -> Result<Resp, String> {
    raw_with(addr, request, timeout, false)
}

/// As [`raw`], then closes the sending side (the server sees end of input: for bytes that
/// are not a complete request it closes the connection, possibly without an answer).
pub fn raw_eof(addr: SocketAddr, request: &[u8], timeout: Duration) -> Result<Resp, String> {
    raw_with(addr, request, timeout, true)
}

/// A connection from the local address `from` (e.g. 127.0.0.2: every 127/8 address is
/// loopback on Linux), so that the server sees another client.
pub fn connect_from(from: std::net::IpAddr, to: SocketAddr) -> Result<TcpStream, String> {
    let s = socket2::Socket::new(
        socket2::Domain::for_address(to),
        socket2::Type::STREAM,
        None,
    )
    .map_err(|e| e.to_string())?;
    s.bind(&SocketAddr::new(from, 0).into())
        .map_err(|e| format!("bind {from}: {e}"))?;
    s.connect(&to.into()).map_err(|e| format!("connect: {e}"))?;
    Ok(s.into())
}

/// As [`try_http`], from the local address `from`.
pub fn try_http_from(
    from: std::net::IpAddr,
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Result<Resp, String> {
    let s = connect_from(from, addr)?;
    exchange(
        s,
        &request_bytes(method, path, headers, body),
        Duration::from_secs(60),
        false,
    )
}

fn raw_with(
    addr: SocketAddr,
    request: &[u8],
    timeout: Duration,
    eof: bool,
) -> Result<Resp, String> {
    let s = TcpStream::connect_timeout(&addr, timeout).map_err(|e| format!("connect: {e}"))?;
    exchange(s, request, timeout, eof)
}

fn exchange(
    mut s: TcpStream,
    request: &[u8],
    timeout: Duration,
    eof: bool,
) -> Result<Resp, String> {
    let deadline = Instant::now() + timeout;
    s.set_write_timeout(Some(timeout)).ok();
    // The server may answer (and close) before reading everything: ignore write errors.
    let _ = s.write_all(request);
    if eof {
        let _ = s.shutdown(std::net::Shutdown::Write);
    }
    let mut raw = Vec::new();
    let mut buf = [0u8; 16384];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(format!(
                "no complete response within {timeout:?} ({} bytes read)",
                raw.len()
            ));
        }
        s.set_read_timeout(Some(left)).ok();
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => raw.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset && !raw.is_empty() => break,
            Err(e) => return Err(format!("read: {e} ({} bytes read)", raw.len())),
        }
    }
    parse_response(&raw)
}

fn parse_response(raw: &[u8]) -> Result<Resp, String> {
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| format!("no header end in {:?}", String::from_utf8_lossy(raw)))?;
    let head = String::from_utf8_lossy(&raw[..split]).to_string();
    let mut lines = head.split("\r\n");
    let status: u16 = lines
        .next()
        .and_then(|l| l.split(' ').nth(1))
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("bad status line in {head:?}"))?;
    let headers: HashMap<String, String> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let mut body = raw[split + 4..].to_vec();
    if headers
        .get("transfer-encoding")
        .is_some_and(|t| t.contains("chunked"))
    {
        let mut out = Vec::new();
        let mut rest = &body[..];
        loop {
            let eol = rest
                .windows(2)
                .position(|w| w == b"\r\n")
                .ok_or("truncated chunked body")?;
            let size = usize::from_str_radix(
                std::str::from_utf8(&rest[..eol])
                    .map_err(|e| e.to_string())?
                    .trim(),
                16,
            )
            .map_err(|e| format!("chunk size: {e}"))?;
            rest = &rest[eol + 2..];
            if size == 0 {
                break;
            }
            if rest.len() < size + 2 {
                return Err("truncated chunk".into());
            }
            out.extend_from_slice(&rest[..size]);
            rest = &rest[size + 2..];
        }
        body = out;
    }
    Ok(Resp {
        status,
        headers,
        body,
    })
}

/// One request with `Connection: close` and a Content-Length.
pub fn try_http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
    timeout: Duration,
) -> Result<Resp, String> {
    raw(addr, &request_bytes(method, path, headers, body), timeout)
}

fn request_bytes(method: &str, path: &str, headers: &[(&str, &str)], body: &[u8]) -> Vec<u8> {
    let mut req = format!(
        "{method} {path} HTTP/1.1\r\nHost: test\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    )
    .into_bytes();
    for (k, v) in headers {
        req.extend_from_slice(format!("{k}: {v}\r\n").as_bytes());
    }
    req.extend_from_slice(b"\r\n");
    req.extend_from_slice(body);
    req
}

pub fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Resp {
    try_http(addr, method, path, headers, body, Duration::from_secs(60))
        .unwrap_or_else(|e| panic!("{method} {path}: {e}"))
}

pub fn get(addr: SocketAddr, path: &str) -> Resp {
    http(addr, "GET", path, &[], b"")
}

pub fn post_json(addr: SocketAddr, path: &str, body: &Value) -> Resp {
    http(
        addr,
        "POST",
        path,
        &[("Content-Type", "application/json")],
        body.to_string().as_bytes(),
    )
}

/// Reads from `s` until the peer closes it, `deadline` passes, or a read fails (the error
/// is returned with what was read). `s` needs a short read timeout so that the deadline is
/// checked.
pub fn read_until_closed(
    s: &mut TcpStream,
    deadline: Instant,
) -> (Vec<u8>, Option<std::io::Error>) {
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while Instant::now() < deadline {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => return (got, Some(e)),
        }
    }
    (got, None)
}

/// Opens the event stream of `id`, reads it for at most `for_` (the stream ends by itself
/// once the job is finished), and returns the response text.
pub fn sse_text(a: SocketAddr, id: &str, for_: Duration) -> Result<String, String> {
    let mut s = TcpStream::connect(a).map_err(|e| e.to_string())?;
    s.set_read_timeout(Some(Duration::from_millis(200))).ok();
    s.write_all(
        format!("GET /jobs/{id}/events HTTP/1.1\r\nHost: t\r\nAccept: text/event-stream\r\n\r\n")
            .as_bytes(),
    )
    .map_err(|e| e.to_string())?;
    let (got, error) = read_until_closed(&mut s, Instant::now() + for_);
    if let Some(e) = error {
        return Err(e.to_string());
    }
    let text = String::from_utf8_lossy(&got).into_owned();
    if !text.starts_with("HTTP/1.1 200") {
        return Err(format!("events: {text}"));
    }
    Ok(text)
}

/// Asserts a problem+json error with this status.
pub fn assert_problem(r: &Resp, status: u16) -> Value {
    assert_eq!(r.status, status, "{}", r.text());
    assert_eq!(
        r.header("content-type"),
        Some("application/problem+json"),
        "{status}: {}",
        r.text()
    );
    let p = r.json();
    assert_eq!(p["status"], status);
    assert!(p["title"].is_string() && p["detail"].is_string(), "{p}");
    p
}

pub fn wait_status(addr: SocketAddr, id: &str, want: &[&str], timeout: Duration) -> Value {
    let t = Instant::now();
    loop {
        let j = get(addr, &format!("/jobs/{id}")).json();
        if want.contains(&j["status"].as_str().unwrap()) {
            return j;
        }
        assert!(t.elapsed() < timeout, "job {id} stuck in {}", j["status"]);
        std::thread::sleep(Duration::from_millis(50));
    }
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
    s
}

/// A job that takes a while: paper-convergence at h = 1/`n` with `steps` steps, storing
/// `stored` evenly spaced steps.
pub fn long_scene(name: &str, n: usize, steps: usize, stored: usize) -> Value {
    let mut s = contact_core::scene::presets::get("paper-convergence").unwrap();
    s["name"] = json!(name);
    s["mesh"]["h"] = json!(format!("1/{n}"));
    s["time"] = json!({"t_end": 1, "N": steps});
    s["output"]["every"] = json!((steps / stored.max(1)).max(1));
    s
}

/// Small deterministic PRNG (xorshift64*), so failures reproduce.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
    pub fn pick<'a, T>(&mut self, xs: &'a [T]) -> &'a T {
        &xs[self.below(xs.len())]
    }
}
