//! A grab across the network, in-process on virtual time, with the peer library the app runs:
//! a host and a client (`softsync_peer::Peer`, the `bench-ball` scene: one soft ball on the
//! table) on net's in-memory hub behind the seeded link conditioner. The client's hand grips
//! one particle of the host-owned ball, which asks for authority; the hold starts only when the
//! grant arrives (nothing moves before); the client simulates and publishes, the host shows the
//! pulled particle; after the release the ball comes to rest, authority goes back to the host,
//! and both peers show the same shape, back at rest.
#![allow(clippy::unwrap_used, missing_docs)]

use std::path::PathBuf;
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_interaction::{HandConfig, HandInput, HandSample};
use softsync_net::transport::HubEndpoint;
use softsync_net::{
    ConditionerConfig, Instant, LinkConditioner, MemoryHub, NetId, ObjectState, PeerId, SendPolicy,
    Session, Transport,
};
use softsync_peer::{Event, Peer, PeerConfig, Scene};

const DT: f32 = 1.0 / 90.0;
const HOST: PeerId = PeerId(100);
const CLIENT: PeerId = PeerId(101);
const RIGHT: usize = 1;

/// One peer and the link it sends on, as a driver would hold them.
struct Node {
    peer: Peer,
    link: LinkConditioner<HubEndpoint>,
    /// Every event the peer said, with the time.
    events: Vec<(Instant, Event)>,
}

impl Node {
    fn new(hub: &MemoryHub, me: PeerId, seed: u64) -> Self {
        let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
        let scene = Scene::by_name("bench-ball", &assets).unwrap();
        let policy = SendPolicy::default();
        let cfg = scene.session_config(policy.clone(), policy.clone(), policy);
        let (session, contact) = if me == HOST {
            (Session::host(me, cfg, Instant::ZERO), None)
        } else {
            (Session::join(me, HOST, cfg, Instant::ZERO), Some(HOST))
        };
        let config = PeerConfig {
            hand: HandConfig {
                // A hand that reaches exactly, as the app gives bots.
                physical_controller: false,
                hover_radius_m: 0.015,
                ..HandConfig::default()
            },
            dt_s: DT,
            ..PeerConfig::default()
        };
        let mut peer = Peer::new(Instant::ZERO, session, contact, scene, config).unwrap();
        if me == HOST {
            peer.open(Instant::ZERO).unwrap();
        }
        let link = ConditionerConfig {
            seed,
            latency: Duration::from_millis(20),
            jitter: Duration::from_millis(5),
            loss: 0.02,
            ..ConditionerConfig::default()
        };
        Node {
            peer,
            link: LinkConditioner::new(hub.endpoint(me), link),
            events: Vec::new(),
        }
    }

    /// One frame of a driver: network in, timers, (hand input and) a fixed step, network out.
    fn frame(&mut self, now: Instant, hand: Option<HandInput>) {
        while let Some((from, bytes)) = self.link.recv(now) {
            self.peer.handle_datagram(now, from, &bytes);
        }
        while let Some(e) = self.link.poll_peer_event() {
            self.peer.handle_link_event(e);
        }
        self.peer.pump(now).unwrap();
        if self.peer.joined() {
            if let Some(input) = hand {
                self.peer.set_hand_input(RIGHT, input);
            }
            self.peer.fixed_step(now);
        }
        while let Some(t) = self.peer.poll_transmit(now) {
            self.link.send(now, &t);
        }
        while let Some(e) = self.peer.poll_event() {
            assert!(!matches!(e, Event::Warning(_)), "{e:?}");
            self.events.push((now, e));
        }
    }

    /// When the peer first said something matching `f`.
    fn first(&self, f: impl Fn(&Event) -> bool) -> Option<Instant> {
        self.events.iter().find(|(_, e)| f(e)).map(|(t, _)| *t)
    }

