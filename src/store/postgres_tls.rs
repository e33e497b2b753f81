//! TLS of the connections to PostgreSQL, with libpq's `sslmode` and `sslrootcert` in the
//! store URL (`postgres://…?sslmode=verify-full&sslrootcert=/etc/ca.pem`, or the key=value
//! form), over rustls with the `ring` provider (`crate::tls::provider`).
//!
//! `tokio-postgres` itself knows `disable`, `prefer` and `require` and no certificates; the
//! other two modes and the CA file are taken out of the URL here and become the certificate
//! verifier of the connector:
//!
//! | `sslmode`            | TLS                          | server certificate checked      |
//! |----------------------|------------------------------|---------------------------------|
//! | `disable`            | never                        | —                               |
//! | `prefer` (default)   | if the server offers it      | no (with `sslrootcert`: chain)  |
//! | `require`            | always                       | no (with `sslrootcert`: chain)  |
//! | `verify-ca`          | always                       | chain up to `sslrootcert`       |
//! | `verify-full`        | always                       | chain and host name             |
//!
//! as libpq does (a given root certificate makes `require` check the chain). Without
//! `sslrootcert`, the verifying modes read libpq's default `~/.postgresql/root.crt`.
//! `allow`, `sslrootcert=system` and client certificates (`sslcert`, `sslkey`) are refused
//! with a message rather than half supported.

use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::client::WebPkiServerVerifier;
use rustls::pki_types::{CertificateDer, ServerName, UnixTime};
use rustls::{CertificateError, DigitallySignedStruct, SignatureScheme};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tokio_postgres_rustls::MakeRustlsConnect;

/// How much of the server is checked (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verify {
    /// Encrypted, server not authenticated (`prefer`, `require`).
    Nothing,
    /// The chain up to a trusted root, any host name (`verify-ca`).
    Chain,
    /// Chain and host name (`verify-full`).
    Full,
}

/// The store URL split into what `tokio-postgres` parses and what the TLS connector does.
#[derive(Debug, Clone)]
pub struct PgTls {
    /// The URL without `sslrootcert`, its `sslmode` one that `tokio-postgres` knows.
    pub url: String,
    pub verify: Verify,
    pub root_cert: Option<PathBuf>,
}

/// The value `tokio-postgres` gets for each libpq mode, and the verification.
fn mode(name: &str) -> Result<(&'static str, Verify), String> {
    Ok(match name {
        "disable" => ("disable", Verify::Nothing),
        "prefer" => ("prefer", Verify::Nothing),
        "require" => ("require", Verify::Nothing),
        "verify-ca" => ("require", Verify::Chain),
        "verify-full" => ("require", Verify::Full),
        other => {
            return Err(format!(
                "sslmode={other} is not supported (disable, prefer, require, verify-ca or \
                 verify-full)"
            ))
        }
    })
}

impl PgTls {
    /// Reads `sslmode` and `sslrootcert` out of `url` (either form); other parameters are
    /// left for `tokio-postgres`.
    pub fn parse(url: &str) -> Result<PgTls, String> {
        let params = if is_uri(url) {
            uri_params(url)?
        } else {
            keyword_params(url)?
        };
        let find = |key: &str| params.found.iter().rev().find(|(k, _)| k == key);
        for refused in ["sslcert", "sslkey", "sslpassword", "sslcrl"] {
            if find(refused).is_some() {
                return Err(format!(
                    "{refused} is not supported (no client certificates): authenticate with a \
                     password over TLS"
                ));
            }
        }
        let (pg_mode, mut verify) = match find("sslmode") {
            Some((_, m)) => mode(m)?,
            None => ("prefer", Verify::Nothing),
        };
        let mut root_cert = match find("sslrootcert") {
            Some((_, p)) if p == "system" => {
                return Err(
                    "sslrootcert=system is not supported: give the path of a PEM \
                            file of the CA certificates to trust"
                        .into(),
                )
            }
            Some((_, p)) => Some(PathBuf::from(p)),
            None => None,
        };
        if pg_mode == "disable" {
            root_cert = None;
        } else if root_cert.is_some() && verify == Verify::Nothing {
            verify = Verify::Chain;
        } else if root_cert.is_none() && verify != Verify::Nothing {
            let default = std::env::var_os("HOME")
                .map(|h| Path::new(&h).join(".postgresql/root.crt"))
                .filter(|p| p.is_file());
            match default {
                Some(p) => root_cert = Some(p),
                None => {
                    return Err(format!(
                        "sslmode={} needs sslrootcert=PATH (a PEM file of the CA \
                         certificates to trust; ~/.postgresql/root.crt does not exist)",
                        if verify == Verify::Full {
                            "verify-full"
                        } else {
                            "verify-ca"
                        }
                    ))
                }
            }
        }
        Ok(PgTls {
            url: params.rebuild(pg_mode),
            verify,
            root_cert,
        })
    }

