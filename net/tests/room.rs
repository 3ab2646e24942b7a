//! Multi-peer behaviour on virtual time: convergence, authority, migration, join, rejection.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeSet;

use common::*;
use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::wire::DenyReason;
use softsync_net::{ConditionerConfig, Event, ObjectState, Session, SessionConfig};

/// Client 1 spawns a rigid body and a soft body, moves them for 2 s, stops; every peer must
/// end within 1.5 mm of the owner's final state (rest sync: thresholds leave no lasting error).
fn converge_under(link: ConditionerConfig) {
    let mut h = room(4, link);
    let now = h.now;
    let (_, r_rigid) = h
        .session(1)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    let (_, r_soft) = h
        .session(1)
        .spawn(now, SOFT, soft_state(Vec3::Y, Quat::IDENTITY, 0.0))
        .unwrap();
    // host-owned object too
    let (host_obj, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::X, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(3000));
    let rigid = spawned_id(&h, 1, r_rigid).expect("rigid spawned");
    let soft = spawned_id(&h, 1, r_soft).expect("soft spawned");
    let start = t(&h);
    h.run_frames(ms(2000), ms(11), |h| {
        // eased to a stop: the last few hundred ms move less than the send threshold
        let x = ((t(h) - start) / 2.0).min(1.0);
        let s = 2.0 * (1.0 - (1.0 - x).powi(3));
        let now = h.now;
        let p = Vec3::new((s * 1.3).sin() * 0.8, 1.0 + (s * 2.1).sin() * 0.3, s * 0.2);
        let q = Quat::from_rotation_y(s * 1.5) * Quat::from_rotation_x(s * 0.4);
        h.session(1)
            .publish_state(now, rigid, &ObjectState::rigid(p, q))
            .unwrap();
        h.session(1)
            .publish_state(
                now,
                soft,
                &soft_state(p + Vec3::Y, q, 0.3 * (s * 3.0).sin().abs()),
            )
            .unwrap();
        h.session(0)
            .publish_state(now, host_obj, &ObjectState::rigid(Vec3::X + p * 0.5, q))
            .unwrap();
    });
    h.advance(ms(4000));
    let now = h.now;
    for (owner, id) in [(1usize, rigid), (1, soft), (0, host_obj)] {
        let truth = h.session(owner).latest_state(id).unwrap();
        for i in 0..4 {
            if i == owner {
                continue;
            }
            let latest = h.session(i).latest_state(id).unwrap();
            let shown = h.session(i).display_state(now, id).unwrap().state;
            let e1 = max_particle_error(&truth, &latest);
            let e2 = max_particle_error(&truth, &shown);
            assert!(e1 < 0.0015, "peer {i} object {id:?}: latest error {e1} m");
            assert!(
                e2 < 0.0015,
                "peer {i} object {id:?}: displayed error {e2} m"
            );
            assert!(truth.rot.angle_between(latest.rot) < 0.01);
        }
    }
    let st = h.peers[0].session.stats();
    assert!(st.max_datagram <= 1200);
}

#[test]
fn converges_without_impairment() {
    converge_under(ConditionerConfig::default());
}

#[test]
fn converges_under_5_percent_loss_50ms_jitter_reorder_dup() {
    converge_under(ConditionerConfig::rough(7, 50, 20, 0.05));
}

#[test]
fn converges_under_20_percent_loss_150ms() {
    converge_under(ConditionerConfig::rough(11, 150, 30, 0.20));
}

#[test]
fn converges_under_20_percent_loss_low_latency() {
    converge_under(ConditionerConfig::rough(3, 5, 10, 0.20));
}

/// The replicated value must actually follow motion (not only the final pose), and the
/// interpolation delay must grow with jitter.
fn follow(jitter_ms: u64) -> (f32, std::time::Duration) {
    let (worst, _, delay) = follow_on(ConditionerConfig::rough(5, 30, jitter_ms, 0.0));
    (worst, delay)
}

/// (worst, p95, last delay) of the remote position error while the owner moves.
fn follow_on(link: ConditionerConfig) -> (f32, f32, std::time::Duration) {
    let mut h = room(2, link);
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(500));
    let mut errors: Vec<f32> = Vec::new();
    let mut delay = std::time::Duration::ZERO;
    let traj = |s: f32| Vec3::new(s.sin() * 0.5, 1.0, 0.0);
    let start = t(&h);
    h.run_frames(ms(3000), ms(11), |h| {
        let s = t(h) - start;
        let now = h.now;
        h.session(0)
            .publish_state(now, id, &ObjectState::rigid(traj(s), Quat::IDENTITY))
            .unwrap();
        if s > 0.5 {
            let d = h.session(1).display_state(now, id).unwrap();
            let truth = traj(d.source_time.as_secs_f64() as f32 - start);
            errors.push(d.state.pos.distance(truth));
            delay = d.delay;
        }
    });
    errors.sort_by(|a, b| a.total_cmp(b));
    let worst = errors.last().copied().unwrap_or(f32::MAX);
    let p95 = errors[(errors.len() - 1) * 95 / 100];
    (worst, p95, delay)
}

/// Deltas are relative to acknowledged state: a lost datagram costs only itself, so motion
/// stays accurate under heavy loss (no waiting for keyframes).
#[test]
fn motion_stays_accurate_under_20_percent_loss() {
    let (worst, p95, _) = follow_on(ConditionerConfig::rough(9, 50, 10, 0.20));
    assert!(p95 < 0.006, "p95 {p95} m under 20 % loss");
    assert!(worst < 0.05, "worst {worst} m under 20 % loss");
}

#[test]
fn remote_follows_motion_and_delay_adapts_to_jitter() {
    let (calm_err, calm_delay) = follow(2);
    let (rough_err, rough_delay) = follow(60);
    assert!(calm_err < 0.005, "remote error while moving {calm_err} m");
    assert!(
        rough_err < 0.010,
        "remote error under 60 ms jitter {rough_err} m"
    );
    assert!(
        rough_delay > calm_delay + ms(20),
        "{calm_delay:?} vs {rough_delay:?}"
    );
    assert!(
        calm_delay >= ms(100) && calm_delay <= ms(130),
        "{calm_delay:?}"
    );
}

