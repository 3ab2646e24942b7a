//! What a remote body costs a peer that only shows it (issue 34: a peer that mostly shows
//! other people's objects should cost little), counted rather than timed: an untouched soft
//! body another peer simulates is deformed at most once per frame (by the state shown after
//! the step), not three times (before the step, by the step, after it), and not at all while
//! it is shown at the same state (at rest: its mesh is kept); the owner's resting body
//! sleeps and costs no restoring and no deformation (its particles never all slept before).
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::time::Duration;

use common::hub::{Node, Room, CLIENT, HOST};
use softsync_net::{Instant, MemoryHub};
use softsync_peer::LocalBody;

#[test]
fn an_untouched_remote_soft_body_is_deformed_once_per_frame_and_its_owner_lets_it_sleep() {
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [Node::new(&hub, HOST, 1), Node::new(&hub, CLIENT, 2)],
        now: Instant::ZERO,
    };
    // joined, and the bodies settled on the table
    room.run(Duration::from_secs(4));
    let work = |n: &Node| -> Vec<(bool, u64, u64, u64)> {
        n.peer
            .objects()
            .values()
            .filter_map(|o| match o.body {
                LocalBody::Soft(h) => n.peer.soft_bodies().get(h),
                _ => None,
            })
            .map(|b| {
                let w = b.work();
                (b.is_replica(), w.deformations, w.restorings, w.meshes_kept)
            })
            .collect()
    };
    let (client0, host0) = (work(&room.nodes[1]), work(&room.nodes[0]));
    assert_eq!(client0.len(), 3, "the thesis room's three soft bodies");
    const FRAMES: u64 = 90;
    room.run(Duration::from_secs_f32(FRAMES as f32 * common::hub::DT));
    let (client1, host1) = (work(&room.nodes[1]), work(&room.nodes[0]));
    for (a, b) in client0.iter().zip(&client1) {
        // the client owns none of them: each is a replica, its mesh updated once a frame at
        // most — and at rest, shown at the same state frame after frame, kept, not deformed
        assert!(b.0, "a remote body is not a replica: {b:?}");
        let (deformed, kept) = (b.1 - a.1, b.3 - a.3);
        assert!(
            (FRAMES - 2..=FRAMES + 1).contains(&(deformed + kept)),
            "{deformed} deformations and {kept} meshes kept in {FRAMES} frames"
        );
        assert!(deformed <= 2, "{deformed} deformations of a body at rest");
    }
    for (a, b) in host0.iter().zip(&host1) {
        // the owner simulates them (not replicas); at rest on the table they sleep, and its
        // steps skip them: no restoring, no deformation
        assert!(!b.0);
        assert_eq!(
            (b.1 - a.1, b.2 - a.2),
            (0, 0),
            "the owner's resting body costs steps"
        );
    }
}
