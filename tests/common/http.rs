//! HTTP for the tests that talk to a server from outside: well-formed requests through
//! `ureq`, and raw bytes on a socket (answers read with `httparse`) for the tests that are
//! about malformed input. The `try_*` and `raw*` functions never panic and never wait
//! forever: failures come back as text, for the caller to assert on; `http`, `get` and
//! `post_json` panic with that text.

use serde_json::Value;
use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::{IpAddr, SocketAddr, TcpStream};
use std::time::{Duration, Instant};

/// A response: status, headers (lower-case names; the last of repeated ones) and the
/// decoded body.
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

/// The deadline of [`http`], [`get`] and [`post_json`], which panic past it.
const HTTP_TIMEOUT: Duration = Duration::from_secs(120);

/// An agent for one exchange: statuses are answers (not errors), no redirects, no pooling
/// across calls, and `timeout` for the whole exchange, body included.
fn config(timeout: Duration) -> ureq::config::Config {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .max_redirects(0)
        .allow_non_standard_methods(true)
        .timeout_global(Some(timeout))
        .build()
}

/// One request; the whole exchange within `timeout`.
pub fn try_http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
    timeout: Duration,
) -> Result<Resp, String> {
    let agent = ureq::Agent::new_with_config(config(timeout));
    let mut req = ureq::http::Request::builder()
        .method(method)
        .uri(format!("http://{addr}{path}"));
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    let req = req.body(body.to_vec()).map_err(|e| e.to_string())?;
    let mut res = agent.run(req).map_err(|e| e.to_string())?;
    let status = res.status().as_u16();
    let headers = res
        .headers()
        .iter()
        .map(|(k, v)| {
            let v = String::from_utf8_lossy(v.as_bytes()).into_owned();
            (k.as_str().to_string(), v)
        })
        .collect();
    let body = res
        .body_mut()
        .with_config()
        .limit(u64::MAX)
        .read_to_vec()
        .map_err(|e| format!("body: {e}"))?;
    Ok(Resp {
        status,
        headers,
        body,
    })
}

pub fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Resp {
    try_http(addr, method, path, headers, body, HTTP_TIMEOUT)
        .unwrap_or_else(|e| panic!("{method} {path}: {e}"))
}

pub fn get(addr: SocketAddr, path: &str) -> Resp {
    http(addr, "GET", path, &[], b"")
}

/// A JSON document POSTed with a deadline: Err when the server does not answer in time
/// (or dies while answering).
pub fn try_post_json(
    addr: SocketAddr,
    path: &str,
    body: &Value,
    timeout: Duration,
) -> Result<Resp, String> {
    try_http(
        addr,
        "POST",
        path,
        &[("Content-Type", "application/json")],
        body.to_string().as_bytes(),
        timeout,
    )
}

pub fn post_json(addr: SocketAddr, path: &str, body: &Value) -> Resp {
    try_post_json(addr, path, body, HTTP_TIMEOUT).unwrap_or_else(|e| panic!("POST {path}: {e}"))
}

/// As [`try_http`], from the local address `from` (every 127/8 address is loopback on
/// Linux), so that the server sees another client. Written on a raw socket: the client crate
/// cannot choose the source address.
pub fn try_http_from(
    from: IpAddr,
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Result<Resp, String> {
    let s = connect_from(from, addr)?;
    let request = request_bytes(method, path, headers, body);
    exchange_raw(s, &request, Duration::from_secs(60), false)
}

/// A TCP connection to `to` from the local address `from`.
pub fn connect_from(from: IpAddr, to: SocketAddr) -> Result<TcpStream, String> {
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

/// Opens the event stream of `id` and returns its body as read within `for_` (the stream
/// ends by itself once the job is finished).
pub fn sse_text(addr: SocketAddr, id: &str, for_: Duration) -> Result<String, String> {
    // The stream is read for `for_`; its response head may take longer on a loaded machine
    // (the load test reads for as little as 300 ms while every core is busy).
    let agent = ureq::Agent::new_with_config(
        ureq::Agent::config_builder()
            .http_status_as_error(false)
            .max_redirects(0)
            .timeout_recv_response(Some(Duration::from_secs(30)))
            .timeout_recv_body(Some(for_))
            .build(),
    );
    let res = agent
        .get(format!("http://{addr}/jobs/{id}/events"))
        .header("Accept", "text/event-stream")
        .call()
        .map_err(|e| e.to_string())?;
    if res.status() != 200 {
        return Err(format!("events: {}", res.status()));
    }
    let mut reader = res.into_body().into_reader();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match reader.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            // The time is up while the stream is open: what was read is the answer.
            Err(e) if is_timeout(&e) => break,
            Err(e) => return Err(e.to_string()),
        }
    }
    Ok(String::from_utf8_lossy(&got).into_owned())
}

