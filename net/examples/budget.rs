//! Error against the host's uplink budget (issue 18 point 1), on the virtual-time harness:
//! rooms of 8 and 16 peers where every client holds one object and moves its avatar (head
//! and two hands) while a few of the host's 20 scene objects drift; the host relays all of it
//! to everyone, so its uplink grows with the square of the room. The host's uplink is capped
//! at fractions of what it sends uncapped; every client measures what it shows of the
//! objects it does not own against the owner's truth at the time it shows (now minus its
//! interpolation delay), so late updates count as error.
//!
//! `cargo run --release -p softsync-net --example budget [-- --quick]` (`--quick`: 8 peers
//! and three caps, nothing written). Writes `docs/results/net/budget.{csv,svg}` and prints
//! `RESULT crowd.budget peers=… cap_bytes_per_s=… host_up_bytes_per_s=… p95_mm=…
//! held_p95_mm=…` lines.
//!
//! `-- --route [--quick]`: the same rooms uncapped, with state relayed by the host (the
//! thesis's way, the default) and sent directly by each owner (issue 18 point 2), at 4, 8
//! and 16 peers: host and client uplink, how late clients' objects appear to other clients
//! (the lag that best explains what they show) and the error. Writes
//! `docs/results/net/route.csv`, prints `RESULT crowd.route …` lines.
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::path::Path;
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_benchkit::plotters::style::{BLUE, RED};
use softsync_benchkit::{percentile, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_net::harness::Harness;
use softsync_net::stats::TRANSPORT_OVERHEAD_BYTES;
use softsync_net::{
    ClassConfig, ClassId, ConditionerConfig, Event, Instant, NetId, ObjectState, SendPolicy,
    SessionConfig, StateRoute,
};

const FRAME: Duration = Duration::from_micros(11_111);
const SCENE: usize = 20;
const SECONDS: f32 = 6.0;

/// Where object `k` of client `c` (0: held, 1-3: head and hands) is at `t`.
fn client_pose(c: usize, k: usize, t: f32) -> Vec3 {
    let phase = c as f32 * 0.7 + k as f32 * 1.3;
    let center = Vec3::new(
        (c as f32 * 0.9).cos() * 1.2,
        1.0,
        (c as f32 * 0.9).sin() * 1.2,
    );
    let r = if k == 0 { 0.25 } else { 0.1 };
    let w = if k == 0 { 3.0 } else { 1.5 };
    center
        + Vec3::new(
            r * (w * t + phase).cos(),
            0.1 * (2.0 * t + phase).sin(),
            r * (w * t + phase).sin(),
        )
}

/// The host's scene object `i`: a quarter of them drift, the rest rest.
fn scene_pose(i: usize, t: f32) -> Vec3 {
    let base = Vec3::new(-0.5 + 0.05 * i as f32, 0.8, 0.0);
    if i % 4 == 0 {
        base + Vec3::new(0.0, 0.0, 0.1 * t)
    } else {
        base
    }
}

/// (peers, p95 of every object against the cap, p95 of held objects against the cap).
type Curve = (usize, Vec<(f64, f64)>, Vec<(f64, f64)>);

#[derive(Clone)]
struct Outcome {
    host_up: f64,
    /// Mean uplink of a client, bytes/s (transport overhead included).
    client_up: f64,
    p95_mm: f64,
    held_p95_mm: f64,
    avatar_p95_mm: f64,
    scene_p95_mm: f64,
    /// How late clients' objects appear to other clients: the lag that best explains what
    /// they show (the median distance to the owner's truth that long ago is least), ms.
    lag_ms: f64,
    /// Clients' objects as others show them against where they really are at that moment
    /// (lateness included), p95, mm.
    now_p95_mm: f64,
}

/// The lag (ms, 0-400 in 1 ms steps) at which what viewers showed of clients' objects is
/// nearest (median distance) to the owners' truth that long before: (lag, p95 at lag 0).
fn fit_lag(shown: &[(f32, usize, usize, Vec3)]) -> (f64, f64) {
    let dist_at = |lag: f32| -> Vec<f64> {
        shown
            .iter()
            .map(|(t, c, k, p)| f64::from(p.distance(client_pose(*c, *k, t - lag))) * 1e3)
            .collect()
    };
    let mut best = (0.0f64, f64::MAX);
    for ms in 0..=400 {
        let mut d = dist_at(ms as f32 / 1000.0);
        d.sort_by(f64::total_cmp);
        let m = percentile(&d, 50.0);
        if m < best.1 {
            best = (f64::from(ms), m);
        }
    }
    let mut now = dist_at(0.0);
    now.sort_by(f64::total_cmp);
    (best.0, percentile(&now, 95.0))
}

fn spawned(h: &Harness, peer: usize, request: u32) -> Option<NetId> {
    h.peers[peer].events.iter().find_map(|e| match e {
        Event::Spawned {
            id,
            request: Some(r),
            ..
        } if *r == request => Some(*id),
        _ => None,
    })
}

fn room(peers: usize, cap: Option<u32>, route: StateRoute) -> Outcome {
    let cfg = SessionConfig {
        classes: vec![ClassConfig::rigid("rigid", SendPolicy::default())],
        state_route: route,
        ..SessionConfig::default()
    };
    let link = ConditionerConfig::rough(7, 15, 2, 0.0);
    // the cap applies to the host only (the clients' uplinks are not the bottleneck here;
    // not part of the room's digest, so the clients join as usual)
    let host_cfg = SessionConfig {
        uplink_bytes_per_s: cap,
        ..cfg.clone()
    };
    let mut h = Harness::new(1, host_cfg, link);
    for _ in 1..peers {
        h.add_peer_with(cfg.clone(), 0);
        h.advance(Duration::from_millis(50));
    }
    h.advance(Duration::from_millis(2000));
    let now = h.now;
    // the host's scene objects, and one object per client that the host spawns and the
    // client grabs (held)
    let scene: Vec<NetId> = (0..SCENE)
        .map(|i| {
            h.session(0)
                .spawn(
                    now,
                    ClassId(0),
                    ObjectState::rigid(scene_pose(i, 0.0), Quat::IDENTITY),
                )
                .unwrap()
                .0
        })
        .collect();
    let held: Vec<NetId> = (1..peers)
        .map(|c| {
            h.session(0)
                .spawn(
                    now,
                    ClassId(0),
                    ObjectState::rigid(client_pose(c, 0, 0.0), Quat::IDENTITY),
                )
                .unwrap()
                .0
        })
        .collect();
    let mut avatar_reqs = Vec::new();
    for c in 1..peers {
        for k in 1..4 {
            let st = ObjectState::rigid(client_pose(c, k, 0.0), Quat::IDENTITY);
            avatar_reqs.push((c, k, h.session(c).spawn(now, ClassId(0), st).unwrap().1));
        }
    }
    h.advance(Duration::from_millis(500));
    let now = h.now;
    for c in 1..peers {
        h.session(c).request_authority(now, held[c - 1]).unwrap();
    }
    h.advance(Duration::from_millis(1500));
    // (owner peer, object, k) for everything that moves under a client
    let mut client_objs: Vec<(usize, NetId, usize)> = Vec::new();
    for c in 1..peers {
        client_objs.push((c, held[c - 1], 0));
    }
    for (c, k, r) in &avatar_reqs {
        if let Some(id) = spawned(&h, *c, *r) {
            client_objs.push((*c, id, *k));
        }
    }
    let t0 = h.now;
    let warm = 1.0f32;
    let mut errs = Vec::new();
    let mut held_errs = Vec::new();
    let mut avatar_errs = Vec::new();
    let mut scene_errs = Vec::new();
    let mut shown: Vec<(f32, usize, usize, Vec3)> = Vec::new();
    let mut up_start: Option<(Instant, f64, f64)> = None;
    let bytes_of = |h: &Harness, i: usize| {
        let s = h.peers[i].session.stats();
        s.up.bytes as f64 + (s.up.packets * TRANSPORT_OVERHEAD_BYTES as u64) as f64
    };
    let host_bytes = |h: &Harness| bytes_of(h, 0);
    let clients_bytes = |h: &Harness| (1..peers).map(|i| bytes_of(h, i)).sum::<f64>();
    while h.now < t0 + Duration::from_secs_f32(SECONDS + warm) {
        let now = h.now;
        let t = (now - t0).as_secs_f32();
        for (i, id) in scene.iter().enumerate() {
            let st = ObjectState::rigid(scene_pose(i, t), Quat::IDENTITY);
            h.session(0).publish_state(now, *id, &st).unwrap();
        }
        for (c, id, k) in &client_objs {
            let st = ObjectState::rigid(client_pose(*c, *k, t), Quat::IDENTITY);
            let _ = h.session(*c).publish_state(now, *id, &st);
        }
        h.advance(FRAME);
        let now = h.now;
        if (now - t0).as_secs_f32() < warm {
            continue;
        }
        if up_start.is_none() {
            up_start = Some((now, host_bytes(&h), clients_bytes(&h)));
        }
        // every 4th frame, every client measures everything it does not own
        if h.peers[0].session.stats().up.packets % 4 != 0 {
            continue;
        }
        for viewer in 1..peers {
            for (c, id, k) in &client_objs {
                if *c == viewer {
                    continue;
                }
                let Some(d) = h.session(viewer).display_state(now, *id) else {
                    continue;
                };
                let at = (now.as_secs_f64() - d.delay.as_secs_f64() - t0.as_secs_f64()) as f32;
                let e = f64::from(d.state.pos.distance(client_pose(*c, *k, at))) * 1e3;
                shown.push(((now - t0).as_secs_f32(), *c, *k, d.state.pos));
                errs.push(e);
                if *k == 0 {
                    held_errs.push(e);
                } else {
                    avatar_errs.push(e);
                }
            }
            for (i, id) in scene.iter().enumerate() {
                let Some(d) = h.session(viewer).display_state(now, *id) else {
                    continue;
                };
                let at = (now.as_secs_f64() - d.delay.as_secs_f64() - t0.as_secs_f64()) as f32;
                let e = f64::from(d.state.pos.distance(scene_pose(i, at))) * 1e3;
                errs.push(e);
                scene_errs.push(e);
            }
        }
    }
    let (ts, bs, cs) = up_start.unwrap();
    let secs = (h.now - ts).as_secs_f64();
    let host_up = (host_bytes(&h) - bs) / secs;
    let client_up = (clients_bytes(&h) - cs) / secs / (peers - 1).max(1) as f64;
    errs.sort_by(f64::total_cmp);
    held_errs.sort_by(f64::total_cmp);
    let (lag_ms, now_p95_mm) = fit_lag(&shown);
    Outcome {
        host_up,
        client_up,
        lag_ms,
        now_p95_mm,
        p95_mm: percentile(&errs, 95.0),
        held_p95_mm: percentile(&held_errs, 95.0),
        avatar_p95_mm: percentile(&avatar_errs, 95.0),
        scene_p95_mm: percentile(&scene_errs, 95.0),
    }
}

/// Relay against direct state (issue 18 point 2): rooms of 4, 8 and 16, uncapped.
fn routes(quick: bool) -> Result<(), Box<dyn std::error::Error>> {
    let sizes: &[usize] = if quick { &[4] } else { &[4, 8, 16] };
    let mut csv = Csv::new(&[
        "peers",
        "route",
        "host_up_bytes_per_s",
        "client_up_bytes_per_s",
        "lag_ms",
        "p95_mm",
        "now_p95_mm",
    ]);
    for &n in sizes {
        for (name, route) in [("relay", StateRoute::Relay), ("direct", StateRoute::Direct)] {
            let o = room(n, None, route);
            println!(
                "{}",
                ResultLine::new("crowd.route")
                    .field("peers", n)
                    .field("route", name)
                    .fixed("host_up_bytes_per_s", o.host_up, 0)
                    .fixed("client_up_bytes_per_s", o.client_up, 0)
                    .fixed("lag_ms", o.lag_ms, 0)
                    .fixed("p95_mm", o.p95_mm, 1)
                    .fixed("now_p95_mm", o.now_p95_mm, 1)
            );
            csv.row([
                n.to_string(),
                name.to_owned(),
                format!("{:.0}", o.host_up),
                format!("{:.0}", o.client_up),
                format!("{:.0}", o.lag_ms),
                format!("{:.2}", o.p95_mm),
                format!("{:.2}", o.now_p95_mm),
            ]);
        }
    }
    if !quick {
        let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results/net");
        std::fs::create_dir_all(&out)?;
        csv.write(out.join("route.csv"))?;
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    if std::env::args().any(|a| a == "--route") {
        return routes(quick);
    }
    let sizes: &[usize] = if quick { &[8] } else { &[8, 16] };
    let fractions: &[f64] = if quick {
        &[1.0, 0.5, 0.25]
    } else {
        &[1.0, 0.75, 0.5, 0.35, 0.25, 0.15, 0.1]
    };
    let mut csv = Csv::new(&[
        "peers",
        "cap_bytes_per_s",
        "host_up_bytes_per_s",
        "p95_mm",
        "held_p95_mm",
        "avatar_p95_mm",
        "scene_p95_mm",
    ]);
    let mut curves: Vec<Curve> = Vec::new();
    for &n in sizes {
        let free = room(n, None, StateRoute::Relay);
        let mut all = Vec::new();
        let mut held = Vec::new();
        for &f in fractions {
            let cap = (f < 1.0).then_some((free.host_up * f) as u32);
            let o = if cap.is_some() {
                room(n, cap, StateRoute::Relay)
            } else {
                free.clone()
            };
            let shown_cap = cap.map_or(free.host_up, f64::from);
            println!(
                "{}",
                ResultLine::new("crowd.budget")
                    .field("peers", n)
                    .field(
                        "cap_bytes_per_s",
                        cap.map_or("none".to_owned(), |c| c.to_string())
                    )
                    .fixed("host_up_bytes_per_s", o.host_up, 0)
                    .fixed("p95_mm", o.p95_mm, 1)
                    .fixed("held_p95_mm", o.held_p95_mm, 1)
                    .fixed("avatar_p95_mm", o.avatar_p95_mm, 1)
                    .fixed("scene_p95_mm", o.scene_p95_mm, 1)
            );
            csv.row([
                n.to_string(),
                cap.map_or("none".to_owned(), |c| c.to_string()),
                format!("{:.0}", o.host_up),
                format!("{:.2}", o.p95_mm),
                format!("{:.2}", o.held_p95_mm),
                format!("{:.2}", o.avatar_p95_mm),
                format!("{:.2}", o.scene_p95_mm),
            ]);
            all.push((shown_cap / 1000.0, o.p95_mm));
            held.push((shown_cap / 1000.0, o.held_p95_mm));
        }
        curves.push((n, all, held));
    }
    if quick {
        return Ok(());
    }
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results/net");
    std::fs::create_dir_all(&out)?;
    csv.write(out.join("budget.csv"))?;
    let panels: Vec<LineChart> = curves
        .iter()
        .map(|(n, all, held)| {
            let xmax = all.iter().map(|p| p.0).fold(1.0, f64::max) * 1.1;
            let ymax = all.iter().chain(held).map(|p| p.1).fold(1.0, f64::max) * 1.15;
            LineChart {
                title: format!("{n} peers: the host's uplink capped"),
                x_desc: "host uplink cap (kB/s; rightmost: uncapped)".to_owned(),
                y_desc: "p95 remote error (mm)".to_owned(),
                x_range: 0.0..xmax,
                x_log: false,
                y_range: 0.0..ymax,
                series: vec![
                    Series::new("every object", RED, all.clone()),
                    Series::new("held objects", BLUE, held.clone()),
                ],
                style: ChartStyle::PANEL,
            }
        })
        .collect();
    write_svg(out.join("budget.svg"), (1100, 480), &panels)?;
    Ok(())
}
