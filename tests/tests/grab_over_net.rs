//! A grab across the network, in-process on virtual time: the host owns a soft body; a client's
//! hand grips one of its particles, which asks for authority through the session; the hold
//! starts only when the grant arrives; the client simulates and publishes, the host shows the
//! pulled particle; after the release the body comes to rest, authority goes back, and both
//! peers end with the same shape.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_interaction::{
    HandConfig, HandInput, HandSample, Interaction, InteractionEvent, ObjectRef, Ownership,
};
use softsync_net::harness::Harness;
use softsync_net::{
    ClassConfig, ClassId, ConditionerConfig, Event, NetId, ObjectState, PeerId, SendPolicy,
    SessionConfig, SoftBodyMode,
};
use softsync_softbody::rapier3d::prelude::PhysicsWorld;
use softsync_softbody::{
    ClusterMethod, Mesh, SimulationSpace, SoftBodyConfig, SoftBodyHandle, SoftBodySet,
};

const DT: f32 = 1.0 / 90.0;

/// One peer's simulation: its own rapier world with the same soft body.
struct Peer {
    world: PhysicsWorld,
    soft: SoftBodySet,
    body: SoftBodyHandle,
}

impl Peer {
    fn new() -> Self {
        let mut world = PhysicsWorld::new();
        let mut soft = SoftBodySet::new();
        let cfg = SoftBodyConfig {
            cluster: ClusterMethod::Distance { radius_m: 0.02 },
            space: SimulationSpace::Local,
            ..Default::default()
        };
        let body = soft
            .insert(&Mesh::icosphere(0.1, 2), cfg, &mut world)
            .unwrap();
        world.step();
        Peer { world, soft, body }
    }

    fn state(&self) -> ObjectState {
        let b = self.soft.get(self.body).unwrap();
        let (pos, rot) = b.center_pose(&self.world);
        ObjectState {
            pos,
            rot,
            particles: b.particle_positions(&self.world),
        }
    }

    fn apply(&mut self, s: &ObjectState) {
        let b = self.soft.get_mut(self.body).unwrap();
        b.apply_state(&mut self.world, s.pos, s.rot, &s.particles)
            .unwrap();
    }
}

/// The app's answer to "may this peer move that object": its session says who owns it.
struct SessionOwnership {
    me: PeerId,
    owner: Option<PeerId>,
}

impl Ownership for SessionOwnership {
    fn is_local(&self, _: ObjectRef) -> bool {
        self.owner == Some(self.me)
    }
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

#[test]
fn a_client_grabs_a_host_owned_soft_body_through_authority_and_the_host_sees_it() {
    let mut class = ClassConfig::soft_body("soft", SendPolicy::default(), SoftBodyMode::Particles);
    class.particle_extent_m = 0.25;
    let cfg = SessionConfig {
        classes: vec![class],
        ..SessionConfig::default()
    };
    let link = ConditionerConfig {
        seed: 3,
        latency: Duration::from_millis(20),
        jitter: Duration::from_millis(5),
        loss: 0.02,
        ..ConditionerConfig::default()
    };
    let mut h = Harness::new(2, cfg, link);
    h.advance(Duration::from_millis(300));
    let mut peers = [Peer::new(), Peer::new()];
    let now = h.now;
    h.session(0)
        .spawn(now, ClassId(0), peers[0].state())
        .unwrap();
    h.advance(Duration::from_millis(300));
    let id: NetId = h.session(1).object_ids()[0];
    let me = Harness::id(1);

    // The client's hand, on the particle farthest along +x.
    let mut hands = Interaction::new();
    let hand = hands
        .add_hand(HandConfig {
            hover_radius_m: 0.015,
            ..Default::default()
        })
        .unwrap();
    let rest = peers[1].state();
    let (grabbed, start) = rest
        .particles
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.x.total_cmp(&b.1.x))
        .map(|(i, p)| (i, *p))
        .unwrap();
    let object = ObjectRef::Soft(peers[1].body);