#[test]
fn concurrent_authority_requests_exactly_one_wins() {
    for seed in [1, 2, 3] {
        let mut h = room(4, ConditionerConfig::rough(seed, 20, 10, 0.05));
        let now = h.now;
        let (id, _) = h
            .session(0)
            .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
            .unwrap();
        h.advance(ms(500));
        h.session(1).request_authority(now, id).unwrap();
        h.session(2).request_authority(now, id).unwrap();
        h.session(3).request_authority(now, id).unwrap();
        h.advance(ms(2000));
        let owner = h.peers[0].session.owner(id).unwrap();
        let mut winners = 0;
        let mut denied = 0;
        for i in 1..4 {
            assert_eq!(h.peers[i].session.owner(id), Some(owner), "replicas agree");
            let won = h.peers[i].events.iter().any(
                |e| matches!(e, Event::AuthorityChanged { owner: o, .. } if *o == Harness::id(i)),
            );
            let den = h.peers[i].events.iter().any(|e| {
                matches!(
                    e,
                    Event::AuthorityDenied {
                        reason: DenyReason::Held(_),
                        ..
                    }
                )
            });
            winners += usize::from(won);
            denied += usize::from(den);
            assert!(won != den, "peer {i} must either win or be denied");
        }
        assert_eq!(winners, 1, "seed {seed}");
        assert_eq!(denied, 2);
        assert_ne!(owner, Harness::id(0));
    }
}

#[test]
fn owner_disconnect_returns_authority_to_host() {
    let mut h = room(3, ConditionerConfig::default());
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(300));
    let now = h.now;
    h.session(2).request_authority(now, id).unwrap();
    h.advance(ms(300));
    assert_eq!(h.peers[0].session.owner(id), Some(Harness::id(2)));
    let e0 = h.peers[0].session.epoch(id).unwrap();
    h.kill(2);
    h.advance(ms(1500));
    assert_eq!(h.peers[0].session.owner(id), Some(Harness::id(0)));
    assert_eq!(h.peers[1].session.owner(id), Some(Harness::id(0)));
    assert!(h.peers[0].session.epoch(id).unwrap() > e0);
    assert!(!h.peers[1].session.members().contains_key(&Harness::id(2)));
}

#[test]
fn release_returns_authority() {
    let mut h = room(2, ConditionerConfig::default());
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(200));
    let now = h.now;
    h.session(1).request_authority(now, id).unwrap();
    h.advance(ms(200));
    assert_eq!(h.peers[1].session.owner(id), Some(Harness::id(1)));
    let now = h.now;
    h.session(1).release_authority(now, id).unwrap();
    h.advance(ms(200));
    assert_eq!(h.peers[1].session.owner(id), Some(Harness::id(0)));
    assert_eq!(h.peers[0].session.owner(id), Some(Harness::id(0)));
}

fn spawn_some(h: &mut Harness) -> Vec<softsync_net::NetId> {
    let now = h.now;
    let mut ids = Vec::new();
    for k in 0..3 {
        let (id, _) = h
            .session(0)
            .spawn(
                now,
                RIGID,
                ObjectState::rigid(Vec3::X * k as f32, Quat::IDENTITY),
            )
            .unwrap();
        ids.push(id);
    }
    let (id, _) = h
        .session(0)
        .spawn(now, SOFT, soft_state(Vec3::Y, Quat::IDENTITY, 0.1))
        .unwrap();
    ids.push(id);
    ids
}

