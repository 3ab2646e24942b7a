//! [`MatchboxTransport`]: softsync's datagram transport over WebRTC data channels.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use matchbox_socket::{
    ChannelConfig, PeerId as MbPeerId, PeerState, RtcIceServerConfig, WebRtcSocket,
};
use softsync_net::{Instant, PeerEvent, PeerId, Transmit, Transport, PROTOCOL_VERSION};

use crate::refusal::classify;
use crate::routes::{Claim, Routes};
use crate::signaller::WatchedBuilder;
use crate::{valid_room_name, DEFAULT_MTU, PROOF_PARAM, ROLE_PARAM, TOKEN_PARAM, VERSION_PARAM};

/// Channel index of the unordered, no-retransmit channel (state, acks, pings).
const UNRELIABLE: usize = 0;
/// Channel index of the ordered, reliable channel (datagrams with control sections).
const RELIABLE: usize = 1;

/// How this socket enters its room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Creates the room (refused if the room has peers).
    Host,
    /// Enters an existing room (refused if nobody is in it).
    Join,
    /// A member of the room registering with another server after its own was lost: enters
    /// the room whether or not anyone is in it yet.
    Member,
}

impl Role {
    /// The `role=` value of the room's URL.
    pub fn as_param(self) -> &'static str {
        match self {
            Role::Host => "host",
            Role::Join => "join",
            Role::Member => "member",
        }
    }
}

/// Where and how to connect.
#[derive(Clone, Debug)]
pub struct MatchboxConfig {
    /// Signaling server base URL, `ws://HOST:PORT` (or `wss://`).
    pub signal_url: String,
    /// Room name.
    pub room: String,
    /// Host or join.
    pub role: Role,
    /// ICE server URLs (`stun:` / `turn:`). Empty by default: no STUN lookups, host candidates
    /// only (LAN and loopback). Real deployments across NATs add their servers here.
    pub ice_servers: Vec<String>,
    /// TURN username.
    pub ice_username: Option<String>,
    /// TURN credential.
    pub ice_credential: Option<String>,
    /// How long to wait for the signaling server to accept us and assign an id.
    pub connect_timeout: Duration,
    /// Largest datagram sent (bigger ones are dropped and counted).
    pub mtu: usize,
    /// The protocol version announced to the signaling server (the build's own by default;
    /// tests set another to see the refusal).
    pub protocol_version: u8,
    /// For a signaling server that wants the room's key: the key, whose fresh proof
    /// (`RoomKey::signal_proof`, good for 5 minutes and once) each connection shows.
    pub signal_key: Option<softsync_net::RoomKey>,
    /// For `wss://` to a server whose certificate the web's roots do not vouch for: a PEM
    /// file of the CA certificates to trust besides them.
    pub tls_ca: Option<std::path::PathBuf>,
    /// Or a join token of the room (its text form).
    pub signal_token: Option<String>,
    /// Signaling servers to register the room with, in turn, when the current one is lost
    /// (the data channels to peers live on; new peers find us through the next one). Empty:
    /// none, and losing signaling closes it ([`MatchboxTransport::closed`]).
    pub fallback_urls: Vec<String>,
}

impl MatchboxConfig {
    /// Defaults for `room` on `signal_url`.
    pub fn new(signal_url: impl Into<String>, room: impl Into<String>, role: Role) -> Self {
        MatchboxConfig {
            signal_url: signal_url.into(),
            room: room.into(),
            role,
            ice_servers: Vec::new(),
            ice_username: None,
            ice_credential: None,
            connect_timeout: Duration::from_secs(10),
            mtu: DEFAULT_MTU,
            protocol_version: PROTOCOL_VERSION,
            signal_key: None,
            tls_ca: None,
            signal_token: None,
            fallback_urls: Vec::new(),
        }
    }

    /// The websocket URL of the room.
    pub fn room_url(&self) -> String {
        let role = self.role.as_param();
        let mut url = format!(
            "{}/{}?{VERSION_PARAM}={}&{ROLE_PARAM}={role}",
            self.signal_url.trim_end_matches('/'),
            self.room,
            self.protocol_version
        );
        if let Some(k) = &self.signal_key {
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs());
            let p = k.signal_proof(&self.room, now, fresh_nonce());
            url.push_str(&format!("&{PROOF_PARAM}={p}"));
        } else if let Some(t) = &self.signal_token {
            url.push_str(&format!("&{TOKEN_PARAM}={t}"));
        }
        url
    }
}

