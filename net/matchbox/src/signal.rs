//! The room signaling server: matchbox's full-mesh topology plus a room registry that refuses
//! wrong protocol versions, joins to empty rooms and second hosts.

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use matchbox_signaling::SignalingServer;
use matchbox_socket::PeerId as MbPeerId;
use softsync_net::PROTOCOL_VERSION;

use softsync_net::wire::RoomToken;
use softsync_net::RoomKey;

use crate::gate::{Gate, GateStats};
use crate::tls::TlsIdentity;
use crate::{valid_room_name, PROOF_PARAM, ROLE_PARAM, TOKEN_PARAM, VERSION_HEADER, VERSION_PARAM};

/// Why the signaling server could not start.
#[derive(Debug, thiserror::Error)]
pub enum SignalError {
    /// The address could not be bound.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// Address asked for.
        addr: SocketAddr,
        /// The OS error.
        source: std::io::Error,
    },
    /// The server's runtime could not start.
    #[error("cannot start the signaling runtime: {0}")]
    Runtime(std::io::Error),
}

/// A room as the signaling server sees it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RoomInfo {
    /// Name.
    pub name: String,
    /// Sockets connected to it.
    pub peers: usize,
}

/// What one signaling server accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SignalLimits {
    /// Sockets in all rooms together (HTTP 503 beyond).
    pub max_sockets: usize,
    /// Sockets in one room (HTTP 409 beyond); the session's own member cap is 64.
    pub max_per_room: usize,
    /// Connections from one address at once (more are closed at once). Behind a load
    /// balancer every connection comes from its address: raise this there.
    pub max_per_source: usize,
    /// Time for the TLS handshake and the HTTP upgrade request together.
    pub upgrade_timeout: Duration,
    /// Longest websocket message a client may send (matchbox's signals are SDP and ICE
    /// candidates, a few KiB).
    pub max_message_bytes: usize,
    /// Websocket messages per second per connection (ten seconds' worth in a burst).
    pub messages_per_s: u32,
    /// Bytes per second per connection (ten seconds' worth in a burst).
    pub bytes_per_s: u32,
    /// A connection silent this long is closed (matchbox sends a keep-alive every 10 s).
    pub idle_timeout: Duration,
    /// A connection throttled this long in all (its messages waiting for the rates) is a
    /// flood, and closed.
    pub throttle_limit: Duration,
}

impl Default for SignalLimits {
    fn default() -> Self {
        SignalLimits {
            max_sockets: 1024,
            max_per_room: 64,
            max_per_source: 256,
            upgrade_timeout: Duration::from_secs(10),
            max_message_bytes: 64 * 1024,
            messages_per_s: 100,
            bytes_per_s: 256 * 1024,
            idle_timeout: Duration::from_secs(60),
            throttle_limit: Duration::from_secs(10),
        }
    }
}

/// An accepted upgrade that never got an id (the client went away mid-handshake) stops
/// counting after this long.
const PENDING_EXPIRY: Duration = Duration::from_secs(30);
/// Most room-key proofs remembered (each until it expires, 5 minutes at most): past it, new
/// keyed connections wait.
pub const MAX_PROOF_NONCES: usize = 65_536;

#[derive(Default, Debug)]
struct Registry {
    /// Connected (or connecting) sockets per room.
    rooms: BTreeMap<String, usize>,
    /// Accepted upgrade requests waiting for their id, by client address.
    pending: HashMap<SocketAddr, (String, Instant)>,
    /// Room of every socket that has an id.
    peers: HashMap<MbPeerId, String>,
    /// Nonces of the room-key proofs that let a connection in, until their expiry: a proof
    /// is good once (a replayed URL is refused).
    nonces: BTreeMap<[u8; 16], u64>,
}

impl Registry {
    fn leave_room(&mut self, room: &str) {
        if let Some(n) = self.rooms.get_mut(room) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                self.rooms.remove(room);
            }
        }
    }

    fn expire_pending(&mut self, now: Instant) {
        let stale: Vec<SocketAddr> = self
            .pending
            .iter()
            .filter(|(_, (_, at))| now.duration_since(*at) > PENDING_EXPIRY)
            .map(|(a, _)| *a)
            .collect();
        for a in stale {
            if let Some((room, _)) = self.pending.remove(&a) {
                self.leave_room(&room);
            }
        }
    }

    fn sockets(&self) -> usize {
        self.rooms.values().sum()
    }
}

fn lock(r: &Mutex<Registry>) -> MutexGuard<'_, Registry> {
    // A panic in a callback must not take the server down with a poisoned lock.
    r.lock().unwrap_or_else(|e| e.into_inner())
}