fn assert_single_owner_everywhere(h: &Harness, ids: &[softsync_net::NetId]) {
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

#[test]
fn host_death_earliest_joiner_takes_over() {
    let mut h = room(4, ConditionerConfig::rough(9, 20, 5, 0.02));
    let ids = spawn_some(&mut h);
    h.advance(ms(500));
    // peer 2 owns one object and keeps moving it
    let now = h.now;
    h.session(2).request_authority(now, ids[0]).unwrap();
    h.advance(ms(300));
    let term = h.peers[1].session.term();
    let heir = h.earliest_live_joiner(0).unwrap();
    h.kill(0);
    let start = t(&h);
    h.run_frames(ms(3000), ms(11), |h| {
        let s = t(h) - start;
        let now = h.now;
        let _ = h.session(2).publish_state(
            now,
            ids[0],
            &ObjectState::rigid(Vec3::new(s * 0.3, 0.0, 0.0), Quat::IDENTITY),
        );
    });
    h.advance(ms(1500));
    for i in 1..4 {
        let s = &h.peers[i].session;
        assert_eq!(
            s.host_id(),
            Some(Harness::id(1)),
            "peer {i} follows the earliest joiner"
        );
        assert!(s.term() > term);
        assert_eq!(s.object_ids(), ids, "nothing lost on peer {i}");
    }
    assert!(h.peers[heir].session.is_host());
    assert_single_owner_everywhere(&h, &ids);
    // objects of the old host now belong to the new host, peer 2 keeps its own
    assert_eq!(h.peers[3].session.owner(ids[1]), Some(Harness::id(heir)));
    assert_eq!(h.peers[3].session.owner(ids[0]), Some(Harness::id(2)));
    // the new host relays peer 2's motion to peer 3
    let truth = h.peers[2].session.latest_state(ids[0]).unwrap();
    let seen = h.peers[3].session.latest_state(ids[0]).unwrap();
    assert!(
        truth.pos.distance(seen.pos) < 0.0015,
        "{truth:?} vs {seen:?}"
    );
}

#[test]
fn host_dies_during_handoff_ends_with_one_owner() {
    for (seed, delay_us) in [(1u64, 0u64), (2, 5_000), (3, 15_000), (4, 40_000)] {
        let mut link = ConditionerConfig::rough(seed, 10, 10, 0.0);
        link.duplicate = 0.0;
        let mut h = room(4, link);
        let ids = spawn_some(&mut h);
        h.advance(ms(500));
        let now = h.now;
        h.session(3).request_authority(now, ids[2]).unwrap();
        // the host dies somewhere around the grant
        h.advance(std::time::Duration::from_micros(10_000 + delay_us));
        h.kill(0);
        h.advance(ms(4000));
        assert_single_owner_everywhere(&h, &ids);
        for i in 1..4 {
            assert_eq!(h.peers[i].session.object_ids(), ids);
        }
    }
}

#[test]
fn late_join_after_migration_gets_everything() {
    let mut h = room(3, ConditionerConfig::rough(4, 20, 5, 0.05));
    let ids = spawn_some(&mut h);
    h.advance(ms(500));
    h.kill(0);
    h.advance(ms(2500));
    assert!(h.peers[1].session.is_host());
    // a newcomer contacts peer 2 (not the host): it is redirected to the new host
    let n = h.add_peer_with(common::config(), 2);
    h.advance(ms(2000));
    let s = &h.peers[n].session;
    assert!(s.is_connected());
    assert_eq!(s.host_id(), Some(Harness::id(1)));
    assert_eq!(s.object_ids(), ids);
    let truth = h.peers[1].session.latest_state(ids[3]).unwrap();
    let got = h.peers[n].session.latest_state(ids[3]).unwrap();
    assert!(max_particle_error(&truth, &got) < 0.0015);
}

#[test]
fn late_joiner_redirected_from_non_host() {
    let mut h = room(3, ConditionerConfig::rough(2, 10, 5, 0.05));
    let ids = spawn_some(&mut h);
    h.advance(ms(300));
    // contact peer 2, a client: it redirects to the host
    let n = h.add_peer_contacting(common::config(), Harness::id(2));
    h.advance(ms(2000));
    let s = &h.peers[n].session;
    assert!(s.is_connected());
    assert_eq!(s.host_id(), Some(Harness::id(0)));
    assert_eq!(s.object_ids(), ids);
    assert!(h.peers[0].session.members().contains_key(&Harness::id(n)));
}

/// Eight peers, everyone moving something, then the host dies: all converge on the new host.
#[test]
fn eight_peers_converge_and_survive_host_death() {
    let mut h = room(8, ConditionerConfig::rough(31, 30, 10, 0.05));
    let mut reqs = Vec::new();
    for i in 1..8 {
        let now = h.now;
        let (_, r) = h
            .session(i)
            .spawn(
                now,
                RIGID,
                ObjectState::rigid(Vec3::X * i as f32, Quat::IDENTITY),
            )
            .unwrap();
        reqs.push((i, r));
    }
    h.advance(ms(2000));
    let owned: Vec<(usize, softsync_net::NetId)> = reqs
        .iter()
        .map(|(i, r)| (*i, spawned_id(&h, *i, *r).unwrap()))
        .collect();
    let heir = h.earliest_live_joiner(0).unwrap();
    let start = t(&h);
    let mut killed = false;
    h.run_frames(ms(4000), ms(11), |h| {
        let s = t(h) - start;
        if s > 1.0 && !killed {
            h.kill(0);
            killed = true;
        }
        let now = h.now;
        let settle = s.min(3.0);
        for (i, id) in &owned {
            let p = Vec3::new(
                *i as f32,
                (settle * 2.0 + *i as f32).sin() * 0.2,
                settle * 0.1,
            );
            let _ = h
                .session(*i)
                .publish_state(now, *id, &ObjectState::rigid(p, Quat::IDENTITY));
        }
    });
    h.advance(ms(3000));
    let ids: Vec<softsync_net::NetId> = owned.iter().map(|(_, id)| *id).collect();
    assert_single_owner_everywhere(&h, &ids);
    for i in 1..8 {
        assert_eq!(h.peers[i].session.host_id(), Some(Harness::id(heir)));
        for (owner, id) in &owned {
            let truth = h.peers[*owner].session.latest_state(*id).unwrap().pos;
            let got = h.peers[i].session.latest_state(*id).unwrap().pos;
            assert!(
                truth.distance(got) < 0.0015,
                "peer {i} sees {id:?} at {got}, owner {truth}"
            );
        }
    }
}

#[test]
fn non_owner_updates_are_rejected() {
    let mut h = room(3, ConditionerConfig::default());
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(200));
    // the API refuses
    let now = h.now;
    let err = h
        .session(1)
        .publish_state(now, id, &ObjectState::rigid(Vec3::ONE, Quat::IDENTITY));
    assert!(err.is_err());
    // peer 1 owns it for a while and we record a datagram it sends to the host
    let now = h.now;
    h.session(1).request_authority(now, id).unwrap();
    h.advance(ms(200));
    let now = h.now;
    h.session(1)
        .publish_state(
            now,
            id,
            &ObjectState::rigid(Vec3::new(0.5, 0.0, 0.0), Quat::IDENTITY),
        )
        .unwrap();
    h.session(1).handle_timeout(now + ms(60));
    let mut recorded = Vec::new();
    while let Some(t) = h.session(1).poll_transmit(now + ms(60)) {
        if t.to == Harness::id(0) {
            recorded.push(t.payload);
        }
    }
    assert!(!recorded.is_empty());
    // authority moves to peer 2, which moves it elsewhere
    let now = h.now;
    h.session(1).release_authority(now, id).unwrap();
    h.advance(ms(300));
    let now = h.now;
    h.session(2).request_authority(now, id).unwrap();
    h.advance(ms(300));
    assert_eq!(h.peers[0].session.owner(id), Some(Harness::id(2)));
    let now = h.now;
    h.session(2)
        .publish_state(
            now,
            id,
            &ObjectState::rigid(Vec3::new(-1.0, 0.0, 0.0), Quat::IDENTITY),
        )
        .unwrap();
    h.advance(ms(500));
    let before = h.peers[0].session.stats().dropped_non_owner;
    // replay peer 1's stale update at the host
    let now = h.now;
    for d in &recorded {
        h.session(0).handle_packet(now, Harness::id(1), d);
    }
    assert!(h.peers[0].session.stats().dropped_non_owner > before);
    let pos = h.peers[0].session.latest_state(id).unwrap().pos;
    assert!(pos.distance(Vec3::new(-1.0, 0.0, 0.0)) < 0.002, "{pos}");
}

#[test]
fn stale_epoch_updates_are_dropped() {
    let mut h = room(2, ConditionerConfig::default());
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(200));
    let now = h.now;
    h.session(1).request_authority(now, id).unwrap();
    h.advance(ms(200));
    let now = h.now;
    h.session(1)
        .publish_state(
            now,
            id,
            &ObjectState::rigid(Vec3::new(0.3, 0.0, 0.0), Quat::IDENTITY),
        )
        .unwrap();
    h.session(1).handle_timeout(now + ms(60));
    let mut recorded = Vec::new();
    while let Some(t) = h.session(1).poll_transmit(now + ms(60)) {
        recorded.push(t.payload);
    }
    // host takes it back and gives it to peer 1 again: new epoch, same owner
    let now = h.now;
    h.session(1).release_authority(now, id).unwrap();
    h.advance(ms(200));
    let now = h.now;
    h.session(1).request_authority(now, id).unwrap();
    h.advance(ms(300));
    assert_eq!(h.peers[0].session.owner(id), Some(Harness::id(1)));
    // in the new epoch it is somewhere else
    let now = h.now;
    let moved = Vec3::new(-0.4, 0.2, 0.1);
    h.session(1)
        .publish_state(now, id, &ObjectState::rigid(moved, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(500));
    let pos = h.peers[0].session.latest_state(id).unwrap().pos;
    assert!(pos.distance(moved) < 0.002, "{pos}");
    let before = h.peers[0].session.stats().dropped_stale_epoch;
    // replay the old datagrams as if they were the newest from peer 1 (datagram sequence
    // right after the one it sends now), so only the epoch check can stop them
    let now = h.now + ms(250);
    h.session(1).handle_timeout(now);
    let mut seq = None;
    while let Some(t) = h.session(1).poll_transmit(now) {
        if t.to == Harness::id(0) {
            seq = Some(t.payload[2]);
            h.session(0).handle_packet(now, Harness::id(1), &t.payload);
        }
    }
    let mut seq = seq.expect("peer 1 sends the host something");
    for d in &recorded {
        let mut d = d.clone();
        seq = seq.wrapping_add(1);
        d[2] = seq; // version, term (1 byte), datagram sequence
        h.session(0).handle_packet(now, Harness::id(1), &d);
    }
    assert!(h.peers[0].session.stats().dropped_stale_epoch > before);
    // the replayed old-epoch position (0.3, 0, 0) is not shown
    let pos = h.peers[0].session.latest_state(id).unwrap().pos;
    assert!(pos.distance(moved) < 0.002, "{pos}");
    h.advance(ms(300));
    let pos = h.peers[0].session.latest_state(id).unwrap().pos;
    assert!(pos.distance(moved) < 0.002, "{pos}");
}

