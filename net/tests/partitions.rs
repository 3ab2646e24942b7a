//! Partitions heal into one room (issue 17 point 2), on virtual time: the room is split in
//! two for 3 or 10 s, each side elects a host and goes on (spawning objects of its own), the
//! links come back, and beacons between the sides merge them by the rule of
//! `RoomSummary::beats` — the larger room wins; between equal rooms, the one whose host joined
//! first. Every peer ends in the winner's room: one host, one term, every member; the
//! winner's objects all there with one owner each; the yielding side's own objects gone.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::collections::BTreeSet;

use common::{assert_single_owner_everywhere, config, ms, room, spawn_rigid, steady_link};
use glam::Vec3;
use softsync_net::harness::Harness;
use softsync_net::{ConditionerConfig, Event, NetId, PeerId};

/// Cuts (or restores) every link between `a` and `b`.
fn split(h: &mut Harness, a: &[usize], b: &[usize], cut: bool) {
    for &x in a {
        for &y in b {
            h.partition(x, y, cut);
        }
    }
}

/// What one run showed.
struct Healed {
    winner_host: PeerId,
    /// Objects the winning side had at the heal.
    winner_objects: BTreeSet<NetId>,
    /// Objects only the yielding side had.
    loser_only: BTreeSet<NetId>,
}

/// `n` peers (0 hosts), objects spawned by 0 and by the last peer; split into `a` | `b` for
/// `apart_ms`; each side spawns one object apart; heal; 8 s to settle.
fn split_and_heal(
    n: usize,
    a: &[usize],
    b: &[usize],
    apart_ms: u64,
    link: ConditionerConfig,
) -> (Harness, Healed) {
    let mut h = room(n, link);
    h.auto_rejoin = true;
    spawn_rigid(&mut h, 0, Vec3::X);
    spawn_rigid(&mut h, n - 1, Vec3::Z);
    h.advance(ms(500));
    split(&mut h, a, b, true);
    h.advance(ms(2500));
    // each side has its own host and room now
    let host_a = h.peers[a[0]].session.host_id().unwrap();
    let host_b = h.peers[b[0]].session.host_id().unwrap();
    assert_ne!(host_a, host_b, "the sides did not separate");
    spawn_rigid(&mut h, a[a.len() - 1], Vec3::Y);
    spawn_rigid(&mut h, b[b.len() - 1], -Vec3::Y);
    h.advance(ms(apart_ms.saturating_sub(2500)));
    let objects = |h: &Harness, i: usize| -> BTreeSet<NetId> {
        h.peers[i].session.object_ids().into_iter().collect()
    };
    let (objs_a, objs_b) = (objects(&h, a[0]), objects(&h, b[0]));
    let summary = |h: &Harness, i: usize| h.peers[i].session.room_summary().unwrap();
    let (sa, sb) = (summary(&h, a[0]), summary(&h, b[0]));
    let a_wins = sa.beats(&sb);
    assert_ne!(a_wins, sb.beats(&sa), "the rule is a total order");
    split(&mut h, a, b, false);
    h.advance(ms(8000));
    let (winner_host, winner_objects, loser_objects) = if a_wins {
        (host_a, objs_a, objs_b)
    } else {
        (host_b, objs_b, objs_a)
    };
    let loser_only = loser_objects.difference(&winner_objects).copied().collect();
    (
        h,
        Healed {
            winner_host,
            winner_objects,
            loser_only,
        },
    )
}

/// One room again: every peer follows `winner_host` in one term with all `n` members; the
/// winner's objects everywhere with one owner each, the loser's own gone.
fn assert_one_room(h: &Harness, n: usize, r: &Healed) {
    let term = h.peers[0].session.term();
    for i in 0..n {
        let s = &h.peers[i].session;
        assert_eq!(s.host_id(), Some(r.winner_host), "peer {i}");
        assert_eq!(s.term(), term, "peer {i}");
        assert_eq!(s.members().len(), n, "peer {i}: {:?}", s.members());
        let ids: BTreeSet<NetId> = s.object_ids().into_iter().collect();
        assert!(
            r.winner_objects.is_subset(&ids),
            "peer {i} lacks some of the winner's objects: {:?} vs {:?}",
            ids,
            r.winner_objects
        );
        assert!(
            ids.is_disjoint(&r.loser_only),
            "peer {i} keeps the yielding side's objects"
        );
    }
    let ids: Vec<NetId> = r.winner_objects.iter().copied().collect();
    assert_single_owner_everywhere(h, &ids);
    assert!(
        !r.loser_only.is_empty(),
        "the yielding side spawned one apart"
    );
}

