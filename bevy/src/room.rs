//! [`Room`]: one peer of a room on a real transport and clock — what [`Room::open`] connects
//! and the plugin runs each frame. Nothing here needs bevy: a server or a test can drive a
//! `Room` by hand with [`Room::network_in`], [`Room::step`] and [`Room::flush`].

// The I/O layer: this machine's clock, the wait for a first data channel, the grace after a
// `Leave`. The session and peer below stay sans-IO.
#![allow(clippy::disallowed_methods)]

use std::net::SocketAddr;
use std::time::Duration;

use crate::connect::{ConnectTimes, Connected};
pub use crate::options::{OpenError, RoomOptions};
use crate::scene_fetch::FetchedScene;
use crate::signal_move::signaling_move;
use crate::voice::RoomVoice;
use softsync_net::door::{Door, FrontDoor};
use softsync_net::messages::Message;
use softsync_net::share::BlobServer;
use softsync_net::{
    Delivery, Instant, LinkConditioner, MessageRefusal, MessageTarget, PeerId, RoomKey, Session,
    Transport,
};
use softsync_net_matchbox::{MatchboxTransport, SignalServer, TlsIdentity};
use softsync_peer::messages::{Presence, SignalingMoved};
use softsync_peer::{Event, Peer, PeerError, Scene};
use softsync_store::keeper::Keeper;

/// Milliseconds on this process's wall clock (the `method: auto` probe's timer).
pub fn wall_ms() -> f64 {
    use std::sync::OnceLock;
    static START: OnceLock<std::time::Instant> = OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_secs_f64()
        * 1e3
}

/// The session's clock: microseconds since the room was opened, on this machine's clock.
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    origin: std::time::Instant,
}

impl Clock {
    /// A clock that reads zero now.
    pub fn start() -> Self {
        Clock {
            origin: std::time::Instant::now(),
        }
    }

    /// Now, on the session's clock.
    pub fn now(&self) -> Instant {
        Instant::from_micros(self.origin.elapsed().as_micros() as u64)
    }
}

/// How long a leaving peer waits for the transport to send its `Leave` before the process
/// ends (the WebRTC thread sends it).
pub const LEAVE_GRACE: Duration = Duration::from_millis(100);

/// One peer in a room: the [`Peer`] (session, world, soft bodies, hands, avatar) on a real
/// transport and clock, and the embedded signaling server a host may run.
pub struct Room {
    /// The peer: objects, hands, messages, the session and its stats.
    pub peer: Peer,
    transport: Box<dyn Transport + Send>,
    clock: Clock,
    name: String,
    signal_url: String,
    signal: Option<SignalServer>,
    ready: bool,
    left: bool,
    events: Vec<Event>,
    /// Serves our scene to joiners without one (built at the first request; in a room with a
    /// key, only to those that prove it).
    share: Option<BlobServer>,
    /// Every datagram received, sorted by protocol (and those no protocol here serves).
    door: FrontDoor,
    fetched: Option<FetchedScene>,
    connect_times: Option<ConnectTimes>,
    /// A failure met while pumped between frames, for the next [`Room::network_in`].
    deferred: Option<OpenError>,
    /// Pumps between frames ([`Room::pump_between_frames`]).
    background_pumps: u64,
    /// Where to serve the room's signaling if we take over from a host that served it.
    takeover: Option<(SocketAddr, Option<RoomKey>, Option<TlsIdentity>)>,
    /// The room's store, if it is kept, and what the reopen from it did.
    keeper: Option<Keeper>,
    reopened: Option<softsync_peer::Reopened>,
    voice: Option<RoomVoice>,
    /// Our presence, and the head it was last sent with.
    presence: Option<(Presence, Option<softsync_net::NetId>)>,
    /// The others' presences, as received (sanitized).
    presences: std::collections::BTreeMap<PeerId, Presence>,
}

impl Room {
    /// Connect to room `opts.name` with `scene`: signaling (embedded for a host without
    /// [`RoomOptions::signal`]), WebRTC, then host the room (spawning the scene's objects) or
    /// join it through the first peer that answers. Blocks until a joiner has a data channel
    /// to some peer of the room (the welcome follows as the room runs) or `connect_timeout`.
    pub fn open(scene: Scene, opts: RoomOptions) -> Result<Room, OpenError> {
        Self::open_with(Some(scene), opts)
    }