#[test]
fn protocol_version_mismatch_is_refused_with_reason() {
    let mut h = Harness::new(1, config(), ConditionerConfig::default());
    let mut joiner =
        softsync_net::Session::join(softsync_net::PeerId(7), Harness::id(0), config(), h.now);
    let mut hello = joiner.poll_transmit(h.now).unwrap();
    hello.payload[0] = softsync_net::PROTOCOL_VERSION + 1;
    let now = h.now;
    h.session(0)
        .handle_packet(now, softsync_net::PeerId(7), &hello.payload);
    let now = h.now;
    let reply = h.session(0).poll_transmit(now).unwrap();
    let now = h.now;
    assert_eq!(reply.to, softsync_net::PeerId(7));
    joiner.handle_packet(now, Harness::id(0), &reply.payload);
    match joiner.poll_event() {
        Some(Event::Refused { reason }) => assert!(reason.contains("version"), "{reason}"),
        other => panic!("expected refusal, got {other:?}"),
    }
    assert!(!joiner.is_connected());
    assert!(h.peers[0].session.members().len() == 1);
}

#[test]
fn class_table_mismatch_is_refused() {
    let mut h = room(1, ConditionerConfig::default());
    let mut other = config();
    other.classes[0].send.rate_hz = 7.0;
    let n = h.add_peer_with(other, 0);
    h.advance(ms(500));
    assert!(!h.peers[n].session.is_connected());
    assert!(h.peers[n]
        .events
        .iter()
        .any(|e| matches!(e, Event::Refused { reason } if reason.contains("configuration"))));
}

#[test]
fn big_soft_body_is_split_by_particle_ranges_under_small_mtu() {
    let mut cfg: SessionConfig = config();
    cfg.mtu = 576;
    cfg.classes[1].particles_per_chunk = 100;
    let mut h = Harness::new(3, cfg, ConditionerConfig::rough(2, 10, 5, 0.05));
    h.set_mtu(576);
    h.advance(ms(1000));
    let big = |s: f32| ObjectState {
        pos: Vec3::Y,
        rot: Quat::IDENTITY,
        particles: (0..1000)
            .map(|i| {
                let a = i as f32 * 0.1;
                Vec3::Y
                    + Vec3::new(a.cos(), (i as f32 / 1000.0) - 0.5, a.sin())
                        * (0.3 + 0.05 * s.sin())
            })
            .collect(),
    };
    let now = h.now;
    let (id, _) = h.session(0).spawn(now, SOFT, big(0.0)).unwrap();
    let start = t(&h);
    h.run_frames(ms(1500), ms(11), |h| {
        let now = h.now;
        let s = t(h) - start;
        h.session(0).publish_state(now, id, &big(s * 4.0)).unwrap();
    });
    h.advance(ms(4000));
    let truth = h.session(0).latest_state(id).unwrap();
    for i in 1..3 {
        let got = h.session(i).latest_state(id).unwrap();
        assert!(max_particle_error(&truth, &got) < 0.0015);
        assert!(h.peers[i].session.stats().max_datagram <= 576);
    }
    assert!(h.peers[0].session.stats().max_datagram <= 576);
    assert_eq!(h.hub.dropped_over_mtu(), 0);
    assert_eq!(h.peers[0].session.stats().oversize_dropped, 0);
}

/// Thesis future work (6.4): with a large ignore threshold, no staleness bound and no
/// periodic keyframes, only rest sync can bring the remote to the exact final pose.
#[test]
fn rest_sync_removes_threshold_error() {
    let mut cfg = config();
    cfg.classes[0].send.position_threshold_m = 0.05;
    cfg.classes[0].send.keyframe_interval = None;
    cfg.classes[0].send.stale_after_intervals = None;
    let mut h = Harness::new(2, cfg, ConditionerConfig::rough(8, 20, 5, 0.05));
    h.advance(ms(1000));
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(300));
    let start = t(&h);
    // 3 cm in 1 s: always below the 5 cm threshold
    h.run_frames(ms(1000), ms(11), |h| {
        let s = (t(h) - start).min(1.0);
        let now = h.now;
        h.session(0)
            .publish_state(
                now,
                id,
                &ObjectState::rigid(Vec3::new(0.03 * s, 0.0, 0.0), Quat::IDENTITY),
            )
            .unwrap();
    });
    h.advance(ms(2000));
    let truth = h.session(0).latest_state(id).unwrap().pos;
    let got = h.session(1).latest_state(id).unwrap().pos;
    assert!(truth.distance(got) < 0.0015, "{truth} vs {got}");
}

/// A late joiner must get the particles of a soft body that a client moved and left at rest
/// (the host only relays on change, so the join itself has to carry the state).
#[test]
fn late_joiner_gets_resting_client_owned_soft_body() {
    let mut h = room(2, ConditionerConfig::rough(6, 20, 5, 0.05));
    let now = h.now;
    let (_, r) = h
        .session(1)
        .spawn(now, SOFT, soft_state(Vec3::Y, Quat::IDENTITY, 0.0))
        .unwrap();
    h.advance(ms(1000));
    let id = spawned_id(&h, 1, r).unwrap();
    let start = t(&h);
    h.run_frames(ms(800), ms(11), |h| {
        let s = (t(h) - start).min(0.7);
        let now = h.now;
        h.session(1)
            .publish_state(
                now,
                id,
                &soft_state(Vec3::Y + Vec3::X * s, Quat::from_rotation_y(s), 0.4 * s),
            )
            .unwrap();
    });
    h.advance(ms(3000));
    let n = h.add_peer();
    h.advance(ms(2000));
    let truth = h.session(1).latest_state(id).unwrap();
    let got = h.session(n).latest_state(id).unwrap();
    assert!(
        max_particle_error(&truth, &got) < 0.0015,
        "{}",
        max_particle_error(&truth, &got)
    );
}

