//! Rollback peers on net's in-memory hub behind the seeded link conditioner, in real time
//! (ggrs keeps its own clock), each driven by a squeeze-and-throw bot.
#![allow(clippy::unwrap_used, dead_code, clippy::disallowed_methods)]

use std::path::Path;
use std::time::{Duration, Instant as WallInstant};

use softsync_net::policy::SendPolicy;
use softsync_net::transport::HubEndpoint;
use softsync_net::{
    ConditionerConfig, Instant, LinkConditioner, MemoryHub, PeerId, Session, Transport,
};
use softsync_peer::Scene;
use softsync_rollback::room::register;
use softsync_rollback::script::SqueezeThrow;
use softsync_rollback::{RollbackConfig, RollbackEvent, RollbackPeer};

pub fn scene() -> Scene {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    Scene::by_name("thesis-room", &assets).unwrap()
}

pub fn session_config(scene: &Scene) -> softsync_net::policy::SessionConfig {
    let p = SendPolicy::default();
    let mut cfg = scene.session_config(p.clone(), p.clone(), p);
    let mut types = softsync_net::messages::MessageTypes::from_config(&cfg).unwrap();
    register(&mut types);
    types.configure(&mut cfg);
    cfg
}

pub struct Node {
    pub peer: RollbackPeer,
    pub link: LinkConditioner<HubEndpoint>,
    pub bot: SqueezeThrow,
    pub alive: bool,
    pub events: Vec<RollbackEvent>,
}

pub struct Room {
    pub hub: MemoryHub,
    pub nodes: Vec<Node>,
    pub start: WallInstant,
    pub net: ConditionerConfig,
}

impl Room {
    pub fn new(net: ConditionerConfig) -> Self {
        Room {
            hub: MemoryHub::new(1400),
            nodes: Vec::new(),
            start: WallInstant::now(),
            net,
        }
    }

    pub fn now(&self) -> Instant {
        Instant::from_micros(self.start.elapsed().as_micros() as u64)
    }

    /// Add a peer: the first hosts, the others join through the host.
    pub fn add(&mut self, id: u64) -> usize {
        self.add_via(id, 0)
    }

    /// Add a joiner whose first contact is peer `contact` (an index; 0 is the host).
    pub fn add_via(&mut self, id: u64, contact: usize) -> usize {
        let scene = scene();
        let cfg = session_config(&scene);
        let now = self.now();
        let me = PeerId(id);
        let (session, contact) = match self.nodes.first() {
            None => (Session::host(me, cfg, now), None),
            Some(_) => {
                let c = self.nodes[contact].peer.me();
                (Session::join(me, c, cfg, now), Some(c))
            }
        };
        let mut peer =
            RollbackPeer::new(now, scene, RollbackConfig::default(), session, contact).unwrap();
        if self.nodes.is_empty() {
            peer.open(now).unwrap();
        }
        let net = ConditionerConfig {
            seed: self.net.seed ^ id,
            ..self.net.clone()
        };
        let link = LinkConditioner::new(self.hub.endpoint(me), net);
        let slot = self.nodes.len();
        self.nodes.push(Node {
            peer,
            link,
            bot: SqueezeThrow::new(me, slot * 2 + 1),
            alive: true,
            events: Vec::new(),
        });
        slot
    }

    /// One tick of every live peer.
    pub fn tick(&mut self) {
        let now = self.now();
        for n in self.nodes.iter_mut().filter(|n| n.alive) {
            while let Some((from, bytes)) = n.link.recv(now) {
                n.peer.handle_datagram(now, from, &bytes);
            }
            while let Some(e) = n.link.poll_peer_event() {
                n.peer.handle_link_event(e);
            }
            if let Some(w) = n.peer.world() {
                let i = n.bot.input(w);
                n.peer.set_input(i);
            }
            n.peer.tick(now);
            while let Some(t) = n.peer.poll_transmit(now) {
                n.link.send(now, &t);
            }
            while let Some(e) = n.peer.poll_event() {
                n.events.push(e);
            }
        }
    }

    /// Run at 60 Hz for `d` of wall time (catching up when late).
    pub fn run(&mut self, d: Duration) {
        let end = WallInstant::now() + d;
        let step = Duration::from_micros(16_667);
        let mut next = WallInstant::now();
        while WallInstant::now() < end {
            self.tick();
            next += step;
            let now = WallInstant::now();
            if next > now {
                std::thread::sleep(next - now);
            } else if now - next > Duration::from_millis(200) {
                next = now; // far behind (a loaded machine): do not burst
            }
        }
    }

    pub fn kill(&mut self, i: usize) {
        self.nodes[i].alive = false;
        self.hub.kill(self.nodes[i].peer.me());
    }

    /// The confirmed frame every live peer has, and each one's checksum there.
    pub fn agreement(&self) -> (i32, Vec<Option<u128>>) {
        let live: Vec<&Node> = self.nodes.iter().filter(|n| n.alive).collect();
        let f = live
            .iter()
            .map(|n| n.peer.confirmed_frame().unwrap_or(-1))
            .min()
            .unwrap_or(-1);
        (f, live.iter().map(|n| n.peer.checksum_at(f)).collect())
    }

    pub fn desyncs(&self) -> u64 {
        self.nodes.iter().map(|n| n.peer.stats().desyncs).sum()
    }

    pub fn warnings(&self) -> Vec<String> {
        self.nodes
            .iter()
            .flat_map(|n| n.events.iter())
            .filter_map(|e| match e {
                RollbackEvent::Warning(w) => Some(w.clone()),
                _ => None,
            })
            .collect()
    }
}
