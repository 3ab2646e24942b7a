//! The adaptive failure detector (`SessionConfig::fast_detection`) on virtual time: a dead
//! host is replaced within 400 ms (p95 of 20 kills) on a loopback-like link, where the fixed
//! 1 s timeout takes over a second; and a room under 150 ms latency, 30 ms jitter and 20 %
//! loss raises no false alarm (2 virtual minutes here; `cargo run --release -p softsync-net
//! --example detector` runs the 10 and sweeps the threshold).
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::*;
use softsync_net::harness::Harness;
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
fn a_dead_host_is_replaced_within_400_ms_where_the_fixed_timeout_takes_a_second() {
    let fast = p95(kill_times(&config().fast_detection(), 20));
    assert!(fast <= ms(400), "adaptive p95 {fast:?}");
    // The fixed timeout: a second after the last datagram heard (up to a heartbeat before
    // the kill).
    let fixed = p95(kill_times(&config(), 5));
    assert!(
        fixed >= ms(750) && fast * 2 < fixed,
        "fixed p95 {fixed:?}, adaptive {fast:?}"
    );
}

#[test]
fn a_lossy_jittery_room_raises_no_false_alarm() {
    for seed in [1, 2] {
        let link = ConditionerConfig::rough(seed, 150, 30, 0.20);
        let mut h = Harness::new(5, config().fast_detection(), link);
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
    let quiet = kill_times(&config().fast_detection(), 3);
    let link = ConditionerConfig::rough(7, 150, 30, 0.20);
    let mut h = Harness::new(4, config().fast_detection(), link);
    h.advance(ms(3000));
    let rough = h.time_to_new_host(ms(5000), ms(5)).unwrap();
    assert!(
        rough > *quiet.iter().max().unwrap(),
        "{rough:?} vs {quiet:?}"
    );
    // Never later than the fixed timeout (plus the latency of the news).
    assert!(rough <= ms(1000 + 400), "{rough:?}");
}
