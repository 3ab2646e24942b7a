//! [`RoomOptions`]: how a room is opened (name, host or join, signaling, ICE, replication,
//! the peer's settings, voice), and [`OpenError`], why it could not be or could not go on.
//! Apart from [`crate::room`] so that the connection code and the room both import them
//! without importing each other.

// The wall clock at the session's time zero, for join tokens' expiry.
#![allow(clippy::disallowed_methods)]

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use softsync_net::messages::{Message, MessageTypes, RegisterError};
use softsync_net::{ConditionerConfig, RoomKey, SendPolicy, SessionConfig};
use softsync_net_matchbox::TlsIdentity;
use softsync_peer::{PeerConfig, Scene};
use softsync_store::keeper::StoreOptions;

/// How a room is opened: its name, host or join, signaling, ICE, the replication policy and
/// the peer's settings. [`RoomOptions::host`] and [`RoomOptions::join`] give the defaults of
/// `softsync host` and `softsync join`.
#[derive(Clone, Debug)]
pub struct RoomOptions {
    /// The room's name (peers with the same name and signaling server meet).
    pub name: String,
    /// Create the room (and spawn the scene's objects) rather than join it.
    pub host: bool,
    /// The signaling server's URL (`ws://…`). A host without one embeds a server on
    /// [`bind`](Self::bind); a joiner needs one.
    pub signal: Option<String>,
    /// Where a host's embedded signaling server listens.
    pub bind: SocketAddr,
    /// A joiner's address for the room's signaling should it become host after the host that
    /// served signaling died (see [`Room`](crate::Room)'s docs on signaling). None: it serves none.
    pub takeover_bind: Option<SocketAddr>,
    /// The embedded signaling server's certificate and key: it then speaks `wss://` (a host's
    /// own, or a new host's after a takeover).
    pub tls: Option<TlsIdentity>,
    /// For `wss://` signaling whose certificate the web's roots do not vouch for: a PEM file
    /// of the CA certificates to trust besides them.
    pub tls_ca: Option<PathBuf>,
    /// STUN/TURN servers (`stun:…`, `turn:…`); none on a LAN.
    pub ice_servers: Vec<String>,
    /// TURN credentials.
    pub ice_username: Option<String>,
    /// TURN credentials.
    pub ice_credential: Option<String>,
    /// How long to wait for signaling, the first data channel and the host's welcome.
    pub connect_timeout: Duration,
    /// The room's shared secret: only peers that know it get in (or show a join token it
    /// signed, see [`RoomKey::issue_token`]).
    pub room_key: Option<RoomKey>,
    /// A join token to show a room with a key when we hold no key.
    pub room_token: Option<softsync_net::wire::RoomToken>,
    /// A seeded link conditioner over the real transport (loss and latency in tests).
    pub condition: Option<ConditionerConfig>,
    /// How often and how precisely objects are sent (the scene's classes refine it).
    pub send: SendPolicy,
    /// Hands, the fixed step, the avatar, rejoining.
    pub peer: PeerConfig,
    /// The application's message types beyond the built-in ones and the scene's `messages`
    /// (every peer of the room must register the same, in the same order).
    pub messages: MessageTypes,
    /// Start pumping the network at once (true), or only after [`Room::set_ready`](crate::Room::set_ready) (a front
    /// end whose first frames stall — a window, an XR session — would otherwise be timed out
    /// by the host while it warms up).
    pub start_ready: bool,
    /// Where a joiner without the scene ([`Room::open_fetching_scene`](crate::Room::open_fetching_scene)) keeps the scene it
    /// receives (a folder per scene, named by its digest). Default: this user's private cache
    /// ([`softsync_peer::scene::cache::default_scene_cache`]), checked and cleaned at each use.
    pub scene_cache: PathBuf,
    /// The adaptive failure detector with 50 ms heartbeats
    /// ([`SessionConfig::fast_detection`], the default): a dead host is replaced in about a
    /// third of a second, a host stopped for less than 250 ms never is. `false`: the fixed
    /// 1 s timeout and 200 ms heartbeats ([`SessionConfig::fixed_detection`]). Every peer of
    /// the room should choose the same.
    pub fast_detection: bool,
    /// This peer's uplink budget, bytes a second, shared by its links; objects wait their
    /// turn by priority (held ones first, then by motion, interest and waiting time). `None`:
    /// no cap. See `softsync_net::SessionConfig::uplink_bytes_per_s`.
    pub uplink_bytes_per_s: Option<u32>,
    /// Which way object state travels: through the host (default) or from each owner to
    /// every member (`softsync_net::StateRoute`). Every peer of the room must set the same
    /// (a joiner with another is refused at the handshake).
    pub state_route: softsync_net::StateRoute,
    /// The host takes no more than this many members, itself included; a joiner beyond it is
    /// refused with "the room is full (N members)". Every peer of the room must set the same
    /// (it is part of the handshake's digest, so a new host after a migration keeps it).
    /// Default 64, the session's limit.
    pub max_members: usize,
    /// Keep the room in a store ([`softsync_store::keeper`]): a host reopens the room kept there and
    /// writes it as it runs; a joiner writes it if it becomes host. `None`: not kept.
    pub store: Option<StoreOptions>,
    /// A host spawns its scene's objects at open (the default); false leaves the room empty
    /// for the application to fill (a recording played back: `softsync replay --serve`).
    pub spawn_scene: bool,
    /// Voice in the room ([`crate::voice`]): `None` sends and plays none (voice datagrams
    /// that arrive are dropped, counted by the front door).
    pub voice: Option<crate::voice::VoiceOptions>,
    /// Our name and colour for the others (`softsync_peer::messages::Presence`), sent with
    /// our head (again whenever it is spawned anew); `None`: others show our id.
    pub presence: Option<softsync_peer::messages::Presence>,
}

