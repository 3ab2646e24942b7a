//! Peers that stall or leave: a `Leave` is handled at once; a host or member that stalls
//! past the peer timeout is told the room moved on and rejoins; refusals of a newer term
//! stop only a peer that stalled.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use softsync_net::harness::Harness;
use softsync_net::wire::encode_refusal;
use softsync_net::{ConditionerConfig, Event, Term};

/// A peer that says `Leave` is gone at once, not after the 1 s timeout: a leaving client's
/// objects go back to the host, a leaving host is replaced by the earliest joiner.
#[test]
fn leaving_peers_are_handled_at_once() {
    let (mut h, ids) = room_with_objects(4, ConditionerConfig::rough(4, 20, 5, 0.0));
    request_authority(&mut h, 3, ids[0]);
    h.advance(ms(300));
    assert_eq!(h.peers[1].session.owner(ids[0]), Some(Harness::id(3)));

    // A client leaves: within 200 ms (5x shorter than the timeout) it is out, its object back.
    leave_and_wait(&mut h, 3);
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
    leave_and_wait(&mut h, 0);
    assert_earliest_joiner_took_over(&h, 1..3, term, &ids);
    assert_single_owner_everywhere(&h, &ids);
}

/// Peer `i` says `Leave` and is gone, 200 ms later.
fn leave_and_wait(h: &mut Harness, i: usize) {
    let now = h.now;
    h.session(i).leave(now);
    // The leaver's own link delays what it sends by 20-25 ms: let that go out, then it is gone.
    h.advance(ms(40));
    h.kill(i);
    h.advance(ms(160));
}

/// A member whose loop stalls past the peer timeout is dropped by the host; when it wakes it
/// is told so (a refusal) and does not elect itself host of a room of one (found live: a peer
/// whose first frames on a software renderer froze its loop for over a second).
#[test]
fn a_host_that_stalls_past_the_timeout_is_told_the_room_moved_on() {
    let (mut h, ids) = room_with_objects(3, ConditionerConfig::default());
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
    assert_told_it_is_out(&h, 0, 1, "moved on");
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
    let (mut h, ids) = room_with_objects(3, ConditionerConfig::default());
    h.freeze(2, true);
    h.advance(ms(2500));
    assert!(
        !h.peers[0].session.members().contains_key(&Harness::id(2)),
        "the host still lists the stalled peer"
    );
    h.freeze(2, false);
    h.advance(ms(1500));
    assert_told_it_is_out(&h, 2, 0, "dropped");
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

/// Peer `i`, awake after a stall, was told by peer `by` that it is out (the reason says
/// `words`) and does not act as host.
fn assert_told_it_is_out(h: &Harness, i: usize, by: usize, words: &str) {
    let refused = dropped_reason(h, i, by);
    assert!(
        refused.as_deref().is_some_and(|r| r.contains(words)),
        "the stalled peer {i} was not told: {:?}",
        h.peers[i].events
    );
    assert!(
        !h.peers[i].session.is_host(),
        "the stalled peer {i} acts as host"
    );
}

#[test]
fn a_newer_term_refusal_stops_only_a_peer_that_stalled() {
    // A peer cut off from the room elects itself host of a newer term; it must not depose
    // a host (or drop a client) that never stopped. The same refusal after a stall of our
    // own is believed.
    let (mut h, _ids) = room_with_objects(3, ConditionerConfig::default());
    let fake = encode_refusal("the room moved on", Term(9));
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