    /// The connector of every connection to this database (certificates read now: a
    /// missing or bad CA file is an error at start, not at the first connection).
    pub fn connector(&self) -> Result<MakeRustlsConnect, String> {
        let provider = crate::tls::provider();
        let builder = rustls::ClientConfig::builder_with_provider(provider.clone())
            .with_safe_default_protocol_versions()
            .map_err(|e| format!("TLS: {e}"))?;
        let verifier: Arc<dyn ServerCertVerifier> = match &self.root_cert {
            None => Arc::new(NoVerifier(provider)),
            Some(path) => {
                let mut roots = rustls::RootCertStore::empty();
                for cert in
                    crate::tls::read_certificates(path).map_err(|e| format!("sslrootcert: {e}"))?
                {
                    roots
                        .add(cert)
                        .map_err(|e| format!("sslrootcert {}: {e}", path.display()))?;
                }
                let full = WebPkiServerVerifier::builder_with_provider(Arc::new(roots), provider)
                    .build()
                    .map_err(|e| format!("sslrootcert {}: {e}", path.display()))?;
                match self.verify {
                    Verify::Full => full,
                    _ => Arc::new(ChainOnly(full)),
                }
            }
        };
        let mut config = builder
            .dangerous()
            .with_custom_certificate_verifier(verifier)
            .with_no_client_auth();
        // As libpq 17: PostgreSQL 17 requires it of `sslnegotiation=direct`, older servers
        // ignore it.
        config.alpn_protocols = vec![b"postgresql".to_vec()];
        Ok(MakeRustlsConnect::new(config))
    }
}

/// Whether a connection failed in TLS for a reason that retrying does not change (a
/// certificate not trusted or not for this host, a server without TLS under `require`), as
/// opposed to the network failing during the handshake.
pub fn is_tls_refusal(e: &postgres::Error) -> bool {
    use std::error::Error as _;
    if !e.to_string().starts_with("error performing TLS handshake") {
        return false;
    }
    let io = e.source().and_then(|s| s.downcast_ref::<std::io::Error>());
    !io.is_some_and(|io| {
        use std::io::ErrorKind::*;
        matches!(
            io.kind(),
            ConnectionReset | ConnectionAborted | UnexpectedEof | BrokenPipe | TimedOut
        )
    })
}

/// The message of a TLS refusal (`error`: its text with causes), with what to check.
pub fn explain(error: &str) -> String {
    format!(
        "{error} (sslmode and sslrootcert of the store URL: the CA file must hold the root of the \
         server's certificate, and with verify-full the URL's host must be one of the \
         certificate's names)"
    )
}

fn is_uri(url: &str) -> bool {
    url.starts_with("postgres://") || url.starts_with("postgresql://")
}

/// The parameters of a URL and how to write it back with a new `sslmode`.
struct Params {
    /// (key, decoded value) in order of appearance.
    found: Vec<(String, String)>,
    /// The URL's text without `sslmode` and `sslrootcert`, and how to append a parameter.
    kept: String,
    form: Form,
}

enum Form {
    /// `postgres://…?a=b&c=d`: `has_query` says whether `kept` already has a `?`.
    Uri {
        has_query: bool,
    },
    Keyword,
}

impl Params {
    fn rebuild(&self, sslmode: &str) -> String {
        match self.form {
            Form::Uri { has_query } => {
                let sep = if has_query { '&' } else { '?' };
                format!("{}{sep}sslmode={sslmode}", self.kept)
            }
            Form::Keyword => format!("{} sslmode={sslmode}", self.kept)
                .trim()
                .to_string(),
        }
    }
}

/// Parameters handled here, taken out of the URL given to `tokio-postgres`.
const OURS: [&str; 2] = ["sslmode", "sslrootcert"];