/// 16 random bytes for a signaling proof, from the system's source (should that fail, the
/// clock and a counter: still never the same twice in this process).
fn fresh_nonce() -> [u8; 16] {
    use ring::rand::SecureRandom;
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut n = [0u8; 16];
    if ring::rand::SystemRandom::new().fill(&mut n).is_err() {
        let t = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        n[..8].copy_from_slice(&t.to_le_bytes());
        n[8..].copy_from_slice(&COUNTER.fetch_add(1, Ordering::Relaxed).to_le_bytes());
    }
    n
}

/// Why a connection could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// The signaling URL is not `ws://…` or `wss://…`.
    #[error("invalid signaling URL {0:?}: expected ws://HOST:PORT")]
    BadUrl(String),
    /// The room name is not valid.
    #[error("invalid room name {0:?}: use 1-64 characters of A-Z a-z 0-9 - _ .")]
    BadRoom(String),
    /// Nothing answers at the signaling URL.
    #[error("signaling server {url} is unreachable: {detail}")]
    Unreachable {
        /// URL tried.
        url: String,
        /// What failed.
        detail: String,
    },
    /// Joining a room nobody is in.
    #[error("room {room:?} not found on {url}: nobody is in it (start it with `softsync host --room {room}`)")]
    RoomNotFound {
        /// Room.
        room: String,
        /// Signaling URL.
        url: String,
    },
    /// Hosting a room that already has peers.
    #[error("room {room:?} already exists on {url}: join it, or host another name")]
    RoomExists {
        /// Room.
        room: String,
        /// Signaling URL.
        url: String,
    },
    /// The server speaks another protocol version.
    #[error("protocol version mismatch: this peer speaks softsync protocol {ours}, the signaling server at {url} speaks {theirs}")]
    VersionMismatch {
        /// Ours.
        ours: u8,
        /// Theirs, as the server reported it.
        theirs: String,
        /// Signaling URL.
        url: String,
    },
    /// The server refused for another reason.
    #[error("signaling server {url} refused the connection: HTTP {status}: {body}")]
    Refused {
        /// URL.
        url: String,
        /// HTTP status.
        status: u16,
        /// Body.
        body: String,
    },
    /// No id within the timeout.
    #[error("signaling server {url} did not assign an id within {timeout:?}")]
    Timeout {
        /// URL.
        url: String,
        /// Timeout.
        timeout: Duration,
    },
    /// The socket's thread could not start.
    #[error("cannot start the WebRTC thread: {0}")]
    Thread(std::io::Error),
    /// The TLS settings could not be read (the CA file).
    #[error("signaling TLS: {0}")]
    Tls(String),
}

/// Counters of one transport.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TransportStats {
    /// Payload bytes handed to WebRTC.
    pub bytes_up: u64,
    /// Payload bytes received.
    pub bytes_down: u64,
    /// Datagrams sent.
    pub datagrams_up: u64,
    /// Datagrams received.
    pub datagrams_down: u64,
    /// Datagrams over the MTU, dropped.
    pub oversize_dropped: u64,
    /// Datagrams to peers we have no channel to, dropped.
    pub unroutable_dropped: u64,
    /// Datagrams on a channel before its peer said who it is, dropped.
    pub unidentified_dropped: u64,
    /// Channels whose peer claimed the id of a peer we already reach (ignored), or that
    /// claimed an id without the server's word and gave way to the peer it vouches for.
    pub idents_refused: u64,
    /// Idents on completed exchanges not answered: more than one per 200 ms on a channel.
    pub ident_replies_withheld: u64,
}

/// A softsync [`Transport`] over matchbox WebRTC sockets (full mesh).
///
/// One socket per signaling registration: the first, and, when its signaling server is lost
/// and [`MatchboxConfig::fallback_urls`] names others, one more on the next server that takes
/// us (the earlier sockets keep their data channels). Peers are known by the id they announce
/// on each new channel ([`IDENT_MAGIC`]), so a peer reached through two servers is one peer.
pub struct MatchboxTransport {
    socks: Vec<Option<Sock>>,
    local: PeerId,
    mb_id: MbPeerId,
    /// Identified channels and each peer's channels, and whose word an id is taken on
    /// (`routes.rs`).
    routes: Routes,
    /// Channels whose ident exchange is not complete (ours not confirmed, or theirs not
    /// heard): idents are repeated until it is (a channel's first datagrams can be lost).
    idents: HashMap<(usize, MbPeerId), IdentExchange>,
    /// Channels whose ident exchange completed, with when we last answered an ident on one
    /// (one still arriving means the other side lacks our confirmation: it is answered, at
    /// most once per [`IDENT_REPEAT`] — a peer that floods idents gets no echo of each).
    identified: HashMap<(usize, MbPeerId), std::time::Instant>,
    inbox: VecDeque<(PeerId, Vec<u8>)>,
    events: VecDeque<PeerEvent>,
    closed: Option<String>,
    stats: TransportStats,
    mtu: usize,
    cfg: MatchboxConfig,
    /// The next fallback server to try, and not before when.
    next_fallback: usize,
    retry_at: Option<std::time::Instant>,
}

