//! [`MatchboxTransport`]: softsync's datagram transport over WebRTC data channels.

use std::collections::{HashMap, VecDeque};
use std::sync::mpsc;
use std::time::Duration;

use matchbox_socket::{
    ChannelConfig, PeerId as MbPeerId, PeerState, RtcIceServerConfig, SignalingError, WebRtcSocket,
};
use softsync_net::{Instant, PeerEvent, PeerId, Transmit, Transport, PROTOCOL_VERSION};

use crate::{
    valid_room_name, DEFAULT_MTU, PROOF_PARAM, ROLE_PARAM, TOKEN_PARAM, VERSION_HEADER,
    VERSION_PARAM,
};

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
    /// For a signaling server that wants the room's key: `RoomKey::signal_proof` of the room.
    pub signal_proof: Option<String>,
    /// Or a join token of the room (its text form).
    pub signal_token: Option<String>,
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
            signal_proof: None,
            signal_token: None,
        }
    }

    /// The websocket URL of the room.
    pub fn room_url(&self) -> String {
        let role = match self.role {
            Role::Host => "host",
            Role::Join => "join",
        };
        let mut url = format!(
            "{}/{}?{VERSION_PARAM}={}&{ROLE_PARAM}={role}",
            self.signal_url.trim_end_matches('/'),
            self.room,
            self.protocol_version
        );
        if let Some(p) = &self.signal_proof {
            url.push_str(&format!("&{PROOF_PARAM}={p}"));
        } else if let Some(t) = &self.signal_token {
            url.push_str(&format!("&{TOKEN_PARAM}={t}"));
        }
        url
    }
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
}

/// A softsync [`Transport`] over a matchbox WebRTC socket (full mesh).
pub struct MatchboxTransport {
    socket: WebRtcSocket,
    local: PeerId,
    mb_id: MbPeerId,
    uuid_of: HashMap<PeerId, MbPeerId>,
    inbox: VecDeque<(PeerId, Vec<u8>)>,
    events: VecDeque<PeerEvent>,
    loop_done: mpsc::Receiver<Result<(), ConnectError>>,
    closed: Option<String>,
    stats: TransportStats,
    mtu: usize,
}

impl std::fmt::Debug for MatchboxTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MatchboxTransport")
            .field("local", &self.local)
            .field("peers", &self.uuid_of.len())
            .field("closed", &self.closed)
            .finish()
    }
}

/// softsync's id of a matchbox peer: the UUID's first 64 bits.
pub fn net_id(p: MbPeerId) -> PeerId {
    PeerId(p.0.as_u64_pair().0)
}

fn classify(err: &matchbox_socket::Error, cfg: &MatchboxConfig) -> ConnectError {
    let url = cfg.signal_url.clone();
    let sig = match err {
        matchbox_socket::Error::ConnectionFailed(s) | matchbox_socket::Error::Disconnected(s) => s,
    };
    let sig = match sig {
        SignalingError::NegotiationFailed(inner) => inner.as_ref(),
        other => other,
    };
    if let SignalingError::WebSocket(ws) = sig {
        if let async_tungstenite::tungstenite::Error::Http(resp) = ws {
            let status = resp.status().as_u16();
            let body = resp
                .body()
                .as_ref()
                .map(|b| String::from_utf8_lossy(b).into_owned())
                .unwrap_or_default();
            let theirs = resp
                .headers()
                .get(VERSION_HEADER)
                .and_then(|v| v.to_str().ok())
                .map(str::to_owned);
            return match status {
                404 => ConnectError::RoomNotFound {
                    room: cfg.room.clone(),
                    url,
                },
                409 if body.contains("is full") => ConnectError::Refused { url, status, body },
                409 => ConnectError::RoomExists {
                    room: cfg.room.clone(),
                    url,
                },
                426 => ConnectError::VersionMismatch {
                    ours: cfg.protocol_version,
                    theirs: theirs.unwrap_or_else(|| "an unknown version".into()),
                    url,
                },
                // Not our signaling server at all (no version header): say so.
                _ if theirs.is_none() => ConnectError::Refused {
                    url,
                    status,
                    body: format!("{body} (not a softsync signaling server?)"),
                },
                _ => ConnectError::Refused { url, status, body },
            };
        }
        return ConnectError::Unreachable {
            url,
            detail: ws.to_string(),
        };
    }
    ConnectError::Unreachable {
        url,
        detail: sig.to_string(),
    }
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
        let ice = RtcIceServerConfig {
            urls: cfg.ice_servers.clone(),
            username: cfg.ice_username.clone(),
            credential: cfg.ice_credential.clone(),
        };
        let (mut socket, message_loop) = WebRtcSocket::builder(cfg.room_url())
            .ice_server(ice)
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
        let start = std::time::Instant::now();
        let mb_id = loop {
            if let Some(id) = socket.id() {
                break id;
            }
            if let Ok(r) = loop_done.try_recv() {
                return Err(match r {
                    Ok(()) => ConnectError::Unreachable {
                        url: cfg.signal_url.clone(),
                        detail: "the signaling connection closed".into(),
                    },
                    Err(e) => e,
                });
            }
            if start.elapsed() > cfg.connect_timeout {
                socket.close();
                return Err(ConnectError::Timeout {
                    url: cfg.signal_url.clone(),
                    timeout: cfg.connect_timeout,
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        Ok(MatchboxTransport {
            socket,
            local: net_id(mb_id),
            mb_id,
            uuid_of: HashMap::new(),
            inbox: VecDeque::new(),
            events: VecDeque::new(),
            loop_done,
            closed: None,
            stats: TransportStats::default(),
            mtu: cfg.mtu,
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

    /// Why the socket's message loop ended (signaling lost), once it has.
    pub fn closed(&self) -> Option<&str> {
        self.closed.as_deref()
    }

    /// Peers with open data channels.
    pub fn connected_peers(&self) -> Vec<PeerId> {
        self.socket.connected_peers().map(net_id).collect()
    }

    /// Move what matchbox has received into our queues.
    fn pump(&mut self) {
        if self.closed.is_none() {
            if let Ok(r) = self.loop_done.try_recv() {
                self.closed = Some(match r {
                    Ok(()) => "signaling closed".into(),
                    Err(e) => e.to_string(),
                });
            }
        }
        match self.socket.try_update_peers() {
            Ok(changes) => {
                for (mb, state) in changes {
                    let id = net_id(mb);
                    match state {
                        PeerState::Connected => {
                            self.uuid_of.insert(id, mb);
                            self.events.push_back(PeerEvent::Connected(id));
                        }
                        PeerState::Disconnected => {
                            self.uuid_of.remove(&id);
                            self.events.push_back(PeerEvent::Disconnected(id));
                        }
                    }
                }
            }
            Err(_) => {
                if self.closed.is_none() {
                    self.closed = Some("the WebRTC socket closed".into());
                }
            }
        }
        for ch in [RELIABLE, UNRELIABLE] {
            let Ok(channel) = self.socket.get_channel_mut(ch) else {
                continue;
            };
            for (mb, packet) in channel.receive() {
                let id = net_id(mb);
                self.uuid_of.entry(id).or_insert(mb);
                self.stats.bytes_down += packet.len() as u64;
                self.stats.datagrams_down += 1;
                self.inbox.push_back((id, packet.to_vec()));
            }
        }
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
        let Some(mb) = self.uuid_of.get(&to).copied() else {
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
        let Ok(channel) = self.socket.get_channel_mut(ch) else {
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
}

impl Drop for MatchboxTransport {
    fn drop(&mut self) {
        self.socket.close();
    }
}
