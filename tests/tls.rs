//! TLS on both connections, with certificates the tests generate (rcgen): a test CA and
//! server certificates it signs.
//!
//! * `https_end_to_end`: `contact-sim serve --tls-cert --tls-key` on an ephemeral port:
//!   health, a submitted job run to the end and read back, over HTTPS with the test CA as
//!   the only root; a client that does not trust the CA is refused; plain HTTP to the port
//!   and a silent connection are disconnected (not answered in plain text, not held open),
//!   as is an incomplete request head after the handshake (the header timeout), and the
//!   server answers HTTPS afterwards; bad certificate flags stop the start with a
//!   message naming the file.
//! * `postgres_over_tls`: the PostgreSQL store on a throwaway server with `ssl=on` that
//!   refuses TCP connections without TLS: `sslmode=require` and `verify-full` connect (the
//!   session is encrypted), `verify-full` refuses a certificate of another CA and a host
//!   name the certificate does not name, `verify-ca` accepts the latter; a password over
//!   TLS with SCRAM channel binding required connects (a wrong one does not); a whole node
//!   (store connection and its LISTEN connection) runs a job over `verify-full`.

mod service_support;

use contact_sim::store::postgres::{describe, PgStore};
use contact_sim::store::postgres_tls::PgTls;
use contact_sim::store::{NewJob, Store};
use rcgen::{
    BasicConstraints, CertificateParams, CertifiedIssuer, DnType, IsCa, KeyPair, KeyUsagePurpose,
};
use serde_json::{json, Value};
use service_support::postgres::{submit as postgres_submit, wait_all, Postgres, ServerCert};
use service_support::*;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A test certificate authority.
struct Ca {
    issuer: CertifiedIssuer<'static, KeyPair>,
}

/// A server certificate chain and its key, PEM.
struct Issued {
    chain: String,
    key: String,
}

impl Ca {
    fn new(name: &str) -> Ca {
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.distinguished_name.push(DnType::CommonName, name);
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        let issuer = CertifiedIssuer::self_signed(params, KeyPair::generate().unwrap()).unwrap();
        Ca { issuer }
    }

    fn pem(&self) -> String {
        self.issuer.pem()
    }

    /// A server certificate for `names` (DNS names or IP addresses).
    fn issue(&self, names: &[&str]) -> Issued {
        let key = KeyPair::generate().unwrap();
        let mut params =
            CertificateParams::new(names.iter().map(|n| n.to_string()).collect::<Vec<_>>())
                .unwrap();
        params.distinguished_name.push(DnType::CommonName, names[0]);
        let cert = params.signed_by(&key, &self.issuer).unwrap();
        Issued {
            chain: cert.pem(),
            key: key.serialize_pem(),
        }
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// An HTTPS client that trusts only `roots` (PEM); statuses are answers, not errors.
fn https_agent(roots: &str) -> ureq::Agent {
    let certs = vec![ureq::tls::Certificate::from_pem(roots.as_bytes()).unwrap()];
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .max_redirects(0)
        .timeout_global(Some(Duration::from_secs(60)))
        .tls_config(
            ureq::tls::TlsConfig::builder()
                .root_certs(ureq::tls::RootCerts::Specific(Arc::new(certs)))
                .build(),
        )
        .build()
        .new_agent()
}

/// One HTTPS exchange: status and JSON body (Null when the body is not JSON).
fn https(agent: &ureq::Agent, method: &str, url: &str, body: Option<&Value>) -> (u16, Value) {
    let mut req = ureq::http::Request::builder().method(method).uri(url);
    if body.is_some() {
        req = req.header("Content-Type", "application/json");
    }
    let req = req
        .body(body.map(|b| b.to_string()).unwrap_or_default())
        .unwrap();
    let mut res = agent
        .run(req)
        .unwrap_or_else(|e| panic!("{method} {url}: {e}"));
    let status = res.status().as_u16();
    let text = res.body_mut().read_to_string().unwrap();
    (status, serde_json::from_str(&text).unwrap_or(Value::Null))
}

/// Sends `bytes` on a fresh connection, then reads until the server closes; returns what
/// came back and how long until the close. Panics if the connection is still open after
/// `limit`.
fn until_closed(addr: SocketAddr, bytes: &[u8], limit: Duration) -> (Vec<u8>, Duration) {
    let mut s = TcpStream::connect(addr).unwrap();
    let t = Instant::now();
    s.write_all(bytes).unwrap();
    s.set_read_timeout(Some(limit)).unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            // A reset is a close too.
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break,
            Err(e) => panic!("connection not closed after {:?}: {e}", t.elapsed()),
        }
    }
    (got, t.elapsed())
}

