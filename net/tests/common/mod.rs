//! Shared helpers of the integration tests: room setups, spawning and moving objects on the
//! current virtual time, assertions every topic makes.
// Each test binary uses a different subset of these helpers.
#![allow(dead_code, clippy::unwrap_used)]

use std::collections::BTreeSet;
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::{
    ClassConfig, ClassId, ConditionerConfig, Event, Instant, NetId, ObjectState, SendPolicy,
    Session, SessionConfig, SoftBodyMode, Term,
};

pub const RIGID: ClassId = ClassId(0);
pub const SOFT: ClassId = ClassId(1);

pub fn config() -> SessionConfig {
    SessionConfig {
        classes: vec![
            ClassConfig::rigid("rigid", SendPolicy::default()),
            ClassConfig::soft_body("soft", SendPolicy::default(), SoftBodyMode::Particles),
        ],
        ..SessionConfig::default()
    }
}

/// A room of `n` peers that have all joined.
pub fn room(n: usize, link: ConditionerConfig) -> Harness {
    let h = room_with(n, config(), link, ms(1500));
    for i in 0..n {
        assert!(h.peers[i].session.is_connected(), "peer {i} did not join");
    }
    h
}

/// A room of `n` peers with `cfg`, `join` of virtual time after they started joining.
pub fn room_with(n: usize, cfg: SessionConfig, link: ConditionerConfig, join: Duration) -> Harness {
    let mut h = Harness::new(n, cfg, link);
    h.advance(join);
    h
}

/// `link` without duplicated or reordered datagrams.
pub fn in_order(mut link: ConditionerConfig) -> ConditionerConfig {
    link.duplicate = 0.0;
    link.reorder = 0.0;
    link
}

/// 20 ms each way, no jitter, loss, duplicates or reordering.
pub fn steady_link() -> ConditionerConfig {
    in_order(ConditionerConfig::rough(5, 20, 0, 0.0))
}

/// Rest offsets of a 60-particle soft body (a squashed sphere of radius ~0.15 m).
pub fn rest_offsets(n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            let t = i as f32 / n as f32;
            let phi = std::f32::consts::PI * (1.0 + 5f32.sqrt()) * i as f32;
            let y = 1.0 - 2.0 * t;
            let r = (1.0 - y * y).max(0.0).sqrt();
            Vec3::new(r * phi.cos(), y, r * phi.sin()) * 0.15
        })
        .collect()
}

/// Soft-body state at time `t` seconds: moving center, squeezed along x.
pub fn soft_state(center: Vec3, rot: Quat, squeeze: f32) -> ObjectState {
    let particles = rest_offsets(60)
        .into_iter()
        .map(|o| {
            let d = Vec3::new(
                o.x * (1.0 - squeeze),
                o.y * (1.0 + 0.5 * squeeze),
                o.z * (1.0 + 0.5 * squeeze),
            );
            center + rot * d
        })
        .collect();
    ObjectState {
        pos: center,
        rot,
        particles,
    }
}

/// Peer `i` spawns `state` of `class` now: (id, request).
pub fn spawn(h: &mut Harness, i: usize, class: ClassId, state: ObjectState) -> (NetId, u32) {
    let now = h.now;
    h.session(i).spawn(now, class, state).unwrap()
}

/// Peer `i` spawns an unrotated rigid body at `pos` now: (id, request).
pub fn spawn_rigid(h: &mut Harness, i: usize, pos: Vec3) -> (NetId, u32) {
    spawn(h, i, RIGID, ObjectState::rigid(pos, Quat::IDENTITY))
}

/// Peer `i` spawns the unrotated, unsqueezed 60-particle soft body at `center` now.
pub fn spawn_soft(h: &mut Harness, i: usize, center: Vec3) -> (NetId, u32) {
    spawn(h, i, SOFT, soft_state(center, Quat::IDENTITY, 0.0))
}

/// Every client `i` of `1..n` asks for a rigid body at `pos(i)`; after a second, each one's
/// object as the host answered it: (client, id). Panics unless every request was answered.
pub fn client_objects(
    h: &mut Harness,
    n: usize,
    pos: impl Fn(usize) -> Vec3,
) -> Vec<(usize, NetId)> {
    let reqs: Vec<u32> = (1..n).map(|i| spawn_rigid(h, i, pos(i)).1).collect();
    h.advance(Duration::from_millis(1000));
    let own: Vec<(usize, NetId)> = (1..n)
        .filter_map(|i| {
            h.peers[i].events.iter().find_map(|e| match e {
                softsync_net::Event::Spawned {
                    id,
                    request: Some(r),
                    ..
                } if *r == reqs[i - 1] => Some((i, *id)),
                _ => None,
            })
        })
        .collect();
    assert_eq!(own.len(), n - 1, "not every peer's spawn was answered");
    own
}

/// The host spawns three rigid bodies (at 0, 1, 2 m on x) and a soft body.
pub fn spawn_some(h: &mut Harness) -> Vec<NetId> {
    let mut ids: Vec<NetId> = (0..3)
        .map(|k| spawn_rigid(h, 0, Vec3::X * k as f32).0)
        .collect();
    ids.push(spawn(h, 0, SOFT, soft_state(Vec3::Y, Quat::IDENTITY, 0.1)).0);
    ids
}

/// A room of `n` peers that have all joined, 500 ms after the host spawned `spawn_some`'s
/// objects.
pub fn room_with_objects(n: usize, link: ConditionerConfig) -> (Harness, Vec<NetId>) {
    let mut h = room(n, link);
    let ids = spawn_some(&mut h);
    h.advance(ms(500));
    (h, ids)
}

