//! Tears and cuts across the network, in-process on virtual time, with the peer library the
//! app runs: a host and a client (`softsync_peer::Peer`, the thesis room) on net's in-memory
//! hub behind the seeded link conditioner (20 ms, 5 ms jitter, 2 % loss). The client takes the
//! bunny and the soft box, tears the bunny along four segments and cuts the box in two; both
//! peers end with the identical torn bunny and the same two pieces (equal topology hashes),
//! the pieces owned by the client, showing the same positions once at rest.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::time::Duration;

use common::hub::{Node, Room, CLIENT, DT, HOST};
use glam::Vec3;
use softsync_net::{Instant, MemoryHub};

#[test]
fn a_client_tears_the_bunny_and_cuts_the_box_and_the_host_shows_the_same_pieces() {
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [Node::new(&hub, HOST, 1), Node::new(&hub, CLIENT, 2)],
        now: Instant::ZERO,
    };
    room.run(Duration::from_secs(3));
    let [host, client] = &mut room.nodes;
    assert!(client.peer.joined());
    let bunny = client.id_of("bunny")[0];
    let soft_box = client.id_of("softbox")[0];
    assert_eq!(host.id_of("bunny"), vec![bunny]);
    let untouched = host.peer.topology_hash(bunny).unwrap();
    assert_eq!(client.peer.topology_hash(bunny), Some(untouched));
    let now = room.now;
    client.peer.ask_authority(now, bunny);
    client.peer.ask_authority(now, soft_box);
    room.run(Duration::from_millis(500));
    let [_, client] = &mut room.nodes;
    assert_eq!(client.peer.session().owner(bunny), Some(CLIENT));
    assert_eq!(client.peer.session().owner(soft_box), Some(CLIENT));
    // A stroke across the bunny's back: the tip 3 cm above its center, the blade upright.
    let c = client.peer.shown_state(room.now, bunny).unwrap().pos;
    // A blade along its own stroke cuts nothing: refused by the owner, never in the room's log
    // (every peer would refuse it when it replays the body's history).
    let now = room.now;
    let along = room.nodes[1].peer.tear(
        now,
        bunny,
        c + Vec3::new(-0.05, 0.03, 0.0),
        c + Vec3::new(-0.025, 0.03, 0.0),
        Vec3::X * 0.04,
    );
    assert!(
        along.as_ref().is_err_and(|e| e.0.contains("blade along")),
        "{along:?}"
    );
    let path: Vec<Vec3> = (0..5)
        .map(|k| c + Vec3::new(-0.05 + 0.025 * k as f32, 0.03, 0.0))
        .collect();
    for w in path.windows(2) {
        let now = room.now;
        room.nodes[1]
            .peer
            .tear(now, bunny, w[0], w[1], Vec3::Y * 0.04)
            .unwrap();
        room.run(Duration::from_millis(100));
    }
    let now = room.now;
    room.nodes[1].peer.lift(now, bunny).unwrap();
    let box_center = room.nodes[1].peer.shown_state(now, soft_box).unwrap().pos;
    room.nodes[1]
        .peer
        .cut(now, soft_box, box_center, Vec3::new(0.2, 1.0, 0.0))
        .unwrap();
    // Both sides: the tear applied, the box replaced by two pieces; then rest.
    room.run(Duration::from_secs(4));
    let [host, client] = &mut room.nodes;
    assert!(host.warnings.is_empty(), "{:?}", host.warnings);
    assert!(client.warnings.is_empty(), "{:?}", client.warnings);
    let torn = client.peer.topology_hash(bunny).unwrap();
    assert_ne!(torn, untouched, "the bunny was not torn");
    assert_eq!(host.peer.topology_hash(bunny), Some(torn));
    assert_eq!(client.peer.objects()[&bunny].topology, 5);
    assert_eq!(host.peer.objects()[&bunny].topology, 5);
    let pieces = client.id_of("softbox");
    assert_eq!(pieces.len(), 2, "{pieces:?}");
    assert!(!pieces.contains(&soft_box));
    assert_eq!(host.id_of("softbox"), pieces);
    let now = room.now;
    for id in &pieces {
        assert_eq!(client.peer.session().owner(*id), Some(CLIENT));
        let h = client.peer.topology_hash(*id).unwrap();
        assert_eq!(host.peer.topology_hash(*id), Some(h), "piece {}", id.0);
        let (a, b) = (
            client.peer.shown_state(now, *id).unwrap(),
            host.peer.shown_state(now, *id).unwrap(),
        );
        assert!(
            a.pos.distance(b.pos) < 0.002,
            "piece {}: {} vs {}",
            id.0,
            a.pos,
            b.pos
        );
        // The pieces fell onto the table and stayed there.
        assert!(
            a.pos.y > 0.75 && a.pos.y < 0.85,
            "piece {} at {}",
            id.0,
            a.pos
        );
    }
    assert_ne!(
        client.peer.topology_hash(pieces[0]),
        client.peer.topology_hash(pieces[1])
    );
}