fn refuse(status: StatusCode, msg: String) -> Response {
    (
        status,
        [(VERSION_HEADER, PROTOCOL_VERSION.to_string())],
        msg,
    )
        .into_response()
}

/// A running signaling server; stops when dropped (or with [`SignalServer::stop`]).
#[derive(Debug)]
pub struct SignalServer {
    addr: SocketAddr,
    registry: Arc<Mutex<Registry>>,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
    /// The front gate (`gate.rs`) on the public port.
    gate: Option<Gate>,
    tls: bool,
}

impl SignalServer {
    /// Bind `bind` (port 0 picks a free port) and serve on a thread of its own, with the
    /// default limits.
    pub fn start(bind: SocketAddr) -> Result<Self, SignalError> {
        Self::start_with(bind, SignalLimits::default())
    }

    /// [`SignalServer::start`] with explicit limits.
    pub fn start_with(bind: SocketAddr, limits: SignalLimits) -> Result<Self, SignalError> {
        Self::start_keyed(bind, limits, None)
    }

    /// [`SignalServer::start_with`] for rooms with a key: a connection must carry the key's
    /// proof for its room (`RoomKey::signal_proof`) or an unexpired join token of it, else HTTP
    /// 403 — outsiders do not even learn the peers' ids. `None`: every room is open.
    pub fn start_keyed(
        bind: SocketAddr,
        limits: SignalLimits,
        key: Option<RoomKey>,
    ) -> Result<Self, SignalError> {
        Self::start_secure(bind, limits, key, None)
    }

