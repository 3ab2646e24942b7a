//! Application messages in the N-peer harness: reliable, in-order, exactly-once delivery under
//! loss and reordering and across host kills; retained messages for late joiners also after
//! a migration; another build's message table refused at the handshake.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;

use common::*;
use softsync_net::harness::Harness;
use softsync_net::{
    ConditionerConfig, Delivery, Event, MessageKind, MessageTarget, PeerId, SessionConfig,
};

fn cfg() -> SessionConfig {
    let mut c = config();
    c.messages.kinds = vec!["step".into(), "valve".into()];
    // 20 % loss with bursts: a longer timeout, so nobody is dropped by bad luck
    c.peer_timeout = ms(2500);
    c
}

/// Every reliable message each peer delivered: origin → payload counters in arrival order.
fn received(h: &Harness, i: usize) -> BTreeMap<PeerId, Vec<u32>> {
    let mut by: BTreeMap<PeerId, Vec<u32>> = BTreeMap::new();
    for e in &h.peers[i].events {
        if let Event::Message(m) = e {
            if m.delivery == Delivery::Reliable {
                let n = u32::from_le_bytes(m.payload[..4].try_into().unwrap());
                by.entry(m.from).or_default().push(n);
            }
        }
    }
    by
}

fn delivered(h: &Harness, i: usize) -> Vec<u32> {
    h.peers[i]
        .events
        .iter()
        .filter_map(|e| match e {
            Event::MessageDelivered { seq } => Some(*seq),
            _ => None,
        })
        .collect()
}

/// `senders` each send `count` reliable messages to everyone, one per 11 ms frame;
/// `during(h, frame)` runs before each frame.
fn stream(
    h: &mut Harness,
    senders: &[usize],
    count: u32,
    mut during: impl FnMut(&mut Harness, u32),
) {
    for n in 0..count {
        during(h, n);
        let now = h.now;
        for &i in senders {
            if !h.peers[i].alive {
                continue;
            }
            let mut payload = n.to_le_bytes().to_vec();
            payload.extend_from_slice(&[i as u8; 12]);
            h.session(i)
                .send_message(
                    now,
                    MessageKind(0),
                    MessageTarget::Everyone,
                    Delivery::Reliable,
                    payload,
                )
                .unwrap();
        }
        h.advance(ms(11));
    }
}

#[test]
fn reliable_messages_arrive_once_and_in_order_under_20_percent_loss_and_reordering() {
    let mut link = ConditionerConfig::rough(17, 20, 10, 0.2);
    link.reorder = 0.1;
    link.duplicate = 0.05;
    let mut h = room_with(4, cfg(), link, ms(3000));
    for i in 0..4 {
        assert!(h.peers[i].session.is_connected(), "peer {i} did not join");
    }
    stream(&mut h, &[0, 1, 2, 3], 60, |_, _| {});
    h.advance(ms(8000));
    let all: Vec<u32> = (0..60).collect();
    for i in 0..4 {
        let got = received(&h, i);
        for j in (0..4).filter(|j| *j != i) {
            assert_eq!(got.get(&Harness::id(j)), Some(&all), "peer {i} from {j}");
        }
        assert_eq!(
            delivered(&h, i),
            (1..=60).collect::<Vec<_>>(),
            "peer {i}'s confirmations"
        );
        assert_eq!(h.peers[i].session.messages_in_flight(), 0);
    }
    let dups: u64 = (0..4)
        .map(|i| h.peers[i].session.stats().messages.duplicates)
        .sum();
    assert_eq!(dups, 0, "no migration, so no resend");
}

/// The host dies while three members stream messages; the heir streams too. Every survivor
/// gets every survivor's messages exactly once and in order, and every sender hears all of
/// them delivered.
#[test]
fn every_message_of_a_survivor_arrives_exactly_once_across_a_host_kill() {
    for (seed, kill_at) in [(1u64, 5u32), (2, 17), (3, 30), (4, 44)] {
        let link = ConditionerConfig::rough(seed, 15, 5, 0.05);
        let mut h = room_with(5, cfg(), link, ms(2000));
        let before = h.peers[1].session.term();
        stream(&mut h, &[0, 1, 2, 3, 4], 60, |h, n| {
            if n == kill_at {
                h.kill(0);
            }
        });
        h.advance(ms(8000));
        assert!(
            h.peers[1].session.is_host(),
            "seed {seed}: the heir took over"
        );
        assert!(h.peers[1].session.term() > before);
        let all: Vec<u32> = (0..60).collect();
        let mut dups = 0;
        for i in 1..5 {
            let got = received(&h, i);
            for j in (1..5).filter(|j| *j != i) {
                assert_eq!(
                    got.get(&Harness::id(j)),
                    Some(&all),
                    "seed {seed}: peer {i} from {j}"
                );
            }
            // what the dead host sent before dying arrived in order, at most once
            let from_host = got.get(&Harness::id(0)).cloned().unwrap_or_default();
            assert!(
                from_host.windows(2).all(|w| w[1] == w[0] + 1),
                "seed {seed}: {from_host:?}"
            );
            assert_eq!(
                delivered(&h, i),
                (1..=60).collect::<Vec<_>>(),
                "seed {seed}: peer {i}"
            );
            assert_eq!(h.peers[i].session.messages_in_flight(), 0);
            dups += h.peers[i].session.stats().messages.duplicates;
        }
        // a kill in mid-stream leaves relays unacknowledged: their resends were recognised
        assert!(dups > 0, "seed {seed}: no resend was needed?");
    }
}