    /// Join room `opts.name` without a scene of our own: the room's host sends its scene (the
    /// scene file and its meshes, SHA-256 verified, kept under [`RoomOptions::scene_cache`]),
    /// then we join as [`open`](Self::open) does. A member we reach first names the host and
    /// sends nothing, so the first contact need not be the host.
    pub fn open_fetching_scene(opts: RoomOptions) -> Result<Room, OpenError> {
        if opts.host {
            return Err(OpenError::Config(
                "a host opens its own scene (Room::open)".into(),
            ));
        }
        Self::open_with(None, opts)
    }

    fn open_with(scene: Option<Scene>, opts: RoomOptions) -> Result<Room, OpenError> {
        // Wrong options fail before anything opens; so does a store that will not open.
        let mut kept = None;
        let mut keeper = None;
        if let Some(scene) = &scene {
            let cfg = opts.session_config(scene)?;
            if let (Some(store), true) = (&opts.store, opts.host) {
                let (k, image) = crate::keep::host_store(store, scene, &cfg)?;
                keeper = Some(k);
                kept = image;
            }
        }
        if let (Some(store), false) = (&opts.store, opts.host) {
            keeper = Some(Keeper::joining(store.clone()));
        }
        let voice = match &opts.voice {
            Some(v) => Some(RoomVoice::new(v.clone()).map_err(OpenError::Config)?),
            None => None,
        };
        let Connected {
            transport: t,
            signal,
            url,
            started,
        } = crate::connect::connect(&opts)?;
        let registered = std::time::Instant::now();
        let mut contact_at = None;
        let mut scene_at = None;
        let mut transport: Box<MatchboxTransport> = Box::new(t);
        let me = transport.local_id();
        let now0 = Instant::ZERO;
        let mut fetched = None;
        let mut link_news = Vec::new();
        let (scene, session, contact) = if opts.host {
            let Some(scene) = scene else {
                return Err(OpenError::Config("a host needs a scene".into()));
            };
            let cfg = opts.session_config(&scene)?;
            (scene, Session::host(me, cfg, now0), None)
        } else {
            // The first data channel is our contact (a peer that is not the host redirects).
            let mut c = crate::connect::first_contact(transport.as_mut(), &opts, started)?;
            contact_at = Some(std::time::Instant::now());
            let scene = match scene {
                Some(s) => s,
                None => {
                    let (s, f) = crate::scene_fetch::fetch_scene(
                        transport.as_mut(),
                        c,
                        &opts,
                        started,
                        &mut link_news,
                    )?;
                    // the scene came from the room's host: say Hello there first (a first
                    // contact that is another joiner could not answer it)
                    c = f.from;
                    fetched = Some(f);
                    scene_at = Some(std::time::Instant::now());
                    s
                }
            };
            let cfg = opts.session_config(&scene)?;
            (scene, Session::join(me, c, cfg, now0), Some(c))
        };
        // `method: auto`: this machine's costs of each resolution level
        let mut scene = scene;
        scene.probe_auto(wall_ms).map_err(OpenError::Config)?;
        let transport: Box<dyn Transport + Send> = match opts.condition.clone() {
            Some(c) => Box::new(LinkConditioner::new(*transport, c)),
            None => transport,
        };
        // The session's clock starts with the peer.
        let clock = Clock::start();
        let mut peer = Peer::new(clock.now(), session, contact, scene, opts.peer.clone())
            .map_err(|e| OpenError::Config(e.to_string()))?;
        let reopened = match (opts.host, &kept) {
            (true, Some(image)) => Some(peer.reopen(clock.now(), image)),
            (true, None) if opts.spawn_scene => peer.open(clock.now()).err().map(Err),
            (true, None) => None,
            (false, _) => None,
        }
        .transpose()
        .map_err(|e| OpenError::Peer(e.to_string()))?;
        // Data channels that opened while we fetched the scene: contacts for the join.
        for e in link_news {
            peer.handle_link_event(e);
        }
        Ok(Room {
            peer,
            transport,
            clock,
            name: opts.name,
            signal_url: url,
            signal,
            ready: opts.start_ready,
            left: false,
            events: Vec::new(),
            share: None,
            door: FrontDoor::default(),
            fetched,
            connect_times: Some(ConnectTimes {
                started,
                registered,
                contact: contact_at,
                scene: scene_at,
                opened: std::time::Instant::now(),
            }),
            deferred: None,
            background_pumps: 0,
            takeover: (!opts.host)
                .then_some(opts.takeover_bind)
                .flatten()
                .map(|b| (b, opts.room_key.clone(), opts.tls.clone())),
            keeper,
            reopened,
            voice,
            presence: opts.presence.map(|p| (p.sanitized(), None)),
            presences: Default::default(),
        })
    }