#[test]
fn owner_must_agree_policy_asks_the_holder() {
    let mut cfg = config();
    cfg.classes[0].authority = softsync_net::AuthorityPolicy::OwnerMustAgree;
    let mut h = Harness::new(3, cfg, ConditionerConfig::rough(12, 30, 10, 0.0));
    h.advance(ms(800));
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(300));
    let now = h.now;
    h.session(1).request_authority(now, id).unwrap();
    h.advance(ms(300));
    assert_eq!(
        h.peers[2].session.owner(id),
        Some(Harness::id(1)),
        "unheld: granted"
    );
    // peer 2 asks; the holder refuses, then agrees to a second ask
    let now = h.now;
    h.session(2).request_authority(now, id).unwrap();
    h.advance(ms(300));
    let asked = h.peers[1]
        .events
        .iter()
        .any(|e| matches!(e, Event::AuthorityAsked { by, .. } if *by == Harness::id(2)));
    assert!(asked);
    let now = h.now;
    h.session(1)
        .answer_authority(now, id, Harness::id(2), false);
    h.advance(ms(300));
    assert!(h.peers[2].events.iter().any(|e| matches!(
        e,
        Event::AuthorityDenied {
            reason: DenyReason::OwnerRefused,
            ..
        }
    )));
    assert_eq!(h.peers[0].session.owner(id), Some(Harness::id(1)));
    let now = h.now;
    h.session(2).request_authority(now, id).unwrap();
    h.advance(ms(300));
    let now = h.now;
    h.session(1).answer_authority(now, id, Harness::id(2), true);
    // sample the handoff every 2 ms: two peers acting as owner at once for at most one RTT
    let mut both = std::time::Duration::ZERO;
    for _ in 0..300 {
        h.advance(ms(2));
        let believers = (0..3)
            .filter(|i| h.peers[*i].session.owner(id) == Some(Harness::id(*i)))
            .count();
        assert!(believers <= 2);
        if believers == 2 {
            both += ms(2);
        }
    }
    assert!(both <= ms(80), "overlap {both:?} exceeds one round trip");
    for i in 0..3 {
        assert_eq!(h.peers[i].session.owner(id), Some(Harness::id(2)));
    }
}

#[test]
fn locked_objects_are_never_granted() {
    let mut cfg = config();
    cfg.classes[0].authority = softsync_net::AuthorityPolicy::Locked;
    let mut h = Harness::new(2, cfg, ConditionerConfig::default());
    h.advance(ms(500));
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(200));
    let now = h.now;
    h.session(1).request_authority(now, id).unwrap();
    h.advance(ms(200));
    assert_eq!(h.peers[1].session.owner(id), Some(Harness::id(0)));
    assert!(h.peers[1].events.iter().any(|e| matches!(
        e,
        Event::AuthorityDenied {
            reason: DenyReason::Locked,
            ..
        }
    )));
}

#[test]
fn stats_report_traffic_rtt_loss_and_classes() {
    let mut link = ConditionerConfig::rough(21, 40, 0, 0.10);
    link.p_enter_burst = 0.0;
    link.duplicate = 0.0;
    link.reorder = 0.0;
    let mut h = room(2, link);
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, SOFT, soft_state(Vec3::Y, Quat::IDENTITY, 0.0))
        .unwrap();
    let start = t(&h);
    h.run_frames(ms(6000), ms(11), |h| {
        let s = t(h) - start;
        let now = h.now;
        h.session(0)
            .publish_state(
                now,
                id,
                &soft_state(
                    Vec3::Y + Vec3::X * s.sin(),
                    Quat::IDENTITY,
                    0.3 * s.sin().abs(),
                ),
            )
            .unwrap();
    });
    let host = h.peers[0].session.stats().clone();
    let client = h.peers[1].session.stats().clone();
    let l = client.links.get(&Harness::id(0)).unwrap();
    let rtt = l.rtt.unwrap();
    assert!(rtt >= ms(75) && rtt <= ms(110), "rtt {rtt:?}");
    assert!((l.loss() - 0.10).abs() < 0.05, "loss {}", l.loss());
    assert!(host.class_up_bytes.get("soft").copied().unwrap_or(0.0) > 1000.0);
    assert!(client.class_down_bytes.get("soft").copied().unwrap_or(0.0) > 500.0);
    assert!(host.mtu_fill() > 0.0 && host.mtu_fill() < 1.0);
    assert_eq!(
        host.up.bytes,
        host.links.values().map(|l| l.up.bytes).sum::<u64>()
    );
}

/// Thesis 5.4.1: a center-only soft body sends no particle data; its center still converges.
#[test]
fn center_only_mode_replicates_the_center_only() {
    let run = |mode: softsync_net::SoftBodyMode| {
        let mut cfg = config();
        cfg.classes[1].soft_body_mode = mode;
        let mut h = Harness::new(2, cfg, ConditionerConfig::default());
        h.advance(ms(500));
        let now = h.now;
        let (id, _) = h
            .session(0)
            .spawn(now, SOFT, soft_state(Vec3::Y, Quat::IDENTITY, 0.0))
            .unwrap();
        let start = t(&h);
        h.run_frames(ms(2000), ms(11), |h| {
            let s = (t(h) - start).min(1.5);
            let now = h.now;
            h.session(0)
                .publish_state(
                    now,
                    id,
                    &soft_state(Vec3::Y + Vec3::Z * s, Quat::IDENTITY, 0.3 * s),
                )
                .unwrap();
        });
        h.advance(ms(1000));
        let truth = h.session(0).latest_state(id).unwrap();
        let got = h.session(1).latest_state(id).unwrap();
        let bytes = h.peers[0]
            .session
            .stats()
            .class_up_bytes
            .get("soft")
            .copied()
            .unwrap_or(0.0);
        (truth, got, bytes)
    };
    let (truth, got, center_bytes) = run(softsync_net::SoftBodyMode::CenterOnly);
    assert!(truth.pos.distance(got.pos) < 0.0015);
    assert!(
        got.particles.is_empty(),
        "center-only replicas carry no particles"
    );
    let (truth, got, particle_bytes) = run(softsync_net::SoftBodyMode::Particles);
    assert!(max_particle_error(&truth, &got) < 0.0015);
    assert!(
        particle_bytes > 3.0 * center_bytes,
        "{particle_bytes} vs {center_bytes}"
    );
}