/// Retained state survives the host: after a migration, a peer that joins the new host gets
/// the latest retained message of each kind, once.
#[test]
fn a_late_joiner_after_a_migration_gets_the_retained_messages() {
    let mut h = room_with(3, cfg(), steady_link(), ms(1000));
    let now = h.now;
    for v in 0..5u32 {
        h.session(2)
            .send_message(
                now,
                MessageKind(1),
                MessageTarget::Everyone,
                Delivery::Retained,
                v.to_le_bytes().to_vec(),
            )
            .unwrap();
    }
    h.advance(ms(500));
    h.kill(0);
    h.advance(ms(4000));
    assert!(h.peers[1].session.is_host());
    let j = h.add_peer_with(cfg(), 1);
    h.advance(ms(1500));
    assert!(h.peers[j].session.is_connected());
    let retained: Vec<(PeerId, Vec<u8>)> = h.peers[j]
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Message(m) => Some((m.from, m.payload.clone())),
            _ => None,
        })
        .collect();
    assert_eq!(
        retained,
        vec![(Harness::id(2), 4u32.to_le_bytes().to_vec())]
    );
    // and the members that had it did not get it again from the new host's snapshot
    let at_2 = h.peers[1]
        .events
        .iter()
        .filter(|e| matches!(e, Event::Message(_)))
        .count();
    assert_eq!(at_2, 5);
}

#[test]
fn a_peer_built_with_other_message_types_is_refused_at_the_handshake() {
    let mut h = room_with(2, cfg(), steady_link(), ms(500));
    let mut other = cfg();
    other.messages.kinds.push("ring_bell".into());
    let j = h.add_peer_with(other, 0);
    h.advance(ms(1000));
    let reason = h.peers[j].events.iter().find_map(|e| match e {
        Event::Refused { reason } => Some(reason.clone()),
        _ => None,
    });
    assert!(
        reason
            .as_deref()
            .is_some_and(|r| r.contains("message types")),
        "{reason:?}"
    );
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config { cases: 12, ..Default::default() })]

    /// Whatever the seed, loss, room size and moment of the host's death: every survivor
    /// delivers every surviving sender's messages exactly once and in order, and every
    /// surviving sender's outbox drains.
    #[test]
    fn exactly_once_in_order_whatever_the_loss_and_the_moment_of_the_kill(
        seed in 1u64..1_000_000,
        loss in 0.0f64..0.15,
        n in 3usize..6,
        kill_at in 0u32..40,
    ) {
        let mut h = room_with(n, cfg(), ConditionerConfig::rough(seed, 15, 5, loss), ms(2500));
        let senders: Vec<usize> = (0..n).collect();
        stream(&mut h, &senders, 40, |h, f| {
            if f == kill_at {
                h.kill(0);
            }
        });
        h.advance(ms(10_000));
        let all: Vec<u32> = (0..40).collect();
        for i in 1..n {
            proptest::prop_assert!(h.peers[i].session.is_connected(), "peer {} left the room", i);
            let got = received(&h, i);
            for j in (1..n).filter(|j| *j != i) {
                proptest::prop_assert_eq!(got.get(&Harness::id(j)), Some(&all), "peer {} from {}", i, j);
            }
            let from_dead = got.get(&Harness::id(0)).cloned().unwrap_or_default();
            proptest::prop_assert!(from_dead.windows(2).all(|w| w[1] == w[0] + 1));
            proptest::prop_assert_eq!(h.peers[i].session.messages_in_flight(), 0);
        }
    }
}

/// The member the dead host never reached gets the origin's reliable message and its later
/// retained one, each once: the new host's snapshot replays the retained state without
/// counting it as the origin's live message, and the resend fills the gap.
#[test]
fn a_replayed_retained_message_does_not_hide_an_earlier_resent_one() {
    let mut h = room_with(4, cfg(), steady_link(), ms(1000));
    h.partition(0, 3, true);
    let now = h.now;
    let s = h.session(2);
    s.send_message(
        now,
        MessageKind(0),
        MessageTarget::Everyone,
        Delivery::Reliable,
        11u32.to_le_bytes().to_vec(),
    )
    .unwrap();
    s.send_message(
        now,
        MessageKind(1),
        MessageTarget::Everyone,
        Delivery::Retained,
        vec![12],
    )
    .unwrap();
    h.advance(ms(60));
    h.kill(0);
    h.advance(ms(5000));
    assert!(h.peers[1].session.is_host());
    let at_3: Vec<Vec<u8>> = h.peers[3]
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Message(m) if m.from == Harness::id(2) => Some(m.payload.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(at_3.len(), 2, "{at_3:?}");
    assert!(at_3.contains(&11u32.to_le_bytes().to_vec()) && at_3.contains(&vec![12]));
    assert_eq!(h.peers[2].session.messages_in_flight(), 0);
}