fn is_timeout(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::TimedOut
        || e.get_ref()
            .and_then(|e| e.downcast_ref::<ureq::Error>())
            .is_some_and(|e| matches!(e, ureq::Error::Timeout(_)))
}

/// The bytes of one request with `Connection: close` and a Content-Length, for [`raw`].
pub fn request_bytes(method: &str, path: &str, headers: &[(&str, &str)], body: &[u8]) -> Vec<u8> {
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

/// One request written byte for byte as given (no client checks or normalises the method,
/// target or headers), answered as by [`raw`].
pub fn raw_request(
    addr: SocketAddr,
    method: &str,
    target: &str,
    headers: &[(&str, &str)],
    body: &[u8],
    timeout: Duration,
) -> Result<Resp, String> {
    raw(addr, &request_bytes(method, target, headers, body), timeout)
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

fn raw_with(
    addr: SocketAddr,
    request: &[u8],
    timeout: Duration,
    eof: bool,
) -> Result<Resp, String> {
    let s = TcpStream::connect_timeout(&addr, timeout).map_err(|e| format!("connect: {e}"))?;
    exchange_raw(s, request, timeout, eof)
}

fn exchange_raw(
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
    let mut got = Vec::new();
    let mut buf = [0u8; 16384];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(format!(
                "no complete response within {timeout:?} ({} bytes read)",
                got.len()
            ));
        }
        s.set_read_timeout(Some(left)).ok();
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset && !got.is_empty() => break,
            Err(e) => return Err(format!("read: {e} ({} bytes read)", got.len())),
        }
    }
    parse_response(&got)
}

/// Reads from `s` until the peer closes it, `deadline` passes, or a read fails (the error
/// is returned with what was read). `s` needs a short read timeout so that the deadline is
/// checked.
pub fn read_until_closed(
    s: &mut TcpStream,
    deadline: Instant,
) -> (Vec<u8>, Option<std::io::Error>) {
    let mut got = Vec::new();
    let mut buf = [0u8; 16384];
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

/// One response read to the end of the connection: its head, and its body with chunked
/// transfer coding removed.
fn parse_response(raw: &[u8]) -> Result<Resp, String> {
    let mut names = [httparse::EMPTY_HEADER; 128];
    let mut head = httparse::Response::new(&mut names);
    let at = match head.parse(raw) {
        Ok(httparse::Status::Complete(n)) => n,
        Ok(httparse::Status::Partial) => {
            return Err(format!(
                "no header end in {:?}",
                String::from_utf8_lossy(raw)
            ))
        }
        Err(e) => return Err(format!("{e} in {:?}", String::from_utf8_lossy(raw))),
    };
    let headers: HashMap<String, String> = head
        .headers
        .iter()
        .map(|h| {
            let v = String::from_utf8_lossy(h.value).into_owned();
            (h.name.to_ascii_lowercase(), v)
        })
        .collect();
    let mut body = raw[at..].to_vec();
    if headers
        .get("transfer-encoding")
        .is_some_and(|t| t.contains("chunked"))
    {
        let mut out = Vec::new();
        let mut rest = &body[..];
        loop {
            let (skip, size) = match httparse::parse_chunk_size(rest) {
                Ok(httparse::Status::Complete((skip, size))) => (skip, size as usize),
                _ => return Err("bad or truncated chunked body".into()),
            };
            if size == 0 {
                break;
            }
            let chunk = rest.get(skip..skip + size).ok_or("truncated chunk")?;
            out.extend_from_slice(chunk);
            rest = rest.get(skip + size + 2..).ok_or("truncated chunk")?;
        }
        body = out;
    }
    Ok(Resp {
        status: head.code.ok_or("no status")?,
        headers,
        body,
    })
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

/// Polls the job until its status is one of `want`.
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
