//! A room on virtual time, headless: a host and two bots on a conditioned link (20 ms ± 5 ms,
//! 2 % loss, seeded). Bot 1 takes authority of the soft body and replays the soft-body crate's
//! recorded squeeze (`assets/traces/softbody60.sstr`); every peer's avatar head moves. Halfway
//! the host is killed: the earliest joiner takes over; then a late joiner arrives. Prints what
//! each peer syncs once per simulated second.
//!
//! `cargo run --release -p softsync-net --example net_demo -- [--seconds 14]`
#![allow(
    clippy::unwrap_used,
    clippy::print_stdout,
    clippy::needless_range_loop,
    missing_docs
)]

use std::path::Path;
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_benchkit::trace::{Frame, Trace};
use softsync_net::harness::Harness;
use softsync_net::{
    ClassConfig, ClassId, ConditionerConfig, Event, NetId, ObjectState, SendPolicy, SessionConfig,
    SoftBodyMode,
};

const FRAME: Duration = Duration::from_micros(11_111);

/// A recorded trace frame as the session's object state.
fn object_state(f: Frame) -> ObjectState {
    ObjectState {
        pos: f.pos,
        rot: f.rot,
        particles: f.particles,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seconds: f32 = args
        .iter()
        .position(|a| a == "--seconds")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(14.0);
    let trace_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/traces/softbody60.sstr");
    let trace = std::fs::read(&trace_path)
        .ok()
        .and_then(|b| Trace::parse(&b))
        .expect("assets/traces/softbody60.sstr (run the soft-body trace example)");
    let mut soft =
        ClassConfig::soft_body("softbody", SendPolicy::default(), SoftBodyMode::Particles);
    soft.particle_extent_m = 0.25;
    let cfg = SessionConfig {
        classes: vec![ClassConfig::rigid("avatar", SendPolicy::default()), soft],
        ..SessionConfig::default()
    };
    let link = ConditionerConfig {
        seed: 7,
        latency: Duration::from_millis(20),
        jitter: Duration::from_millis(5),
        loss: 0.02,
        ..ConditionerConfig::default()
    };
    let mut h = Harness::new(3, cfg, link);
    h.advance(Duration::from_millis(500));
    let now = h.now;
    // The host spawns the soft body; each peer spawns its avatar head.
    h.session(0)
        .spawn(now, ClassId(1), object_state(trace.state(0.0)))
        .unwrap();
    for i in 0..3 {
        h.session(i)
            .spawn(
                now,
                ClassId(0),
                ObjectState::rigid(Vec3::new(i as f32, 1.6, 0.0), Quat::IDENTITY),
            )
            .unwrap();
    }
    h.advance(Duration::from_millis(300));
    let soft_id = h
        .session(0)
        .object_ids()
        .into_iter()
        .find(|id| h.session(0).class_of(*id) == Some(ClassId(1)))
        .unwrap();
    println!(
        "room up: host {:?}, peers {:?}; soft body {:?} ({} particles), link 20±5 ms, 2 % loss",
        h.session(0).host_id().unwrap(),
        (0..3).map(Harness::id).collect::<Vec<_>>(),
        soft_id,
        trace.frames[0].particles.len()
    );
    let now = h.now;
    h.session(1).request_authority(now, soft_id).unwrap();
    // The demo clock t is 0 at this harness time; owners publish trace.state(t).
    let t0 = h.now.as_secs_f64();
    let mut t = 0.0f32;
    let mut last_bytes: Vec<u64> = vec![0; 8];
    let mut killed = false;
    let mut late: Option<usize> = None;
    let mut late_spawned = false;
    while t < seconds {
        // Each peer's frame: move its avatar; the soft body's owner publishes the trace.
        let now = h.now;
        for i in 0..h.peers.len() {
            if !h.peers[i].alive {
                continue;
            }
            let me = Harness::id(i);
            let ids = h.session(i).object_ids();
            for id in ids {
                if h.session(i).owner(id) != Some(me) {
                    continue;
                }
                let state = if h.session(i).class_of(id) == Some(ClassId(1)) {
                    object_state(trace.state(t))
                } else {
                    let a = t * 0.8 + i as f32;
                    ObjectState::rigid(
                        Vec3::new(i as f32 + 0.3 * a.cos(), 1.6, 0.3 * a.sin()),
                        Quat::from_rotation_y(a),
                    )
                };
                let _ = h.session(i).publish_state(now, id, &state);
            }
        }
        h.advance(FRAME);
        t += FRAME.as_secs_f32();
        for (i, p) in h.peers.iter_mut().enumerate() {
            for e in p.events.drain(..) {
                match e {
                    Event::HostChanged { host, term } => println!(
                        "  peer {:?}: host is now {host:?} (term {})",
                        Harness::id(i),
                        term.0
                    ),
                    Event::AuthorityChanged { id, owner, .. } if id == soft_id => println!(
                        "  peer {:?}: soft body {id:?} now owned by {owner:?}",
                        Harness::id(i)
                    ),
                    Event::PeerLeft(who) => {
                        println!("  peer {:?}: {who:?} left (silent ≥ 1 s)", Harness::id(i))
                    }
                    Event::Joined { host, term } => println!(
                        "  peer {:?}: joined, host {host:?}, term {}",
                        Harness::id(i),
                        term.0
                    ),
                    _ => {}
                }
            }
        }
        if !killed && t >= seconds * 0.45 {
            println!("t={t:4.1}s  -- SIGKILL the host {:?} --", Harness::id(0));
            h.kill(0);
            killed = true;
        }
        if let Some(i) = late {
            // The late joiner spawns its avatar once it is in (a client's spawn goes through the host).
            if h.peers[i].session.is_connected() && !late_spawned {
                let now = h.now;
                late_spawned = h
                    .session(i)
                    .spawn(
                        now,
                        ClassId(0),
                        ObjectState::rigid(Vec3::new(3.0, 1.6, 0.0), Quat::IDENTITY),
                    )
                    .is_ok();
            }
        }
        if late.is_none() && killed && t >= seconds * 0.75 {
            let cfg = h.session(1).config().clone();
            let i = h.add_peer_with(cfg, 1);
            println!("t={t:4.1}s  -- late joiner {:?} arrives --", Harness::id(i));
            late = Some(i);
        }
        // Once per second: what each live peer syncs.
        if (t / 1.0).floor() != ((t - FRAME.as_secs_f32()) / 1.0).floor() {
            for i in 0..h.peers.len() {
                if !h.peers[i].alive {
                    continue;
                }
                let now = h.now;
                let s = h.session(i);
                let up = s.stats().up.bytes;
                let rate = up.saturating_sub(last_bytes[i]);
                last_bytes[i] = up;
                let me = s.local_id();
                let owned = s
                    .object_ids()
                    .iter()
                    .filter(|id| s.owner(**id) == Some(me))
                    .count();
                let rtt = s
                    .stats()
                    .links
                    .values()
                    .filter_map(|l| l.rtt)
                    .map(|d| d.as_secs_f64() * 1e3)
                    .fold(0.0, f64::max);
                let shown = s.display_state(now, soft_id).map(|d| {
                    // Remote error against the owner's trace at the displayed (sender) time.
                    let truth = trace.state((d.source_time.as_secs_f64() - t0) as f32);
                    d.state
                        .particles
                        .iter()
                        .zip(&truth.particles)
                        .map(|(a, b)| a.distance(*b))
                        .fold(0.0f32, f32::max)
                });
                println!(
                    "t={t:4.1}s peer {:?}{}: host {:?} term {} | objects {} owned {} | up {:5} B/s | rtt {:4.1} ms | soft body {}",
                    me,
                    if s.is_host() { " (host)" } else { "" },
                    s.host_id().map(|p| p.0).unwrap_or(0),
                    s.term().0,
                    s.object_ids().len(),
                    owned,
                    rate,
                    rtt,
                    match shown {
                        Some(e) if s.owner(soft_id) != Some(me) => format!("shown, max particle error {:.1} mm", e * 1e3),
                        Some(_) => "simulated here".to_string(),
                        None => "not yet".to_string(),
                    }
                );
            }
        }
    }
    // Summary: every live peer agrees on the objects and their single owner.
    let live: Vec<usize> = (0..h.peers.len()).filter(|&i| h.peers[i].alive).collect();
    let reference: Vec<(NetId, Option<softsync_net::PeerId>)> = {
        let s = h.session(live[0]);
        s.object_ids()
            .iter()
            .map(|id| (*id, s.owner(*id)))
            .collect()
    };
    let agree = live.iter().all(|&i| {
        let s = h.session(i);
        s.object_ids()
            .iter()
            .map(|id| (*id, s.owner(*id)))
            .collect::<Vec<_>>()
            == reference
    });
    println!(
        "end: {} live peers agree on {} objects and their owners: {agree}",
        live.len(),
        reference.len()
    );
}
