//! Rollback rooms of in-process peers on the seeded link conditioner, in real time.
#![allow(clippy::unwrap_used)]
// ggrs keeps its own wall clock (its timers read `Instant::now`): these rooms run in real
// time, paced by sleeps, and cannot run on virtual time like the session's tests.
#![allow(clippy::disallowed_methods)]

mod common;

use std::time::Duration;

use common::Room;
use softsync_net::wire::{Delivery, MessageTarget};
use softsync_net::{ConditionerConfig, PeerId};
use softsync_rollback::{Epoch, RollbackEvent};

fn net(latency_ms: u64, loss: f64) -> ConditionerConfig {
    ConditionerConfig {
        seed: 11,
        latency: Duration::from_millis(latency_ms),
        jitter: Duration::from_millis(latency_ms / 10),
        loss,
        ..ConditionerConfig::default()
    }
}

fn assert_agree(room: &Room) {
    let (f, sums) = room.agreement();
    for n in room.nodes.iter().filter(|n| n.alive) {
        let s = n.peer.stats();
        eprintln!(
            "peer {} epoch {:?} frames {} resim {} rollbacks {} stalled {} waited {} switch_ms_max {:.0} ggrs_bytes {} confirmed {:?} agreed frame {f}",
            n.peer.me().0, n.peer.epoch().map(|e| e.n), s.frames, s.resimulated, s.rollbacks,
            s.stalled_ticks, s.waited_ticks, s.switch_ms_max, s.ggrs_bytes, n.peer.confirmed_frame()
        );
    }
    assert!(f > 0, "no frame confirmed everywhere");
    assert!(
        sums.iter().all(|s| s.is_some()),
        "a peer lost frame {f}: {sums:?}"
    );
    assert!(
        sums.windows(2).all(|w| w[0] == w[1]),
        "worlds differ at frame {f}: {sums:?}"
    );
}

#[test]
fn a_two_peer_room_under_50_ms_and_5_percent_loss_runs_60_s_without_a_desync() {
    let mut room = Room::new(net(50, 0.05));
    room.add(1);
    room.add(2);
    room.run(Duration::from_secs(60));
    for n in &room.nodes {
        let s = n.peer.stats();
        assert!(
            s.frames > 2500,
            "peer {} advanced only {} frames: {s:?}",
            n.peer.me().0,
            s.frames
        );
        assert_eq!(n.peer.epoch().map(|e| e.players.len()), Some(2));
    }
    assert!(
        room.nodes[1].peer.stats().rollbacks > 100,
        "no rollbacks under 50 ms?"
    );
    assert_eq!(room.desyncs(), 0, "warnings: {:?}", room.warnings());
    assert_agree(&room);
}

#[test]
fn a_peer_killed_mid_grab_leaves_the_others_going_from_an_agreed_state_and_a_late_joiner_plays_on()
{
    let mut room = Room::new(net(20, 0.02));
    room.add(1);
    room.add(2);
    room.add(3);
    room.run(Duration::from_secs(4));
    assert!(room
        .nodes
        .iter()
        .all(|n| n.peer.epoch().map(|e| e.players.len()) == Some(3)));
    // Kill peer 3 while its right hand grips.
    let mut waited = 0;
    while room.nodes[2]
        .peer
        .world()
        .and_then(|w| w.held(2, 1))
        .is_none()
        && waited < 400
    {
        room.tick();
        std::thread::sleep(Duration::from_millis(16));
        waited += 1;
    }
    assert!(
        room.nodes[2].peer.world().unwrap().held(2, 1).is_some(),
        "peer 3 never held anything"
    );
    let before = room.nodes[0].peer.stats().frames;
    room.kill(2);
    room.run(Duration::from_secs(5));
    assert!(
        room.nodes[0].peer.stats().frames > before + 150,
        "the room stopped"
    );
    assert!(room.nodes[..2].iter().all(|n| n
        .events
        .iter()
        .any(|e| matches!(e, RollbackEvent::PlayerDisconnected(p) if p.0 == 3))));
    // Nobody holds what the dead peer held any more: its hands opened.
    for n in &room.nodes[..2] {
        assert!(n.peer.world().unwrap().held(2, 1).is_none());
    }
    assert_agree(&room);
    // A late joiner gets the state and plays on.
    room.add(4);
    room.run(Duration::from_secs(6));
    let joiner = &room.nodes[3];
    assert_eq!(
        joiner.peer.epoch().map(|e| e.players.len()),
        Some(3),
        "{:?}",
        joiner.events
    );
    assert!(
        joiner.peer.stats().frames > 120,
        "{:?}",
        joiner.peer.stats()
    );
    assert_eq!(room.desyncs(), 0, "warnings: {:?}", room.warnings());
    assert_agree(&room);
}

