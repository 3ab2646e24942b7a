//! Rooms of 32 on virtual time (issue 18 point 3): every peer joins, spawns an object and
//! moves it, a third of them grab one of the host's objects and let it go again; at the end
//! every peer lists the same members and the same owner for every object, and no object has
//! two owners — with and without the host's uplink capped.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;
use std::time::Duration;

use common::*;
use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::{NetId, ObjectState, PeerId, SessionConfig};

const FRAME: Duration = Duration::from_micros(16_667);

fn pose(i: usize, t: f32) -> Vec3 {
    let a = i as f32 * 0.4 + t;
    Vec3::new(a.cos() * 1.5, 1.0 + 0.1 * (2.0 * t).sin(), a.sin() * 1.5)
}

/// Members and owners as each live peer sees them.
fn views(h: &Harness) -> Vec<(Vec<PeerId>, BTreeMap<NetId, PeerId>)> {
    h.peers
        .iter()
        .filter(|p| p.alive)
        .map(|p| {
            let members = p.session.members().keys().copied().collect();
            let owners = p
                .session
                .object_ids()
                .into_iter()
                .filter_map(|id| Some((id, p.session.owner(id)?)))
                .collect();
            (members, owners)
        })
        .collect()
}

fn crowd(n: usize, cap: Option<u32>) {
    let cfg = SessionConfig {
        uplink_bytes_per_s: cap,
        ..config()
    };
    let mut h = Harness::new(n, cfg, steady_link());
    h.advance(ms(2000));
    for i in 0..n {
        assert!(h.peers[i].session.is_connected(), "peer {i} did not join");
    }
    let now = h.now;
    let scene: Vec<NetId> = (0..8)
        .map(|k| {
            let st = ObjectState::rigid(Vec3::new(k as f32 * 0.2, 0.8, 0.0), Quat::IDENTITY);
            h.session(0).spawn(now, RIGID, st).unwrap().0
        })
        .collect();
    let own = client_objects(&mut h, n, |i| pose(i, 0.0));
    // a third of the clients grab one of the host's objects (several want the same)
    let now = h.now;
    for i in (1..n).step_by(3) {
        h.session(i)
            .request_authority(now, scene[i % scene.len()])
            .unwrap();
    }
    let t0 = h.now;
    while h.now < t0 + Duration::from_secs(4) {
        let now = h.now;
        let t = (now - t0).as_secs_f32();
        for (i, id) in &own {
            let st = ObjectState::rigid(pose(*i, t), Quat::IDENTITY);
            h.session(*i).publish_state(now, *id, &st).unwrap();
        }
        h.advance(FRAME);
    }
    // the grabbers let go
    let now = h.now;
    for i in (1..n).step_by(3) {
        let id = scene[i % scene.len()];
        if h.session(i).owner(id) == Some(Harness::id(i)) {
            h.session(i).release_authority(now, id).unwrap();
        }
    }
    h.advance(ms(2000));
    let v = views(&h);
    assert_eq!(v.len(), n);
    let (members, owners) = &v[0];
    assert_eq!(members.len(), n, "the host lists {} members", members.len());
    assert_eq!(owners.len(), 8 + n - 1);
    for (i, (m, o)) in v.iter().enumerate() {
        assert_eq!(m, members, "peer {i} lists other members");
        assert_eq!(o, owners, "peer {i} sees other owners");
    }
    // every client owns its own object; the host's objects came back
    for (i, id) in &own {
        assert_eq!(owners[id], Harness::id(*i));
    }
    for id in &scene {
        assert_eq!(owners[id], Harness::id(0), "{id:?} did not come back");
    }
    assert_eq!(h.host_changes(), 0);
}

#[test]
fn a_room_of_32_agrees_on_members_and_owners() {
    crowd(32, None);
}

#[test]
fn a_room_of_32_with_the_hosts_uplink_capped_still_agrees() {
    crowd(32, Some(40_000));
}

#[test]
fn a_room_of_64_agrees_on_members_and_owners() {
    crowd(64, None);
}
