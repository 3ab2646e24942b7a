//! A grab across the network, in-process on virtual time, with the peer library the app runs:
//! a host and a client (`softsync_peer::Peer`, the `bench-ball` scene: one soft ball on the
//! table) on net's in-memory hub behind the seeded link conditioner. The client's hand grips
//! one particle of the host-owned ball, which asks for authority; the hold starts only when the
//! grant arrives (nothing moves before); the client simulates and publishes, the host shows the
//! pulled particle; after the release the ball comes to rest, authority goes back to the host,
//! and both peers show the same shape, back at rest.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::time::Duration;

use common::hub::{Node, CLIENT, DT, HOST};
use glam::{Quat, Vec3};
use softsync_interaction::{HandInput, HandSample};
use softsync_net::{Instant, MemoryHub, NetId, ObjectState, PeerId};
use softsync_peer::Event;

const RIGHT: usize = 1;

/// A peer of the `bench-ball` room with a hand that reaches exactly, as the app gives bots.
fn node(hub: &MemoryHub, me: PeerId, seed: u64) -> Node {
    Node::bench_ball(hub, me, seed, |_, _| {})
}

/// One frame of a driver, the right hand's input if given; the peer must say no warning.
fn frame(n: &mut Node, now: Instant, hand: Option<HandInput>) {
    n.frame_input(now, hand);
    assert!(n.warnings.is_empty(), "{:?}", n.warnings);
}

fn ball(n: &mut Node, now: Instant, id: NetId) -> ObjectState {
    n.peer.shown_state(now, id).unwrap()
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
    let mut host = node(&hub, HOST, 3);
    let mut client = node(&hub, CLIENT, 4);
    let step = Duration::from_secs_f32(DT);
    let mut now = Instant::ZERO;

    // The client joins; the ball falls onto the table and settles.
    for _ in 0..(2.0 / DT) as usize {
        now += step;
        frame(&mut host, now, None);
        frame(&mut client, now, None);
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
    let rest = ball(&mut client, now, id);
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
        frame(&mut host, now, None);
        frame(&mut client, now, Some(input));
        if granted_at.is_none() {
            granted_at = client.first(|e| *e == Event::AuthorityGained(id));
            let shown = ball(&mut client, now, id).particles[grabbed];
            moved_before_grant = moved_before_grant.max(shown.distance(start));
        }
        if released_at.is_none() {
            released_at = client.first(|e| matches!(e, Event::GrabEnded { .. }));
        }
        if granted_at.is_some() && released_at.is_none() {
            let shown = ball(&mut host, now, id).particles[grabbed];
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
    let (a, b) = (ball(&mut host, now, id), ball(&mut client, now, id));
    let apart = max_distance(&a.particles, &b.particles);
    assert!(apart < 0.002, "peers disagree by {apart} m");
    let off_rest = max_distance(&a.particles, &rest.particles);
    assert!(off_rest < 0.003, "not back at rest ({off_rest} m off)");
}