fn uri_params(url: &str) -> Result<Params, String> {
    let (base, query) = match url.split_once('?') {
        Some((b, q)) => (b, q),
        None => (url, ""),
    };
    let mut found = Vec::new();
    let mut kept_pairs = Vec::new();
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        let key = percent_decode(k)?;
        let value = percent_decode(v)?;
        if !OURS.contains(&key.as_str()) {
            kept_pairs.push(pair);
        }
        found.push((key, value));
    }
    let mut kept = base.to_string();
    if !kept_pairs.is_empty() {
        kept.push('?');
        kept.push_str(&kept_pairs.join("&"));
    }
    Ok(Params {
        found,
        kept,
        form: Form::Uri {
            has_query: !kept_pairs.is_empty(),
        },
    })
}

fn percent_decode(s: &str) -> Result<String, String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = s
                .get(i + 1..i + 3)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("invalid percent-encoding in the store URL at {s:?}"))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| "the store URL is not UTF-8 once decoded".to_string())
}

/// libpq's key=value form: `key = value` pairs separated by white space; a value is either
/// single-quoted (`\'` and `\\` escapes) or runs to the next white space (`\` escapes).
fn keyword_params(s: &str) -> Result<Params, String> {
    let mut found = Vec::new();
    let mut kept: Vec<&str> = Vec::new();
    let mut rest = s;
    loop {
        rest = rest.trim_start();
        if rest.is_empty() {
            break;
        }
        let start = s.len() - rest.len();
        let eq = rest
            .find('=')
            .ok_or_else(|| format!("missing \"=\" after {:?} in the store URL", rest.trim()))?;
        let key = rest[..eq].trim().to_string();
        if key.is_empty() || key.contains(char::is_whitespace) {
            return Err(format!("invalid key {key:?} in the store URL"));
        }
        let mut chars = rest[eq + 1..].trim_start().char_indices().peekable();
        let value_start = s.len() - rest[eq + 1..].trim_start().len();
        let mut value = String::new();
        let mut end = s.len() - value_start;
        let quoted = chars.peek().is_some_and(|&(_, c)| c == '\'');
        if quoted {
            chars.next();
        }
        let mut closed = !quoted;
        while let Some((i, c)) = chars.next() {
            match c {
                '\\' => match chars.next() {
                    Some((_, e)) => value.push(e),
                    None => return Err("a \"\\\" ends the store URL".into()),
                },
                '\'' if quoted => {
                    closed = true;
                    end = i + 1;
                    break;
                }
                c if !quoted && c.is_whitespace() => {
                    end = i;
                    break;
                }
                c => value.push(c),
            }
        }
        if !closed {
            return Err(format!(
                "unterminated quoted value of {key} in the store URL"
            ));
        }
        let stop = value_start + end;
        if !OURS.contains(&key.as_str()) {
            kept.push(&s[start..stop]);
        }
        found.push((key, value));
        rest = &s[stop..];
    }
    Ok(Params {
        found,
        kept: kept.join(" "),
        form: Form::Keyword,
    })
}

/// `prefer` and `require` without a CA: the connection is encrypted and the server proves
/// it holds the key of the certificate it sends, but nothing says whose certificate that is
/// (libpq's behaviour in these modes).
#[derive(Debug)]
struct NoVerifier(Arc<rustls::crypto::CryptoProvider>);

