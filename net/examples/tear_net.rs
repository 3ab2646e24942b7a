//! What a tear costs on the wire and how long until every peer has it:
//! `cargo run --release -p softsync-net --example tear_net`.
//!
//! A room of three on the in-memory hub with the seeded link conditioner (20 ms latency,
//! 5 ms jitter, 2 % loss per direction): peer 1 (a client) owns a 60-particle soft body and
//! asks for 100 tear segments at 90 Hz; the host checks and relays them. The same room runs
//! twice from the same seeds, with and without the tears, so the difference in bytes is what
//! the tears cost (requests, relays, their acknowledgements and retransmissions).
//! `converge_ms`: from a segment's request to the last peer holding it in its log. Then a
//! late joiner: the bytes the host sends it in its first 2 s, with and without the log.
#![allow(clippy::unwrap_used, clippy::print_stdout, missing_docs)]

use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_benchkit::{median, percentile, ResultLine};
use softsync_net::harness::Harness;
use softsync_net::policy::{ClassConfig, SendPolicy, SessionConfig, SoftBodyMode};
use softsync_net::wire::TopologyEvent;
use softsync_net::{ClassId, ConditionerConfig, ObjectState};

const SEGMENTS: usize = 100;

struct Run {
    bytes: u64,
    converge_ms: Vec<f64>,
    joiner_bytes: u64,
}

fn config() -> SessionConfig {
    SessionConfig {
        classes: vec![ClassConfig::soft_body(
            "soft",
            SendPolicy::default(),
            SoftBodyMode::Particles,
        )],
        ..SessionConfig::default()
    }
}

fn run(tears: bool) -> Run {
    let link = ConditionerConfig::rough(11, 20, 5, 0.02);
    let mut h = Harness::new(3, config(), link);
    let st = ObjectState {
        pos: Vec3::new(0.0, 1.0, 0.0),
        rot: Quat::IDENTITY,
        particles: (0..60)
            .map(|k| Vec3::new((k % 4) as f32, (k / 16) as f32, ((k / 4) % 4) as f32) * 0.02)
            .collect(),
    };
    let now = h.now;
    h.session(1).spawn(now, ClassId(0), st).unwrap();
    h.advance(Duration::from_millis(500));
    let id = h.peers[0].session.object_ids()[0];
    let bytes0: u64 = h.peers.iter().map(|p| p.session.stats().up.bytes).sum();
    let mut asked_at = Vec::new();
    let mut have_at: Vec<Vec<Option<f64>>> = vec![vec![None; SEGMENTS]; 3];
    let frame = Duration::from_micros(11_111);
    let mut next = 0;
    let end = h.now + frame * (SEGMENTS as u32) + Duration::from_millis(1500);
    while h.now < end {
        if tears && next < SEGMENTS {
            let k = next as i32;
            let ev = TopologyEvent::Tear {
                from: [k * 100, 9000, 0],
                to: [k * 100 + 100, 9000, 30],
                blade: [0, 3000, 0],
            };
            let now = h.now;
            h.session(1).request_topology(now, id, ev, vec![]).unwrap();
            asked_at.push(now.as_secs_f64() * 1e3);
            next += 1;
        }
        // Step in 1 ms slices, noting when each peer's log grows.
        for _ in 0..11 {
            h.advance(Duration::from_millis(1));
            for (p, have) in have_at.iter_mut().enumerate() {
                let len = h.peers[p].session.topology_log(id).map_or(0, <[_]>::len);
                for slot in have.iter_mut().take(len) {
                    slot.get_or_insert(h.now.as_secs_f64() * 1e3);
                }
            }
        }
    }
    let bytes: u64 = h
        .peers
        .iter()
        .map(|p| p.session.stats().up.bytes)
        .sum::<u64>()
        - bytes0;
    let converge_ms = (0..asked_at.len())
        .filter_map(|k| {
            let last = have_at
                .iter()
                .map(|h| h[k])
                .collect::<Option<Vec<f64>>>()?
                .into_iter()
                .fold(f64::MIN, f64::max);
            Some(last - asked_at[k])
        })
        .collect();
    let host_up0 = h.peers[0].session.stats().up.bytes;
    h.add_peer_with(config(), 0);
    h.advance(Duration::from_secs(2));
    Run {
        bytes,
        converge_ms,
        joiner_bytes: h.peers[0].session.stats().up.bytes - host_up0,
    }
}

fn main() {
    let with = run(true);
    let without = run(false);
    assert_eq!(
        with.converge_ms.len(),
        SEGMENTS,
        "every segment reached every peer"
    );
    let per_segment = (with.bytes as f64 - without.bytes as f64) / SEGMENTS as f64;
    let snapshot = with.joiner_bytes as f64 - without.joiner_bytes as f64;
    let line = ResultLine::new("tear.net")
        .fixed("bytes_per_segment", per_segment, 1)
        .fixed("converge_ms", median(&with.converge_ms), 1)
        .fixed("converge_p95_ms", percentile(&with.converge_ms, 0.95), 1)
        .fixed("snapshot_bytes_100_segments", snapshot, 0)
        .field("peers", 3)
        .field("segments", SEGMENTS)
        .field("link", "20ms+-5ms_2%loss");
    println!("{line}");
}