    /// A room on a transport the caller made (an in-memory hub in tests, another WebRTC
    /// stack): `peer` is already built on a session of `transport.local_id()`.
    pub fn with_transport(
        name: impl Into<String>,
        peer: Peer,
        transport: Box<dyn Transport + Send>,
    ) -> Self {
        Room {
            peer,
            transport,
            clock: Clock::start(),
            name: name.into(),
            signal_url: String::new(),
            signal: None,
            ready: true,
            left: false,
            events: Vec::new(),
            share: None,
            door: FrontDoor::default(),
            fetched: None,
            connect_times: None,
            deferred: None,
            background_pumps: 0,
            takeover: None,
            keeper: None,
            reopened: None,
            voice: None,
            presence: None,
            presences: Default::default(),
        }
    }

    /// The room's voice, if it has one ([`RoomOptions::voice`]).
    pub fn voice(&mut self) -> Option<&mut RoomVoice> {
        self.voice.as_mut()
    }

    /// The room's voice to read (who speaks, levels, drops).
    pub fn voice_view(&self) -> Option<&RoomVoice> {
        self.voice.as_ref()
    }

    /// The datagrams received, per protocol ([`softsync_net::door`]), and those dropped unread.
    pub fn front_door(&self) -> &FrontDoor {
        &self.door
    }

    /// How we received the room's scene, if we did ([`Room::open_fetching_scene`]).
    pub fn fetched_scene(&self) -> Option<&FetchedScene> {
        self.fetched.as_ref()
    }

    /// Requests for our scene answered, and refused (malformed, or over a requester's rate).
    pub fn scene_requests(&self) -> (u64, u64) {
        self.share
            .as_ref()
            .map_or((0, 0), |s| (s.served, s.refused))
    }

    /// When each step of opening the room ended (None for a room on a caller's transport).
    pub fn connect_times(&self) -> Option<&ConnectTimes> {
        self.connect_times.as_ref()
    }

    /// Now, on the session's clock.
    pub fn now(&self) -> Instant {
        self.clock.now()
    }

    /// The room's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The signaling server's URL (the embedded one's, on a host that runs it).
    pub fn signal_url(&self) -> &str {
        &self.signal_url
    }

    /// Whether our path to `peer` goes through a TURN relay (`None` while unknown: about a
    /// second after it connected).
    pub fn is_relayed(&self, peer: PeerId) -> Option<bool> {
        self.transport.relayed(peer)
    }

    /// Whether this process runs the room's signaling server.
    pub fn runs_signaling(&self) -> bool {
        self.signal.is_some()
    }

    /// Whether the network is pumped (see [`RoomOptions::start_ready`]).
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// The front end is up: start pumping the network, and count the join timeout from now.
    /// Returns false if it already was.
    pub fn set_ready(&mut self) -> bool {
        if self.ready {
            return false;
        }
        self.ready = true;
        let now = self.now();
        self.peer.restart_join_clock(now);
        true
    }

    /// Whether [`leave`](Self::leave) was called.
    pub fn has_left(&self) -> bool {
        self.left
    }

