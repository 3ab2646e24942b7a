//! The uplink budget with priorities (issue 18 point 1), on virtual time: a host whose uplink
//! cannot carry every moving object at every tick sends the one it holds first, still
//! refreshes every other object within a bounded time, and never exceeds its cap over any
//! one-second window.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::*;
use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::stats::TRANSPORT_OVERHEAD_BYTES;
use softsync_net::{Instant, NetId, ObjectState, SessionConfig};

const FRAME: Duration = Duration::from_micros(11_111);
const CROWD: usize = 40;
/// m/s: the held object's speed on its circle, the crowd's drift.
const HELD_SPEED: f64 = 0.9;
const CROWD_SPEED: f64 = 0.16;

/// Where object `i` is at time `t`: the crowd drifts 8 mm a tick (past the 5 mm threshold,
/// so every object has something to send at every tick); the held one (i = CROWD) circles
/// fast.
fn pose(i: usize, t: f32) -> Vec3 {
    if i == CROWD {
        Vec3::new(0.3 * (3.0 * t).cos(), 1.0, 0.3 * (3.0 * t).sin())
    } else {
        Vec3::new(-1.0 + 0.05 * i as f32 + 0.16 * t, 0.8, 0.5 * (i % 3) as f32)
    }
}

struct Run {
    /// How old the newest state client 1 shows of the held object is, per frame (s).
    held_age: Vec<f64>,
    /// The oldest any crowd object's shown state got (s).
    crowd_worst_age: f64,
    /// The host's largest bytes (payload plus transport overhead) over any 1 s window.
    max_window_bytes: f64,
}

fn run(cap: Option<u32>) -> Run {
    run_with_voice(cap, 0)
}

/// As [`run`], with `voice` payload bytes sent to each client beside the session every fourth
/// frame (~44 ms: a voice frame of two 20 ms packets), paid through `Session::charge_uplink`.
fn run_with_voice(cap: Option<u32>, voice: usize) -> Run {
    // the fixed detector's 5 heartbeats a second: with the default's 20 to every link quiet
    // for 37.5 ms (links under a cap often are), the crowd's worst age at this cap went to
    // 2.5 s (a cost of the default detector under tight caps, reported, not hidden)
    let cfg = SessionConfig {
        uplink_bytes_per_s: cap,
        ..config().fixed_detection()
    };
    let mut h = Harness::new(3, cfg, steady_link());
    h.advance(ms(1500));
    let now = h.now;
    let ids: Vec<NetId> = (0..=CROWD)
        .map(|i| {
            h.session(0)
                .spawn(now, RIGID, ObjectState::rigid(pose(i, 0.0), Quat::IDENTITY))
                .unwrap()
                .0
        })
        .collect();
    // the host holds the last one (its own grab: granted at once, held)
    h.session(0).request_authority(now, ids[CROWD]).unwrap();
    h.advance(ms(1000));
    let t0 = h.now;
    let mut held_age = Vec::new();
    let mut crowd_worst_age = 0.0f64;
    // (time, host bytes) samples for the sliding window
    let mut sent: Vec<(Instant, f64)> = Vec::new();
    let clients: Vec<_> = (1..3).map(|i| h.peers[i].session.local_id()).collect();
    let mut voice_bytes = 0.0;
    let mut frame = 0u64;
    while h.now < t0 + Duration::from_secs(8) {
        let now = h.now;
        let t = (now - t0).as_secs_f32();
        frame += 1;
        if voice > 0 && frame % 4 == 0 {
            for c in &clients {
                h.session(0).charge_uplink(now, *c, voice);
                voice_bytes += (voice + TRANSPORT_OVERHEAD_BYTES) as f64;
            }
        }
        for (i, id) in ids.iter().enumerate() {
            let st = ObjectState::rigid(pose(i, t), Quat::IDENTITY);
            h.session(0).publish_state(now, *id, &st).unwrap();
        }
        h.advance(FRAME);
        let now = h.now;
        let st = h.peers[0].session.stats();
        sent.push((
            now,
            st.up.bytes as f64
                + (st.up.packets * TRANSPORT_OVERHEAD_BYTES as u64) as f64
                + voice_bytes,
        ));
        if now < t0 + Duration::from_secs(2) {
            continue; // the start: every object's first state
        }
        // how old client 1's latest state of each object is: its distance to the truth now
        // over the object's speed
        let t = (now - t0).as_secs_f32();
        for (i, id) in ids.iter().enumerate() {
            let Some(latest) = h.session(1).latest_state(*id) else {
                continue;
            };
            let err = f64::from(latest.pos.distance(pose(i, t)));
            if i == CROWD {
                held_age.push(err / HELD_SPEED);
            } else {
                crowd_worst_age = crowd_worst_age.max(err / CROWD_SPEED);
            }
        }
    }
    let mut max_window_bytes = 0.0f64;
    for (k, (t, b)) in sent.iter().enumerate() {
        if let Some((_, b1)) = sent[k..]
            .iter()
            .take_while(|(t1, _)| *t1 <= *t + Duration::from_secs(1))
            .last()
        {
            max_window_bytes = max_window_bytes.max(b1 - b);
        }
    }
    Run {
        held_age,
        crowd_worst_age,
        max_window_bytes,
    }
}

