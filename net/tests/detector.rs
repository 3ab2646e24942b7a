//! The default failure detector (adaptive, `SessionConfig::fast_detection`) on virtual time:
//! a dead host is replaced within 400 ms (p95 of 20 kills) on a loopback-like link, where the
//! fixed 1 s timeout takes over a second; a host stopped for less than 250 ms is never
//! replaced, nor deposed by a member whose own process stalled; a room whose every process
//! stalls now and then (a seeded CPU-stall model) and a room under 150 ms latency, 30 ms
//! jitter and 20 % loss raise no false alarm (2 virtual minutes each here; `cargo run
//! --release -p softsync-net --example detector` runs the 10 and sweeps the
//! threshold).
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::*;
use softsync_net::harness::{Harness, StallModel};
use softsync_net::{ConditionerConfig, SessionConfig};

fn kill_times(cfg: &SessionConfig, kills: u64) -> Vec<Duration> {
    (1..=kills)
        .map(|seed| {
            let link = ConditionerConfig::rough(seed, 1, 1, 0.0);
            let mut h = Harness::new(4, cfg.clone(), link);
            // Each kill at another moment of the heartbeat rhythm.
            h.advance(ms(3000 + 7 * seed));
            assert_eq!(
                h.host_changes(),
                0,
                "seed {seed}: a host change before the kill"
            );
            h.time_to_new_host(ms(5000), ms(5))
                .unwrap_or_else(|| panic!("seed {seed}: nobody took over"))
        })
        .collect()
}

fn p95(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[(v.len() * 95).div_ceil(100) - 1]
}

#[test]
fn a_dead_host_is_replaced_within_400_ms_by_default_where_the_fixed_timeout_takes_a_second() {
    let fast = p95(kill_times(&config(), 20));
    assert!(fast <= ms(400), "adaptive p95 {fast:?}");
    assert_eq!(config(), config(), "the default is the adaptive detector");
    // The fixed timeout: a second after the last datagram heard (up to a heartbeat before
    // the kill).
    let fixed = p95(kill_times(&config().fixed_detection(), 5));
    assert!(
        fixed >= ms(750) && fast * 2 < fixed,
        "fixed p95 {fixed:?}, adaptive {fast:?}"
    );
}

#[test]
fn a_lossy_jittery_room_raises_no_false_alarm() {
    for seed in [1, 2] {
        let link = ConditionerConfig::rough(seed, 150, 30, 0.20);
        let mut h = Harness::new(5, config(), link);
        h.advance(ms(3000));
        let term = h.peers[0].session.term();
        h.advance(Duration::from_secs(120));
        assert_eq!(h.failure_verdicts(), 0, "seed {seed}");
        for (i, p) in h.peers.iter().enumerate() {
            assert_eq!(p.session.term(), term, "seed {seed}: peer {i}");
            assert_eq!(p.session.members().len(), 5, "seed {seed}: peer {i}");
        }
    }
}

#[test]
fn the_adaptive_timeout_stretches_with_a_bad_link_and_stays_within_its_bounds() {
    // With 20 % loss and jitter, the allowed silence grows past the quiet link's.
    let quiet = kill_times(&config(), 3);
    let link = ConditionerConfig::rough(7, 150, 30, 0.20);
    let mut h = Harness::new(4, config(), link);
    h.advance(ms(3000));
    let rough = h.time_to_new_host(ms(5000), ms(5)).unwrap();
    assert!(
        rough > *quiet.iter().max().unwrap(),
        "{rough:?} vs {quiet:?}"
    );
    // Never later than the fixed timeout (plus the latency of the news).
    assert!(rough <= ms(1000 + 400), "{rough:?}");
}

/// A clean link with jitter: 20 ± 5 ms, nothing lost, duplicated or reordered.
fn lan(seed: u64) -> ConditionerConfig {
    ConditionerConfig {
        seed,
        latency: ms(20),
        jitter: ms(5),
        ..ConditionerConfig::default()
    }
}

/// The host (peer 0) stops for `stop` at `phase` into a settled room of 4, then goes on:
/// whether anyone took it for gone.
fn host_stop_verdicts(seed: u64, phase: Duration, stop: Duration) -> usize {
    let mut h = Harness::new(4, config(), lan(seed));
    h.advance(ms(3000) + phase);
    assert_eq!(
        h.failure_verdicts(),
        0,
        "seed {seed}: a verdict before the stop"
    );
    h.freeze(0, true);
    h.advance(stop);
    h.freeze(0, false);
    h.advance(ms(2000));
    h.failure_verdicts()
}

#[test]
fn a_host_stopped_for_less_than_250_ms_is_never_replaced_and_one_stopped_for_600_is() {
    // every phase of the heartbeat rhythm, 5 ms apart
    for (k, phase) in (0..50).step_by(5).enumerate() {
        let seed = 11 + k as u64;
        let v = host_stop_verdicts(seed, ms(phase), ms(249));
        assert_eq!(
            v, 0,
            "seed {seed}, phase {phase} ms: a 249 ms stop was a verdict"
        );
    }
    // a stop well past the tolerance is a crash to the others (the test can fail)
    assert!(host_stop_verdicts(3, ms(0), ms(600)) > 0);
}

