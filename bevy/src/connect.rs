//! Opening a room's network: signaling (embedded in a host without one) and the WebRTC
//! transport, a joiner's first contact, and the scene share a member serves. [`Room::open`]
//! opens its room with these, and so does a peer of another kind (`softsync-rollback`'s, in
//! the binary's `--sync rollback`).
//!
//! [`Room::open`]: crate::Room::open

// The I/O layer: this machine's clock and the waits for the transport.
#![allow(clippy::disallowed_methods)]

use std::time::Duration;

use softsync_net::policy::SessionConfig;
use softsync_net::share::{self, BlobServer};
use softsync_net::{PeerEvent, PeerId, Transport};
use softsync_net_matchbox::{MatchboxConfig, MatchboxTransport, Role, SignalServer};
use softsync_peer::Scene;

use crate::room::{OpenError, RoomOptions};

/// Signaling (embedded for a host without [`RoomOptions::signal`]) and the WebRTC transport,
/// connected: what [`Room::open`](crate::Room::open) starts with, and what a peer of another
/// kind (a rollback room's, `softsync-rollback`) opens the same way.
pub struct Connected {
    /// The transport, registered with the room's signaling.
    pub transport: MatchboxTransport,
    /// The embedded signaling server, if we run it.
    pub signal: Option<SignalServer>,
    /// The signaling URL we registered with.
    pub url: String,
    /// When connecting started (the connect timeout counts from it).
    pub started: std::time::Instant,
}

/// Open signaling and the transport for `opts` (see [`Connected`]).
pub fn connect(opts: &RoomOptions) -> Result<Connected, OpenError> {
    let (signal, url) = match (&opts.signal, opts.host) {
        (Some(u), _) => (None, u.clone()),
        (None, true) => {
            // a room with a key keeps outsiders off its embedded signaling server too
            let s = SignalServer::start_secure(
                opts.bind,
                softsync_net_matchbox::SignalLimits::default(),
                opts.room_key.clone(),
                opts.tls.clone(),
            )
            .map_err(|e| OpenError::Connect(format!("signaling on {}: {e}", opts.bind)))?;
            let url = s.url();
            (Some(s), url)
        }
        (None, false) => {
            return Err(OpenError::Config(
                "joining needs a signaling server's URL".into(),
            ))
        }
    };
    // `signal` may list several servers (comma-separated): the first that takes us is
    // the room's (one unreachable, or not hosting the room, is passed over)
    let urls: Vec<String> = url
        .split(',')
        .map(str::trim)
        .filter(|u| !u.is_empty())
        .map(str::to_owned)
        .collect();
    let mut mcfg = MatchboxConfig::new(
        urls.first().cloned().unwrap_or_default(),
        opts.name.clone(),
        if opts.host { Role::Host } else { Role::Join },
    );
    mcfg.ice_servers = opts.ice_servers.clone();
    mcfg.ice_username = opts.ice_username.clone();
    mcfg.signal_key = opts.room_key.clone();
    mcfg.tls_ca = opts.tls_ca.clone();
    mcfg.signal_token = opts.room_token.as_ref().map(|t| t.to_string());
    mcfg.ice_credential = opts.ice_credential.clone();
    mcfg.connect_timeout = opts.connect_timeout.min(Duration::from_secs(30));
    // when our server is lost, register the room with the next in the list (new peers find
    // it there; the data channels we have live on); with one URL, with that one again
    // each second: behind a load balancer it is a live instance's
    mcfg.fallback_urls = urls.clone();
    let started = std::time::Instant::now();
    let mut tried = Vec::new();
    let mut connected = None;
    for u in &urls {
        mcfg.signal_url = u.clone();
        match MatchboxTransport::connect(&mcfg) {
            Ok(t) => {
                connected = Some(t);
                break;
            }
            Err(
                e @ (softsync_net_matchbox::ConnectError::Unreachable { .. }
                | softsync_net_matchbox::ConnectError::RoomNotFound { .. }),
            ) if urls.len() > 1 => tried.push(e.to_string()),
            Err(e) => return Err(OpenError::Connect(e.to_string())),
        }
    }
    let Some(t) = connected else {
        return Err(OpenError::Connect(tried.join("; ")));
    };
    Ok(Connected {
        transport: t,
        signal,
        url: mcfg.signal_url.clone(),
        started,
    })
}

/// A joiner's contact: the first peer we get a data channel to (one that is not the host
/// redirects us), within the connect timeout.
pub fn first_contact(
    transport: &mut MatchboxTransport,
    opts: &RoomOptions,
    started: std::time::Instant,
) -> Result<PeerId, OpenError> {
    loop {
        if let Some(PeerEvent::Connected(p)) = transport.poll_peer_event() {
            return Ok(p);
        }
        if let Some(why) = transport.closed() {
            return Err(OpenError::Connect(format!(
                "signaling lost while joining: {why}"
            )));
        }
        if started.elapsed() > opts.connect_timeout {
            return Err(OpenError::Connect(format!(
                "room {:?}: no WebRTC connection to any of its peers within {:?}",
                opts.name, opts.connect_timeout
            )));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// What serves `scene` to joiners that have none (the scene share): its bundle, behind the
/// room's key if it has one; a member that joined with a token and holds no key says it
/// cannot check credentials.
pub fn scene_server(scene: &Scene, cfg: &SessionConfig, me: PeerId) -> BlobServer {
    let key = cfg.room_key.clone();
    // in with a token, holding no key: we could not check a joiner's credentials
    let keyless_member = key.is_none() && cfg.room_token.is_some();
    match scene.bundle() {
        _ if keyless_member => BlobServer::unavailable(share::CANNOT_CHECK.to_owned()),
        Ok(b) => BlobServer::new(b),
        Err(why) => BlobServer::unavailable(why),
    }
    .with_key(key, me)
}

/// When each step of [`Room::open`](crate::Room::open) ended, on the wall clock: where a join's time went before
/// the room runs (the Welcome and the first state follow as it does). `softsync bench join`
/// prints them beside the WebRTC stack's own (ICE, DTLS).
#[derive(Clone, Copy, Debug)]
pub struct ConnectTimes {
    /// Connecting started.
    pub started: std::time::Instant,
    /// The signaling server assigned us an id.
    pub registered: std::time::Instant,
    /// A joiner's first data channel to a peer of the room was open (its contact).
    pub contact: Option<std::time::Instant>,
    /// A joiner without a scene had the room's scene ([`Room::open_fetching_scene`](crate::Room::open_fetching_scene)).
    pub scene: Option<std::time::Instant>,
    /// The room was built: a joiner says Hello at its first pump.
    pub opened: std::time::Instant,
}
