//! Spawn requests across a host migration: lost with the host, answered by a dead host,
//! pending on the heir itself.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use glam::Vec3;
use softsync_net::harness::Harness;

/// The host dies before it sees a client's spawn request: after the migration the request
/// goes to the new host, and a later request is not mistaken for it.
#[test]
fn spawn_request_lost_with_the_host_is_resent_and_matched_exactly() {
    let mut h = room(3, steady_link());
    let (_, r0) = spawn_rigid(&mut h, 2, Vec3::X);
    h.kill(0); // the request dies in flight
    h.advance(ms(3000));
    assert!(h.peers[1].session.is_host());
    let (_, r1) = spawn_soft(&mut h, 2, Vec3::Y * 2.0);
    h.advance(ms(1000));
    let a = spawned_for(&h, 2, r0);
    let b = spawned_for(&h, 2, r1);
    assert_eq!(a.len(), 1, "request {r0} matched {a:?}");
    assert_eq!(b.len(), 1, "request {r1} matched {b:?}");
    let (a, b) = (a[0], b[0]);
    for i in 1..3 {
        let s = &h.peers[i].session;
        assert_eq!(s.object_ids().len(), 2, "peer {i}: {:?}", s.object_ids());
        assert_eq!(s.class_of(a), Some(RIGID));
        assert_eq!(s.class_of(b), Some(SOFT));
        assert_eq!(s.owner(a), Some(Harness::id(2)));
        assert_eq!(s.owner(b), Some(Harness::id(2)));
        let pa = s.latest_state(a).unwrap().pos;
        let pb = s.latest_state(b).unwrap().pos;
        assert!(pa.distance(Vec3::X) < 0.002, "peer {i}: {pa}");
        assert!(pb.distance(Vec3::Y * 2.0) < 0.002, "peer {i}: {pb}");
    }
}

/// The host creates a client's object and dies before its answer reaches the client (the
/// heir heard of it): the client gets that object, not a second one.
#[test]
fn spawn_answer_lost_with_the_host_yields_one_object() {
    let mut h = room(3, steady_link());
    let (_, r0) = spawn_rigid(&mut h, 2, Vec3::X);
    // the host creates it after one link latency; cut the answer off, let the broadcast out
    while h.peers[0].session.object_ids().is_empty() {
        h.advance(ms(1));
    }
    h.partition(0, 2, true);
    h.advance(ms(30));
    assert_eq!(h.peers[1].session.object_ids().len(), 1);
    assert!(spawned_for(&h, 2, r0).is_empty());
    h.kill(0);
    h.advance(ms(3000));
    assert!(h.peers[1].session.is_host());
    let got = spawned_for(&h, 2, r0);
    assert_eq!(got.len(), 1, "{got:?}");
    for i in 1..3 {
        let s = &h.peers[i].session;
        assert_eq!(s.object_ids(), got, "peer {i}");
        assert_eq!(s.owner(got[0]), Some(Harness::id(2)));
    }
}

/// The heir's own unanswered spawn request is created when it takes over.
#[test]
fn heirs_own_pending_spawn_is_created_on_takeover() {
    let mut h = room(3, steady_link());
    let (_, r0) = spawn_rigid(&mut h, 1, Vec3::Z);
    h.kill(0);
    h.advance(ms(3000));
    assert!(h.peers[1].session.is_host());
    let got = spawned_for(&h, 1, r0);
    assert_eq!(got.len(), 1);
    for i in 1..3 {
        let s = &h.peers[i].session;
        assert_eq!(s.object_ids(), got, "peer {i}");
        assert_eq!(s.owner(got[0]), Some(Harness::id(1)));
        assert!(s.latest_state(got[0]).unwrap().pos.distance(Vec3::Z) < 0.002);
    }
}