    fn ball(&mut self, now: Instant, id: NetId) -> ObjectState {
        self.peer.shown_state(now, id).unwrap()
    }
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

#[test]
fn a_client_grabs_a_host_owned_soft_body_through_authority_and_the_host_sees_it() {
    let hub = MemoryHub::new(1200);
    let mut host = Node::new(&hub, HOST, 3);
    let mut client = Node::new(&hub, CLIENT, 4);
    let step = Duration::from_secs_f32(DT);
    let mut now = Instant::ZERO;

    // The client joins; the ball falls onto the table and settles.
    for _ in 0..(2.0 / DT) as usize {
        now += step;
        host.frame(now, None);
        client.frame(now, None);
    }
    assert!(client.peer.joined(), "the client never joined");
    assert!(host
        .first(|e| *e == Event::Room(softsync_net::Event::PeerJoined(CLIENT)))
        .is_some());
    let (&id, _) = client
        .peer
        .objects()
        .iter()
        .find(|(_, o)| Some(o.kind) == client.peer.scene().kind("softball"))
        .expect("the client has no ball");
    assert_eq!(client.peer.session().owner(id), Some(HOST));

    // The client's right hand, on the ball's particle farthest along +x.
    let rest = client.ball(now, id);
    let (grabbed, start) = rest
        .particles
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.x.total_cmp(&b.1.x))
        .map(|(i, p)| (i, *p))
        .unwrap();

    let gripped_at = now;
    let mut granted_at: Option<Instant> = None;
    let mut released_at: Option<Instant> = None;
    let mut returned_at: Option<Instant> = None;
    let mut host_saw_pull = 0.0f32;
    let mut moved_before_grant = 0.0f32;
    for _ in 0..900 {
        now += step;
        // Grip; once held, pull out 5 cm over 0.5 s, hold, let go after 1 s.
        let held_for = granted_at.map_or(0.0, |g| now.saturating_since(g).as_secs_f32());
        let out = (held_for / 0.5).min(1.0) * 0.05;
        let grip = if released_at.is_none() && held_for < 1.0 {
            1.0
        } else {
            0.0
        };
        let input = HandInput {
            sample: HandSample {
                position_m: start + Vec3::X * out,
                rotation: Quat::IDENTITY,
                time_s: now.as_secs_f64(),
            },
            grip,
            trigger: 0.0,
        };
        host.frame(now, None);
        client.frame(now, Some(input));
        if granted_at.is_none() {
            granted_at = client.first(|e| *e == Event::AuthorityGained(id));
            let shown = client.ball(now, id).particles[grabbed];
            moved_before_grant = moved_before_grant.max(shown.distance(start));
        }
        if released_at.is_none() {
            released_at = client.first(|e| matches!(e, Event::GrabEnded { .. }));
        }
        if granted_at.is_some() && released_at.is_none() {
            let shown = host.ball(now, id).particles[grabbed];
            host_saw_pull = host_saw_pull.max(shown.x - start.x);
        }
        if released_at.is_some()
            && returned_at.is_none()
            && client.peer.session().owner(id) == Some(HOST)
        {
            returned_at = Some(now);
        }
        if returned_at.is_some_and(|r| now.saturating_since(r) > Duration::from_secs(1)) {
            break;
        }
    }

    // The hand asked, then the grant came, and only then did it hold.
    let asked = client.first(|e| *e == Event::AuthorityAsked(id));
    let asked = asked.expect("the hand never asked for authority");
    let granted = granted_at.expect("authority never granted");
    let held = client.first(|e| matches!(e, Event::GrabStarted { id: o, .. } if *o == id));
    let held = held.expect("the hand never held the ball");
    assert!(gripped_at < asked && asked < granted && granted <= held);
    assert!(
        client
            .first(|e| *e
                == Event::GrabStarted {
                    id,
                    hand: RIGHT,
                    particle: Some(grabbed as u32)
                })
            .is_some(),
        "the hand held something else: {:?}",
        client.events
    );
    // Before the grant the client only shows the host's state (0.5 mm quantization grid).
    assert!(
        moved_before_grant < 1e-3,
        "the particle moved before the grant ({moved_before_grant} m)"
    );
    assert!(
        host_saw_pull > 0.03,
        "the host never showed the pulled particle ({host_saw_pull} m)"
    );
    // After the release the ball came to rest and went back to the host.
    let released = client.first(|e| *e == Event::AuthorityReleased(id));
    let released = released.expect("the client never gave the ball back");
    assert!(released > released_at.unwrap());
    let returned = returned_at.expect("authority never went back after the body came to rest");
    assert!(returned >= released);
    assert_eq!(host.peer.session().owner(id), Some(HOST));
    assert_eq!(client.peer.session().owner(id), Some(HOST));
    // Both peers show the same shape, back at rest.
    let (a, b) = (host.ball(now, id), client.ball(now, id));
    let apart = max_distance(&a.particles, &b.particles);
    assert!(apart < 0.002, "peers disagree by {apart} m");
    let off_rest = max_distance(&a.particles, &rest.particles);
    assert!(off_rest < 0.003, "not back at rest ({off_rest} m off)");
}