/// The ident exchange on one channel.
#[derive(Clone, Copy, Debug)]
struct IdentExchange {
    /// We received its ident (accepted or not).
    heard: bool,
    /// It said it received ours.
    confirmed: bool,
    /// When we last sent ours.
    sent_at: std::time::Instant,
    /// When the channel opened (we stop repeating after [`IDENT_GIVE_UP`]).
    opened: std::time::Instant,
}

/// How often an unconfirmed ident is repeated.
const IDENT_REPEAT: Duration = Duration::from_millis(200);
/// How long an ident is repeated at most.
const IDENT_GIVE_UP: Duration = Duration::from_secs(30);

/// Send our ident on channel `mb` of `socket` (`heard`: we have theirs).
fn send_ident(socket: &mut WebRtcSocket, mb: MbPeerId, local: PeerId, heard: bool) {
    let mut ident = IDENT_MAGIC.to_vec();
    ident.extend_from_slice(&local.0.to_le_bytes());
    ident.push(u8::from(heard));
    if let Ok(ch) = socket.get_channel_mut(RELIABLE) {
        let _ = ch.try_send(ident.into(), mb);
    }
}

/// An ident datagram: the sender's id, and whether it has heard ours.
fn parse_ident(packet: &[u8]) -> Option<(PeerId, bool)> {
    if packet.len() != IDENT_LEN || packet[..4] != IDENT_MAGIC {
        return None;
    }
    let mut b = [0u8; 8];
    b.copy_from_slice(&packet[4..12]);
    Some((PeerId(u64::from_le_bytes(b)), packet[12] != 0))
}

/// One socket: a registration with one signaling server.
struct Sock {
    socket: WebRtcSocket,
    url: String,
    /// Its id on that server (none while registering).
    mb_id: Option<MbPeerId>,
    loop_done: mpsc::Receiver<Result<(), ConnectError>>,
    /// Raised when its signaling connection ends (the data channels may live on).
    lost: Arc<AtomicBool>,
    ended: bool,
    started: std::time::Instant,
}

/// The first datagram on every new data channel: these 4 bytes, then the sender's
/// softsync id (8 bytes, little-endian) and 1 if it has received the other side's ident
/// (else 0). Repeated every 200 ms until both sides have each other's: a channel's very
/// first datagrams can be lost (WebRTC may deliver before the other side's channel exists).
/// No session or share datagram starts so.
pub const IDENT_MAGIC: [u8; 4] = softsync_net::wire::CHANNEL_IDENT;

/// Bytes of an ident datagram.
const IDENT_LEN: usize = 13;

/// How long to wait before trying the next fallback signaling server after one refused us.
const FALLBACK_RETRY: Duration = Duration::from_secs(1);

impl std::fmt::Debug for MatchboxTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MatchboxTransport")
            .field("local", &self.local)
            .field("peers", &self.routes.peers().count())
            .field("sockets", &self.socks.iter().flatten().count())
            .field("closed", &self.closed)
            .finish()
    }
}

/// softsync's id of a matchbox peer: the UUID's first 64 bits.
pub fn net_id(p: MbPeerId) -> PeerId {
    PeerId(p.0.as_u64_pair().0)
}