impl ServerCertVerifier for NoVerifier {
    fn verify_server_cert(
        &self,
        _end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        Ok(ServerCertVerified::assertion())
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(
            message,
            cert,
            dss,
            &self.0.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(
            message,
            cert,
            dss,
            &self.0.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.0.signature_verification_algorithms.supported_schemes()
    }
}

/// `verify-ca`: webpki's verification, a wrong host name forgiven. webpki checks the name
/// last, after the chain, validity and revocation, so a name error means all else passed.
#[derive(Debug)]
struct ChainOnly(Arc<WebPkiServerVerifier>);

impl ServerCertVerifier for ChainOnly {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        server_name: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        match self
            .0
            .verify_server_cert(end_entity, intermediates, server_name, ocsp_response, now)
        {
            Err(rustls::Error::InvalidCertificate(
                CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. },
            )) => Ok(ServerCertVerified::assertion()),
            other => other,
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.0.verify_tls12_signature(message, cert, dss)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.0.verify_tls13_signature(message, cert, dss)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.0.supported_verify_schemes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parsed(url: &str) -> (String, Verify, Option<String>) {
        let t = PgTls::parse(url).unwrap_or_else(|e| panic!("{url}: {e}"));
        let root = t.root_cert.map(|p| p.display().to_string());
        (t.url, t.verify, root)
    }

    #[test]
    fn uri_form() {
        assert_eq!(
            parsed("postgres://u@h/db"),
            (
                "postgres://u@h/db?sslmode=prefer".into(),
                Verify::Nothing,
                None
            )
        );
        assert_eq!(
            parsed("postgres://u@h/db?sslmode=require&application_name=x"),
            (
                "postgres://u@h/db?application_name=x&sslmode=require".into(),
                Verify::Nothing,
                None
            )
        );
        assert_eq!(
            parsed("postgresql://u@h:5/db?sslrootcert=%2Fetc%2Fca%20x.pem&sslmode=verify-full"),
            (
                "postgresql://u@h:5/db?sslmode=require".into(),
                Verify::Full,
                Some("/etc/ca x.pem".into())
            )
        );
        assert_eq!(
            parsed("postgres://u@h/db?sslmode=verify-ca&sslrootcert=/ca.pem&connect_timeout=3"),
            (
                "postgres://u@h/db?connect_timeout=3&sslmode=require".into(),
                Verify::Chain,
                Some("/ca.pem".into())
            )
        );
        // libpq: a root certificate makes require check the chain; disable ignores it.
        assert_eq!(
            parsed("postgres://u@h/db?sslmode=require&sslrootcert=/ca.pem").1,
            Verify::Chain
        );
        assert_eq!(
            parsed("postgres://u@h/db?sslmode=disable&sslrootcert=/ca.pem"),
            (
                "postgres://u@h/db?sslmode=disable".into(),
                Verify::Nothing,
                None
            )
        );
        // The last of repeated parameters counts, as in libpq.
        assert_eq!(
            parsed("postgres://u@h/db?sslmode=verify-full&sslmode=disable").0,
            "postgres://u@h/db?sslmode=disable"
        );
    }

    #[test]
    fn keyword_form() {
        assert_eq!(
            parsed("host=h user=u dbname=db"),
            (
                "host=h user=u dbname=db sslmode=prefer".into(),
                Verify::Nothing,
                None
            )
        );
        assert_eq!(
            parsed("host=h sslmode = verify-full  sslrootcert='/a b/c\\'s.pem' password='x y'"),
            (
                "host=h password='x y' sslmode=require".into(),
                Verify::Full,
                Some("/a b/c's.pem".into())
            )
        );
        assert_eq!(
            parsed("sslrootcert=/ca\\ x.pem sslmode=verify-ca host=h"),
            (
                "host=h sslmode=require".into(),
                Verify::Chain,
                Some("/ca x.pem".into())
            )
        );
        // What is kept still parses the same for tokio-postgres.
        let t = PgTls::parse("host=h password='x y' sslmode=require").unwrap();
        let c: postgres::Config = t.url.parse().unwrap();
        assert_eq!(c.get_password(), Some(&b"x y"[..]));
    }

    #[test]
    fn refusals_say_why() {
        for (url, words) in [
            ("postgres://h/db?sslmode=allow", "sslmode=allow"),
            (
                "postgres://h/db?sslmode=verify-full&sslrootcert=system",
                "system",
            ),
            ("postgres://h/db?sslmode=require&sslcert=/c.pem", "sslcert"),
            ("host=h sslmode='require", "unterminated"),
            ("host=h sslkey=/k", "sslkey"),
            ("postgres://h/db?sslrootcert=%zz", "percent"),
        ] {
            let e = PgTls::parse(url).unwrap_err();
            assert!(e.contains(words), "{url}: {e}");
        }
    }

    #[test]
    fn a_missing_ca_file_is_an_error_at_start() {
        let t = PgTls::parse("postgres://h/db?sslmode=verify-full&sslrootcert=/nonexistent.pem")
            .unwrap();
        let e = t.connector().err().expect("no such file");
        assert!(e.contains("/nonexistent.pem"), "{e}");
        assert!(PgTls::parse("postgres://h/db?sslmode=require")
            .unwrap()
            .connector()
            .is_ok());
    }
}