    /// Network in: datagrams, link news, timers and the session's news, then what that sends.
    /// The peer's events are kept for [`drain_events`](Self::drain_events). An error means
    /// the peer cannot go on (refused, timed out, the room gone past rejoining).
    pub fn network_in(&mut self) -> Result<(), OpenError> {
        if let Some(e) = self.deferred.take() {
            return Err(e);
        }
        if !self.ready || self.left {
            return Ok(());
        }
        let now = self.now();
        while let Some((from, bytes)) = self.transport.recv(now) {
            // the front door: each protocol's datagrams to its own code, the rest dropped
            match self.door.sort(&bytes) {
                Door::Share => self.serve_scene(now, from, &bytes),
                Door::Session | Door::OtherVersion | Door::Refusal => {
                    self.peer.handle_datagram(now, from, &bytes)
                }
                Door::Voice => match &mut self.voice {
                    Some(v) => v.handle(now, &mut self.peer, self.transport.as_mut(), from, &bytes),
                    None => self.door.drop_unserved(),
                },
                Door::Rollback | Door::Ident | Door::Unknown => self.door.drop_unserved(),
            }
        }
        if let Some(v) = &mut self.voice {
            v.tick(now, &mut self.peer, self.transport.as_mut());
        }
        while let Some(e) = self.transport.poll_peer_event() {
            self.peer.handle_link_event(e);
        }
        let pumped = self.peer.pump(now);
        self.take_events(now);
        match pumped {
            Ok(()) => {
                self.flush();
                Ok(())
            }
            Err(e @ PeerError::NotWelcomed { .. }) => Err(OpenError::Peer(format!(
                "connected to room {:?} but {e}",
                self.name
            ))),
            Err(e) => Err(OpenError::Peer(e.to_string())),
        }
    }

    /// The peer's events into our queue; the room's own signaling news acted on here.
    fn take_events(&mut self, now: Instant) {
        while let Some(e) = self.peer.poll_event() {
            match &e {
                Event::Room(softsync_net::Event::Message(m)) => {
                    if let Some(Ok(p)) = self.peer.decode::<Presence>(m) {
                        self.presences.insert(m.from, p.sanitized());
                    }
                    if let Some(moved) = self.peer.decode::<SignalingMoved>(m) {
                        let host = self.peer.session().host_id();
                        match signaling_move(moved, m.from, host) {
                            Ok(url) => {
                                self.transport.prefer_signaling(&url);
                                self.events.push(Event::Warning(format!(
                                    "the room's signaling moved to {url} (peer {})",
                                    m.from.0
                                )));
                            }
                            Err(why) => self.events.push(Event::Warning(why)),
                        }
                        continue;
                    }
                }
                Event::Room(softsync_net::Event::HostChanged { host, .. })
                    if *host == self.peer.me() =>
                {
                    self.serve_signaling_after_takeover(now);
                }
                _ => {}
            }
            if let Some(k) = &mut self.keeper {
                k.observe(now, &self.peer, &e);
            }
            self.events.push(e);
        }
    }

    /// We are the new host: if our predecessor served the room's signaling and we have an
    /// address for it, serve it now, register there ourselves and tell the room.
    fn serve_signaling_after_takeover(&mut self, now: Instant) {
        let Some((bind, key, tls)) = self.takeover.take() else {
            return;
        };
        if self.signal.is_some() {
            return;
        }
        let server = match SignalServer::start_secure(
            bind,
            softsync_net_matchbox::SignalLimits::default(),
            key,
            tls,
        ) {
            Ok(s) => s,
            Err(e) => {
                self.events.push(Event::Warning(format!(
                    "cannot serve the room's signaling on {bind}: {e}"
                )));
                return;
            }
        };
        let url = server.url();
        self.signal = Some(server);
        self.signal_url.clone_from(&url);
        self.transport.prefer_signaling(&url);
        let notice = SignalingMoved { url: url.clone() };
        if let Err(e) = self
            .peer
            .send(now, MessageTarget::Everyone, Delivery::Reliable, &notice)
        {
            self.events.push(Event::Warning(format!(
                "cannot tell the room our signaling URL: {e}"
            )));
        }
        self.events.push(Event::Warning(format!(
            "serving the room's signaling at {url} (the host that served it is gone)"
        )));
    }

    /// [`network_in`](Self::network_in) between frames ([`crate::pump::NetPump`]): the events
    /// wait in the queue for [`drain_events`](Self::drain_events), a failure for the next
    /// `network_in` (and nothing is pumped after it).
    pub fn pump_between_frames(&mut self) {
        if self.deferred.is_some() {
            return;
        }
        self.background_pumps += 1;
        if let Err(e) = self.network_in() {
            self.deferred = Some(e);
        }
    }

    /// How many times the network was pumped between frames (by the plugin's pump thread).
    pub fn background_pumps(&self) -> u64 {
        self.background_pumps
    }

