//! What the store tests share: a room with every kind of event, its identity, a scratch
//! folder.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::PathBuf;
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_net::wire::{AppMessage, Delivery, MessageKind, MessageTarget, TopologyEvent};
use softsync_net::{ClassId, KeptObject, NetId, ObjectState, PeerId, RoomImage};
use softsync_store::RoomIdentity;

pub fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("softsync-store-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn identity() -> RoomIdentity {
    RoomIdentity::of(b"the thesis room", 0x1234)
}

pub fn tear(x: i32) -> TopologyEvent {
    TopologyEvent::Tear {
        from: [x, 10, -20],
        to: [x + 500, 12, -20],
        blade: [0, 4000, 0],
    }
}

pub fn soft(x: f32, n: usize) -> ObjectState {
    let pos = Vec3::new(x, 1.0, 0.0);
    ObjectState {
        pos,
        rot: Quat::from_rotation_y(0.4),
        particles: (0..n)
            .map(|i| pos + Vec3::new(i as f32 * 1e-3, 0.01, -0.02))
            .collect(),
    }
}

/// A room with every kind of event: a torn bunny, two pieces of a cut box (the parent is gone),
/// a body at another resolution, a rigid tool, and retained messages.
pub fn room() -> RoomImage {
    let cut = |keep| TopologyEvent::Cut {
        point: [0, 100, 0],
        normal: [0, 0, 32767],
        keep,
    };
    let parent = vec![tear(0), tear(500), TopologyEvent::Lift];
    let piece = |keep: u8| {
        let mut l = parent.clone();
        l.push(cut(keep));
        l
    };
    RoomImage {
        room_time: Duration::from_millis(123_456),
        objects: vec![
            KeptObject {
                id: NetId(2),
                class: ClassId(0),
                state: ObjectState::rigid(Vec3::X, Quat::IDENTITY),
                topology: vec![],
            },
            KeptObject {
                id: NetId(5),
                class: ClassId(1),
                state: soft(0.2, 40),
                topology: parent.clone(),
            },
            KeptObject {
                id: NetId(9),
                class: ClassId(1),
                state: soft(0.4, 20),
                topology: piece(0),
            },
            KeptObject {
                id: NetId(10),
                class: ClassId(1),
                state: soft(0.5, 22),
                topology: piece(1),
            },
            KeptObject {
                id: NetId(11),
                class: ClassId(2),
                state: soft(-0.3, 12),
                topology: vec![TopologyEvent::Resolution {
                    level: 1,
                    particles: 12,
                }],
            },
        ],
        retained: vec![
            AppMessage {
                origin: PeerId(77),
                seq: 3,
                kind: MessageKind(1),
                to: MessageTarget::Everyone,
                delivery: Delivery::Retained,
                payload: b"step 4: retract".to_vec(),
            },
            AppMessage {
                origin: PeerId(u64::MAX - 5),
                seq: 9,
                kind: MessageKind(2),
                to: MessageTarget::Everyone,
                delivery: Delivery::ObjectState(NetId(5)),
                payload: vec![0, 255, 7],
            },
        ],
    }
}
