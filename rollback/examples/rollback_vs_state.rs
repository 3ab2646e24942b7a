//! Rollback against state sync, side by side, on the same bot motions (issue 15's evidence).
//!
//! `cargo run --release -p softsync-rollback --example rollback_vs_state -- [--quick] [--seconds S]
//! [--out docs/results/rollback]`
//!
//! Each configuration is a room of in-process peers on net's in-memory hub, every link behind
//! the seeded conditioner (one-way latency L with L/10 jitter, 5 % loss), run in real time at
//! 60 Hz (ggrs keeps its own clock): the thesis room, each peer a squeeze-and-throw bot
//! (`script::SqueezeThrow`: reach, grip, squeeze, lift, throw, over the objects in turn).
//! State sync is `softsync_peer::Peer` (owners simulate, a grab of another's object asks for
//! authority); rollback is `RollbackPeer` (everyone simulates from inputs, ggrs). Measured
//! over the run after every peer is in:
//! - `bytes_per_s`: datagram payload bytes sent per peer per second (session, state, ggrs);
//! - `local_response_frames`: frames from a bot's grip to its own hand holding the object in
//!   its own view (median over grips; a grip still not holding after 60 frames counts 60);
//! - `remote_p95_mm`: while a peer holds an object, the distance between where each other
//!   peer shows it and where the holder shows it, same instant (p95 over samples): how wrong
//!   a remote peer's motion appears against its actor's truth;
//! - `rollback_frames_per_s`: frames simulated again per peer per second;
//! - `remote_lag_ms`: how late those views are: the delay of the holder's motion that best
//!   matches them;
//! - `stalled_pct`: ticks a rollback peer could not advance (too far ahead of a silent peer);
//! - `frame_ms_p95`: wall time of one peer's tick (network, simulation, re-simulation, saves).
//!
//! Writes `rooms.csv`, `rooms.svg` (bytes/s and remote error against latency, both modes)
//! and `RESULT rollback.room …` / `RESULT statesync.room …` lines. All peers share this
//! process's one thread: a configuration whose ticks do not fit 16.7 ms falls behind real time
//! (`late_ticks_pct` says how often).
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant as Wall};