/// Peer `i` publishes `state` of `id` now (it must own it).
pub fn publish(h: &mut Harness, i: usize, id: NetId, state: &ObjectState) {
    let now = h.now;
    h.session(i).publish_state(now, id, state).unwrap();
}

/// Peer `i` publishes an unrotated rigid pose of `id` at `pos` now (it must own it).
pub fn publish_rigid(h: &mut Harness, i: usize, id: NetId, pos: Vec3) {
    publish(h, i, id, &ObjectState::rigid(pos, Quat::IDENTITY));
}

/// Peer `i` asks for authority over `id` now.
pub fn request_authority(h: &mut Harness, i: usize, id: NetId) {
    let now = h.now;
    h.session(i).request_authority(now, id).unwrap();
}

/// Peer `i` gives up its authority over `id` now.
pub fn release_authority(h: &mut Harness, i: usize, id: NetId) {
    let now = h.now;
    h.session(i).release_authority(now, id).unwrap();
}

/// What peer `from` sends to peer `to` once its timers ran at `at` (taken off the harness,
/// so it is never delivered unless the test does so).
pub fn datagrams_to(h: &mut Harness, from: usize, to: usize, at: Instant) -> Vec<Vec<u8>> {
    h.session(from).handle_timeout(at);
    let mut sent = Vec::new();
    while let Some(t) = h.session(from).poll_transmit(at) {
        if t.to == Harness::id(to) {
            sent.push(t.payload);
        }
    }
    sent
}

/// Id of the object spawned for `request` by peer `i` (from its events).
pub fn spawned_id(h: &Harness, i: usize, request: u32) -> Option<NetId> {
    spawned_for(h, i, request).first().copied()
}

/// Every object matched to spawn `request` in peer `i`'s events.
pub fn spawned_for(h: &Harness, i: usize, request: u32) -> Vec<NetId> {
    h.peers[i]
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Spawned {
                id,
                request: Some(r),
                ..
            } if *r == request => Some(*id),
            _ => None,
        })
        .collect()
}

/// The reason peer `i` was given when peer `by` dropped it or refused it (from its events).
pub fn dropped_reason(h: &Harness, i: usize, by: usize) -> Option<String> {
    h.peers[i].events.iter().find_map(|e| match e {
        Event::Dropped { host, reason } if *host == Harness::id(by) => Some(reason.clone()),
        _ => None,
    })
}

/// Every live peer names the same owner of each of `ids`, and that owner is a live peer.
pub fn assert_single_owner_everywhere(h: &Harness, ids: &[NetId]) {
    let live: Vec<usize> = (0..h.peers.len()).filter(|i| h.peers[*i].alive).collect();
    for id in ids {
        let owners: BTreeSet<_> = live
            .iter()
            .map(|i| h.peers[*i].session.owner(*id).expect("object exists"))
            .collect();
        assert_eq!(
            owners.len(),
            1,
            "replicas disagree on owner of {id:?}: {owners:?}"
        );
        let owner = *owners.iter().next().unwrap();
        let believers = live.iter().filter(|i| Harness::id(**i) == owner).count();
        assert_eq!(
            believers, 1,
            "owner {owner:?} of {id:?} must be a live peer"
        );
    }
}

/// Each peer of `survivors` follows peer 1, the earliest joiner, in a term after `term`, and
/// still has every one of `ids`.
pub fn assert_earliest_joiner_took_over(
    h: &Harness,
    survivors: std::ops::Range<usize>,
    term: Term,
    ids: &[NetId],
) {
    for i in survivors {
        let s = &h.peers[i].session;
        assert_eq!(
            s.host_id(),
            Some(Harness::id(1)),
            "peer {i} follows the earliest joiner"
        );
        assert!(s.term() > term);
        assert_eq!(s.object_ids(), ids, "nothing lost on peer {i}");
    }
}

/// Peer `i`, dropped, joins `host` again with a fresh session (as the app does).
pub fn rejoin(h: &mut Harness, i: usize, host: usize) {
    let cfg = h.peers[host].session.config().clone();
    let now = h.now;
    h.peers[i].events.clear();
    *h.session(i) = Session::join(Harness::id(i), Harness::id(host), cfg, now);
    h.advance(ms(1500));
    assert!(
        h.peers[i].events.iter().any(|e| matches!(
            e,
            Event::Joined { host: hh, .. } if *hh == Harness::id(host)
        )),
        "peer {i} did not get back in: {:?}",
        h.peers[i].events
    );
}

/// Three members under `host`, which owns every object; every replica agrees.
pub fn assert_room_whole_again(h: &Harness, ids: &[NetId], host: usize) {
    assert_eq!(h.host_index(), Some(host));
    for i in 0..3 {
        let s = &h.peers[i].session;
        assert_eq!(s.members().len(), 3, "peer {i}: {:?}", s.members());
        for id in ids {
            assert_eq!(s.owner(*id), Some(Harness::id(host)), "peer {i}, {id:?}");
        }
    }
    assert_single_owner_everywhere(h, ids);
    let host_state = h.peers[host].session.latest_state(ids[0]).unwrap();
    for i in 0..3 {
        let s = h.peers[i].session.latest_state(ids[0]).unwrap();
        assert!(
            s.pos.distance(host_state.pos) < 0.002,
            "peer {i}: {:?} vs the host's {:?}",
            s.pos,
            host_state.pos
        );
    }
}

pub fn max_particle_error(a: &ObjectState, b: &ObjectState) -> f32 {
    let mut e = a.pos.distance(b.pos);
    for (x, y) in a.particles.iter().zip(&b.particles) {
        e = e.max(x.distance(*y));
    }
    assert_eq!(a.particles.len(), b.particles.len());
    e
}

pub fn t(h: &Harness) -> f32 {
    h.now.as_secs_f64() as f32
}

pub fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}