/// ggrs 0.13 can panic after a stalled peer dies (a rollback past its window). The peer
/// survives it: its session is dropped, the host starts a new epoch of the same players from
/// a confirmed frame, and the room goes on agreeing — whether a member's session failed or the
/// host's own.
#[test]
fn a_peer_whose_ggrs_session_fails_is_given_a_new_epoch_and_the_room_goes_on_agreeing() {
    let mut room = Room::new(net(20, 0.02));
    room.add(1);
    room.add(2);
    room.add(3);
    room.run(Duration::from_secs(3));
    let n0 = room.nodes[0].peer.epoch().map(|e| e.n).unwrap();
    assert!(room
        .nodes
        .iter()
        .all(|n| n.peer.epoch().map(|e| e.n) == Some(n0)));
    for (who, round) in [(1usize, 1u32), (0, 2)] {
        let before = room.nodes[who].peer.stats().frames;
        room.nodes[who].peer.simulate_ggrs_failure();
        room.run(Duration::from_secs(4));
        for n in &room.nodes {
            let e = n.peer.epoch().unwrap();
            assert_eq!(
                e.n,
                n0 + round,
                "peer {}: {:?}",
                n.peer.me().0,
                n.peer.stats()
            );
            assert_eq!(e.players.len(), 3);
        }
        let s = room.nodes[who].peer.stats();
        assert_eq!(s.ggrs_failures, 1);
        assert!(s.frames > before + 60, "peer {} stopped: {s:?}", who + 1);
        assert_agree(&room);
    }
    assert_eq!(room.nodes[0].peer.stats().resyncs, 2);
    assert_eq!(room.desyncs(), 0, "warnings: {:?}", room.warnings());
}

#[test]
fn a_members_forged_epoch_is_refused_and_the_room_still_takes_joiners() {
    let mut room = Room::new(net(10, 0.0));
    room.add(1);
    room.add(2);
    room.run(Duration::from_secs(3));
    let running = room.nodes[0].peer.epoch().unwrap().clone();
    // Member 2 announces an epoch as if it were the host: the largest number (every later
    // one would look old: joins frozen for ever) and itself as the snapshot's server.
    let now = room.now();
    let forged = Epoch {
        n: u32::MAX,
        frame: i32::MAX,
        players: vec![PeerId(2)],
        digest: [7; 32],
        host: PeerId(2),
    };
    room.nodes[1]
        .peer
        .send(now, MessageTarget::Everyone, Delivery::Retained, &forged)
        .unwrap();
    // and one naming the host as its server
    let forged_as_host = Epoch {
        host: PeerId(1),
        ..forged
    };
    room.nodes[1]
        .peer
        .send(
            now,
            MessageTarget::Everyone,
            Delivery::Retained,
            &forged_as_host,
        )
        .unwrap();
    room.run(Duration::from_secs(2));
    assert_eq!(room.nodes[0].peer.stats().epochs_refused, 2);
    assert_eq!(room.nodes[0].peer.epoch().map(|e| e.n), Some(running.n));
    // A joiner still gets in: the host's next epoch is taken by everyone, the joiner too
    // (the forged one is retained, so the joiner is offered it as well, and refuses it).
    room.add(3);
    room.run(Duration::from_secs(6));
    for n in &room.nodes {
        assert_eq!(
            n.peer.epoch().map(|e| (e.n, e.players.len())),
            Some((running.n + 1, 3)),
            "peer {}: {:?}",
            n.peer.me().0,
            n.events
        );
    }
    assert_eq!(room.desyncs(), 0, "warnings: {:?}", room.warnings());
    assert_agree(&room);
}

#[test]
fn joiners_that_first_reach_each_other_still_get_in() {
    let mut room = Room::new(net(10, 0.0));
    room.add(1);
    // Two joiners at once, each asking the other first (neither can answer): after the retry
    // each asks the next peer it is connected to, and the host welcomes both.
    room.add_via(2, 0);
    let b = room.add_via(3, 0);
    let c = room.add_via(4, b);
    room.nodes[b].peer = {
        // re-made to ask peer 4 first
        let scene = common::scene();
        let cfg = common::session_config(&scene);
        let now = room.now();
        let s =
            softsync_net::Session::join(softsync_net::PeerId(3), softsync_net::PeerId(4), cfg, now);
        softsync_rollback::RollbackPeer::new(
            now,
            scene,
            softsync_rollback::RollbackConfig::default(),
            s,
            Some(softsync_net::PeerId(4)),
        )
        .unwrap()
    };
    let _ = c;
    room.run(Duration::from_secs(8));
    for n in &room.nodes {
        assert_eq!(
            n.peer.epoch().map(|e| e.players.len()),
            Some(4),
            "{:?}",
            n.events
        );
    }
    assert_agree(&room);
}

