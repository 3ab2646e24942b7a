//! The room clock on virtual time: every member reads the host's room time within a few
//! milliseconds over a jittery, lossy link; when the host dies its heir carries the room's
//! time on, and no peer's reading ever goes back.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::*;
use softsync_net::harness::Harness;
use softsync_net::ConditionerConfig;

/// Every live peer's room time now, by index.
fn readings(h: &Harness) -> Vec<(usize, Duration)> {
    h.peers
        .iter()
        .enumerate()
        .filter(|(_, p)| p.alive)
        .filter_map(|(i, p)| p.session.room_time(h.now).map(|t| (i, t)))
        .collect()
}

/// How far the readings are from the room time every peer should read: the first host's
/// clock, which is the harness's virtual time (all peers share it here).
fn worst_error(h: &Harness) -> Duration {
    readings(h)
        .iter()
        .map(|(_, t)| t.abs_diff(Duration::from_micros(h.now.as_micros())))
        .max()
        .unwrap()
}

/// Every live peer's room time now is no earlier than `last` (by index), which it updates.
fn never_back(h: &Harness, last: &mut [Duration]) {
    for (i, t) in readings(h) {
        assert!(
            t >= last[i],
            "peer {i} went back: {t:?} after {:?}",
            last[i]
        );
        last[i] = t;
    }
}

#[test]
fn every_peer_reads_the_room_time_and_a_new_host_carries_it_on_without_going_back() {
    // 25 ms each way, 8 ms of jitter, 5 % loss (bursts), duplicates and reordering
    let link = ConditionerConfig::rough(7, 25, 8, 0.05);
    let mut h = room(4, link);
    h.advance(ms(2000));
    assert_eq!(readings(&h).len(), 4, "every peer knows the room time");
    let mut last = [Duration::ZERO; 4];
    let mut worst = Duration::ZERO;
    for _ in 0..100 {
        h.advance(ms(20));
        worst = worst.max(worst_error(&h));
        never_back(&h, &mut last);
    }
    assert!(worst <= ms(3), "members {worst:?} off the host's room time");

    // the host dies: its heir hosts the room's time, not its own
    let took = h.time_to_new_host(ms(5000), ms(5)).unwrap();
    let heir = h.host_index().unwrap();
    assert_ne!(heir, 0);
    let mut after = Duration::ZERO;
    for step in 0..150 {
        h.advance(ms(20));
        never_back(&h, &mut last);
        if step >= 50 {
            after = after.max(worst_error(&h));
        }
    }
    assert!(
        after <= ms(5),
        "after the migration ({took:?}) the room time is {after:?} off"
    );
}