fn p95(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[(v.len() * 95).div_ceil(100) - 1]
}

#[test]
fn under_a_cap_the_held_object_goes_first_nothing_starves_and_the_cap_holds() {
    let free = run(None);
    // the host's two links need ~2 x 40 objects x 20 Hz x ~10 B without a cap; a third of it
    let cap = 6_000;
    let capped = run(Some(cap));
    let (free_held, capped_held) = (p95(&free.held_age), p95(&capped.held_age));
    println!(
        "uncapped: {:.0} B/s max window, held age p95 {:.0} ms, crowd worst {:.0} ms",
        free.max_window_bytes,
        free_held * 1e3,
        free.crowd_worst_age * 1e3
    );
    println!(
        "cap {cap} B/s: {:.0} B/s max window, held age p95 {:.0} ms, crowd worst {:.0} ms",
        capped.max_window_bytes,
        capped_held * 1e3,
        capped.crowd_worst_age * 1e3
    );
    assert!(
        free.max_window_bytes > 2.0 * f64::from(cap),
        "the room does not need more than the cap: the test tests nothing"
    );
    // the cap holds over every 1 s window
    assert!(
        capped.max_window_bytes <= f64::from(cap),
        "{} B in a 1 s window, cap {cap}",
        capped.max_window_bytes
    );
    // the held object is not delayed behind the crowd: at most one send tick more than
    // without a cap
    assert!(
        capped_held <= free_held + 0.050,
        "held object's age p95 {capped_held} s capped, {free_held} s free"
    );
    // and every other object still gets through (its shown state at most 1.5 s old)
    assert!(
        capped.crowd_worst_age < 1.5,
        "a crowd object's state got {} s old",
        capped.crowd_worst_age
    );
    assert!(
        capped.crowd_worst_age > free.crowd_worst_age,
        "the cap changed nothing"
    );
}

#[test]
fn voice_is_paid_first_from_the_budget_and_the_cap_still_holds() {
    // 5 kB/s a link (the state alone wants more); voice frames of 60 B every ~44 ms to each
    // client take ~2.9 kB/s of each link's 5 with the transport's 69 B each (at such caps a
    // voice frame's overhead is most of it)
    let cap = 10_000;
    let with = run_with_voice(Some(cap), 60);
    let without = run(Some(cap));
    println!(
        "cap {cap} B/s: with voice {:.0} B/s max window (held age p95 {:.0} ms, crowd worst {:.0} ms); without {:.0} B/s (held {:.0} ms, crowd worst {:.0} ms)",
        with.max_window_bytes,
        p95(&with.held_age) * 1e3,
        with.crowd_worst_age * 1e3,
        without.max_window_bytes,
        p95(&without.held_age) * 1e3,
        without.crowd_worst_age * 1e3
    );
    assert!(
        without.max_window_bytes > 0.8 * f64::from(cap),
        "the state alone does not fill the cap: the test tests nothing"
    );
    // state and voice together stay under the cap: the state made room
    assert!(
        with.max_window_bytes <= f64::from(cap),
        "{} B in a 1 s window with voice, cap {cap}",
        with.max_window_bytes
    );
    // and the held object still goes first
    assert!(
        p95(&with.held_age) <= p95(&without.held_age) + 0.1,
        "held age p95 {:.3} s with voice, {:.3} s without",
        p95(&with.held_age),
        p95(&without.held_age)
    );
}