/// The host hands its moving object to peer 1 while peer 2's `OwnerChanged` is lost (peer 2
/// is cut off from the host for a while); the host relays peer 1's updates to peer 2 with the
/// new epoch before the retransmitted `OwnerChanged` arrives, so peer 2 drops them. Peer 2's
/// base ring is full from the host's own 60+ updates, so a dropped entry must not become a
/// delta base: after settling peer 2 shows peer 1's position.
#[test]
fn observer_missing_owner_change_does_not_diverge() {
    let mut h = room(3, ConditionerConfig::default());
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(300));
    // the host moves it: well over 32 relayed entries on the host → peer 2 link
    let start = t(&h);
    h.run_frames(ms(3000), ms(11), |h| {
        let s = t(h) - start;
        let now = h.now;
        let p = Vec3::new((s * 1.7).sin() * 0.5, 1.0, s * 0.1);
        h.session(0)
            .publish_state(now, id, &ObjectState::rigid(p, Quat::IDENTITY))
            .unwrap();
    });
    let before = h.peers[2].session.latest_state(id).unwrap().pos;
    // peer 2 loses the grant's OwnerChanged (and a few retransmissions) …
    h.partition(0, 2, true);
    let now = h.now;
    h.session(1).request_authority(now, id).unwrap();
    let start = t(&h);
    let mut healed = false;
    let mut caught_up = None;
    h.run_frames(ms(3000), ms(11), |h| {
        let s = t(h) - start;
        if s > 0.6 && !healed {
            h.partition(0, 2, false); // … while peer 1's updates keep flowing
            healed = true;
        }
        // peer 1's positions have x ≥ 1, the host's were within ±0.5
        if caught_up.is_none() && h.peers[2].session.latest_state(id).unwrap().pos.x > 0.99 {
            caught_up = Some(s);
        }
        let now = h.now;
        let x = (s / 2.0).min(1.0);
        let p = Vec3::new(1.0 + x, 1.5 - x * 0.5, -x);
        let _ = h
            .session(1)
            .publish_state(now, id, &ObjectState::rigid(p, Quat::IDENTITY));
    });
    assert_eq!(h.peers[1].session.owner(id), Some(Harness::id(1)));
    assert!(
        h.peers[2].session.stats().dropped_stale_epoch > 0,
        "scenario: peer 2 must drop relayed updates of the new epoch"
    );
    // after a gap of more than 16 entries, newer entries are still shown at once
    let caught_up = caught_up.expect("peer 2 never showed peer 1's updates");
    assert!(
        caught_up < 0.6 + 0.4,
        "peer 2 showed peer 1's updates only at {caught_up} s"
    );
    h.advance(ms(2000));
    let truth = h.peers[1].session.latest_state(id).unwrap().pos;
    let now = h.now;
    for i in [0, 2] {
        assert_eq!(h.peers[i].session.owner(id), Some(Harness::id(1)));
        let latest = h.session(i).latest_state(id).unwrap().pos;
        let shown = h.session(i).display_state(now, id).unwrap().state.pos;
        assert!(
            latest.distance(truth) < 0.0015,
            "peer {i}: latest {latest} vs owner {truth}"
        );
        assert!(
            shown.distance(truth) < 0.0015,
            "peer {i}: shown {shown} vs owner {truth}"
        );
    }
    assert!(truth.distance(before) > 0.5);
}

/// Spawn requests matched to `request` in peer `i`'s events.
fn spawned_for(h: &Harness, i: usize, request: u32) -> Vec<softsync_net::NetId> {
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

fn steady_link() -> ConditionerConfig {
    let mut link = ConditionerConfig::rough(5, 20, 0, 0.0);
    link.duplicate = 0.0;
    link.reorder = 0.0;
    link
}

/// The host dies before it sees a client's spawn request: after the migration the request
/// goes to the new host, and a later request is not mistaken for it.
#[test]
fn spawn_request_lost_with_the_host_is_resent_and_matched_exactly() {
    let mut h = room(3, steady_link());
    let now = h.now;
    let (_, r0) = h
        .session(2)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::X, Quat::IDENTITY))
        .unwrap();
    h.kill(0); // the request dies in flight
    h.advance(ms(3000));
    assert!(h.peers[1].session.is_host());
    let now = h.now;
    let (_, r1) = h
        .session(2)
        .spawn(now, SOFT, soft_state(Vec3::Y * 2.0, Quat::IDENTITY, 0.0))
        .unwrap();
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
    let now = h.now;
    let (_, r0) = h
        .session(2)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::X, Quat::IDENTITY))
        .unwrap();
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
    let now = h.now;
    let (_, r0) = h
        .session(1)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::Z, Quat::IDENTITY))
        .unwrap();
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

/// The heir dies right after taking over: the next one takes over and every survivor follows
/// it, although some heard the first heir's `NewHost` and some did not.
#[test]
fn heir_dying_right_after_takeover_still_converges() {
    for (seed, after_us) in [(1u64, 0u64), (2, 10_000), (3, 30_000), (4, 200_000)] {
        let mut h = room(5, ConditionerConfig::rough(seed, 15, 5, 0.0));
        let ids = spawn_some(&mut h);
        h.advance(ms(500));
        h.kill(0);
        while !h.peers[1].session.is_host() {
            h.advance(ms(1));
        }
        h.advance(std::time::Duration::from_micros(after_us));
        h.kill(1);
        h.advance(ms(5000));
        for i in 2..5 {
            let s = &h.peers[i].session;
            assert_eq!(s.host_id(), Some(Harness::id(2)), "seed {seed}: peer {i}");
            assert_eq!(s.object_ids(), ids, "seed {seed}: peer {i}");
        }
        assert_single_owner_everywhere(&h, &ids);
    }
}

/// Negative or non-finite interpolation settings are made sane: display never panics and the
/// delay is never negative.
#[test]
fn bad_interpolation_settings_are_sanitized() {
    let mut h = room(2, ConditionerConfig::rough(3, 20, 5, 0.0));
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    let start = t(&h);
    h.run_frames(ms(1000), ms(11), |h| {
        let now = h.now;
        let p = Vec3::X * (t(h) - start);
        h.session(0)
            .publish_state(now, id, &ObjectState::rigid(p, Quat::IDENTITY))
            .unwrap();
    });
    for (intervals, jitter_factor) in [(-5.0, -3.0), (f32::NAN, f32::INFINITY), (-0.0, -1e30)] {
        h.session(1)
            .set_interpolation(softsync_net::InterpolationConfig {
                intervals,
                jitter_factor,
                snap_distance_m: -1.0,
                ..Default::default()
            });
        let cfg = h.peers[1].session.interpolation();
        assert!(cfg.intervals >= 0.0 && cfg.jitter_factor >= 0.0 && cfg.snap_distance_m >= 0.0);
        let now = h.now;
        let shown = h.session(1).display_state(now, id).unwrap();
        assert!(shown.state.pos.is_finite());
        assert!(shown.delay <= ms(300), "{:?}", shown.delay);
    }
}

