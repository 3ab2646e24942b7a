//! Host migration: the earliest joiner takes over when the host dies (during a handoff, with
//! eight peers, when the heir dies too); late joiners and redirected joiners find the host.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::{ConditionerConfig, Event, NetId, ObjectState};

#[test]
fn host_death_earliest_joiner_takes_over() {
    let (mut h, ids) = room_with_objects(4, ConditionerConfig::rough(9, 20, 5, 0.02));
    // peer 2 owns one object and keeps moving it
    request_authority(&mut h, 2, ids[0]);
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
    assert_earliest_joiner_took_over(&h, 1..4, term, &ids);
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
        let (mut h, ids) = room_with_objects(4, link);
        request_authority(&mut h, 3, ids[2]);
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

/// The heir dies right after taking over: the next one takes over and every survivor follows
/// it, although some heard the first heir's `NewHost` and some did not.
#[test]
fn heir_dying_right_after_takeover_still_converges() {
    for (seed, after_us) in [(1u64, 0u64), (2, 10_000), (3, 30_000), (4, 200_000)] {
        let (mut h, ids) = room_with_objects(5, ConditionerConfig::rough(seed, 15, 5, 0.0));
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

/// Eight peers, everyone moving something, then the host dies: all converge on the new host.
#[test]
fn eight_peers_converge_and_survive_host_death() {
    let mut h = room(8, ConditionerConfig::rough(31, 30, 10, 0.05));
    let mut reqs = Vec::new();
    for i in 1..8 {
        let (_, r) = spawn_rigid(&mut h, i, Vec3::X * i as f32);
        reqs.push((i, r));
    }
    h.advance(ms(2000));
    let owned: Vec<(usize, NetId)> = reqs
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
    let ids: Vec<NetId> = owned.iter().map(|(_, id)| *id).collect();
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
fn late_join_after_migration_gets_everything() {
    let (mut h, ids) = room_with_objects(3, ConditionerConfig::rough(4, 20, 5, 0.05));
    h.kill(0);
    h.advance(ms(2500));
    assert!(h.peers[1].session.is_host());
    // a newcomer contacts peer 2 (not the host): it is redirected to the new host
    let n = h.add_peer_with(config(), 2);
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
    let n = h.add_peer_contacting(config(), Harness::id(2));
    h.advance(ms(2000));
    let s = &h.peers[n].session;
    assert!(s.is_connected());
    assert_eq!(s.host_id(), Some(Harness::id(0)));
    assert_eq!(s.object_ids(), ids);
    assert!(h.peers[0].session.members().contains_key(&Harness::id(n)));
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
    let (_, request) = spawn_rigid(&mut h, j2, Vec3::Y);
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
