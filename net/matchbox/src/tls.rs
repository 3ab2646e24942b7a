//! Signaling over TLS (`wss://`, rustls with ring).
//!
//! Client: [`client_connector`] trusts the web's roots (webpki-roots) and, for a server with a
//! certificate of its own making, the CA certificates of a PEM file
//! ([`MatchboxConfig::tls_ca`](crate::MatchboxConfig::tls_ca)).
//!
//! Server: [`TlsIdentity`] (a PEM certificate chain and its key) makes a
//! [`SignalServer`](crate::SignalServer) speak TLS: the matchbox server listens on loopback
//! and a terminator in front of it takes the public port, completes each TLS handshake
//! (within [`HANDSHAKE_TIMEOUT`]) and copies bytes both ways, one thread per connection, at
//! most the server's socket limit at once (more are closed at once).

use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use async_io::Async;
use futures::io::AsyncReadExt;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};

/// How long a client may take over its TLS handshake.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

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

/// The TLS terminator in front of a signaling server: runs until dropped.
#[derive(Debug)]
pub(crate) struct Terminator {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Terminator {
    /// The public address.
    pub(crate) fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Take `listener` (the public port) and serve TLS there, each connection's plain bytes
    /// to `backend`; at most `max_conns` at once.
    pub(crate) fn start(
        listener: TcpListener,
        backend: SocketAddr,
        identity: &TlsIdentity,
        max_conns: usize,
    ) -> std::io::Result<Self> {
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let acceptor = futures_rustls::TlsAcceptor::from(identity.config.clone());
        let live = Arc::new(AtomicUsize::new(0));
        let stop2 = stop.clone();
        let thread = std::thread::Builder::new()
            .name("signaling-tls".into())
            .spawn(move || {
                for conn in listener.incoming() {
                    if stop2.load(Ordering::Acquire) {
                        break;
                    }
                    let Ok(conn) = conn else { continue };
                    if live.load(Ordering::Acquire) >= max_conns {
                        continue; // dropped: closed at once
                    }
                    live.fetch_add(1, Ordering::AcqRel);
                    let (acceptor, live) = (acceptor.clone(), live.clone());
                    let spawned = std::thread::Builder::new()
                        .name("signaling-tls-conn".into())
                        .spawn(move || {
                            let _ = async_io::block_on(proxy(conn, backend, acceptor));
                            live.fetch_sub(1, Ordering::AcqRel);
                        });
                    if spawned.is_err() {
                        // no thread for it: the connection is closed
                    }
                }
            })?;
        Ok(Terminator {
            addr,
            stop,
            thread: Some(thread),
        })
    }
}

impl Drop for Terminator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // wake the accept loop
        let _ = TcpStream::connect_timeout(&self.addr, Duration::from_secs(1));
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// One connection: the TLS handshake (bounded in time), then bytes both ways until either
/// side closes.
async fn proxy(
    conn: TcpStream,
    backend: SocketAddr,
    acceptor: futures_rustls::TlsAcceptor,
) -> std::io::Result<()> {
    let conn = Async::new(conn)?;
    let handshake = acceptor.accept(conn);
    let timeout = async {
        async_io::Timer::after(HANDSHAKE_TIMEOUT).await;
        Err(std::io::Error::new(
            std::io::ErrorKind::TimedOut,
            "TLS handshake too slow",
        ))
    };
    let tls = futures::future::select(Box::pin(handshake), Box::pin(timeout))
        .await
        .factor_first()
        .0?;
    let plain = Async::<TcpStream>::connect(backend).await?;
    let (tls_r, tls_w) = tls.split();
    let (plain_r, plain_w) = plain.split();
    let (mut plain_w, mut tls_w) = (plain_w, tls_w);
    let up = futures::io::copy(tls_r, &mut plain_w);
    let down = futures::io::copy(plain_r, &mut tls_w);
    let _ = futures::future::select(Box::pin(up), Box::pin(down)).await;
    Ok(())
}
