//! HTTPS of `serve --tls-cert PEM --tls-key PEM`: the certificate chain and private key read
//! once at start (a bad path or PEM is a start-up error naming the file), and the rustls
//! acceptor the accept loop (`crate::server`) wraps each connection in.
//!
//! Only HTTP/1.1 is offered (ALPN `http/1.1`): hyper's HTTP/2 server has no counterpart of
//! the HTTP/1.1 header read timeout, so a client could hold an HTTP/2 connection open
//! without ever completing a request, which the plain port does not allow.
//!
//! The crypto provider is `ring`, chosen explicitly rather than through rustls' process-wide
//! default: it builds with a C compiler alone (no cmake, no Go), as the rest of the build.

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The crypto provider of every TLS connection of this program, server and client side.
pub fn provider() -> Arc<rustls::crypto::CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// The server's certificate and key, ready to accept connections.
#[derive(Clone)]
pub struct ServerTls {
    config: Arc<rustls::ServerConfig>,
    /// Where the certificate chain came from (logs and `Debug`).
    cert_path: PathBuf,
}

impl std::fmt::Debug for ServerTls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServerTls")
            .field("cert", &self.cert_path)
            .finish_non_exhaustive()
    }
}

impl ServerTls {
    /// Reads the PEM certificate chain (the server's certificate first, then any
    /// intermediates) and the PEM private key (PKCS#8, PKCS#1 or SEC1), and checks that they
    /// belong together. Errors name the file and what is wrong with it.
    pub fn load(cert: &Path, key: &Path) -> Result<ServerTls, String> {
        let chain = read_certificates(cert)?;
        let key_der = PrivateKeyDer::from_pem_file(key).map_err(|e| {
            format!(
                "TLS key {}: {}",
                key.display(),
                pem_error(e, "no private key (BEGIN PRIVATE KEY) in it")
            )
        })?;
        let mut config = rustls::ServerConfig::builder_with_provider(provider())
            .with_safe_default_protocol_versions()
            .map_err(|e| format!("TLS: {e}"))?
            .with_no_client_auth()
            .with_single_cert(chain, key_der)
            .map_err(|e| {
                format!(
                    "TLS certificate {} and key {} cannot be used together: {e}",
                    cert.display(),
                    key.display()
                )
            })?;
        config.alpn_protocols = vec![b"http/1.1".to_vec()];
        Ok(ServerTls {
            config: Arc::new(config),
            cert_path: cert.to_path_buf(),
        })
    }

    /// The acceptor of the accept loop (cheap: shares the configuration).
    pub fn acceptor(&self) -> tokio_rustls::TlsAcceptor {
        tokio_rustls::TlsAcceptor::from(self.config.clone())
    }

    pub fn cert_path(&self) -> &Path {
        &self.cert_path
    }
}

/// Every certificate of a PEM file, in order; at least one.
pub fn read_certificates(path: &Path) -> Result<Vec<CertificateDer<'static>>, String> {
    let what = |e| {
        format!(
            "TLS certificate {}: {}",
            path.display(),
            pem_error(e, "no certificate")
        )
    };
    let certs = CertificateDer::pem_file_iter(path)
        .map_err(what)?
        .collect::<Result<Vec<_>, _>>()
        .map_err(what)?;
    if certs.is_empty() {
        return Err(format!(
            "TLS certificate {}: no certificate (BEGIN CERTIFICATE) in it",
            path.display()
        ));
    }
    Ok(certs)
}

/// A PEM reading error in words (`none`: what "no item found" means for this file).
fn pem_error(e: rustls::pki_types::pem::Error, none: &str) -> String {
    use rustls::pki_types::pem::Error;
    match e {
        Error::Io(e) => format!("cannot read it: {e}"),
        Error::NoItemsFound => none.to_string(),
        other => format!("not valid PEM: {other:?}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("contact-sim-tls-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn bad_files_are_named_errors() {
        let d = temp("bad");
        let pair = rcgen::generate_simple_self_signed(vec!["localhost".into()]).unwrap();
        let cert = d.join("cert.pem");
        let key = d.join("key.pem");
        std::fs::write(&cert, pair.cert.pem()).unwrap();
        std::fs::write(&key, pair.signing_key.serialize_pem()).unwrap();
        assert!(ServerTls::load(&cert, &key).is_ok());

        let missing = d.join("missing.pem");
        let e = ServerTls::load(&missing, &key).unwrap_err();
        assert!(
            e.contains("missing.pem") && e.contains("cannot read"),
            "{e}"
        );
        let e = ServerTls::load(&cert, &missing).unwrap_err();
        assert!(e.contains("TLS key") && e.contains("cannot read"), "{e}");

        // Certificate and key swapped: neither file has what is asked of it.
        let e = ServerTls::load(&key, &cert).unwrap_err();
        assert!(e.contains("no certificate"), "{e}");
        let e = ServerTls::load(&cert, &cert).unwrap_err();
        assert!(e.contains("no private key"), "{e}");

        let garbage = d.join("garbage.pem");
        std::fs::write(
            &garbage,
            "-----BEGIN CERTIFICATE-----\n@@@@\n-----END CERTIFICATE-----\n",
        )
        .unwrap();
        let e = ServerTls::load(&garbage, &key).unwrap_err();
        assert!(e.contains("garbage.pem"), "{e}");

        // A key of another certificate.
        let other = rcgen::generate_simple_self_signed(vec!["localhost".into()]).unwrap();
        let other_key = d.join("other.pem");
        std::fs::write(&other_key, other.signing_key.serialize_pem()).unwrap();
        let e = ServerTls::load(&cert, &other_key).unwrap_err();
        assert!(e.contains("cannot be used together"), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }
}