#[test]
fn a_member_whose_own_process_stalled_deposes_nobody_when_it_wakes() {
    // The heir (peer 1) stalls for 450 ms, and what the host sent it meanwhile is lost (a
    // starved receiver whose socket overflowed): when it wakes, the host has been silent to
    // it for longer than the detector allows. Its own stall is "I was away", not "they are
    // dead": it must not take over. (The host rightly drops it: it was stopped past 250 ms.)
    for seed in [1, 2, 3] {
        let mut h = Harness::new(4, config(), lan(seed));
        h.auto_rejoin = true;
        h.advance(ms(3000));
        let term = h.peers[0].session.term();
        h.freeze(1, true);
        for other in [0, 2, 3] {
            h.partition(1, other, true);
        }
        h.advance(ms(450));
        for other in [0, 2, 3] {
            h.partition(1, other, false);
        }
        h.freeze(1, false);
        h.advance(ms(3000));
        assert_eq!(h.host_changes(), 0, "seed {seed}: a host change");
        assert_eq!(h.host_index(), Some(0), "seed {seed}");
        for (i, p) in h.peers.iter().enumerate() {
            assert_eq!(p.session.term(), term, "seed {seed}: peer {i}");
            assert_eq!(p.session.members().len(), 4, "seed {seed}: peer {i}");
        }
    }
}

#[test]
fn a_room_whose_processes_stall_now_and_then_raises_no_false_alarm() {
    // The seeded CPU-stall model: every process, the host included, stops at random moments
    // (exponential gaps, 1.5 s on average) for 10 – 249 ms, as a loaded machine's scheduler
    // makes them; 2 virtual minutes in frames of 5 ms (20 seeds passed when this was written).
    // Nobody is gone, so every host change or member seen leaving is a false alarm.
    for seed in [5, 6] {
        let n = 5;
        let mut h = Harness::new(n, config(), lan(seed));
        h.advance(ms(3000));
        let term = h.peers[0].session.term();
        let stalls =
            h.run_with_stalls(Duration::from_secs(120), ms(5), StallModel::tolerated(seed));
        assert!(stalls > 300, "seed {seed}: {stalls} stalls");
        assert_eq!(h.failure_verdicts(), 0, "seed {seed} ({stalls} stalls)");
        for (i, p) in h.peers.iter().enumerate() {
            assert_eq!(p.session.term(), term, "seed {seed}: peer {i}");
            assert_eq!(p.session.members().len(), n, "seed {seed}: peer {i}");
        }
    }
}

#[test]
fn links_between_members_are_pinged_at_their_slower_interval() {
    // Every member pings its host (and the host every member) at the fast interval; two
    // members ping each other at `member_heartbeat_interval` (250 ms): a room of n pays ~n
    // fast links, not n²/2. Nothing but heartbeats flows here (no objects).
    let mut h = Harness::new(6, config(), lan(3));
    h.advance(ms(3000));
    let (host, member, other) = (Harness::id(0), Harness::id(2), Harness::id(3));
    let up = |h: &mut Harness, i: usize, to| h.session(i).stats().links[&to].up;
    let (to_host0, to_member0, host_to0) = (
        up(&mut h, 2, host),
        up(&mut h, 2, other),
        up(&mut h, 0, member),
    );
    h.advance(ms(10_000));
    let rate = |now: softsync_net::stats::Traffic, then| now.rate_since(&then, ms(10_000)).1;
    let to_host = rate(up(&mut h, 2, host), to_host0);
    let to_member = rate(up(&mut h, 2, other), to_member0);
    let host_to = rate(up(&mut h, 0, member), host_to0);
    eprintln!(
        "member to host {to_host}/s, host to member {host_to}/s, member to member {to_member}/s"
    );
    assert!(
        (15.0..=30.0).contains(&to_host),
        "member to host {to_host}/s"
    );
    assert!(
        (15.0..=30.0).contains(&host_to),
        "host to member {host_to}/s"
    );
    assert!(
        (2.0..=12.0).contains(&to_member),
        "member to member {to_member}/s"
    );
    assert_eq!(h.host_changes(), 0);
}

#[test]
fn a_host_and_its_heir_killed_together_are_replaced_by_the_next_heir() {
    // The members judge each other on the slower links: with the heir dead too, they wait
    // for the heir until its link's timeout (at most six member intervals, 1.5 s), then the
    // next earliest joiner takes over. Meanwhile no session asks to be woken in the past for
    // the dead host's deadline (a driver that trusted it would spin).
    for seed in [1, 2, 3] {
        let mut h = Harness::new(5, config(), lan(seed));
        h.advance(ms(3000 + 11 * seed));
        let start = h.now;
        h.kill(1);
        h.kill(0);
        h.advance(ms(600));
        assert_eq!(h.host_index(), None, "seed {seed}: the heir is dead");
        for i in 2..5 {
            let t = h.session(i).poll_timeout().expect("a deadline");
            assert!(
                t > h.now,
                "seed {seed}: peer {i} asks to be woken in the past"
            );
        }
        while h.host_index().is_none() && h.now.saturating_since(start) < ms(5000) {
            h.advance(ms(5));
        }
        let took = h.now.saturating_since(start);
        eprintln!("seed {seed}: {took:?}");
        assert!(took <= ms(1800), "seed {seed}: {took:?}");
        assert_eq!(h.host_index(), Some(2), "seed {seed}");
    }
}
