//! A partition heals between two peers of the thesis room, in-process on virtual time with
//! the peer library the app runs (the hub harness of `common/hub.rs`): the client owns the
//! soft box; the link is cut for 3 s, so the client's session elects itself host of a room of
//! one; when the link returns, beacons meet, the two rooms of one member each compare (equal
//! size: the one whose host joined first wins, the original host's), and the client yields:
//! it joins the host again with a fresh session, every object it hosted apart dropped and counted,
//! and both peers show one room again with the same objects and owners.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::time::Duration;

use common::hub::{Node, Room, CLIENT, HOST};
use softsync_net::{Instant, MemoryHub};

#[test]
fn a_client_cut_off_for_3_s_yields_to_the_original_host_and_both_agree_again() {
    let hub = MemoryHub::new(1200);
    let mut room = Room {
        nodes: [Node::new(&hub, HOST, 21), Node::new(&hub, CLIENT, 22)],
        now: Instant::ZERO,
    };
    room.run(Duration::from_secs(3));
    let softbox = room.nodes[1].id_of("softbox")[0];
    let now = room.now;
    room.nodes[1].peer.ask_authority(now, softbox);
    room.run(Duration::from_millis(500));
    assert_eq!(room.nodes[1].peer.session().owner(softbox), Some(CLIENT));
    hub.set_partition(HOST, CLIENT, true);
    room.run(Duration::from_secs(3));
    // apart: the client hosts a room of one
    assert!(room.nodes[1].peer.session().is_host());
    assert!(room.nodes[0].peer.session().is_host());
    hub.set_partition(HOST, CLIENT, false);
    room.run(Duration::from_secs(6));
    let [host, client] = &room.nodes;
    assert!(host.warnings.is_empty(), "{:?}", host.warnings);
    assert!(client.warnings.is_empty(), "{:?}", client.warnings);
    assert_eq!(client.peer.counters().rejoins, 1);
    // apart, the client hosted every object of the room (the lost host's went to it): all 7
    // of its replicas were its own, and none is the room's
    assert_eq!(client.peer.counters().discarded_objects, 7);
    assert_eq!(host.peer.counters().rejoins, 0);
    for n in [host, client] {
        assert_eq!(n.peer.session().host_id(), Some(HOST));
        assert_eq!(n.peer.session().members().len(), 2);
    }
    let ids = host.peer.session().object_ids();
    assert_eq!(client.peer.session().object_ids(), ids);
    for id in ids {
        assert_eq!(
            client.peer.session().owner(id),
            host.peer.session().owner(id),
            "{id:?}"
        );
    }
    // the box went back to the host when it timed the client out
    assert_eq!(host.peer.session().owner(softbox), Some(HOST));
}

/// A client stopped (SIGSTOP) for longer than the peer timeout while it holds an object, in
/// a room of four: the host drops it and takes the object back; when the client runs again it
/// learns it was dropped, joins again with a fresh session (asking whichever peer, redirected
/// to the host) and is in the room within a few seconds. Seeds and stop lengths vary (the
/// churn soak found rejoins that never completed).
#[test]
fn a_client_stopped_past_the_timeout_joins_again() {
    use softsync_net::PeerId;
    for (seed, stop_ms) in [
        (31u64, 1400u64),
        (32, 1100),
        (33, 2500),
        (34, 1700),
        (35, 1250),
    ] {
        let hub = MemoryHub::new(1200);
        let mut nodes = vec![
            Node::new(&hub, HOST, seed),
            Node::new(&hub, CLIENT, seed + 100),
            Node::new(&hub, PeerId(102), seed + 200),
            Node::new(&hub, PeerId(103), seed + 300),
        ];
        let mut now = Instant::ZERO;
        let dt = Duration::from_secs_f32(common::hub::DT);
        let run = |nodes: &mut Vec<Node>, now: &mut Instant, d: Duration, skip: Option<usize>| {
            let end = *now + d;
            while *now < end {
                for (i, n) in nodes.iter_mut().enumerate() {
                    if Some(i) != skip {
                        n.frame(*now);
                    }
                }
                *now += dt;
            }
        };
        run(&mut nodes, &mut now, Duration::from_secs(3), None);
        let softbox = nodes[1].id_of("softbox")[0];
        nodes[1].peer.ask_authority(now, softbox);
        run(&mut nodes, &mut now, Duration::from_millis(500), None);
        assert_eq!(nodes[1].peer.session().owner(softbox), Some(CLIENT));
        // the client's process stops: the others run
        run(
            &mut nodes,
            &mut now,
            Duration::from_millis(stop_ms),
            Some(1),
        );
        run(&mut nodes, &mut now, Duration::from_secs(5), None);
        let client = &nodes[1];
        assert_eq!(client.peer.counters().rejoins, 1, "seed {seed}");
        assert!(
            client.peer.joined(),
            "seed {seed}, stopped {stop_ms} ms: not in the room again"
        );
        for n in &nodes {
            assert_eq!(n.peer.session().members().len(), 4, "seed {seed}");
            assert_eq!(n.peer.session().host_id(), Some(HOST), "seed {seed}");
        }
    }
}