use glam::Vec3;
use softsync_benchkit::{percentile, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_net::transport::HubEndpoint;
use softsync_net::{
    ConditionerConfig, Instant, LinkConditioner, MemoryHub, NetId, PeerId, SendPolicy, Session,
    Transport,
};
use softsync_peer::{Peer, PeerConfig, Scene};
use softsync_rollback::room::register;
use softsync_rollback::script::SqueezeThrow;
use softsync_rollback::world::bot_hand;
use softsync_rollback::{PlayerInput, RollbackConfig, RollbackPeer};

const DT: f32 = 1.0 / 60.0;

enum Sim {
    State(Box<Peer>),
    Rollback(Box<RollbackPeer>),
}

struct Node {
    me: PeerId,
    sim: Sim,
    link: LinkConditioner<HubEndpoint>,
    bot: SqueezeThrow,
    bytes: u64,
    tick_ms: Vec<f64>,
    grip_since: Option<u32>,
    last_grip: bool,
    responses: Vec<f64>,
    frame: i32,
}

impl Node {
    /// Scene-order object ids (state sync: the host spawned them in scene order).
    fn ids(p: &Peer) -> Vec<NetId> {
        p.objects()
            .iter()
            .filter(|(_, o)| !o.kind.is_avatar())
            .map(|(id, _)| *id)
            .collect()
    }

    fn ready(&self, n: usize) -> bool {
        match &self.sim {
            Sim::State(p) => p.joined() && Self::ids(p).len() == p.scene().objects.len(),
            Sim::Rollback(p) => p.running() && p.epoch().is_some_and(|e| e.players.len() == n),
        }
    }

    fn center(&mut self, now: Instant, i: usize) -> Option<Vec3> {
        match &mut self.sim {
            Sim::State(p) => {
                let id = *Self::ids(p).get(i)?;
                p.drawn_pose(now, id).map(|x| x.0)
            }
            Sim::Rollback(p) => p.world()?.object_pose(i).map(|x| x.0),
        }
    }

    /// The object this peer's right hand holds, in its own view.
    fn held(&self) -> Option<usize> {
        match &self.sim {
            Sim::State(p) => {
                let (id, _) = p.held(1)?;
                Self::ids(p).iter().position(|x| *x == id)
            }
            Sim::Rollback(p) => {
                let e = p.epoch()?;
                let me = e.players.iter().position(|x| *x == self.me)?;
                p.world()?.held(me, 1)
            }
        }
    }

    fn tick(&mut self, now: Instant, n_objects: usize) {
        let t0 = Wall::now();
        while let Some((from, bytes)) = self.link.recv(now) {
            match &mut self.sim {
                Sim::State(p) => p.handle_datagram(now, from, &bytes),
                Sim::Rollback(p) => p.handle_datagram(now, from, &bytes),
            }
        }
        while let Some(e) = self.link.poll_peer_event() {
            match &mut self.sim {
                Sim::State(p) => p.handle_link_event(e),
                Sim::Rollback(p) => p.handle_link_event(e),
            }
        }
        self.frame += 1;
        let mut centers = Vec::with_capacity(n_objects);
        for i in 0..n_objects {
            centers.push(self.center(now, i));
        }
        let device = match &self.sim {
            Sim::Rollback(p) => p.world().map(|w| {
                let f = w.frame() + 1;
                self.bot.device_at(f, n_objects, &|i| centers[i])
            }),
            Sim::State(_) => Some(self.bot.device_at(self.frame, n_objects, &|i| centers[i])),
        };
        let grip = device.is_some_and(|d| d.grip[1] > 0.5);
        if grip && !self.last_grip {
            self.grip_since = Some(0);
        }
        self.last_grip = grip;
        match &mut self.sim {
            Sim::State(p) => {
                let _ = p.pump(now);
                if p.joined() {
                    if let Some(d) = device {
                        d.apply(p);
                    }
                    p.fixed_step(now);
                }
                while let Some(t) = p.poll_transmit(now) {
                    self.bytes += t.payload.len() as u64;
                    self.link.send(now, &t);
                }
                while p.poll_event().is_some() {}
            }
            Sim::Rollback(p) => {
                if let Some(d) = device {
                    p.set_input(softsync_rollback::PlayerInput::from_device(&d));
                }
                p.tick(now);
                while let Some(t) = p.poll_transmit(now) {
                    self.bytes += t.payload.len() as u64;
                    self.link.send(now, &t);
                }
                while p.poll_event().is_some() {}
            }
        }
        if let Some(k) = self.grip_since {
            if self.held().is_some() || k >= 60 {
                self.responses.push(f64::from(k));
                self.grip_since = None;
            } else {
                self.grip_since = Some(k + 1);
            }
        }
        self.tick_ms.push(t0.elapsed().as_secs_f64() * 1e3);
    }
}

#[derive(Clone, Copy, Debug)]
struct Config {
    rollback: bool,
    peers: usize,
    lat_ms: u64,
}

struct Outcome {
    cfg: Config,
    bytes_per_s: f64,
    response_frames: f64,
    remote_p95_mm: f64,
    remote_p50_mm: f64,
    rollback_frames_per_s: f64,
    frame_ms_p95: f64,
    late_pct: f64,
    stalled_pct: f64,
    lag_ms: f64,
    desyncs: u64,
    samples: usize,
    grips: usize,
}

/// The sum of a counter over the rollback peers (0 in a state-sync room).
fn rollback_sum(nodes: &[Node], f: impl Fn(&softsync_rollback::RollbackStats) -> u64) -> u64 {
    nodes
        .iter()
        .map(|n| match &n.sim {
            Sim::Rollback(p) => f(p.stats()),
            Sim::State(_) => 0,
        })
        .sum()
}

/// Per (holder, viewer, object): (tick, where the viewer shows it, where the holder does).
type Held = std::collections::BTreeMap<(usize, usize, usize), Vec<(usize, Vec3, Vec3)>>;

/// How late remote views are: the shift (whole frames, 0–30) of the holders' truth that best
/// matches what the others show (least mean distance over every held stretch), in ms.
fn lag_ms(series: &Held) -> f64 {
    let mut best = (f64::INFINITY, 0usize);
    for shift in 0..=30usize {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for s in series.values() {
            let truth: std::collections::BTreeMap<usize, Vec3> =
                s.iter().map(|(t, _, tr)| (*t, *tr)).collect();
            for (t, seen, _) in s {
                if let Some(tr) = t.checked_sub(shift).and_then(|t0| truth.get(&t0)) {
                    sum += f64::from(seen.distance(*tr));
                    n += 1;
                }
            }
        }
        if n > 0 && sum / (n as f64) < best.0 {
            best = (sum / n as f64, shift);
        }
    }
    best.1 as f64 * 1000.0 / 60.0
}

fn scene() -> Scene {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    Scene::by_name("thesis-room", &assets).unwrap()
}

fn build(cfg: Config, hub: &MemoryHub, now: Instant) -> Vec<Node> {
    let policy = SendPolicy::default();
    let mut nodes = Vec::new();
    let host = PeerId(1);
    for k in 0..cfg.peers {
        let me = PeerId(1 + k as u64);
        let sc = scene();
        let mut scfg = sc.session_config(policy.clone(), policy.clone(), policy.clone());
        let sim = if cfg.rollback {
            let mut types = softsync_net::messages::MessageTypes::from_config(&scfg).unwrap();
            register(&mut types);
            types.configure(&mut scfg);
            let (session, contact) = if k == 0 {
                (Session::host(me, scfg, now), None)
            } else {
                (Session::join(me, host, scfg, now), Some(host))
            };
            let mut p =
                RollbackPeer::new(now, sc, RollbackConfig::default(), session, contact).unwrap();
            if k == 0 {
                p.open(now).unwrap();
            }
            Sim::Rollback(Box::new(p))
        } else {
            let (session, contact) = if k == 0 {
                (Session::host(me, scfg, now), None)
            } else {
                (Session::join(me, host, scfg, now), Some(host))
            };
            let pc = PeerConfig {
                hand: bot_hand(),
                dt_s: DT,
                ..PeerConfig::default()
            };
            let mut p = Peer::new(now, session, contact, sc, pc).unwrap();
            if k == 0 {
                p.open(now).unwrap();
            }
            Sim::State(Box::new(p))
        };
        let net = ConditionerConfig {
            seed: 17 + k as u64,
            latency: Duration::from_millis(cfg.lat_ms),
            jitter: Duration::from_millis(cfg.lat_ms / 10),
            loss: 0.05,
            ..ConditionerConfig::default()
        };
        nodes.push(Node {
            me,
            sim,
            link: LinkConditioner::new(hub.endpoint(me), net),
            bot: SqueezeThrow::new(me, 2 * k + 1),
            bytes: 0,
            tick_ms: Vec::new(),
            grip_since: None,
            last_grip: false,
            responses: Vec::new(),
            frame: 0,
        });
    }
    nodes
}

fn run(cfg: Config, seconds: f64) -> Outcome {
    let hub = MemoryHub::new(1400);
    let start = Wall::now();
    let clock = |s: Wall| Instant::from_micros(s.elapsed().as_micros() as u64);
    let mut nodes = build(cfg, &hub, clock(start));
    let n_objects = scene().objects.len();
    let step = Duration::from_micros(16_667);
    let mut next = Wall::now();
    let pace = |next: &mut Wall| -> bool {
        *next += step;
        let now = Wall::now();
        if *next > now {
            std::thread::sleep(*next - now);
            false
        } else {
            if now - *next > Duration::from_millis(250) {
                *next = now;
            }
            true
        }
    };
    // In: every peer joined (state) or in one epoch with everyone (rollback); then 1 s more.
    let warm_until = Wall::now() + Duration::from_secs(30);
    let mut ready_at = None;
    while Wall::now() < warm_until {
        let now = clock(start);
        for n in nodes.iter_mut() {
            n.tick(now, n_objects);
        }
        if ready_at.is_none() && nodes.iter().all(|n| n.ready(cfg.peers)) {
            ready_at = Some(Wall::now());
        }
        if ready_at.is_some_and(|t| t.elapsed() > Duration::from_secs(1)) {
            break;
        }
        pace(&mut next);
    }
    assert!(ready_at.is_some(), "{cfg:?}: the room never formed");
    for n in nodes.iter_mut() {
        n.bytes = 0;
        n.tick_ms.clear();
        n.responses.clear();
    }
    let resim0 = rollback_sum(&nodes, |s| s.resimulated);
    let t0 = Wall::now();
    let ticks = (seconds * 60.0) as usize;
    let mut late = 0usize;
    let mut errors = Vec::new();
    // (tick, holder, viewer, object) → (seen, holder's truth), for the lag estimate.
    let mut series: Held = Default::default();
    let stalled0 = rollback_sum(&nodes, |s| s.stalled_ticks);
    for tick in 0..ticks {
        let now = clock(start);
        for n in nodes.iter_mut() {
            n.tick(now, n_objects);
        }
        // Each holder's object, where every other peer shows it against where it does.
        for a in 0..nodes.len() {
            let Some(k) = nodes[a].held() else { continue };
            let Some(truth) = nodes[a].center(now, k) else {
                continue;
            };
            for (v, node) in nodes.iter_mut().enumerate() {
                if v != a {
                    if let Some(seen) = node.center(now, k) {
                        errors.push(f64::from(seen.distance(truth)) * 1000.0);
                        series
                            .entry((a, v, k))
                            .or_default()
                            .push((tick, seen, truth));
                    }
                }
            }
        }
        if pace(&mut next) {
            late += 1;
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    let stalled = rollback_sum(&nodes, |s| s.stalled_ticks) - stalled0;
    let peers = nodes.len() as f64;
    let bytes = nodes.iter().map(|n| n.bytes).sum::<u64>() as f64;
    let resim = rollback_sum(&nodes, |s| s.resimulated) - resim0;
    let desyncs = rollback_sum(&nodes, |s| s.desyncs);
    let ms: Vec<f64> = nodes
        .iter()
        .flat_map(|n| n.tick_ms.iter().copied())
        .collect();
    let responses: Vec<f64> = nodes
        .iter()
        .flat_map(|n| n.responses.iter().copied())
        .collect();
    Outcome {
        cfg,
        bytes_per_s: bytes / peers / secs,
        response_frames: percentile(&responses, 0.5),
        remote_p95_mm: percentile(&errors, 0.95),
        remote_p50_mm: percentile(&errors, 0.5),
        rollback_frames_per_s: resim as f64 / peers / secs,
        frame_ms_p95: percentile(&ms, 0.95),
        late_pct: 100.0 * late as f64 / ticks.max(1) as f64,
        stalled_pct: 100.0 * stalled as f64 / (ticks * nodes.len()).max(1) as f64,
        lag_ms: lag_ms(&series),
        desyncs,
        samples: errors.len(),
        grips: responses.len(),
    }
}

/// Scalpel strokes (player 0's right hand, trigger held) through the thesis room's soft box
/// and bunny, then 1 s for the slits to open: a torn room for [`step_cost`].
fn tear_the_room(w: &mut softsync_rollback::RollbackWorld) {
    use glam::Quat;
    let input = |pos: Vec3, trigger: bool| {
        let d = softsync_peer::DeviceFrame {
            head: Some((Vec3::new(0.0, 1.5, 0.6), Quat::IDENTITY)),
            hands: [None, Some((pos, Quat::IDENTITY))],
            grip: [0.0; 2],
            trigger: [0.0, if trigger { 1.0 } else { 0.0 }],
            tool: Default::default(),
            talk: false,
        };
        [PlayerInput::from_device(&d), PlayerInput::default()]
    };
    let away = Vec3::new(0.0, 1.1, 0.3);
    for _ in 0..60 {
        w.step(&input(away, false));
    }
    // the soft box at x 0.32 and the bunny at x −0.32, each crossed at its upper part
    for (x0, y) in [(0.25f32, 0.83f32), (-0.42, 0.86)] {
        for f in 0..=40 {
            w.step(&input(
                Vec3::new(x0 + 0.18 * f as f32 / 40.0, y, 0.05),
                true,
            ));
        }
        for _ in 0..10 {
            w.step(&input(away, false));
        }
    }
    for _ in 0..60 {
        w.step(&input(away, false));
    }
}

/// What one frame of a scene costs a rollback peer: the median step of the world with two
/// players' hands, and its save and load; how many frames fit a 60 Hz frame's budget. With
/// `torn`, the room's soft box and bunny are torn first ([`tear_the_room`]): save and load
/// then carry the torn meshes.
fn step_cost(name: &str, torn: bool) -> (usize, f64, f64, f64) {
    use softsync_rollback::RollbackWorld;
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let sc = Scene::by_name(name, &assets).unwrap();
    let players = [PeerId(1), PeerId(2)];
    let mut w = RollbackWorld::new(&sc, DT, &players).unwrap();
    if torn {
        tear_the_room(&mut w);
        let tears = w.topology_log().len();
        assert!(tears > 10, "the strokes tore nothing ({tears} log entries)");
    }
    let particles: usize = w.soft_bodies().iter().map(|(_, b)| b.num_particles()).sum();
    let mut bots = [
        SqueezeThrow::new(players[0], 1),
        SqueezeThrow::new(players[1], 3),
    ];
    let (mut step, mut save, mut load) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..600 {
        let i = [bots[0].input(&w), bots[1].input(&w)];
        let t = Wall::now();
        let s = w.save();
        save.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Wall::now();
        w.load(&s);
        load.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Wall::now();
        w.step(&i);
        step.push(t.elapsed().as_secs_f64() * 1e3);
    }
    (
        particles,
        percentile(&step, 0.5),
        percentile(&save, 0.5),
        percentile(&load, 0.5),
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let seconds: f64 = arg("--seconds")
        .and_then(|s| s.parse().ok())
        .unwrap_or(if quick { 8.0 } else { 16.0 });
    let out = PathBuf::from(arg("--out").unwrap_or_else(|| "docs/results/rollback".into()));
    std::fs::create_dir_all(&out).unwrap();
    let mut steps = Csv::new(&[
        "scene",
        "particles",
        "step_ms",
        "save_ms",
        "load_ms",
        "frames_per_16ms",
    ]);
    for (name, torn) in [
        ("bench-ball", false),
        ("thesis-room", false),
        ("thesis-room-torn", true),
    ] {
        let (particles, step, save, load) = step_cost(name.trim_end_matches("-torn"), torn);
        // a re-simulated frame costs a load (once), a step and a save
        let fit = (16.7 / (step + save)).floor();
        println!(
            "{}",
            ResultLine::new("rollback.step")
                .field("scene", name)
                .field("particles", particles)
                .fixed("step_ms", step, 3)
                .fixed("save_ms", save, 3)
                .fixed("load_ms", load, 3)
                .fixed("frames_per_16ms", fit, 0)
        );
        steps.row([
            name.to_string(),
            particles.to_string(),
            format!("{step:.3}"),
            format!("{save:.3}"),
            format!("{load:.3}"),
            format!("{fit:.0}"),
        ]);
    }
    steps.write(out.join("step.csv")).unwrap();
    let sizes: &[usize] = if quick { &[2] } else { &[2, 4] };
    let lats = [0u64, 50, 150];
    let mut csv = Csv::new(&[
        "mode",
        "peers",
        "lat_ms",
        "loss_pct",
        "bytes_per_s",
        "local_response_frames",
        "remote_p50_mm",
        "remote_p95_mm",
        "remote_lag_ms",
        "rollback_frames_per_s",
        "frame_ms_p95",
        "stalled_pct",
        "late_ticks_pct",
        "desyncs",
        "error_samples",
        "grips",
    ]);
    let mut outcomes = Vec::new();
    for &peers in sizes {
        for &lat_ms in &lats {
            for rollback in [false, true] {
                let o = run(
                    Config {
                        rollback,
                        peers,
                        lat_ms,
                    },
                    seconds,
                );
                let name = if rollback {
                    "rollback.room"
                } else {
                    "statesync.room"
                };
                let line = ResultLine::new(name)
                    .field("peers", peers)
                    .field("lat_ms", lat_ms)
                    .field("loss_pct", 5)
                    .fixed("bytes_per_s", o.bytes_per_s, 0)
                    .fixed("local_response_frames", o.response_frames, 1)
                    .fixed("remote_p95_mm", o.remote_p95_mm, 1)
                    .fixed("remote_lag_ms", o.lag_ms, 0)
                    .fixed("rollback_frames_per_s", o.rollback_frames_per_s, 1)
                    .fixed("frame_ms_p95", o.frame_ms_p95, 2)
                    .fixed("stalled_pct", o.stalled_pct, 1)
                    .fixed("late_ticks_pct", o.late_pct, 1)
                    .field("desyncs", o.desyncs);
                println!("{line}");
                csv.row([
                    if rollback { "rollback" } else { "state" }.to_string(),
                    peers.to_string(),
                    lat_ms.to_string(),
                    "5".into(),
                    format!("{:.0}", o.bytes_per_s),
                    format!("{:.1}", o.response_frames),
                    format!("{:.1}", o.remote_p50_mm),
                    format!("{:.1}", o.remote_p95_mm),
                    format!("{:.0}", o.lag_ms),
                    format!("{:.1}", o.rollback_frames_per_s),
                    format!("{:.2}", o.frame_ms_p95),
                    format!("{:.1}", o.stalled_pct),
                    format!("{:.1}", o.late_pct),
                    o.desyncs.to_string(),
                    o.samples.to_string(),
                    o.grips.to_string(),
                ]);
                outcomes.push(o);
            }
        }
    }
    csv.write(out.join("rooms.csv")).unwrap();
    let mut md = String::from(
        "# Rollback against state sync (generated by `cargo run --release -p softsync-rollback \
         --example rollback_vs_state`)\n\nThe thesis room, squeeze-and-throw bots, in-process peers on the \
         seeded conditioner (one-way latency, 5 % loss), real time at 60 Hz, all peers on one \
         thread of this machine. Payload bytes; response in frames of 16.7 ms; remote error \
         against the holder's own view while it holds.\n\n\
         | mode | peers | latency ms | bytes/s per peer | own grab, frames | remote p95 mm | \
         remote lag ms | re-simulated frames/s | frame ms p95 | late ticks % | desyncs |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for o in &outcomes {
        md.push_str(&format!(
            "| {} | {} | {} | {:.0} | {:.1} | {:.1} | {:.0} | {:.1} | {:.2} | {:.1} | {} |\n",
            if o.cfg.rollback { "rollback" } else { "state" },
            o.cfg.peers,
            o.cfg.lat_ms,
            o.bytes_per_s,
            o.response_frames,
            o.remote_p95_mm,
            o.lag_ms,
            o.rollback_frames_per_s,
            o.frame_ms_p95,
            o.late_pct,
            o.desyncs
        ));
    }
    md.push_str(
        "\nStep cost of the deterministic world (two players' hands; median of 600 frames):\n\n",
    );
    md.push_str("```\n");
    md.push_str(steps.text());
    md.push_str("```\n");
    std::fs::write(out.join("rooms.md"), md).unwrap();
    let colors = [
        plotters_color(31, 119, 180),
        plotters_color(255, 127, 14),
        plotters_color(44, 160, 44),
        plotters_color(214, 39, 40),
    ];
    let series = |metric: &dyn Fn(&Outcome) -> f64| {
        let mut s = Vec::new();
        let mut c = 0;
        for &peers in sizes {
            for rollback in [false, true] {
                let pts: Vec<(f64, f64)> = outcomes
                    .iter()
                    .filter(|o| o.cfg.peers == peers && o.cfg.rollback == rollback)
                    .map(|o| (o.cfg.lat_ms as f64, metric(o)))
                    .collect();
                let label = format!(
                    "{} {peers} peers",
                    if rollback { "rollback" } else { "state sync" }
                );
                s.push(Series::new(label, colors[c % colors.len()], pts));
                c += 1;
            }
        }
        s
    };
    let max = |m: &dyn Fn(&Outcome) -> f64| outcomes.iter().map(m).fold(1.0, f64::max) * 1.15;
    let bytes = |o: &Outcome| o.bytes_per_s;
    let err = |o: &Outcome| o.remote_p95_mm;
    // one panel per metric, against latency, every mode and size a line
    let panel = |title: &str, y_desc: &str, metric: &dyn Fn(&Outcome) -> f64| LineChart {
        title: title.into(),
        x_desc: "one-way latency, ms (5 % loss)".into(),
        y_desc: y_desc.into(),
        x_range: 0.0..160.0,
        x_log: false,
        y_range: 0.0..max(metric),
        series: series(metric),
        style: ChartStyle::PANEL,
    };
    let charts = [
        panel("bytes/s per peer", "payload bytes/s", &bytes),
        panel("remote error against the holder's view, p95", "mm", &err),
    ];
    write_svg(out.join("rooms.svg"), (1100, 420), &charts).unwrap();
    println!("wrote {}/rooms.csv and rooms.svg", out.display());
}

fn plotters_color(r: u8, g: u8, b: u8) -> softsync_benchkit::plotters::style::RGBColor {
    softsync_benchkit::plotters::style::RGBColor(r, g, b)
}
