//! Two `softsync_peer::Peer`s in-process on virtual time, on net's in-memory hub behind the
//! seeded link conditioner (20 ms, 5 ms jitter, 2 % loss): a host and a client, each with a
//! scene of its own choosing, stepped frame by frame with an optional hand input.
#![allow(dead_code)]

use std::path::PathBuf;
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_interaction::{HandInput, HandSample};
use softsync_net::transport::HubEndpoint;
use softsync_net::{
    ConditionerConfig, Instant, LinkConditioner, MemoryHub, NetId, PeerId, SendPolicy, Session,
    Transport,
};
use softsync_peer::{Event, Peer, PeerConfig, Scene};

pub const DT: f32 = 1.0 / 90.0;
pub const HOST: PeerId = PeerId(100);
pub const CLIENT: PeerId = PeerId(101);

pub struct Node {
    pub peer: Peer,
    pub link: LinkConditioner<HubEndpoint>,
    pub warnings: Vec<String>,
    /// Every other event the peer said, with the time.
    pub events: Vec<(Instant, Event)>,
    /// The node's process is gone (a test stops stepping it).
    pub link_dead: bool,
}

impl Node {
    /// The shipped scene `name` (or a path).
    pub fn new(hub: &MemoryHub, me: PeerId, seed: u64) -> Self {
        Self::with_scene(hub, me, seed, "thesis-room")
    }

    pub fn with_scene(hub: &MemoryHub, me: PeerId, seed: u64, name: &str) -> Self {
        let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
        let scene = Scene::by_name(name, &assets).unwrap();
        Self::with(hub, me, seed, scene)
    }

    pub fn with(hub: &MemoryHub, me: PeerId, seed: u64, scene: Scene) -> Self {
        let config = PeerConfig {
            dt_s: DT,
            avatar: false,
            ..PeerConfig::default()
        };
        Self::with_config(hub, me, seed, scene, config)
    }

    /// A peer of the `bench-ball` room (one soft ball on the table) whose hands reach
    /// exactly, as the app gives bots; `tweak` changes the scene and the hands first.
    pub fn bench_ball(
        hub: &MemoryHub,
        me: PeerId,
        seed: u64,
        tweak: impl FnOnce(&mut Scene, &mut softsync_interaction::HandConfig),
    ) -> Self {
        let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
        let mut scene = Scene::by_name("bench-ball", &assets).unwrap();
        let mut hand = softsync_interaction::HandConfig {
            physical_controller: false,
            hover_radius_m: 0.015,
            ..Default::default()
        };
        tweak(&mut scene, &mut hand);
        let config = PeerConfig {
            hand,
            dt_s: DT,
            ..PeerConfig::default()
        };
        Self::with_config(hub, me, seed, scene, config)
    }

    pub fn with_config(
        hub: &MemoryHub,
        me: PeerId,
        seed: u64,
        scene: Scene,
        config: PeerConfig,
    ) -> Self {
        Self::with_loss(hub, me, seed, scene, config, 0.02)
    }

    /// As [`Node::with_config`], with `loss` on the link (20 ms, 5 ms jitter).
    pub fn with_loss(
        hub: &MemoryHub,
        me: PeerId,
        seed: u64,
        scene: Scene,
        config: PeerConfig,
        loss: f64,
    ) -> Self {
        let policy = SendPolicy::default();
        let cfg = scene.session_config(policy.clone(), policy.clone(), policy);
        Self::with_session_config(hub, me, seed, scene, config, loss, cfg)
    }

    /// As [`Node::with_loss`], with the session's configuration given.
    pub fn with_session_config(
        hub: &MemoryHub,
        me: PeerId,
        seed: u64,
        scene: Scene,
        config: PeerConfig,
        loss: f64,
        cfg: softsync_net::SessionConfig,
    ) -> Self {
        let (session, contact) = if me == HOST {
            (Session::host(me, cfg, Instant::ZERO), None)
        } else {
            (Session::join(me, HOST, cfg, Instant::ZERO), Some(HOST))
        };
        let mut peer = Peer::new(Instant::ZERO, session, contact, scene, config).unwrap();
        if me == HOST {
            peer.open(Instant::ZERO).unwrap();
        }
        let link = ConditionerConfig {
            seed,
            latency: Duration::from_millis(20),
            jitter: Duration::from_millis(5),
            loss,
            ..ConditionerConfig::default()
        };
        Node {
            peer,
            link: LinkConditioner::new(hub.endpoint(me), link),
            warnings: Vec::new(),
            events: Vec::new(),
            link_dead: false,
        }
    }

