//! Signaling over TLS (`wss://`, rustls with ring).
//!
//! Client: [`client_connector`] trusts the web's roots (webpki-roots) and, for a server with a
//! certificate of its own making, the CA certificates of a PEM file
//! ([`MatchboxConfig::tls_ca`](crate::MatchboxConfig::tls_ca)).
//!
//! Server: [`TlsIdentity`] (a PEM certificate chain and its key) makes a
//! [`SignalServer`](crate::SignalServer) speak TLS: its front gate (`gate.rs`) completes each
//! TLS handshake within the server's upgrade timeout, then checks the plain bytes as it does
//! for `ws://`.

use std::path::Path;
use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};

fn provider() -> Arc<rustls::crypto::CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// A server's certificate chain and key, for `wss://`.
#[derive(Clone)]
pub struct TlsIdentity {
    config: Arc<rustls::ServerConfig>,
}

impl std::fmt::Debug for TlsIdentity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TlsIdentity(..)")
    }
}

impl TlsIdentity {
    /// From PEM files: `cert` the chain (leaf first), `key` its private key (PKCS#8, PKCS#1
    /// or SEC1). An error names the file and what is wrong.
    pub fn from_pem_files(cert: &Path, key: &Path) -> Result<Self, String> {
        let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(cert)
            .map_err(|e| format!("TLS certificate {}: {e}", cert.display()))?
            .collect::<Result<_, _>>()
            .map_err(|e| format!("TLS certificate {}: {e}", cert.display()))?;
        if chain.is_empty() {
            return Err(format!(
                "TLS certificate {}: no certificate in it",
                cert.display()
            ));
        }
        let key = PrivateKeyDer::from_pem_file(key)
            .map_err(|e| format!("TLS key {}: {e}", key.display()))?;
        let config = rustls::ServerConfig::builder_with_provider(provider())
            .with_safe_default_protocol_versions()
            .map_err(|e| e.to_string())?
            .with_no_client_auth()
            .with_single_cert(chain, key)
            .map_err(|e| format!("TLS certificate and key: {e}"))?;
        Ok(TlsIdentity {
            config: Arc::new(config),
        })
    }

    /// The server side of the handshake.
    pub(crate) fn acceptor(&self) -> futures_rustls::TlsAcceptor {
        futures_rustls::TlsAcceptor::from(self.config.clone())
    }
}

/// What a client trusts for `wss://`: the web's roots, and the certificates of `extra_ca`
/// (PEM) if given.
pub fn client_connector(extra_ca: Option<&Path>) -> Result<futures_rustls::TlsConnector, String> {
    let mut roots = rustls::RootCertStore {
        roots: webpki_roots::TLS_SERVER_ROOTS.to_vec(),
    };
    if let Some(p) = extra_ca {
        let certs = CertificateDer::pem_file_iter(p)
            .map_err(|e| format!("TLS CA file {}: {e}", p.display()))?;
        let mut n = 0;
        for c in certs {
            let c = c.map_err(|e| format!("TLS CA file {}: {e}", p.display()))?;
            roots
                .add(c)
                .map_err(|e| format!("TLS CA file {}: {e}", p.display()))?;
            n += 1;
        }
        if n == 0 {
            return Err(format!("TLS CA file {}: no certificate in it", p.display()));
        }
    }
    let config = rustls::ClientConfig::builder_with_provider(provider())
        .with_safe_default_protocol_versions()
        .map_err(|e| e.to_string())?
        .with_root_certificates(roots)
        .with_no_client_auth();
    Ok(futures_rustls::TlsConnector::from(Arc::new(config)))
}