/// Completes a TLS handshake (trusting `ca`), sends the start of a request head and no
/// more, then reads until the server closes; returns what came back and how long the
/// connection lasted after the handshake.
fn incomplete_head_over_tls(addr: SocketAddr, ca: &str) -> (Vec<u8>, Duration) {
    use rustls::pki_types::pem::PemObject;
    let mut roots = rustls::RootCertStore::empty();
    roots
        .add(rustls::pki_types::CertificateDer::from_pem_slice(ca.as_bytes()).unwrap())
        .unwrap();
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
    let name = rustls::pki_types::ServerName::try_from("127.0.0.1").unwrap();
    let conn = rustls::ClientConnection::new(Arc::new(config), name).unwrap();
    let sock = TcpStream::connect(addr).unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let mut tls = rustls::StreamOwned::new(conn, sock);
    while tls.conn.is_handshaking() {
        tls.conn.complete_io(&mut tls.sock).unwrap();
    }
    let t = Instant::now();
    tls.write_all(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        .unwrap();
    tls.flush().unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match tls.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            // Closed without close_notify, or reset: closed all the same.
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::UnexpectedEof | std::io::ErrorKind::ConnectionReset
                ) =>
            {
                break
            }
            Err(e) => panic!("connection not closed after {:?}: {e}", t.elapsed()),
        }
    }
    (got, t.elapsed())
}

#[test]
fn https_end_to_end() {
    let dir = TempDir::new("https");
    let ca = Ca::new("contact-sim test CA");
    let server = ca.issue(&["127.0.0.1", "localhost"]);
    let cert = write(&dir.0, "cert.pem", &server.chain);
    let key = write(&dir.0, "key.pem", &server.key);
    let data = dir.0.join("data");
    let (cert_s, key_s) = (cert.to_str().unwrap(), key.to_str().unwrap());
    let mut node = Proc::start_https(
        &data,
        &[
            "--tls-cert",
            cert_s,
            "--tls-key",
            key_s,
            "--workers",
            "1",
            "--header-timeout",
            "1",
        ],
    );
    let base = format!("https://127.0.0.1:{}", node.addr.port());
    let agent = https_agent(&ca.pem());

    let (status, health) = https(&agent, "GET", &format!("{base}/healthz"), None);
    assert_eq!(status, 200, "{health}");
    assert_eq!(health["status"], "ok", "{health}");

    // A preset job, run to the end and read back.
    let submit = json!({"preset": "paper-exp1", "overrides": {"h": "1/4", "k": "1/4"}});
    let (status, job) = https(&agent, "POST", &format!("{base}/jobs"), Some(&submit));
    assert!(status == 202 || status == 200, "{status} {job}");
    let id = job["id"].as_str().unwrap().to_string();
    let t = Instant::now();
    let done = loop {
        let (status, j) = https(&agent, "GET", &format!("{base}/jobs/{id}"), None);
        assert_eq!(status, 200, "{j}");
        if j["status"] != "queued" && j["status"] != "running" {
            break j;
        }
        assert!(t.elapsed() < Duration::from_secs(120), "job stuck: {j}");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(done["status"], "succeeded", "{done}");
    let (status, summary) = https(&agent, "GET", &format!("{base}/jobs/{id}/summary"), None);
    assert_eq!(status, 200, "{summary}");
    assert!(summary.is_object() && summary != json!({}), "{summary}");

    // A client that does not trust the test CA (here: trusting another CA) is refused.
    let stranger = https_agent(&Ca::new("another CA").pem());
    let r = stranger.get(format!("{base}/healthz")).call();
    let e = r.expect_err("an untrusted certificate must be refused");
    assert!(
        e.to_string().to_lowercase().contains("certificate")
            || e.to_string().contains("UnknownIssuer"),
        "{e}"
    );

    // Plain HTTP to the HTTPS port: no HTTP answer, the connection closed at once.
    let plain = try_http(
        node.addr,
        "GET",
        "/healthz",
        &[],
        b"",
        Duration::from_secs(10),
    );
    assert!(
        plain.is_err(),
        "plain HTTP was answered: {:?}",
        plain.map(|r| r.status)
    );
    let (got, took) = until_closed(
        node.addr,
        b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
        Duration::from_secs(10),
    );
    assert!(
        !got.starts_with(b"HTTP/"),
        "{:?}",
        String::from_utf8_lossy(&got)
    );
    // What comes back, if anything, is a TLS alert record (content type 21).
    assert!(got.is_empty() || got[0] == 21, "{got:?}");
    assert!(took < Duration::from_secs(5), "closed after {took:?}");
    // A connection that never starts the handshake is closed after the header timeout.
    let (got, took) = until_closed(node.addr, b"", Duration::from_secs(20));
    assert!(got.is_empty(), "{got:?}");
    assert!(
        took >= Duration::from_millis(900) && took < Duration::from_secs(10),
        "closed after {took:?}"
    );
    // After the handshake, the header timeout still holds: an incomplete request head is
    // disconnected after it, as on the plain port.
    let (got, took) = incomplete_head_over_tls(node.addr, &ca.pem());
    assert!(got.is_empty(), "{:?}", String::from_utf8_lossy(&got));
    assert!(
        took >= Duration::from_millis(900) && took < Duration::from_secs(10),
        "closed after {took:?}"
    );
    // The server is unaffected, and did not log the bad connections above debug level.
    let (status, _) = https(&agent, "GET", &format!("{base}/healthz"), None);
    assert_eq!(status, 200);
    assert!(node.alive());
    let log = node.log.lock().unwrap().clone();
    assert!(
        !log.contains("ERROR") && !log.contains("WARN") && !log.contains("handshake"),
        "{log}"
    );
    node.terminate();

    // Bad certificate flags: a message naming the file and exit status 2, no panic.
    let missing = dir.0.join("missing.pem");
    for (cert_arg, key_arg, words) in [
        (missing.to_str().unwrap(), key_s, "missing.pem"),
        (key_s, key_s, "no certificate"),
        (cert_s, cert_s, "no private key"),
    ] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_contact-sim"))
            .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
            .arg(&data)
            .args(["--tls-cert", cert_arg, "--tls-key", key_arg])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(words) && !err.contains("panicked"), "{err}");
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_contact-sim"))
        .args(["serve", "--tls-cert", cert_s])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--tls-key"));
}