    /// A host that reopens a kept room (`image`) instead of opening its scene's objects.
    pub fn reopened(
        hub: &MemoryHub,
        me: PeerId,
        seed: u64,
        name: &str,
        image: &softsync_net::RoomImage,
    ) -> (Self, softsync_peer::Reopened) {
        let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
        let scene = Scene::by_name(name, &assets).unwrap();
        let policy = SendPolicy::default();
        let cfg = scene.session_config(policy.clone(), policy.clone(), policy);
        let config = PeerConfig {
            dt_s: DT,
            avatar: false,
            ..PeerConfig::default()
        };
        let session = Session::host(me, cfg, Instant::ZERO);
        let mut peer = Peer::new(Instant::ZERO, session, None, scene, config).unwrap();
        let done = peer.reopen(Instant::ZERO, image).unwrap();
        let link = ConditionerConfig {
            seed,
            latency: Duration::from_millis(20),
            jitter: Duration::from_millis(5),
            loss: 0.02,
            ..ConditionerConfig::default()
        };
        let node = Node {
            peer,
            link: LinkConditioner::new(hub.endpoint(me), link),
            warnings: Vec::new(),
            events: Vec::new(),
            link_dead: false,
        };
        (node, done)
    }

    pub fn frame(&mut self, now: Instant) {
        self.frame_with(now, None);
    }

    /// A frame with the right hand's input (position, trigger) if given.
    pub fn frame_with(&mut self, now: Instant, hand: Option<(Vec3, f32)>) {
        let input = hand.map(|(p, trigger)| HandInput {
            sample: HandSample {
                position_m: p,
                rotation: Quat::IDENTITY,
                time_s: now.as_secs_f64(),
            },
            grip: 0.0,
            trigger,
        });
        self.frame_input(now, input);
    }

    /// A frame with the right hand's full input if given.
    pub fn frame_input(&mut self, now: Instant, input: Option<HandInput>) {
        while let Some((from, bytes)) = self.link.recv(now) {
            self.peer.handle_datagram(now, from, &bytes);
        }
        while let Some(e) = self.link.poll_peer_event() {
            self.peer.handle_link_event(e);
        }
        self.peer.pump(now).unwrap();
        if self.peer.joined() {
            if let Some(input) = input {
                self.peer.set_hand_input(1, input);
            }
            self.peer.fixed_step(now);
        }
        while let Some(t) = self.peer.poll_transmit(now) {
            self.link.send(now, &t);
        }
        while let Some(e) = self.peer.poll_event() {
            match e {
                Event::Warning(w) => self.warnings.push(w),
                e => self.events.push((now, e)),
            }
        }
    }

    /// When the peer first said something matching `f`.
    pub fn first(&self, f: impl Fn(&Event) -> bool) -> Option<Instant> {
        self.events.iter().find(|(_, e)| f(e)).map(|(t, _)| *t)
    }

    /// The objects of class `name`.
    pub fn id_of(&self, name: &str) -> Vec<NetId> {
        let kind = self.peer.scene().kind(name);
        self.peer
            .objects()
            .iter()
            .filter(|(_, o)| Some(o.kind) == kind)
            .map(|(id, _)| *id)
            .collect()
    }
}

pub struct Room {
    pub nodes: [Node; 2],
    pub now: Instant,
}

impl Room {
    pub fn run(&mut self, d: Duration) {
        let end = self.now + d;
        while self.now < end {
            for n in &mut self.nodes {
                n.frame(self.now);
            }
            self.now += Duration::from_secs_f32(DT);
        }
    }
}