    /// [`SignalServer::start_keyed`], over TLS (`wss://`) when `tls` is given. The matchbox
    /// server listens on loopback; the front gate (`gate.rs`: connection counts, time limits,
    /// frame rules and rates, and TLS) takes `bind`.
    pub fn start_secure(
        bind: SocketAddr,
        limits: SignalLimits,
        key: Option<RoomKey>,
        tls: Option<TlsIdentity>,
    ) -> Result<Self, SignalError> {
        let public = std::net::TcpListener::bind(bind)
            .map_err(|source| SignalError::Bind { addr: bind, source })?;
        let public_addr = bind;
        let bind = SocketAddr::from(([127, 0, 0, 1], 0));
        let registry = Arc::new(Mutex::new(Registry::default()));
        let (tx, rx) = tokio::sync::oneshot::channel();
        let (r1, r2, r3) = (registry.clone(), registry.clone(), registry.clone());
        let mut server = SignalingServer::full_mesh_builder(bind)
            // matchbox fixes the callback type (its Err is an axum Response).
            .on_connection_request(#[allow(clippy::result_large_err)] move |meta| {
                let room = meta.path.clone().unwrap_or_default();
                let version = meta.query_params.get(VERSION_PARAM).cloned();
                if version.as_deref() != Some(&PROTOCOL_VERSION.to_string()) {
                    return Err(refuse(
                        StatusCode::UPGRADE_REQUIRED,
                        format!(
                            "protocol version mismatch: this server speaks softsync protocol {PROTOCOL_VERSION}, the client {}",
                            version.as_deref().unwrap_or("none")
                        ),
                    ));
                }
                if !valid_room_name(&room) {
                    return Err(refuse(
                        StatusCode::BAD_REQUEST,
                        format!("invalid room name {room:?}"),
                    ));
                }
                let unix_now = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_secs());
                let mut proven = None;
                if let Some(k) = &key {
                    let proof = meta.query_params.get(PROOF_PARAM).map(String::as_str);
                    let token = meta
                        .query_params
                        .get(TOKEN_PARAM)
                        .and_then(|t| t.parse::<RoomToken>().ok());
                    let verdict = match (proof, token) {
                        (Some(p), _) => k.check_signal_proof(&room, p, unix_now).map(Some),
                        (None, Some(t)) if k.admits_signal_token(&room, &t, unix_now) => Ok(None),
                        (None, Some(_)) => Err("the join token is not this room's, or expired"),
                        (None, None) => Err("no key's proof or join token"),
                    };
                    match verdict {
                        Ok(p) => proven = p,
                        Err(why) => {
                            return Err(refuse(
                                StatusCode::FORBIDDEN,
                                format!(
                                    "room {room:?} needs its key on this signaling server \
                                     (--room-key-file, or a join token: --room-token): {why}"
                                ),
                            ))
                        }
                    }
                }
                let role = meta.query_params.get(ROLE_PARAM).map(String::as_str);
                let mut reg = lock(&r1);
                reg.expire_pending(Instant::now());
                if let Some((nonce, _)) = proven {
                    reg.nonces.retain(|_, exp| *exp > unix_now);
                    if reg.nonces.contains_key(&nonce) {
                        return Err(refuse(
                            StatusCode::FORBIDDEN,
                            format!(
                                "room {room:?}: this room-key proof was used already (a \
                                 replayed URL); a peer makes a fresh one for each connection"
                            ),
                        ));
                    }
                    if reg.nonces.len() >= MAX_PROOF_NONCES {
                        return Err(refuse(
                            StatusCode::SERVICE_UNAVAILABLE,
                            "too many keyed connections in the last minutes: try again".into(),
                        ));
                    }
                }
                if reg.sockets() >= limits.max_sockets {
                    return Err(refuse(
                        StatusCode::SERVICE_UNAVAILABLE,
                        format!("the signaling server is full ({} sockets)", limits.max_sockets),
                    ));
                }
                let present = reg.rooms.get(&room).copied().unwrap_or(0);
                if present >= limits.max_per_room {
                    return Err(refuse(
                        StatusCode::CONFLICT,
                        format!("room {room:?} is full ({present} peers)"),
                    ));
                }
                match role {
                    Some("host") if present > 0 => {
                        return Err(refuse(
                            StatusCode::CONFLICT,
                            format!("room {room:?} already exists ({present} peers in it)"),
                        ))
                    }
                    Some("join") if present == 0 => {
                        return Err(refuse(
                            StatusCode::NOT_FOUND,
                            format!("room {room:?} not found: nobody is in it"),
                        ))
                    }
                    Some("host") | Some("join") | Some("member") => {}
                    other => {
                        return Err(refuse(
                            StatusCode::BAD_REQUEST,
                            format!("role must be host, join or member, not {other:?}"),
                        ))
                    }
                }
                if let Some((nonce, exp)) = proven {
                    reg.nonces.insert(nonce, exp);
                }
                *reg.rooms.entry(room.clone()).or_insert(0) += 1;
                if let Some((old, _)) = reg.pending.insert(meta.origin, (room, Instant::now())) {
                    reg.leave_room(&old); // the same address again: its first try failed
                }
                Ok(true)
            })
            .on_id_assignment(move |(origin, peer)| {
                let mut reg = lock(&r2);
                if let Some((room, _)) = reg.pending.remove(&origin) {
                    reg.peers.insert(peer, room);
                }
            })
            .on_peer_disconnected(move |peer| {
                let mut reg = lock(&r3);
                if let Some(room) = reg.peers.remove(&peer) {
                    reg.leave_room(&room);
                }
            })
            .with_shutdown(rx)
            .build();
        let addr = server.bind().map_err(|e| SignalError::Bind {
            addr: bind,
            source: match e {
                matchbox_signaling::Error::Bind(io) => io,
                other => std::io::Error::other(other.to_string()),
            },
        })?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(SignalError::Runtime)?;
        let thread = std::thread::Builder::new()
            .name("signaling".into())
            .spawn(move || {
                if let Err(e) = runtime.block_on(server.serve()) {
                    eprintln!("signaling server stopped: {e}");
                }
            })
            .map_err(SignalError::Runtime)?;
        let secure = tls.is_some();
        let acceptor = tls.map(|t| t.acceptor());
        let gate =
            Gate::start(public, addr, acceptor, limits).map_err(|source| SignalError::Bind {
                addr: public_addr,
                source,
            })?;
        Ok(SignalServer {
            addr: gate.addr(),
            registry,
            shutdown: Some(tx),
            thread: Some(thread),
            gate: Some(gate),
            tls: secure,
        })
    }

    /// The bound address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The server's base URL, `ws://ADDR` (`wss://ADDR` over TLS).
    pub fn url(&self) -> String {
        let scheme = if self.tls { "wss" } else { "ws" };
        format!("{scheme}://{}", self.addr)
    }

    /// The rooms that have peers, by name.
    pub fn rooms(&self) -> Vec<RoomInfo> {
        lock(&self.registry)
            .rooms
            .iter()
            .map(|(name, peers)| RoomInfo {
                name: name.clone(),
                peers: *peers,
            })
            .collect()
    }

    /// What the front gate has let in, refused and closed.
    pub fn gate_stats(&self) -> GateStats {
        self.gate.as_ref().map(Gate::stats).unwrap_or_default()
    }

    /// Stop serving: close every websocket and wait (a few seconds at most) for the thread.
    pub fn stop(mut self) {
        self.shutdown_now();
    }

    fn shutdown_now(&mut self) {
        self.gate.take();
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for SignalServer {
    fn drop(&mut self) {
        self.shutdown_now();
    }
}