#[test]
fn a_hand_with_its_trigger_held_tears_along_its_path_and_both_peers_agree() {
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [Node::new(&hub, HOST, 3), Node::new(&hub, CLIENT, 4)],
        now: Instant::ZERO,
    };
    room.run(Duration::from_secs(3));
    let bunny = room.nodes[1].id_of("bunny")[0];
    let untouched = room.nodes[0].peer.topology_hash(bunny).unwrap();
    let c = room.nodes[1].peer.shown_state(room.now, bunny).unwrap().pos;
    // The right hand sweeps 10 cm across the bunny's back in 1 s, trigger held, then lets go.
    let frames = 90;
    for k in 0..=frames + 30 {
        let f = (k.min(frames) as f32) / frames as f32;
        let p = c + Vec3::new(-0.05 + 0.1 * f, 0.02, 0.0);
        let trigger = if k <= frames { 1.0 } else { 0.0 };
        let now = room.now;
        room.nodes[0].frame(now);
        room.nodes[1].frame_with(now, Some((p, trigger)));
        room.now += Duration::from_secs_f32(DT);
    }
    room.run(Duration::from_secs(1));
    let [host, client] = &mut room.nodes;
    assert!(client.warnings.is_empty(), "{:?}", client.warnings);
    // the bunny stays the host's: the scalpel's strokes went to it as requests
    // (`peer/blade.rs`), which it applied as its own
    assert_eq!(client.peer.session().owner(bunny), Some(HOST));
    assert!(client.peer.counters().blade_requests_sent >= 1);
    assert_eq!(client.peer.counters().authority_requests, 0);
    let applied = client.peer.objects()[&bunny].topology;
    // 10 cm in 5 mm samples (the first one starts the stroke), and the lift
    assert!(applied >= 18, "{applied} entries");
    assert_eq!(host.peer.objects()[&bunny].topology, applied);
    let torn = client.peer.topology_hash(bunny).unwrap();
    assert_ne!(torn, untouched);
    assert_eq!(host.peer.topology_hash(bunny), Some(torn));
}

/// A cut's pieces are built off the frame (`peer/builds.rs`) on the client, in the frame on
/// the host: both end with the same pieces; on the client the box never blinks (every frame
/// shows the box or all its pieces) and never overlaps (never the box and a piece at once).
#[test]
fn a_cuts_pieces_built_off_the_frame_are_the_frames_and_the_box_never_blinks() {
    cut_pieces_off_the_frame(false);
}

/// The same with the client landing its builds once their workers are done (the app's
/// `land_when_ready`): a frame never waits for a worker, and the pieces are the same.
#[test]
fn pieces_landed_once_their_workers_are_done_are_the_same_and_the_box_never_blinks() {
    cut_pieces_off_the_frame(true);
}

fn cut_pieces_off_the_frame(land_when_ready: bool) {
    use softsync_peer::{LocalBody, PeerConfig, Scene};
    let hub = MemoryHub::new(1200);
    let assets = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let in_frame = PeerConfig {
        dt_s: DT,
        avatar: false,
        build_off_frame: false,
        ..PeerConfig::default()
    };
    let off_frame = PeerConfig {
        dt_s: DT,
        avatar: false,
        land_when_ready,
        ..PeerConfig::default()
    };
    let scene = Scene::by_name("thesis-room", &assets).unwrap();
    let mut room = Room {
        nodes: [
            Node::with_config(&hub, HOST, 1, scene.clone(), in_frame),
            Node::with_config(&hub, CLIENT, 2, scene, off_frame),
        ],
        now: Instant::ZERO,
    };
    room.run(Duration::from_secs(3));
    let soft_box = room.nodes[1].id_of("softbox")[0];
    let now = room.now;
    room.nodes[1].peer.ask_authority(now, soft_box);
    room.run(Duration::from_millis(500));
    // a tear first, so the pieces' history has more than the cut
    let c = room.nodes[1]
        .peer
        .shown_state(room.now, soft_box)
        .unwrap()
        .pos;
    for k in 0..3 {
        let now = room.now;
        let from = c + Vec3::new(-0.03 + 0.02 * k as f32, 0.02, 0.0);
        room.nodes[1]
            .peer
            .tear(now, soft_box, from, from + Vec3::X * 0.02, Vec3::Y * 0.04)
            .unwrap();
        room.run(Duration::from_millis(100));
    }
    let now = room.now;
    room.nodes[1].peer.lift(now, soft_box).unwrap();
    room.run(Duration::from_millis(200));
    let now = room.now;
    let c = room.nodes[1].peer.shown_state(now, soft_box).unwrap().pos;
    room.nodes[1]
        .peer
        .cut(now, soft_box, c, Vec3::new(1.0, 0.3, 0.0))
        .unwrap();
    // frame by frame (with a little wall time each, for the workers), watching the client
    let soft_of = |n: &Node, id| {
        matches!(
            n.peer.objects().get(&id).map(|o| o.body),
            Some(LocalBody::Soft(_))
        )
    };
    let mut landed_at = None;
    for frame in 0..400 {
        let now = room.now;
        for n in room.nodes.iter_mut() {
            n.frame(now);
        }
        room.now += Duration::from_secs_f32(DT);
        // the builds run on worker threads, in wall time: each virtual frame leaves them some
        #[allow(clippy::disallowed_methods)]
        std::thread::sleep(Duration::from_micros(500));
        let client = &room.nodes[1];
        let pieces: Vec<_> = client
            .id_of("softbox")
            .into_iter()
            .filter(|id| *id != soft_box)
            .collect();
        let parent = soft_of(client, soft_box);
        let shown = pieces.iter().filter(|id| soft_of(client, **id)).count();
        assert!(
            !(parent && shown > 0),
            "frame {frame}: the box and {shown} pieces at once"
        );
        assert!(
            parent || (shown == 2 && pieces.len() == 2),
            "frame {frame}: neither the box nor its pieces ({shown} of {})",
            pieces.len()
        );
        if landed_at.is_none() && shown == 2 {
            landed_at = Some(frame);
        }
    }
    assert!(landed_at.is_some(), "the pieces never landed");
    room.run(Duration::from_secs(3));
    let now = room.now;
    let [host, client] = &mut room.nodes;
    assert!(client.warnings.is_empty(), "{:?}", client.warnings);
    assert!(host.warnings.is_empty(), "{:?}", host.warnings);
    assert_eq!(client.peer.counters().bodies_built_off_frame, 2);
    assert_eq!(host.peer.counters().bodies_built_off_frame, 0);
    let pieces = client.id_of("softbox");
    assert_eq!(host.id_of("softbox"), pieces);
    assert_eq!(pieces.len(), 2);
    for id in &pieces {
        let h = client.peer.topology_hash(*id).unwrap();
        assert_eq!(host.peer.topology_hash(*id), Some(h), "piece {}", id.0);
        let (a, b) = (
            client.peer.shown_state(now, *id).unwrap(),
            host.peer.shown_state(now, *id).unwrap(),
        );
        assert_eq!(a.particles.len(), b.particles.len());
        assert!(a.pos.distance(b.pos) < 0.002, "piece {}", id.0);
    }
}

