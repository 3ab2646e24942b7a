//! `method: auto` across the network, in-process on virtual time: a host and a client on the
//! in-memory hub behind the seeded link conditioner, a soft box whose class has a three-level
//! resolution ladder. The box's owner moves it between levels as it is used — the touch level
//! when awake, asleep at rest, the squeeze level while the client's hand pulls on it, back
//! down when let go — and the other peer's replica follows every change: the same level, the
//! same particle count, the same shape within a centimetre.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::path::PathBuf;
use std::time::Duration;

use common::hub::{Node, Room, CLIENT, DT, HOST};
use glam::{Quat, Vec3};
use softsync_interaction::{HandInput, HandSample};
use softsync_net::{Instant, MemoryHub, NetId};
use softsync_peer::mirror::LocalBody;
use softsync_peer::Scene;

/// A table and a 10 cm soft box with an auto ladder (clusters 6, 3 and 1.5 cm). Budgets so
/// lax that the probe's picks are certain: touch = the cheapest level (the coarsest, an eighth
/// of the particles), squeeze = the most accurate (the finest, the probe's reference).
const SCENE: &str = r#"Scene(
    name: "auto-test",
    fixed: [
        (half_extents: (10.0, 0.5, 10.0), at: (0.0, -0.5, 0.0)),
        (half_extents: (0.6, 0.02, 0.4), at: (0.0, 0.73, 0.0)),
    ],
    classes: [
        (
            name: "squishy",
            shape: Cuboid(half_extents: (0.05, 0.05, 0.05), subdivisions: 8),
            body: Auto(
                soft: (cluster: (method: "distance", radius_m: 0.03), stiffness: 15.0),
                error_budget_mm: 1000.0,
                cost_budget_ms: 1000.0,
            ),
        ),
    ],
    objects: [(class: "squishy", at: (0.0, 0.81, 0.0))],
)"#;

fn scene() -> Scene {
    let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let mut s = Scene::parse(SCENE, &assets.join("auto-test.ron")).unwrap();
    s.probe_auto(common::wall_ms).unwrap();
    s
}

/// The object's level and particle count on a peer.
fn level(n: &Node, id: NetId) -> (Option<u8>, usize) {
    let o = &n.peer.objects()[&id];
    let LocalBody::Soft(h) = o.body else {
        panic!("not soft")
    };
    (
        o.level,
        n.peer.soft_bodies().get(h).unwrap().num_particles(),
    )
}

/// The highest particle of object `id`'s soft body on a peer (where a hand grips to pull).
fn top_particle(n: &Node, id: NetId) -> Vec3 {
    let LocalBody::Soft(h) = n.peer.objects()[&id].body else {
        panic!("not soft")
    };
    n.peer
        .soft_bodies()
        .get(h)
        .unwrap()
        .particle_positions(n.peer.world())
        .into_iter()
        .max_by(|a, b| a.y.total_cmp(&b.y))
        .unwrap()
}

fn hand(now: Instant, at: Vec3, grip: f32) -> Option<HandInput> {
    Some(HandInput {
        sample: HandSample {
            position_m: at,
            rotation: Quat::IDENTITY,
            time_s: now.as_secs_f64(),
        },
        grip,
        trigger: 0.0,
    })
}

#[test]
fn the_owner_moves_the_box_between_levels_as_it_is_used_and_the_replica_follows() {
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [
            Node::with(&hub, HOST, 11, scene()),
            Node::with(&hub, CLIENT, 12, scene()),
        ],
        now: Instant::ZERO,
    };
    let scene = room.nodes[0].peer.scene();
    let ladder = scene
        .auto(scene.kind("squishy").unwrap())
        .unwrap()
        .ladder
        .clone();
    let (coarse, fine) = (ladder.touch, ladder.squeeze);
    assert_eq!((coarse, fine), (0, 2), "{:?}", ladder.probed);
    assert!(ladder.particles[0] < ladder.particles[1] && ladder.particles[1] < ladder.particles[2]);
    // Awake at spawn: the host (owner) asks for the touch level; then the box rests and sleeps.
    room.run(Duration::from_secs(3));
    let id = room.nodes[1].id_of("squishy")[0];
    for n in &room.nodes {
        assert_eq!(level(n, id), (Some(coarse as u8), ladder.particles[coarse]));
    }
    let host_modes = room.nodes[0].peer.counters().auto_mode_changes;
    assert!(
        host_modes >= 1,
        "the resting box went to sleep: {host_modes}"
    );
    // The client's hand grips the box's top particle and pulls it up 8 cm.
    let top = top_particle(&room.nodes[1], id);
    let mut squeezed_seen = false;
    for k in 0..180 {
        let now = room.now;
        let lift = 0.08 * ((k as f32 - 30.0) / 30.0).clamp(0.0, 1.0);
        room.nodes[0].frame(now);
        room.nodes[1].frame_input(now, hand(now, top + Vec3::Y * lift, 1.0));
        room.now += Duration::from_secs_f32(DT);
        squeezed_seen |= level(&room.nodes[0], id).0 == Some(fine as u8);
    }
    let [host, client] = &room.nodes;
    assert_eq!(client.peer.session().owner(id), Some(CLIENT));
    assert!(
        squeezed_seen,
        "the host's replica never went to the fine level"
    );
    for n in [host, client] {
        assert_eq!(level(n, id), (Some(fine as u8), ladder.particles[fine]));
    }
    // The replica shows the owner's shape.
    let now = room.now;
    let (a, b) = (
        room.nodes[1].peer.shown_state(now, id).unwrap(),
        room.nodes[0].peer.shown_state(now, id).unwrap(),
    );
    assert_eq!(a.particles.len(), b.particles.len());
    let worst = a
        .particles
        .iter()
        .zip(&b.particles)
        .map(|(x, y)| x.distance(*y))
        .fold(0.0f32, f32::max);
    assert!(worst < 0.01, "replica off by {worst} m");
    // Let go: the box settles back to the touch level on both peers.
    for _ in 0..(3.0 / DT) as usize {
        let now = room.now;
        room.nodes[0].frame(now);
        room.nodes[1].frame_input(now, hand(now, top + Vec3::new(0.3, 0.2, 0.0), 0.0));
        room.now += Duration::from_secs_f32(DT);
    }
    for n in &room.nodes {
        assert_eq!(level(n, id), (Some(coarse as u8), ladder.particles[coarse]));
        assert!(n.warnings.is_empty(), "{:?}", n.warnings);
        assert_eq!(n.peer.counters().apply_errors, 0);
    }
    assert!(room.nodes[1].peer.counters().resolution_requests >= 2);
}

