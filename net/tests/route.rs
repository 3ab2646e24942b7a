//! Direct state (issue 18 point 2, `StateRoute::Direct`): owners send their objects' state to
//! every member themselves instead of through the host. Every member still shows every other
//! member's object (close to the owner's truth), the host relays none of it (its uplink no
//! longer grows with the clients' objects), authority still moves through the host, and a
//! joiner whose route differs from the room's is refused at the handshake.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::*;
use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::{Event, ObjectState, SessionConfig, StateRoute};

const FRAME: Duration = Duration::from_micros(16_667);

fn pose(i: usize, t: f32) -> Vec3 {
    let a = i as f32 * 0.7 + 2.0 * t;
    Vec3::new(a.cos() * 1.2, 1.0, a.sin() * 1.2)
}

/// A room of `n` where every client spawns an object and moves it for 3 s: (the host's bytes
/// sent over the last 2 s, the largest distance any member shows any client's object from
/// where its owner had it 100 ms earlier at most).
fn room(n: usize, route: StateRoute) -> (u64, f32) {
    // the fixed detector's 5 heartbeats a second: the default's 20 to every quiet link are
    // a constant beside what the route changes
    let cfg = SessionConfig {
        state_route: route,
        ..config().fixed_detection()
    };
    let mut h = Harness::new(n, cfg, steady_link());
    h.advance(ms(2000));
    let own = client_objects(&mut h, n, |i| pose(i, 0.0));
    let t0 = h.now;
    let mut host_bytes_at_1s = None;
    let mut worst = 0.0f32;
    while h.now < t0 + ms(3000) {
        let now = h.now;
        let t = (now - t0).as_secs_f32();
        for (i, id) in &own {
            let st = ObjectState::rigid(pose(*i, t), Quat::IDENTITY);
            h.session(*i).publish_state(now, *id, &st).unwrap();
        }
        h.advance(FRAME);
        if h.now >= t0 + ms(1000) {
            host_bytes_at_1s.get_or_insert(h.peers[0].session.stats().up.bytes);
            let now = h.now;
            for viewer in 0..n {
                for (i, id) in &own {
                    if *i == viewer {
                        continue;
                    }
                    let shown = h.session(viewer).display_state(now, *id).unwrap().state.pos;
                    // nearest the owner's path over the last 200 ms (the display is late by
                    // the interpolation delay and the path)
                    let t = (now - t0).as_secs_f32();
                    let d = (0..=200)
                        .map(|ms| shown.distance(pose(*i, t - ms as f32 / 1000.0)))
                        .fold(f32::MAX, f32::min);
                    worst = worst.max(d);
                }
            }
        }
    }
    let host = h.peers[0].session.stats().up.bytes - host_bytes_at_1s.unwrap();
    (host, worst)
}

#[test]
fn direct_state_reaches_every_member_without_the_host_relaying_it() {
    let (relay_host, relay_worst) = room(6, StateRoute::Relay);
    let (direct_host, direct_worst) = room(6, StateRoute::Direct);
    println!("relay: host {relay_host} B, worst {relay_worst} m; direct: host {direct_host} B, worst {direct_worst} m");
    assert!(relay_worst < 0.02, "relay: {relay_worst} m");
    assert!(direct_worst < 0.02, "direct: {direct_worst} m");
    // the host relays 5 clients' objects to 4 others each under relay; under direct it sends
    // only heartbeats, acks and its avatar-less share
    assert!(
        (direct_host as f64) < 0.3 * relay_host as f64,
        "host sent {direct_host} B direct, {relay_host} B relayed"
    );
}

#[test]
fn a_joiner_with_another_route_is_refused() {
    let direct = SessionConfig {
        state_route: StateRoute::Direct,
        ..config()
    };
    assert_ne!(direct.digest(), config().digest());
    let mut h = Harness::new(1, config(), steady_link());
    let j = h.add_peer_with(direct, 0);
    h.advance(ms(1500));
    assert!(!h.peers[j].session.is_connected());
    assert!(
        h.peers[j]
            .events
            .iter()
            .any(|e| matches!(e, Event::Refused { reason } if reason.contains("configuration"))),
        "{:?}",
        h.peers[j].events
    );
}