/// A rotation that is not a unit quaternion is refused (far off, or zero), or normalized
/// (rounding): particle offsets stay right on remote peers either way.
#[test]
fn publish_state_refuses_or_normalizes_non_unit_rotations() {
    let mut h = room(2, ConditionerConfig::default());
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, SOFT, soft_state(Vec3::Y, Quat::IDENTITY, 0.0))
        .unwrap();
    h.advance(ms(300));
    let q = Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.3);
    let now = h.now;
    for bad in [q * 2.0, q * 0.5, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)] {
        let st = soft_state(Vec3::Y, q, 0.2);
        let err = h
            .session(0)
            .publish_state(now, id, &ObjectState { rot: bad, ..st });
        assert!(
            matches!(err, Err(softsync_net::NetError::InvalidState(_))),
            "{bad:?}: {err:?}"
        );
    }
    assert!(h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, q * 3.0))
        .is_err());
    // 0.9 % off (|q|² = 1.018): accepted and normalized
    let truth = soft_state(Vec3::Y + Vec3::X * 0.3, q, 0.2);
    let sloppy = ObjectState {
        rot: q * 1.009,
        ..truth.clone()
    };
    h.session(0).publish_state(now, id, &sloppy).unwrap();
    h.advance(ms(1000));
    let got = h.session(1).latest_state(id).unwrap();
    let e = max_particle_error(&truth, &got);
    assert!(e < 0.0015, "particle error {e} m");
    let own = h.session(0).latest_state(id).unwrap();
    assert!((own.rot.length() - 1.0).abs() < 1e-5);
}

/// A long outage (within the peer timeout) loses more datagrams than the 8-bit datagram
/// sequence can tell from a late one: the receiver still takes the new ones as the newest
/// and follows again at once.
#[test]
fn outage_losing_hundreds_of_datagrams_recovers_at_once() {
    let cfg = SessionConfig {
        peer_timeout: ms(20_000),
        ..common::config()
    };
    let mut h = Harness::new(2, cfg, ConditionerConfig::default());
    h.advance(ms(1500));
    let now = h.now;
    let (id, _) = h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(300));
    let start = t(&h);
    let pos = |s: f32| Vec3::new((s * 0.9).sin(), 1.0, (s * 0.5).cos());
    let mut cut_at = None;
    let mut lag = Vec::new();
    let mut sent_at_cut = (0, 0);
    h.run_frames(ms(14_000), ms(11), |h| {
        let s = t(h) - start;
        let now = h.now;
        h.session(0)
            .publish_state(now, id, &ObjectState::rigid(pos(s), Quat::IDENTITY))
            .unwrap();
        let sent = |h: &Harness| h.peers[0].session.stats().links[&Harness::id(1)].up.packets;
        if s > 2.0 && cut_at.is_none() {
            h.partition(0, 1, true);
            cut_at = Some(s);
            sent_at_cut.0 = sent(h);
        }
        if s > 10.0 && cut_at.is_some_and(|c| c < 10.0) {
            h.partition(0, 1, false);
            cut_at = Some(s);
            sent_at_cut.1 = sent(h);
        }
        if s > 10.5 {
            let seen = h.peers[1].session.latest_state(id).unwrap().pos;
            lag.push((s, seen.distance(pos(s))));
        }
    });
    // the datagrams lost in the outage make the next one look 16–127 datagrams late
    let lost = sent_at_cut.1 - sent_at_cut.0;
    assert!((128..240).contains(&(lost % 256)), "{lost} datagrams lost");
    let worst = lag.iter().map(|(_, e)| *e).fold(0.0, f32::max);
    assert!(
        worst < 0.1,
        "peer 1 lags the host by up to {worst} m after the outage"
    );
}

/// A peer that says `Leave` is gone at once, not after the 1 s timeout: a leaving client's
/// objects go back to the host, a leaving host is replaced by the earliest joiner.
#[test]
fn leaving_peers_are_handled_at_once() {
    let mut h = room(4, ConditionerConfig::rough(4, 20, 5, 0.0));
    let ids = spawn_some(&mut h);
    h.advance(ms(500));
    let now = h.now;
    h.session(3).request_authority(now, ids[0]).unwrap();
    h.advance(ms(300));
    assert_eq!(h.peers[1].session.owner(ids[0]), Some(Harness::id(3)));

    // A client leaves: within 200 ms (5x shorter than the timeout) it is out, its object back.
    let now = h.now;
    h.session(3).leave(now);
    // The leaver's own link delays what it sends by 20-25 ms: let that go out, then it is gone.
    h.advance(ms(40));
    h.kill(3);
    h.advance(ms(160));
    for i in 0..3 {
        let s = &h.peers[i].session;
        assert!(
            !s.members().contains_key(&Harness::id(3)),
            "peer {i} still lists the leaver"
        );
        assert_eq!(
            s.owner(ids[0]),
            Some(Harness::id(0)),
            "peer {i}: authority not back"
        );
    }

    // The host leaves: the earliest joiner takes over within 200 ms, with a higher term.
    let term = h.peers[1].session.term();
    let now = h.now;
    h.session(0).leave(now);
    h.advance(ms(40));
    h.kill(0);
    h.advance(ms(160));
    for i in 1..3 {
        let s = &h.peers[i].session;
        assert_eq!(
            s.host_id(),
            Some(Harness::id(1)),
            "peer {i} follows the earliest joiner"
        );
        assert!(s.term() > term);
        assert_eq!(s.object_ids(), ids, "nothing lost on peer {i}");
    }
    assert_single_owner_everywhere(&h, &ids);
}

/// A member whose loop stalls past the peer timeout is dropped by the host; when it wakes it
/// is told so (a refusal) and does not elect itself host of a room of one (found live: a peer
/// whose first frames on a software renderer froze its loop for over a second).
#[test]
fn a_host_that_stalls_past_the_timeout_is_told_the_room_moved_on() {
    let mut h = room(3, ConditionerConfig::default());
    let ids = spawn_some(&mut h);
    h.advance(ms(500));
    h.freeze(0, true);
    h.advance(ms(3000));
    assert_eq!(
        h.host_index(),
        Some(1),
        "no new host while the old one stalled"
    );
    for id in &ids {
        assert_eq!(h.peers[1].session.owner(*id), Some(Harness::id(1)));
    }
    // it carries on where it stopped: still host, still owning everything, and it talks
    h.freeze(0, false);
    h.advance(ms(1500));
    let refused = h.peers[0].events.iter().find_map(|e| match e {
        Event::Dropped { host, reason } if *host == Harness::id(1) => Some(reason.clone()),
        _ => None,
    });
    assert!(
        refused.as_deref().is_some_and(|r| r.contains("moved on")),
        "the stalled host was not told: {:?}",
        h.peers[0].events
    );
    assert!(
        !h.peers[0].session.is_host(),
        "the stalled host still believes it is host"
    );
    // the room it left is whole: one host, two members, every object owned once
    assert_eq!(h.host_index(), Some(1));
    for i in 1..3 {
        let s = &h.peers[i].session;
        assert_eq!(s.members().len(), 2, "peer {i}: {:?}", s.members());
        assert!(!s.members().contains_key(&Harness::id(0)), "peer {i}");
        assert!(
            !h.peers[i].events.iter().any(|e| matches!(
                e,
                Event::HostChanged { host, .. } if *host == Harness::id(0)
            )),
            "peer {i} followed the stalled host back"
        );
        for id in &ids {
            assert_eq!(s.owner(*id), Some(Harness::id(1)), "peer {i}, {id:?}");
        }
    }
    // and it stays out: quiet from then on, the room unchanged
    let sent = h.peers[0].session.stats().up.bytes;
    h.advance(ms(2000));
    assert!(!h.peers[0].session.is_host());
    assert_eq!(h.host_index(), Some(1));
    assert_eq!(
        h.peers[0].session.stats().up.bytes,
        sent,
        "the refused old host kept sending"
    );
    // It comes back as a member of the room it used to host.
    rejoin(&mut h, 0, 1);
    assert_room_whole_again(&h, &ids, 1);
}