/// The short version of `scripts/bench-auto`: `softsync-bench auto` over the first 4 s of
/// its script (the soft ball's grab and squeeze) writes its tables and a RESULT line with
/// every field; the error is a measurement, bounded only to catch a broken comparison.
#[test]
fn bench_auto_writes_its_tables_and_result_line() {
    let dir = common::scratch("bench-auto");
    let out = std::process::Command::new(common::bench_binary())
        .args(["auto", "--seconds", "4", "--out"])
        .arg(&dir)
        .arg("--assets")
        .arg(common::repo_file("assets"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = stdout
        .lines()
        .find(|l| l.starts_with("RESULT framework.auto "))
        .unwrap_or_else(|| panic!("no RESULT line: {stdout}"));
    for key in [
        "frame_ms",
        "fixed_frame_ms",
        "base_frame_ms",
        "worst_error_mm",
    ] {
        let v: f64 = common::field(line, key).parse().unwrap();
        assert!(v.is_finite() && v >= 0.0, "{key}={v}");
    }
    let worst: f64 = common::field(line, "worst_error_mm").parse().unwrap();
    assert!(worst < 50.0, "{line}");
    for f in [
        "auto.csv",
        "auto_frames.csv",
        "auto_ladders.csv",
        "auto.svg",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    let ladders = std::fs::read_to_string(dir.join("auto_ladders.csv")).unwrap();
    for class in ["bunny", "softball", "softbox"] {
        assert!(ladders.contains(class), "{ladders}");
    }
}

/// A cut's pieces keep changing resolution, each with its own particle count (a piece is not
/// its class's mesh): the client cuts the box in two, pulls one piece, and both peers rebuild
/// that piece at the squeeze level with the same count the owner asked for.
#[test]
fn a_cut_piece_changes_resolution_with_its_own_particle_count_on_both_peers() {
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [
            Node::with(&hub, HOST, 13, scene()),
            Node::with(&hub, CLIENT, 14, scene()),
        ],
        now: Instant::ZERO,
    };
    room.run(Duration::from_secs(2));
    let id = room.nodes[1].id_of("squishy")[0];
    let now = room.now;
    room.nodes[1].peer.ask_authority(now, id);
    room.run(Duration::from_millis(500));
    let c = room.nodes[1].peer.shown_state(room.now, id).unwrap().pos;
    let now = room.now;
    room.nodes[1]
        .peer
        .cut(now, id, c, Vec3::new(1.0, 0.1, 0.0))
        .unwrap();
    room.run(Duration::from_secs(3));
    let pieces = room.nodes[1].id_of("squishy");
    assert_eq!(pieces.len(), 2, "{pieces:?}");
    let piece = pieces[0];
    // pull the piece's top particle up 6 cm and hold
    let top = top_particle(&room.nodes[1], piece);
    for k in 0..150 {
        let now = room.now;
        let lift = 0.06 * ((k as f32 - 30.0) / 30.0).clamp(0.0, 1.0);
        room.nodes[0].frame(now);
        room.nodes[1].frame_input(now, hand(now, top + Vec3::Y * lift, 1.0));
        room.now += Duration::from_secs_f32(DT);
    }
    let (owner_level, owner_n) = level(&room.nodes[1], piece);
    let (replica_level, replica_n) = level(&room.nodes[0], piece);
    assert_eq!(
        owner_level,
        Some(2),
        "the pulled piece went to the squeeze level"
    );
    assert_eq!((replica_level, replica_n), (owner_level, owner_n));
    assert_eq!(
        room.nodes[0].peer.session().particles_of(piece),
        Some(owner_n as u32)
    );
    for n in &room.nodes {
        assert!(n.warnings.is_empty(), "{:?}", n.warnings);
        assert_eq!(n.peer.counters().apply_errors, 0);
    }
}