#[test]
fn a_stranger_asking_for_the_epochs_snapshot_gets_nothing() {
    let mut room = Room::new(net(10, 0.0));
    room.add(1);
    room.add(2);
    room.run(Duration::from_secs(3));
    let epoch = room.nodes[0].peer.epoch().unwrap().n;
    let now = room.now();
    let ask = softsync_net::share::ShareMsg::Request {
        offset: 0,
        len: 1024,
        proof: None,
        token: None,
    }
    .encode();
    let datagram = softsync_rollback::socket::encode_snapshot(epoch, &ask);
    // a member may ask (it is served a chunk); a peer outside the session may not
    for (from, served) in [(PeerId(2), true), (PeerId(9), false)] {
        let host = &mut room.nodes[0].peer;
        host.handle_datagram(now, from, &datagram);
        let mut to_it = 0;
        while let Some(t) = host.poll_transmit(now) {
            let snapshot = matches!(
                softsync_rollback::socket::decode(&t.payload),
                Ok(softsync_rollback::socket::Datagram::Snapshot { .. })
            );
            to_it += usize::from(t.to == from && snapshot);
        }
        assert_eq!(to_it > 0, served, "peer {from:?}");
    }
    assert_eq!(room.nodes[0].peer.stats().snapshots_refused, 1);
}

#[test]
fn hostile_rollback_datagrams_change_nothing_and_the_room_goes_on_agreeing() {
    let mut room = Room::new(net(10, 0.0));
    room.add(1);
    room.add(2);
    room.run(Duration::from_secs(3));
    let epoch = room.nodes[0].peer.epoch().unwrap().n;
    // a stranger (9) and a member (2) send junk of every kind, this epoch's and others'
    let mut r = 0x2026_1128u64;
    let mut next = || {
        r = r.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        (r >> 33) as u32
    };
    for k in 0..2000u32 {
        let now = room.now();
        let e = if k % 3 == 0 { next() } else { epoch };
        let mut d = vec![
            softsync_rollback::socket::ROLLBACK_MARKER,
            1 + (k % 3) as u8,
        ];
        d.extend_from_slice(&e.to_le_bytes());
        for _ in 0..next() % 200 {
            d.push(next() as u8);
        }
        let from = if k % 2 == 0 { PeerId(9) } else { PeerId(2) };
        room.nodes[0].peer.handle_datagram(now, from, &d);
    }
    room.run(Duration::from_secs(3));
    assert_eq!(room.desyncs(), 0, "warnings: {:?}", room.warnings());
    assert_agree(&room);
}

/// Issue 38, desync repair: a one-off non-determinism on one peer mid-epoch is detected by
/// the checksums, the host starts a new epoch from its state, the odd peer fetches it, and
/// the worlds agree again — within 2 s of the detection, with no join.
#[test]
fn a_desync_in_the_middle_of_an_epoch_is_repaired_within_two_seconds() {
    let mut room = Room::new(net(20, 0.02));
    room.add(1);
    room.add(2);
    room.add(3);
    room.run(Duration::from_secs(3));
    assert_agree(&room);
    let n0 = room.nodes[0].peer.epoch().map(|e| e.n).unwrap();
    for (who, round) in [(2usize, 1u32), (0, 2)] {
        // a member, then the host itself
        room.nodes[who].peer.inject_desync();
        room.run(Duration::from_secs(4));
        let detected: u64 = room.nodes.iter().map(|n| n.peer.stats().desyncs).sum();
        assert!(detected > 0, "round {round}: the desync was not detected");
        for n in &room.nodes {
            let e = n.peer.epoch().unwrap();
            assert_eq!(
                e.n,
                n0 + round,
                "peer {}: {:?}",
                n.peer.me().0,
                n.peer.stats()
            );
            assert_eq!(e.players.len(), 3);
        }
        // every peer that saw it reports the repair, within 2 s
        let repaired: Vec<(u64, f32)> = room
            .nodes
            .iter()
            .map(|n| (n.peer.stats().repairs, n.peer.stats().repair_ms_max))
            .collect();
        eprintln!("round {round}: repairs (count, longest ms) {repaired:?}");
        assert!(
            repaired.iter().any(|(c, _)| *c == u64::from(round)),
            "{repaired:?}"
        );
        assert!(repaired.iter().all(|(_, ms)| *ms <= 2000.0), "{repaired:?}");
        assert_agree(&room);
    }
}
