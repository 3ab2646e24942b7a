//! Signaling that survives its own failure (issue 17 point 4), live on real WebRTC: a room
//! whose standalone signaling server dies registers with the next server of its list and new
//! peers join through that one; a room whose host embedded its signaling and died gets it
//! back from the new host, on that peer's `--bind`. Each test checks that the newcomer
//! reaches every member directly (the full mesh is whole again), not only the host.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::time::Duration;

mod common;
use common::{embedded_host, field, peer_on, require_netns, scratch, standalone_signal, Proc};

/// The peers that `p`'s final stats line has an RTT to (it printed it at exit), sorted.
fn reached(p: &Proc) -> Vec<u64> {
    let l = p.wait_line("final stats", Duration::from_secs(1));
    let mut v: Vec<u64> = field(&l, "rtts")
        .split(',')
        .map(|e| e.split(':').next().unwrap().parse().unwrap())
        .collect();
    v.sort_unstable();
    v
}

/// The newcomer ends its run cleanly, having reached exactly `want` (in any order).
fn ends_reaching(late: &mut Proc, mut want: Vec<u64>, context: &str) {
    assert_eq!(
        late.wait_exit(Duration::from_secs(20)),
        0,
        "{}",
        late.logs()
    );
    want.sort_unstable();
    assert_eq!(
        reached(late),
        want,
        "the newcomer's links ({context})\n{}",
        late.logs()
    );
}

/// A free port on loopback (bound, read and let go: a peer binds it moments later).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn a_room_stays_joinable_through_the_next_server_when_its_signaling_dies() {
    require_netns();
    let dir = scratch("failover");
    let (mut sig_a, a) = standalone_signal(&dir);
    let sig_b = Proc::spawn(&dir, "signal-b", &["signal", "--bind", "127.0.0.1:0"]);
    let b = common::signal_url(&sig_b);
    let both = format!("{a},{b}");
    let host = peer_on(&dir, "host", "host", &both, "fo", &["--duration", "40"]);
    let host_id = host.peer_id();
    let bot = peer_on(
        &dir,
        "bot",
        "join",
        &both,
        "fo",
        &["--duration", "40", "--bot", "wave"],
    );
    let bot_id = bot.peer_id();
    bot.wait_line("joined", Duration::from_secs(20));
    // The room's server dies; the room carries on and registers with the next one.
    sig_a.kill();
    std::thread::sleep(Duration::from_millis(1500));
    // A newcomer that knows only the second server gets in, and reaches both members.
    let mut late = peer_on(&dir, "late", "join", &b, "fo", &["--duration", "6"]);
    let late_id = late.peer_id();
    late.wait_line("joined", Duration::from_secs(20));
    host.wait_line(&format!("peer-joined {late_id}"), Duration::from_secs(10));
    ends_reaching(
        &mut late,
        vec![host_id, bot_id],
        "through the second server",
    );
}

#[test]
fn a_new_host_serves_the_signaling_its_dead_predecessor_embedded() {
    require_netns();
    let dir = scratch("takeover-signal");
    let (mut host, h) = embedded_host(&dir, "ts", &["--duration", "60"]);
    host.peer_id();
    let ports = [free_port(), free_port()];
    let urls: Vec<String> = ports
        .iter()
        .map(|p| format!("ws://127.0.0.1:{p}"))
        .collect();
    let bots: Vec<Proc> = ports
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let bind = format!("127.0.0.1:{p}");
            // stats lines on (stderr): they say which peers each reaches
            let args = [
                "join",
                "--room",
                "ts",
                "--signal",
                &h,
                "--duration",
                "40",
                "--bot",
                "wave",
                "--bind",
                &bind,
            ];
            let b = Proc::spawn(&dir, &format!("bot{i}"), &args);
            b.wait_line("joined", Duration::from_secs(20));
            b
        })
        .collect();
    let ids: Vec<u64> = bots.iter().map(Proc::peer_id).collect();
    // the survivors reach each other before the host dies (else each is a room of one)
    let start = std::time::Instant::now();
    while !std::fs::read_to_string(&bots[1].err)
        .unwrap_or_default()
        .lines()
        .any(|l| l.starts_with("stats ") && l.contains(&format!("{}:", ids[0])))
    {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "bot1 never reached bot0\n{}",
            bots[1].logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // The host dies with its signaling server; a survivor takes over and serves signaling.
    host.kill();
    let line = bots[0].wait_line("host-changed", Duration::from_secs(10));
    let new_host: u64 = field(&line, "host").parse().unwrap();
    let k = ids.iter().position(|i| *i == new_host).unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    // A newcomer with every address it might have been given: the dead host's and the
    // survivors' (only the new host's answers).
    let list = format!("{h},{},{}", urls[0], urls[1]);
    let mut late = peer_on(&dir, "late", "join", &list, "ts", &["--duration", "6"]);
    late.wait_line("joined", Duration::from_secs(25));
    let context = format!("new host {new_host}, serving on {}", urls[k]);
    ends_reaching(&mut late, ids.clone(), &context);
}