fn dropped_towards(h: &Harness, i: usize, host: PeerId) -> bool {
    h.peers[i]
        .events
        .iter()
        .any(|e| matches!(e, Event::Dropped { host: to, .. } if *to == host))
}

#[test]
fn a_minority_with_the_old_host_joins_the_majority_after_3_and_10_s_apart() {
    for apart in [3000, 10_000] {
        let (h, r) = split_and_heal(5, &[0, 1], &[2, 3, 4], apart, steady_link());
        // the larger side's host: peer 2, the earliest joiner there
        assert_eq!(r.winner_host, Harness::id(2), "{apart} ms apart");
        assert_one_room(&h, 5, &r);
        for i in [0, 1] {
            assert!(
                dropped_towards(&h, i, r.winner_host),
                "peer {i}, {apart} ms apart"
            );
        }
        assert_eq!(h.rejoins, 2, "{apart} ms apart");
    }
}

#[test]
fn an_even_split_goes_to_the_side_whose_host_joined_first() {
    let (h, r) = split_and_heal(4, &[2, 3], &[0, 1], 3000, steady_link());
    assert_eq!(r.winner_host, Harness::id(0));
    assert_one_room(&h, 4, &r);
    assert_eq!(h.rejoins, 2);
}

#[test]
fn a_lone_host_cut_off_joins_the_two_that_went_on_also_under_loss() {
    let lossy = ConditionerConfig::rough(11, 30, 10, 0.05);
    for link in [steady_link(), lossy] {
        let (h, r) = split_and_heal(3, &[0], &[1, 2], 10_000, link);
        assert_eq!(r.winner_host, Harness::id(1));
        assert_one_room(&h, 3, &r);
        assert!(h.peers[0].session.stats().merges <= 1);
    }
}

#[test]
fn rooms_with_another_configuration_never_merge() {
    // The same peers, but one side's configuration differs (another class table): their
    // beacons are heard and ignored.
    let mut h = room(3, steady_link());
    h.auto_rejoin = true;
    split(&mut h, &[0], &[1, 2], true);
    h.advance(ms(3000));
    let mut other = config();
    other.classes.pop();
    let now = h.now;
    // peer 0 starts a room of its own with the other configuration
    *h.session(0) = softsync_net::Session::host(Harness::id(0), other, now);
    split(&mut h, &[0], &[1, 2], false);
    h.advance(ms(5000));
    assert_eq!(h.peers[0].session.host_id(), Some(Harness::id(0)));
    assert_eq!(h.peers[1].session.host_id(), Some(Harness::id(1)));
    assert_eq!(h.rejoins, 0);
}

/// A beacon from a peer that is not of the room, claiming a room of 100 under host 999.
fn forged_beacon(h: &Harness) -> Vec<u8> {
    let digest = h.peers[0].session.config().digest();
    let header = softsync_net::wire::PacketHeader {
        term: softsync_net::Term(7),
        seq: 0,
        time_ms: 0,
    };
    let s = softsync_net::wire::RoomSummary {
        digest,
        host: PeerId(999),
        host_join: 0,
        members: 100,
        tag: None,
    };
    softsync_net::wire::encode_beacon(&header, &s)
}