/// Connects with the store URL's TLS settings and says whether the session is encrypted
/// (`pg_stat_ssl` of the server's own backend).
fn session_is_encrypted(url: &str) -> Result<bool, String> {
    let tls = PgTls::parse(url)?;
    let config: ::postgres::Config = tls.url.parse().map_err(|e| describe(&e))?;
    let mut client = config.connect(tls.connector()?).map_err(|e| describe(&e))?;
    let row = client
        .query_one(
            "SELECT ssl FROM pg_stat_ssl WHERE pid = pg_backend_pid()",
            &[],
        )
        .map_err(|e| describe(&e))?;
    Ok(row.get(0))
}

#[test]
fn postgres_over_tls() {
    let dir = TempDir::new("pg-tls");
    let ca = Ca::new("database CA");
    let server = ca.issue(&["localhost"]);
    let Some(pg) = Postgres::start_tls(
        "tls",
        ServerCert {
            chain: &server.chain,
            key: &server.key,
        },
    ) else {
        return;
    };
    let ca_file = write(&dir.0, "ca.pem", &ca.pem());
    let other_ca = write(&dir.0, "other-ca.pem", &Ca::new("another CA").pem());
    let port = pg.port;
    let ca_s = ca_file.to_str().unwrap();
    let other_s = other_ca.to_str().unwrap();
    // The certificate names "localhost"; hostaddr keeps the connection on 127.0.0.1.
    let by_name = format!("postgres://contact@localhost:{port}/postgres?hostaddr=127.0.0.1");
    let by_ip = format!("postgres://contact@127.0.0.1:{port}/postgres");

    // The server refuses connections without TLS.
    let e = PgStore::connect(&format!("{by_ip}?sslmode=disable")).unwrap_err();
    assert!(e.to_string().contains("no encryption"), "{e}");

    // require: encrypted, the certificate not checked.
    let require = format!("{by_ip}?sslmode=require");
    assert_eq!(session_is_encrypted(&require), Ok(true));
    let store = PgStore::connect(&require).unwrap();
    assert_eq!(store.schema_version().unwrap(), 5);
    let rec = service_support::store_contract::enqueued(
        &store,
        NewJob {
            scene: json!({"name": "over TLS"}),
            ..service_support::store_contract::new_job(0)
        },
    );
    assert_eq!(
        store.get(rec.id).unwrap().unwrap().scene["name"],
        "over TLS"
    );
    // The default (prefer) takes TLS when the server offers it.
    assert_eq!(session_is_encrypted(&by_ip), Ok(true));

    // verify-full: the right CA and a name of the certificate.
    let full = format!("{by_name}&sslmode=verify-full&sslrootcert={ca_s}");
    assert_eq!(session_is_encrypted(&full), Ok(true));
    assert_eq!(
        PgStore::connect(&full).unwrap().schema_version().unwrap(),
        5
    );
    // The same in libpq's key=value form.
    let keywords = format!(
        "host=localhost hostaddr=127.0.0.1 port={port} user=contact dbname=postgres \
         sslmode=verify-full sslrootcert='{ca_s}'"
    );
    assert_eq!(session_is_encrypted(&keywords), Ok(true));

    // A password over TLS: SCRAM with channel binding (tls-server-end-point) required, so
    // the password exchange is tied to this TLS session.
    let mut admin = ::postgres::Config::from_str(&PgTls::parse(&require).unwrap().url)
        .unwrap()
        .connect(PgTls::parse(&require).unwrap().connector().unwrap())
        .unwrap();
    admin
        .batch_execute("CREATE ROLE scram LOGIN SUPERUSER PASSWORD 'pw'")
        .unwrap();
    let scram = format!(
        "postgres://scram:pw@localhost:{port}/postgres?hostaddr=127.0.0.1&channel_binding=require\
         &sslmode=verify-full&sslrootcert={ca_s}"
    );
    assert_eq!(session_is_encrypted(&scram), Ok(true));
    assert_eq!(
        PgStore::connect(&scram).unwrap().schema_version().unwrap(),
        5
    );
    let e = session_is_encrypted(&scram.replace(":pw@", ":wrong@")).unwrap_err();
    assert!(e.contains("password authentication failed"), "{e}");

    // verify-full refuses another CA's certificate, and a host name not in the certificate;
    // at once (not retried as an outage) and saying what to check.
    let t = Instant::now();
    let wrong_ca = format!("{by_name}&sslmode=verify-full&sslrootcert={other_s}");
    let e = PgStore::connect(&wrong_ca).unwrap_err().to_string();
    assert!(
        e.contains("UnknownIssuer") && e.contains("sslrootcert"),
        "{e}"
    );
    let wrong_name = format!("{by_ip}?sslmode=verify-full&sslrootcert={ca_s}");
    let e = PgStore::connect(&wrong_name).unwrap_err().to_string();
    assert!(e.contains("not valid for name"), "{e}");
    assert!(t.elapsed() < Duration::from_secs(5), "{:?}", t.elapsed());
    assert!(session_is_encrypted(&wrong_ca).is_err());
    // verify-ca checks the chain only: the IP address is fine, the other CA is not.
    assert_eq!(
        session_is_encrypted(&format!("{by_ip}?sslmode=verify-ca&sslrootcert={ca_s}")),
        Ok(true)
    );
    let e = session_is_encrypted(&format!("{by_ip}?sslmode=verify-ca&sslrootcert={other_s}"))
        .unwrap_err();
    assert!(e.contains("UnknownIssuer"), "{e}");
    // As libpq: a root certificate makes require check the chain.
    assert!(
        session_is_encrypted(&format!("{by_ip}?sslmode=require&sslrootcert={other_s}")).is_err()
    );

    // A whole node over verify-full: its store connection and its LISTEN connection (a
    // submission wakes the worker) are both TLS connections that must succeed.
    let node = Proc::start(
        &dir.0.join("data"),
        &["--store", &full, "--workers", "1", "--submit-rate", "0"],
    );
    let id = postgres_submit(node.addr, &small_scene("node over TLS"), "tls-1");
    let done = wait_all(node.addr, &[id], Duration::from_secs(120));
    assert_eq!(done[0]["status"], "succeeded", "{}", done[0]);
    node.terminate();
}