impl MatchboxTransport {
    /// Connect to the signaling server and wait (up to `cfg.connect_timeout`) for an id.
    /// Peers connect afterwards; [`Transport::poll_peer_event`] reports them.
    pub fn connect(cfg: &MatchboxConfig) -> Result<Self, ConnectError> {
        if !(cfg.signal_url.starts_with("ws://") || cfg.signal_url.starts_with("wss://")) {
            return Err(ConnectError::BadUrl(cfg.signal_url.clone()));
        }
        if !valid_room_name(&cfg.room) {
            return Err(ConnectError::BadRoom(cfg.room.clone()));
        }
        let mut sock = Sock::open(cfg)?;
        let mb_id = loop {
            if let Some(id) = sock.socket.id() {
                break id;
            }
            if let Ok(r) = sock.loop_done.try_recv() {
                return Err(match r {
                    Ok(()) => ConnectError::Unreachable {
                        url: cfg.signal_url.clone(),
                        detail: "the signaling connection closed".into(),
                    },
                    Err(e) => e,
                });
            }
            if sock.started.elapsed() > cfg.connect_timeout {
                sock.socket.close();
                return Err(ConnectError::Timeout {
                    url: cfg.signal_url.clone(),
                    timeout: cfg.connect_timeout,
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        sock.mb_id = Some(mb_id);
        let next_fallback = cfg
            .fallback_urls
            .iter()
            .position(|u| *u == cfg.signal_url)
            .map_or(0, |i| i + 1);
        Ok(MatchboxTransport {
            socks: vec![Some(sock)],
            local: net_id(mb_id),
            mb_id,
            routes: Routes::default(),
            idents: HashMap::new(),
            identified: Default::default(),
            inbox: VecDeque::new(),
            events: VecDeque::new(),
            closed: None,
            stats: TransportStats::default(),
            mtu: cfg.mtu,
            cfg: cfg.clone(),
            next_fallback,
            retry_at: None,
        })
    }

    /// matchbox's id of this socket.
    pub fn matchbox_id(&self) -> MbPeerId {
        self.mb_id
    }

    /// Counters.
    pub fn stats(&self) -> TransportStats {
        self.stats
    }

    /// Why signaling ended with no server left to register with (the data channels may live
    /// on), once it has.
    pub fn closed(&self) -> Option<&str> {
        self.closed.as_deref()
    }

    /// Peers with open (identified) data channels.
    pub fn connected_peers(&self) -> Vec<PeerId> {
        self.routes.peers().collect()
    }

    /// The signaling server we are registered with now (the latest), if any is up.
    pub fn signaling(&self) -> Option<&str> {
        self.socks
            .iter()
            .rev()
            .flatten()
            .find(|s| s.mb_id.is_some() && !s.lost.load(Ordering::Acquire))
            .map(|s| s.url.as_str())
    }

    /// Add `url` to the servers to register with when ours is lost, first in line (a new host
    /// serving signaling itself). A URL already listed moves up.
    pub fn prefer_signaling(&mut self, url: &str) {
        self.cfg.fallback_urls.retain(|u| u != url);
        self.cfg.fallback_urls.insert(0, url.to_owned());
        self.next_fallback = 0;
        self.retry_at = None;
    }

    /// Signaling in order: register with the next fallback server once ours is lost.
    fn keep_registered(&mut self) {
        let latest = self.socks.iter().rev().flatten().next();
        let registered = latest.is_some_and(|s| !s.ended && !s.lost.load(Ordering::Acquire));
        if registered {
            return;
        }
        let registering = latest.is_some_and(|s| s.mb_id.is_none() && !s.ended);
        if registering {
            if let Some(Some(s)) = self.socks.last_mut() {
                if s.started.elapsed() > self.cfg.connect_timeout {
                    // no id from that server in time: the next one
                    s.socket.close();
                    s.ended = true;
                }
            }
            return;
        }
        if self.cfg.fallback_urls.is_empty() {
            if self.closed.is_none() {
                self.closed = Some(format!("signaling lost ({})", self.cfg.signal_url));
            }
            return;
        }
        if self.retry_at.is_some_and(|t| std::time::Instant::now() < t) {
            return;
        }
        let urls = &self.cfg.fallback_urls;
        let url = urls[self.next_fallback % urls.len()].clone();
        self.next_fallback = (self.next_fallback + 1) % urls.len();
        let mut cfg = self.cfg.clone();
        cfg.signal_url = url;
        cfg.role = Role::Member;
        match Sock::open(&cfg) {
            Ok(s) => self.socks.push(Some(s)),
            Err(_) => self.retry_at = Some(std::time::Instant::now() + FALLBACK_RETRY),
        }
    }

    /// Move what matchbox has received into our queues.
    fn pump(&mut self) {
        for i in 0..self.socks.len() {
            let Some(sock) = self.socks[i].as_mut() else {
                continue;
            };
            if sock.mb_id.is_none() {
                sock.mb_id = sock.socket.id();
            }
            if !sock.ended {
                if let Ok(r) = sock.loop_done.try_recv() {
                    sock.ended = true;
                    if i == 0 && self.cfg.fallback_urls.is_empty() {
                        self.closed = Some(match r {
                            Ok(()) => "signaling closed".into(),
                            Err(e) => e.to_string(),
                        });
                    }
                }
            }
            let changes = match sock.socket.try_update_peers() {
                Ok(c) => c,
                Err(_) => {
                    sock.ended = true;
                    Vec::new()
                }
            };
            for (mb, state) in changes {
                match state {
                    PeerState::Connected => {
                        // who we are, first on the ordered channel (repeated until confirmed)
                        let heard = self.idents.get(&(i, mb)).is_some_and(|x| x.heard);
                        send_ident(&mut sock.socket, mb, self.local, heard);
                        let now = std::time::Instant::now();
                        let x = self.idents.entry((i, mb)).or_insert(IdentExchange {
                            heard,
                            confirmed: false,
                            sent_at: now,
                            opened: now,
                        });
                        x.sent_at = now;
                    }
                    PeerState::Disconnected => {
                        self.idents.remove(&(i, mb));
                        self.identified.remove(&(i, mb));
                        if let Some(id) = self.routes.close((i, mb)) {
                            self.events.push_back(PeerEvent::Disconnected(id));
                        }
                    }
                }
            }
            let mut replies = Vec::new();
            for ch in [RELIABLE, UNRELIABLE] {
                let Ok(channel) = sock.socket.get_channel_mut(ch) else {
                    continue;
                };
                for (mb, packet) in channel.receive() {
                    self.stats.bytes_down += packet.len() as u64;
                    self.stats.datagrams_down += 1;
                    let ident = parse_ident(&packet);
                    let Some((id, has_ours)) = ident else {
                        match self.routes.peer_of(&(i, mb)) {
                            Some(id) => self.inbox.push_back((id, packet.to_vec())),
                            // before its ident: dropped (it repeats its ident)
                            None => self.stats.unidentified_dropped += 1,
                        }
                        continue;
                    };
                    // an ident (never passed on): note the exchange; answer one that lacks ours,
                    // and any on a completed exchange (the other side is still repeating: it
                    // lacks our confirmation)
                    if let Some(last) = self.identified.get_mut(&(i, mb)) {
                        let now = std::time::Instant::now();
                        if now.duration_since(*last) >= IDENT_REPEAT {
                            *last = now;
                            replies.push(mb);
                        } else {
                            self.stats.ident_replies_withheld += 1;
                        }
                    } else {
                        let now = std::time::Instant::now();
                        let x = self.idents.entry((i, mb)).or_insert(IdentExchange {
                            heard: true,
                            confirmed: false,
                            sent_at: now,
                            opened: now,
                        });
                        x.heard = true;
                        x.confirmed |= has_ours;
                        if !has_ours {
                            replies.push(mb);
                        }
                    }
                    // The server vouches for a peer's first id (its UUID's); another id is
                    // taken only for a peer we have no channel to (one that registered again
                    // after its server was lost), and gives way to the vouched one (`routes.rs`)
                    match self.routes.claim((i, mb), id, id == net_id(mb), self.local) {
                        Claim::Ignored => {}
                        Claim::Refused => self.stats.idents_refused += 1,
                        Claim::Taken { first, evicted } => {
                            self.stats.idents_refused += evicted.len() as u64;
                            if first {
                                self.events.push_back(PeerEvent::Connected(id));
                            }
                        }
                    }
                }
            }
            for mb in replies {
                send_ident(&mut sock.socket, mb, self.local, true);
            }
            // repeat idents the other side has not confirmed (or whose answer we lack)
            let now = std::time::Instant::now();
            for ((j, mb), x) in self.idents.iter_mut() {
                if *j == i
                    && !(x.heard && x.confirmed)
                    && now.duration_since(x.sent_at) >= IDENT_REPEAT
                    && now.duration_since(x.opened) < IDENT_GIVE_UP
                {
                    x.sent_at = now;
                    send_ident(&mut sock.socket, *mb, self.local, x.heard);
                }
            }
            let identified = &mut self.identified;
            self.idents.retain(|key, x| {
                if x.heard && x.confirmed {
                    identified.insert(*key, now.checked_sub(IDENT_REPEAT).unwrap_or(now));
                    return false;
                }
                now.duration_since(x.opened) < IDENT_GIVE_UP
            });
        }
        // a socket whose signaling and channels are both gone is dropped (its slot stays, so
        // the channel keys of the others do not move)
        let n = self.socks.len();
        for (i, slot) in self.socks.iter_mut().enumerate() {
            let dead = slot.as_ref().is_some_and(|s| {
                (s.ended || s.lost.load(Ordering::Acquire))
                    && !self.routes.uses_socket(i)
                    && s.socket.connected_peers().next().is_none()
            });
            let is_latest_attempt = i + 1 == n;
            if dead && !is_latest_attempt {
                *slot = None;
            } else if dead && slot.as_ref().is_some_and(|s| s.mb_id.is_none()) {
                // the latest attempt failed: try the next server after a pause
                *slot = None;
                self.retry_at = Some(std::time::Instant::now() + FALLBACK_RETRY);
            }
        }
        self.keep_registered();
    }
}

impl Sock {
    /// Start registering with `cfg.signal_url` (the id comes later, see [`Sock::mb_id`]).
    fn open(cfg: &MatchboxConfig) -> Result<Sock, ConnectError> {
        let ice = RtcIceServerConfig {
            urls: cfg.ice_servers.clone(),
            username: cfg.ice_username.clone(),
            credential: cfg.ice_credential.clone(),
        };
        let watch = WatchedBuilder {
            tls: Some(
                crate::tls::client_connector(cfg.tls_ca.as_deref()).map_err(ConnectError::Tls)?,
            ),
            ..WatchedBuilder::default()
        };
        let lost = watch.lost.clone();
        let (socket, message_loop) = WebRtcSocket::builder(cfg.room_url())
            .ice_server(ice)
            .signaller_builder(Arc::new(watch))
            .reconnect_attempts(Some(1))
            .signaling_keep_alive_interval(Some(Duration::from_secs(5)))
            .add_channel(ChannelConfig::unreliable())
            .add_channel(ChannelConfig::reliable())
            .build();
        let (done_tx, loop_done) = mpsc::channel();
        let cfg2 = cfg.clone();
        std::thread::Builder::new()
            .name("webrtc".into())
            .spawn(move || {
                let r = async_io::block_on(message_loop);
                let _ = done_tx.send(r.map_err(|e| classify(&e, &cfg2)));
            })
            .map_err(ConnectError::Thread)?;
        Ok(Sock {
            socket,
            url: cfg.signal_url.clone(),
            mb_id: None,
            loop_done,
            lost,
            ended: false,
            started: std::time::Instant::now(),
        })
    }
}

impl Transport for MatchboxTransport {
    fn local_id(&self) -> PeerId {
        self.local
    }

    fn send(&mut self, _now: Instant, transmit: &Transmit) {
        let (to, datagram) = (transmit.to, &transmit.payload);
        if datagram.len() > self.mtu {
            self.stats.oversize_dropped += 1;
            return;
        }
        let Some((i, mb)) = self.routes.route(to) else {
            self.stats.unroutable_dropped += 1;
            return;
        };
        let Some(sock) = self.socks.get_mut(i).and_then(Option::as_mut) else {
            self.stats.unroutable_dropped += 1;
            return;
        };
        // The session says which datagrams carry control messages (and refusals): those go
        // on the reliable, ordered channel; state and heartbeats on the unreliable one.
        let ch = if transmit.reliable {
            RELIABLE
        } else {
            UNRELIABLE
        };
        let Ok(channel) = sock.socket.get_channel_mut(ch) else {
            self.stats.unroutable_dropped += 1;
            return;
        };
        match channel.try_send(datagram.to_vec().into(), mb) {
            Ok(()) => {
                self.stats.bytes_up += datagram.len() as u64;
                self.stats.datagrams_up += 1;
            }
            Err(_) => self.stats.unroutable_dropped += 1,
        }
    }

    fn recv(&mut self, _now: Instant) -> Option<(PeerId, Vec<u8>)> {
        if self.inbox.is_empty() {
            self.pump();
        }
        self.inbox.pop_front()
    }

    fn poll_peer_event(&mut self) -> Option<PeerEvent> {
        if self.events.is_empty() {
            self.pump();
        }
        self.events.pop_front()
    }

    fn mtu(&self) -> usize {
        self.mtu
    }

    fn prefer_signaling(&mut self, url: &str) {
        MatchboxTransport::prefer_signaling(self, url);
    }

    fn relayed(&self, peer: PeerId) -> Option<bool> {
        let (i, mb) = self.routes.route(peer)?;
        self.socks.get(i)?.as_ref()?.socket.is_relayed(mb)
    }
}

impl Drop for MatchboxTransport {
    fn drop(&mut self) {
        for s in self.socks.iter_mut().flatten() {
            s.socket.close();
        }
    }
}