impl RoomOptions {
    /// Create room `name` with an embedded signaling server on `127.0.0.1:3536`.
    pub fn host(name: impl Into<String>) -> Self {
        RoomOptions {
            name: name.into(),
            host: true,
            signal: None,
            bind: SocketAddr::from(([127, 0, 0, 1], 3536)),
            takeover_bind: None,
            tls: None,
            tls_ca: None,
            ice_servers: Vec::new(),
            ice_username: None,
            ice_credential: None,
            connect_timeout: Duration::from_secs(15),
            room_key: None,
            room_token: None,
            condition: None,
            send: SendPolicy {
                rate_hz: 20.0,
                position_threshold_m: 0.005,
                particle_threshold_m: 0.005,
                ..SendPolicy::default()
            },
            peer: PeerConfig::default(),
            messages: MessageTypes::new(),
            start_ready: true,
            scene_cache: softsync_peer::scene::cache::default_scene_cache(),
            fast_detection: true,
            uplink_bytes_per_s: None,
            state_route: softsync_net::StateRoute::Relay,
            max_members: softsync_net::SessionConfig::default().max_members,
            store: None,
            spawn_scene: true,
            voice: None,
            presence: None,
        }
    }

    /// Join room `name` through the signaling server at `signal`.
    pub fn join(name: impl Into<String>, signal: impl Into<String>) -> Self {
        RoomOptions {
            host: false,
            signal: Some(signal.into()),
            ..RoomOptions::host(name)
        }
    }

    /// The command line of a small softsync app: `host ROOM [BIND]` (an embedded signaling
    /// server on BIND, `127.0.0.1:3536` by default; port 0 picks a free one) or `join ROOM
    /// SIGNAL_URL`, as its first words; later words (the app's own flags) are left to the app.
    pub fn from_args(args: &[String]) -> Result<Self, OpenError> {
        let usage = || {
            OpenError::Config(
                "usage: host ROOM [BIND] | join ROOM SIGNAL_URL, then the app's flags".into(),
            )
        };
        let word = |i: usize| {
            args.get(i)
                .map(String::as_str)
                .filter(|w| !w.starts_with("--"))
        };
        match (word(0), word(1), word(2)) {
            (Some("host"), Some(room), bind) => {
                let mut o = RoomOptions::host(room);
                if let Some(b) = bind {
                    o.bind = b.parse().map_err(|e| {
                        OpenError::Config(format!("bind address {b:?}: {e} (e.g. 127.0.0.1:3536)"))
                    })?;
                }
                Ok(o)
            }
            (Some("join"), Some(room), Some(url)) => Ok(RoomOptions::join(room, url)),
            _ => Err(usage()),
        }
    }

    /// Register the application's message type `M` (see [`RoomOptions::messages`]). A type
    /// the scene file already names is accepted as it is.
    pub fn with_message<M: Message>(mut self) -> Result<Self, RegisterError> {
        if !self.messages.names().iter().any(|n| n == M::NAME) {
            self.messages.register::<M>()?;
        }
        Ok(self)
    }

    /// The session configuration of `scene` under these options: the scene's classes with
    /// [`send`](Self::send) under their own replication settings, the message table (built-in,
    /// the scene's, then [`messages`](Self::messages)), the room key.
    pub fn session_config(&self, scene: &Scene) -> Result<SessionConfig, OpenError> {
        let mut cfg = scene.session_config(self.send.clone(), self.send.clone(), self.send.clone());
        let mut types = MessageTypes::from_config(&cfg)
            .ok_or_else(|| OpenError::Config("the scene names a message type twice".into()))?;
        for n in self.messages.names() {
            if !types.names().contains(n) {
                types
                    .register_name(n)
                    .map_err(|e| OpenError::Config(e.to_string()))?;
            }
        }
        types.configure(&mut cfg);
        // the key names this room (join tokens are bound to it) and carries this machine's
        // wall clock at the session's time zero (now, within a frame), for token expiry
        let unix_now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        cfg.room_key = self
            .room_key
            .clone()
            .map(|k| k.for_room(&self.name).with_clock(unix_now));
        cfg.room_token = self.room_token.clone();
        cfg.uplink_bytes_per_s = self.uplink_bytes_per_s;
        cfg.state_route = self.state_route;
        cfg.max_members = self.max_members;
        Ok(if self.fast_detection {
            cfg.fast_detection()
        } else {
            cfg.fixed_detection()
        })
    }
}

/// Why a room could not be opened or could not go on.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The options or the scene are wrong (nothing was opened).
    #[error("{0}")]
    Config(String),
    /// Signaling or WebRTC failed, or no peer of the room answered in time.
    #[error("{0}")]
    Connect(String),
    /// The room refused us, or the peer stopped.
    #[error("{0}")]
    Peer(String),
}

impl OpenError {
    /// The process exit code the `softsync` binary uses for it: 2 for a usage or
    /// configuration error, 3 for a connection or room failure.
    pub fn exit_code(&self) -> u8 {
        match self {
            OpenError::Config(_) => 2,
            OpenError::Connect(_) | OpenError::Peer(_) => 3,
        }
    }
}