    /// A joiner without the scene asks for ours: the bundle is built at the first request
    /// (from the files the scene was loaded from), or every request is told why there is none.
    fn serve_scene(&mut self, now: Instant, from: PeerId, datagram: &[u8]) {
        // a joiner takes the scene from the room's host only: a member names it
        let session = self.peer.session();
        if let (false, Some(host)) = (session.is_host(), session.host_id()) {
            if session.is_connected() {
                if let Some(t) = softsync_net::share::ask_host(from, datagram, host) {
                    self.transport.send(now, &t);
                }
                return;
            }
        }
        let (scene, cfg, me) = (
            self.peer.scene(),
            self.peer.session().config(),
            self.peer.me(),
        );
        let server = self
            .share
            .get_or_insert_with(|| crate::connect::scene_server(scene, cfg, me));
        let session = self.peer.session();
        let judged =
            server.handle_judged(now, from, datagram, |t| session.token_admits(t, from, now));
        if let Some(t) = judged {
            self.transport.send(now, &t);
        }
    }

    /// The events since the last call, oldest first.
    pub fn drain_events(&mut self) -> std::vec::Drain<'_, Event> {
        self.events.drain(..)
    }

    /// One fixed step of the peer (after the hands were set) and what it sends. Nothing
    /// before the peer is in the room or after it left.
    pub fn step(&mut self) {
        if !self.peer.joined() || self.left {
            return;
        }
        let now = self.now();
        self.peer.fixed_step(now);
        self.send_presence(now);
        self.flush();
        self.take_events(now);
        if let Some(k) = &mut self.keeper {
            k.tick(now, &mut self.peer, &mut self.events);
        }
    }

    /// Our presence with our head, once it exists and whenever it is spawned anew.
    fn send_presence(&mut self, now: Instant) {
        let head = self.peer.avatar_parts()[0];
        let Some((p, sent)) = &mut self.presence else {
            return;
        };
        if head.is_none() || *sent == head {
            return;
        }
        if let Some(h) = head {
            let p = p.clone();
            if self
                .peer
                .send(now, MessageTarget::Everyone, Delivery::ObjectState(h), &p)
                .is_ok()
            {
                if let Some((_, sent)) = &mut self.presence {
                    *sent = Some(h);
                }
            }
        }
    }

    /// The others' names and colours, by peer, as they announced them.
    pub fn presences(&self) -> &std::collections::BTreeMap<PeerId, Presence> {
        &self.presences
    }

    /// The room's store, if it is kept (what it has written: [`Keeper::status`]).
    pub fn store(&self) -> Option<&Keeper> {
        self.keeper.as_ref()
    }

    /// What opening the room from its store put back, if it was reopened.
    pub fn reopened(&self) -> Option<&softsync_peer::Reopened> {
        self.reopened.as_ref()
    }

    /// Network out: everything the peer has to send.
    pub fn flush(&mut self) {
        if !self.ready {
            // Not before the front end is ready: a `Hello` flushed early makes the host count
            // us a member, and time us out while we warm up.
            return;
        }
        let now = self.now();
        while let Some(t) = self.peer.poll_transmit(now) {
            self.transport.send(now, &t);
        }
    }

    /// Send a typed message through the room now (see [`Peer::send`]).
    pub fn send<M: Message>(
        &mut self,
        to: MessageTarget,
        delivery: Delivery,
        msg: &M,
    ) -> Result<u32, MessageRefusal> {
        let now = self.now();
        self.peer.send(now, to, delivery, msg)
    }

    /// Host: kick `peer` out and ban it for the room's life, telling it `reason` (see
    /// [`softsync_net::Session::kick`]); sent at once.
    pub fn kick(&mut self, peer: PeerId, reason: &str) -> Result<(), softsync_net::KickError> {
        let now = self.now();
        self.peer.kick(now, peer, reason)?;
        self.flush();
        Ok(())
    }

    /// Leave the room: a `Leave` to everyone (a host is replaced at once, authority returns),
    /// and a moment for the transport to send it. Once only.
    pub fn leave(&mut self) {
        if self.left {
            return;
        }
        self.left = true;
        if let Some(v) = &mut self.voice {
            v.finish();
        }
        // the store's last checkpoint before we go (the room may go on without it)
        let now = self.now();
        if let Some(k) = &mut self.keeper {
            k.finish(now, &self.peer);
        }
        if self.peer.joined() {
            let now = self.now();
            self.peer.leave(now);
            let now = self.now();
            while let Some(t) = self.peer.poll_transmit(now) {
                self.transport.send(now, &t);
            }
            std::thread::sleep(LEAVE_GRACE);
        }
    }
}