    let mut t = 0.0f64;
    let mut granted_at = None;
    let mut released_at = None;
    let mut returned_at = None;
    let mut host_saw_pull = 0.0f32;
    let mut moved_before_grant = 0.0f32;
    for frame in 0..900 {
        t += DT as f64;
        // Hand script: grip at 0.1 s, pull out 5 cm over 0.5 s once held, hold, let go at 1.5 s.
        let held_for: f64 = granted_at.map_or(0.0, |g: f64| t - g);
        let out = (held_for / 0.5).min(1.0) as f32 * 0.05;
        let grip = if t > 0.1 && released_at.is_none() && (granted_at.is_none() || held_for < 1.0) {
            1.0
        } else {
            0.0
        };
        let input = HandInput {
            sample: HandSample {
                position_m: start + Vec3::X * out,
                rotation: Quat::IDENTITY,
                time_s: t,
            },
            grip,
            trigger: 0.0,
        };
        hands.set_input(hand, input).unwrap();
        let ownership = SessionOwnership {
            me,
            owner: h.session(1).owner(id),
        };
        hands.update(&mut peers[1].world, &mut peers[1].soft, &ownership, DT);
        while let Some(e) = hands.poll_event() {
            match e {
                InteractionEvent::AuthorityRequested { object: o, .. } => {
                    assert_eq!(o, object);
                    let now = h.now;
                    h.session(1).request_authority(now, id).unwrap();
                }
                InteractionEvent::Released { .. } => released_at = Some(t),
                InteractionEvent::CameToRest { .. } => {
                    let now = h.now;
                    h.session(1).release_authority(now, id).unwrap();
                }
                _ => {}
            }
        }
        // Each peer simulates what it owns and shows what it does not.
        for i in 0..2 {
            let owner = h.session(i).owner(id);
            if owner == Some(Harness::id(i)) {
                peers[i].soft.step(&mut peers[i].world, DT);
                let state = peers[i].state();
                let now = h.now;
                h.session(i).publish_state(now, id, &state).unwrap();
            } else {
                let now = h.now;
                if let Some(d) = h.session(i).display_state(now, id) {
                    peers[i].apply(&d.state);
                }
            }
        }
        if granted_at.is_none() {
            moved_before_grant =
                moved_before_grant.max(peers[1].state().particles[grabbed].distance(start));
        }
        h.advance(Duration::from_micros(11_111));
        for e in h.peers[1].events.drain(..) {
            if let Event::AuthorityChanged { id: o, owner, .. } = e {
                if o == id && owner == me && granted_at.is_none() {
                    granted_at = Some(t);
                    hands.grant(object);
                } else if o == id && owner != me && granted_at.is_some() {
                    returned_at = Some(t);
                }
            }
        }
        h.peers[0].events.clear();
        if granted_at.is_some() && released_at.is_none() {
            let shown = peers[0].state().particles[grabbed];
            host_saw_pull = host_saw_pull.max(shown.x - start.x);
        }
        if returned_at.is_some_and(|r| t > r + 1.0) {
            assert!(frame > 100);
            break;
        }
    }
    let granted = granted_at.expect("authority never granted");
    assert!(granted > 0.1, "held before asking");
    // Before the grant the client only shows the host's state (0.5 mm quantization grid).
    assert!(
        moved_before_grant < 1e-3,
        "the particle moved before the grant ({moved_before_grant} m)"
    );
    assert!(
        host_saw_pull > 0.03,
        "the host never showed the pulled particle ({host_saw_pull} m)"
    );
    let returned = returned_at.expect("authority never went back after the body came to rest");
    assert!(returned > released_at.unwrap());
    assert_eq!(h.session(0).owner(id), Some(Harness::id(0)));
    assert_eq!(h.session(1).owner(id), Some(Harness::id(0)));
    // Both peers show the same shape, back at rest.
    let (a, b) = (peers[0].state(), peers[1].state());
    assert!(
        max_distance(&a.particles, &b.particles) < 0.002,
        "peers disagree by {} m",
        max_distance(&a.particles, &b.particles)
    );
    assert!(
        max_distance(&a.particles, &rest.particles) < 0.003,
        "not back at rest"
    );
}