/// The cut gesture (`HandTool::Cutter`, tear paper §3.2): the client's right hand sweeps its
/// cutter through the host's soft box along z, the blade upright, trigger held; the box is cut
/// by the plane through where the blade met it and the blade's ends — x = the box's center —
/// through its owner (the client owns nothing), one cut for the press, pieces on either side.
#[test]
fn a_hand_sweeping_its_cutter_through_the_box_cuts_it_by_the_sweeps_plane() {
    use softsync_peer::HandTool;
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [Node::new(&hub, HOST, 1), Node::new(&hub, CLIENT, 2)],
        now: Instant::ZERO,
    };
    room.run(Duration::from_secs(3));
    let soft_box = room.nodes[1].id_of("softbox")[0];
    assert_eq!(room.nodes[1].peer.session().owner(soft_box), Some(HOST));
    let c = room.nodes[1]
        .peer
        .shown_state(room.now, soft_box)
        .unwrap()
        .pos;
    room.nodes[1].peer.set_hand_tool(1, HandTool::Cutter);
    assert_eq!(room.nodes[1].peer.hand_tool(1), HandTool::Cutter);
    // from 6 cm in front of the center to 6 cm behind it, in 0.5 s, trigger held; then let go
    let (from, to) = (c - Vec3::Z * 0.06, c + Vec3::Z * 0.06);
    let mut swept = false;
    for k in 0..90 {
        let f = (k as f32 / 45.0).min(1.0);
        let now = room.now;
        let trigger = if k < 60 { 1.0 } else { 0.0 };
        let [host, client] = &mut room.nodes;
        host.frame(now);
        client.frame_with(now, Some((from.lerp(to, f), trigger)));
        swept |= client.peer.is_sweeping(1);
        room.now += Duration::from_secs_f32(DT);
    }
    assert!(swept, "the cutter never met the box");
    room.run(Duration::from_secs(3));
    let [host, client] = &mut room.nodes;
    assert!(client.warnings.is_empty(), "{:?}", client.warnings);
    assert_eq!(client.peer.counters().cut_gestures, 1, "one cut per press");
    assert!(client.peer.counters().blade_requests_sent >= 1);
    let pieces = host.id_of("softbox");
    assert_eq!(pieces.len(), 2, "{pieces:?}");
    assert_eq!(client.id_of("softbox"), pieces);
    let now = room.now;
    let mut sides: Vec<f32> = pieces
        .iter()
        .map(|id| host.peer.shown_state(now, *id).unwrap().pos.x - c.x)
        .collect();
    sides.sort_by(f32::total_cmp);
    assert!(
        sides[0] < -0.005 && sides[1] > 0.005,
        "the pieces are not on either side of x = {}: {sides:?}",
        c.x
    );
    for id in &pieces {
        let h = host.peer.topology_hash(*id).unwrap();
        assert_eq!(client.peer.topology_hash(*id), Some(h));
    }
}