#[test]
fn a_member_that_stalls_past_the_timeout_is_told_it_was_dropped() {
    let mut h = room(3, ConditionerConfig::default());
    let ids = spawn_some(&mut h);
    h.advance(ms(500));
    h.freeze(2, true);
    h.advance(ms(2500));
    assert!(
        !h.peers[0].session.members().contains_key(&Harness::id(2)),
        "the host still lists the stalled peer"
    );
    h.freeze(2, false);
    h.advance(ms(1500));
    let refused = h.peers[2].events.iter().find_map(|e| match e {
        Event::Dropped { host, reason } if *host == Harness::id(0) => Some(reason.clone()),
        _ => None,
    });
    assert!(
        refused.as_deref().is_some_and(|r| r.contains("dropped")),
        "the stalled peer was not told: {:?}",
        h.peers[2].events
    );
    assert!(
        !h.peers[2].session.is_host(),
        "the stalled peer made itself host"
    );
    assert!(
        !h.peers[2]
            .events
            .iter()
            .any(|e| matches!(e, Event::HostChanged { .. })),
        "the stalled peer saw a host change"
    );
    assert_eq!(h.host_index(), Some(0));
    for i in 0..2 {
        let s = &h.peers[i].session;
        assert_eq!(s.members().len(), 2, "peer {i}: {:?}", s.members());
        assert_eq!(s.owner(ids[0]), Some(Harness::id(0)), "peer {i}");
    }
    // It comes back with a fresh session (same peer id): a member again, with the room's
    // state, and the others see it join.
    rejoin(&mut h, 2, 0);
    assert_room_whole_again(&h, &ids, 0);
}

/// Peer `i`, dropped, joins `host` again with a fresh session (as the app does).
fn rejoin(h: &mut Harness, i: usize, host: usize) {
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
fn assert_room_whole_again(h: &Harness, ids: &[softsync_net::NetId], host: usize) {
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

#[test]
fn a_newer_term_refusal_stops_only_a_peer_that_stalled() {
    // A peer cut off from the room elects itself host of a newer term; it must not depose
    // a host (or drop a client) that never stopped. The same refusal after a stall of our
    // own is believed.
    let mut h = room(3, ConditionerConfig::default());
    let _ids = spawn_some(&mut h);
    h.advance(ms(500));
    let fake = softsync_net::wire::encode_refusal("the room moved on", softsync_net::Term(9));
    let now = h.now;
    for i in 0..2 {
        h.session(i).handle_packet(now, Harness::id(2), &fake);
    }
    h.advance(ms(500));
    assert_eq!(h.host_index(), Some(0));
    for i in 0..2 {
        assert!(
            !h.peers[i]
                .events
                .iter()
                .any(|e| matches!(e, Event::Dropped { .. })),
            "peer {i} believed it"
        );
    }
    assert_eq!(h.peers[0].session.members().len(), 3);
    // after a stall of the peer timeout, it is believed
    h.freeze(1, true);
    h.advance(ms(1200));
    h.freeze(1, false);
    let now = h.now;
    h.session(1).handle_packet(now, Harness::id(2), &fake);
    assert!(
        h.peers[1]
            .session
            .poll_event()
            .into_iter()
            .chain(std::iter::from_fn(|| h.peers[1].session.poll_event()))
            .any(|e| matches!(e, Event::Dropped { host, .. } if host == Harness::id(2))),
        "the stalled peer did not believe it"
    );
}

#[test]
fn a_joiner_redirected_by_a_member_follows_that_member_when_it_takes_over() {
    // The joiner first says Hello to a member (it answers Redirect on the reliable channel),
    // then joins through the host. When the host dies, that member takes over and its
    // `NewHost` to the joiner travels on the same channel: sequences on both ends must still
    // agree (resetting the member's link when it learned of the join broke this).
    let mut h = room(3, ConditionerConfig::default());
    let ids = spawn_some(&mut h);
    let j = h.add_peer_contacting(config(), Harness::id(1));
    h.advance(ms(2000));
    assert!(h.peers[j].session.is_connected(), "the joiner is not in");
    h.freeze(0, true);
    h.advance(ms(3000));
    assert_eq!(h.host_index(), Some(1));
    for i in [1, 2, j] {
        let s = &h.peers[i].session;
        assert_eq!(s.host_id(), Some(Harness::id(1)), "peer {i}");
        assert_eq!(s.members().len(), 3, "peer {i}: {:?}", s.members());
    }
    assert_single_owner_everywhere(&h, &ids);
}

#[test]
fn a_joiner_that_asked_another_joiner_first_keeps_its_reliable_channel_with_it() {
    // J2 says Hello to J1 while J1 is still joining (no answer), then asks the host with the
    // same session (`join_via`, as the app does after a second). The host dies and J1 takes
    // over: J2's first reliable message to it, a spawn request, must arrive (with a fresh
    // session J1 took it for a repeat of the unanswered Hello).
    let mut h = Harness::new(1, config(), ConditionerConfig::default());
    let j1 = h.add_peer_contacting(config(), Harness::id(0));
    let j2 = h.add_peer_contacting(config(), Harness::id(j1));
    h.advance(ms(1000));
    assert!(h.peers[j1].session.is_connected());
    assert!(
        !h.peers[j2].session.is_connected(),
        "J1 answered while joining"
    );
    let now = h.now;
    assert!(h.session(j2).join_via(now, Harness::id(0)));
    h.advance(ms(1000));
    assert!(h.peers[j2].session.is_connected(), "J2 did not get in");
    h.freeze(0, true);
    h.advance(ms(3000));
    assert_eq!(h.host_index(), Some(j1));
    assert_eq!(h.peers[j2].session.host_id(), Some(Harness::id(j1)));
    let now = h.now;
    let (_, request) = h
        .session(j2)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::Y, Quat::IDENTITY))
        .unwrap();
    h.advance(ms(1000));
    assert!(
        h.peers[j2].events.iter().any(|e| matches!(
            e,
            Event::Spawned { request: Some(r), .. } if *r == request
        )),
        "J2's spawn request never reached the new host: {:?}",
        h.peers[j2].events
    );
}
