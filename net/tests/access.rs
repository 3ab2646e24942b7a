//! Rooms with a key, in the N-peer harness: after the host dies, the new host admits by the
//! same rule — the key opens the door, no key or another key does not.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use softsync_net::{Event, RoomKey, SessionConfig};

fn keyed(secret: &[u8], seed: u64) -> SessionConfig {
    let mut c = config();
    c.room_key = Some(RoomKey::new(secret, seed));
    c
}

fn refusal(h: &softsync_net::harness::Harness, i: usize) -> Option<String> {
    h.peers[i].events.iter().find_map(|e| match e {
        Event::Refused { reason } => Some(reason.clone()),
        _ => None,
    })
}

#[test]
fn a_new_host_after_a_migration_admits_only_keyholders() {
    const SECRET: &[u8] = b"a long random room secret";
    let mut h = room_with(3, keyed(SECRET, 1), steady_link(), ms(1000));
    for i in 0..3 {
        assert!(h.peers[i].session.is_connected(), "peer {i} has the key");
    }
    h.kill(0);
    h.advance(ms(4000));
    assert!(h.peers[1].session.is_host());
    let with = h.add_peer_with(keyed(SECRET, 7), 1);
    let without = h.add_peer_with(config(), 1);
    let wrong = h.add_peer_with(keyed(b"a guess", 8), 1);
    h.advance(ms(2000));
    assert!(h.peers[with].session.is_connected());
    assert!(refusal(&h, without).is_some_and(|r| r.contains("needs a key")));
    assert_eq!(refusal(&h, wrong).as_deref(), Some("wrong room key"));
    assert_eq!(
        h.peers[1].session.members().len(),
        3,
        "heir, peer 2 and the keyholder"
    );
    assert_eq!(h.peers[1].session.stats().refused_joins, 1);
}