#[test]
fn in_a_keyed_room_only_beacons_tagged_with_the_key_count() {
    let mut cfg = config();
    cfg.room_key = Some(softsync_net::RoomKey::new(
        b"sixteen-byte-key-for-the-test",
        1,
    ));
    let mut h = common::room_with(3, cfg, steady_link(), ms(1500));
    h.auto_rejoin = true;
    // a forged beacon (no tag) changes nothing
    let bytes = forged_beacon(&h);
    let now = h.now;
    h.session(0).handle_packet(now, PeerId(999), &bytes);
    h.advance(ms(500));
    assert_eq!(h.peers[0].session.host_id(), Some(Harness::id(0)));
    assert!(h.peers[0].session.stats().beacons_refused >= 1);
    assert_eq!(h.rejoins, 0);
    // the room's own beacons carry the tag: a partition still heals
    split(&mut h, &[0], &[1, 2], true);
    h.advance(ms(3000));
    split(&mut h, &[0], &[1, 2], false);
    h.advance(ms(8000));
    for i in 0..3 {
        assert_eq!(
            h.peers[i].session.host_id(),
            Some(Harness::id(1)),
            "peer {i}"
        );
        assert_eq!(h.peers[i].session.members().len(), 3, "peer {i}");
    }
}

/// Issue 32: a beacon counts only from a peer the room lost, claiming at most a room's
/// worth of members. Unkeyed, a made-up beacon from a stranger, from a member, or from a lost
/// peer claiming 100 members (more than `max_members`) takes nothing; the room's own beacons
/// still heal a partition.
#[test]
fn a_made_up_beacon_takes_no_room_even_without_a_key() {
    let mut h = room(3, steady_link());
    h.auto_rejoin = true;
    let bytes = forged_beacon(&h);
    let now = h.now;
    // a stranger, and a member of the room (which the room did not lose)
    h.session(0).handle_packet(now, PeerId(999), &bytes);
    h.session(0).handle_packet(now, Harness::id(2), &bytes);
    h.advance(ms(500));
    assert!(!dropped_towards(&h, 0, PeerId(999)));
    assert_eq!(h.peers[0].session.host_id(), Some(Harness::id(0)));
    assert!(h.peers[0].session.stats().beacons_refused >= 2);
    assert_eq!(h.rejoins, 0);
    // a real partition: peer 0 alone, 1 and 2 go on; then a lost peer's made-up summary of
    // 100 members is refused too, and the real beacons heal the room
    split(&mut h, &[0], &[1, 2], true);
    h.advance(ms(3000));
    assert!(h.peers[0].session.lost_peers().contains(&Harness::id(2)));
    let refused = h.peers[0].session.stats().beacons_refused;
    let now = h.now;
    h.session(0).handle_packet(now, Harness::id(2), &bytes);
    assert_eq!(h.peers[0].session.stats().beacons_refused, refused + 1);
    assert!(!dropped_towards(&h, 0, PeerId(999)));
    split(&mut h, &[0], &[1, 2], false);
    h.advance(ms(8000));
    for i in 0..3 {
        assert_eq!(
            h.peers[i].session.host_id(),
            Some(Harness::id(1)),
            "peer {i}"
        );
        assert_eq!(h.peers[i].session.members().len(), 3, "peer {i}");
    }
}

fn arb_summary() -> impl proptest::strategy::Strategy<Value = softsync_net::wire::RoomSummary> {
    use proptest::prelude::*;
    (0u32..6, 0u32..6, 0u64..4).prop_map(|(members, host_join, host)| {
        softsync_net::wire::RoomSummary {
            digest: 1,
            host: PeerId(host),
            host_join,
            members,
            tag: None,
        }
    })
}

proptest::proptest! {
    /// The merge rule is a strict total order on rooms: of two different rooms exactly one
    /// wins, and it is transitive — so every peer agrees which side yields, whatever order
    /// beacons arrive in.
    #[test]
    fn the_merge_rule_is_a_strict_total_order(a in arb_summary(), b in arb_summary(), c in arb_summary()) {
        let key = |s: &softsync_net::wire::RoomSummary| (s.members, s.host_join, s.host);
        if key(&a) == key(&b) {
            proptest::prop_assert!(!a.beats(&b) && !b.beats(&a));
        } else {
            proptest::prop_assert!(a.beats(&b) != b.beats(&a));
        }
        if a.beats(&b) && b.beats(&c) {
            proptest::prop_assert!(a.beats(&c));
        }
    }

    /// A join token's text form never panics the parser, whatever is given.
    #[test]
    fn any_text_parses_to_a_token_or_an_error(s in ".{0,120}") {
        let _ = s.parse::<softsync_net::wire::RoomToken>();
    }
}
