//! An object that leaves the room's bounds (the box positions are quantized in) is put back at
//! its place by the peer that simulates it, at rest, and the others follow: never shown stuck
//! at the edge of the box while its owner has it elsewhere. Found by the churn soak: a soft
//! ball rolled off the thesis room's floor and every other peer showed it clamped at the
//! bounds, metres from its owner's.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::path::Path;
use std::time::Duration;

use common::hub::{Node, Room, CLIENT, HOST};
use softsync_net::MemoryHub;
use softsync_peer::{Event, Scene};

/// No floor: the ball falls from 1 m and leaves the bounds at y = -1.
const FALLING: &str = r#"Scene(
    name: "falling",
    bounds: (min: (-2.0, -1.0, -2.0), max: (2.0, 3.0, 2.0)),
    classes: [(name: "ball", shape: Ball(radius: 0.05), body: Rigid(density: 300.0))],
    objects: [(class: "ball", at: (0.5, 1.0, 0.0))],
)"#;

#[test]
fn an_object_out_of_bounds_returns_home_on_every_peer() {
    let scene = Scene::parse(FALLING, Path::new("falling.ron")).unwrap();
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [
            Node::with(&hub, HOST, 1, scene.clone()),
            Node::with(&hub, CLIENT, 2, scene),
        ],
        now: softsync_net::Instant::ZERO,
    };
    room.run(Duration::from_secs(1));
    let id = room.nodes[0].id_of("ball")[0];
    let mut lowest_shown = f32::MAX;
    let mut shown_jumps_up = 0;
    let mut last_y: Option<f32> = None;
    let mut rising = false;
    for _ in 0..300 {
        room.run(Duration::from_millis(10));
        let now = room.now;
        if let Some(s) = room.nodes[1].peer.shown_state(now, id) {
            lowest_shown = lowest_shown.min(s.pos.y);
            assert!(
                (s.pos.x - 0.5).abs() < 1e-2 && s.pos.z.abs() < 1e-2,
                "{s:?}"
            );
            // a falling ball never rises: a rise is a return home (interpolated over a few
            // frames)
            let up = last_y.is_some_and(|y| s.pos.y > y + 0.01);
            if up && !rising {
                shown_jumps_up += 1;
            }
            rising = up;
            last_y = Some(s.pos.y);
        }
    }
    let returns: Vec<_> = room.nodes[0]
        .events
        .iter()
        .filter_map(|(_, e)| match e {
            Event::ReturnedHome { id: i, from } if *i == id => Some(*from),
            _ => None,
        })
        .collect();
    // a fall from 1 m to -1 m takes ~0.64 s: several returns in 4 s, each from just past the
    // bottom of the box
    assert!(returns.len() >= 3, "{returns:?}");
    assert!(
        returns
            .iter()
            .all(|f| f.y < -1.0 && f.y > -1.2 && (f.x - 0.5).abs() < 1e-3),
        "{returns:?}"
    );
    // the client never showed it below the box (where it would have been clamped), and saw
    // it come back up
    assert!(lowest_shown >= -1.0 - 1e-3, "{lowest_shown}");
    assert!(
        shown_jumps_up + 1 >= returns.len(),
        "{shown_jumps_up} of {}",
        returns.len()
    );
    assert!(room.nodes[0].warnings.is_empty() && room.nodes[1].warnings.is_empty());
}
