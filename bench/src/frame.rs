//! The frame-budget room (issue 34): everything at once, and what each frame costs.
//!
//! Four [`Peer`]s — the library the `softsync` binary runs — share one process on net's
//! in-memory hub behind the seeded link conditioner (20 ms, 5 ms jitter, 1 % loss), on virtual
//! time, in the `frame-budget` scene (the thesis room with 8 more soft bodies: 11 in all):
//! - peers A and B hold the thesis's soft ball together, one particle each, and pull it apart
//!   and back once a second (co-manipulation: the host simulates it, their hands are remote);
//! - peer C tears a soft body every 2 s (a stroke of 8 segments, one per frame) and cuts one
//!   through its centre every 10 s — bodies others own, so the owner applies them;
//! - the host stops (a SIGKILL, as far as the others can tell) half-way, at 30 s of a 60 s
//!   run, and the room migrates.
//!
//! Each live peer's frame — its datagrams in, [`Peer::pump`], [`Peer::fixed_step`], its
//! datagrams out — is timed on the wall clock, phase by phase ([`Peer::set_stopwatch`]).
//! Virtual time is paced to the wall clock ([`FramePlan::real_time`]): work a peer does off
//! the frame, on worker threads, has the time it would have in an app.
//! Rendering is not in it: nothing here draws. One process steps the four peers one after
//! another, so each frame is measured alone, as one core would run it.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_benchkit::plotters::style::RGBColor;
use softsync_benchkit::{percentile, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_interaction::{HandConfig, HandInput, HandSample};
use softsync_net::transport::HubEndpoint;
use softsync_net::{
    ConditionerConfig, Instant, LinkConditioner, MemoryHub, NetId, PeerId, SendPolicy, Session,
    Transport,
};
use softsync_peer::{Event, Peer, PeerConfig, Phase, Scene};
use softsync_store::keeper::{open_store, Keeper, StoreOptions};

/// The room's fixed step: 90 Hz, a VR headset's frame.
pub const DT_S: f32 = 1.0 / 90.0;
const HOST: PeerId = PeerId(100);
const A: PeerId = PeerId(101);
const B: PeerId = PeerId(102);
const C: PeerId = PeerId(103);
/// Seconds before measuring: joins, the bodies settle on the table, the hands take hold.
const WARMUP_S: f64 = 3.0;

/// What to run.
#[derive(Clone, Debug)]
pub struct FramePlan {
    /// Measured seconds (virtual), after the warm-up.
    pub seconds: f64,
    /// Seconds into the measurement at which the host stops (`None`: it never does).
    pub kill_host_at_s: Option<f64>,
    /// A tear stroke every this many seconds.
    pub tear_every_s: f64,
    /// A cut every this many seconds (the first at half of it).
    pub cut_every_s: f64,
    /// The link conditioner's seed.
    pub seed: u64,
    /// The shipped scenes (`assets/`).
    pub assets: PathBuf,
    /// Keep virtual time no faster than the wall clock (a frame every 11.1 ms at the
    /// earliest): what runs off the frame (a cut's pieces built on worker threads, landing
    /// 30 ms later) gets the wall-clock time it would have in an app. Without it the frames
    /// come faster than real time and a landing waits for its worker.
    pub real_time: bool,
    /// Keep the room in this store while it runs (`softsync_store::keeper`: the host writes,
    /// and its heir after the migration); `None`: not kept.
    pub store: Option<String>,
    /// With `store`: record the session too (`--record`).
    pub record: bool,
}

impl FramePlan {
    /// The run: 60 s, the host stopped at 30 s, a tear every 2 s, a cut every 10 s.
    pub fn full(assets: &Path) -> Self {
        FramePlan {
            seconds: 60.0,
            kill_host_at_s: Some(30.0),
            tear_every_s: 2.0,
            cut_every_s: 10.0,
            seed: 7,
            assets: assets.to_owned(),
            real_time: true,
            store: None,
            record: false,
        }
    }

    /// A short run with every kind of event in it (CI's smoke run): 8 s, the host stopped at
    /// 4 s, a tear every second, a cut every 3 s.
    pub fn quick(assets: &Path) -> Self {
        FramePlan {
            seconds: 8.0,
            kill_host_at_s: Some(4.0),
            tear_every_s: 1.0,
            cut_every_s: 3.0,
            ..Self::full(assets)
        }
    }
}

/// One peer's frame.
#[derive(Clone, Debug)]
pub struct FrameSample {
    /// Seconds into the measurement (virtual).
    pub t_s: f64,
    /// Whose frame.
    pub peer: PeerId,
    /// The whole frame, wall-clock seconds.
    pub total_s: f64,
    /// Datagrams in (decoding, the session's handling, snapshots for joiners).
    pub datagrams_s: f64,
    /// The peer's own phases ([`Phase::ALL`] order).
    pub phases_s: [f64; 10],
    /// Datagrams out.
    pub transmit_s: f64,
    /// The peer hosted the room in this frame.
    pub hosting: bool,
    /// The store's share of the frame (the keeper's look at the room and its hand-over).
    pub store_s: f64,
    /// What this frame did that may cost: `topology` (a cut or tear applied), `host` (the
    /// host changed), `cut`/`tear` (asked this frame), joined by `+`.
    pub note: String,
}

impl FrameSample {
    /// The phase (or `datagrams`/`transmit`) that took longest in this frame.
    pub fn worst_phase(&self) -> &'static str {
        let mut best = ("datagrams", self.datagrams_s);
        for p in Phase::ALL {
            let s = self.phases_s[p as usize];
            if s > best.1 {
                best = (p.name(), s);
            }
        }
        if self.transmit_s > best.1 {
            best = ("transmit", self.transmit_s);
        }
        best.0
    }
}

/// What a run did and measured.
#[derive(Clone, Debug, Default)]
pub struct FrameReport {
    /// Every live peer's every measured frame.
    pub samples: Vec<FrameSample>,
    /// Tear segments asked (by C) and refused at once.
    pub tears_asked: u64,
    /// Tears or cuts C could not ask (the body was gone, a segment out of range).
    pub blades_refused: u64,
    /// Cuts asked (by C).
    pub cuts_asked: u64,
    /// Topology entries (cuts, tears, lifts) peer C applied to its mirror.
    pub topology_seen: u64,
    /// Host changes the survivors saw (each counts its own).
    pub host_changes: u64,
    /// Most hands holding the co-held ball at once (as its simulating peer saw them).
    pub most_holders: usize,
    /// Soft bodies in the room at the end (as C sees it).
    pub soft_bodies_at_end: usize,
    /// Warnings the peers said.
    pub warnings: Vec<String>,
    /// What each store writer wrote (the host's, its heir's), when the room was kept.
    pub store_written: Vec<softsync_store::WriterStatus>,
}

use crate::wall_s;

struct Node {
    peer: Peer,
    link: LinkConditioner<HubEndpoint>,
    alive: bool,
    keeper: Option<Keeper>,
}

impl Node {
    fn new(
        hub: &MemoryHub,
        me: PeerId,
        seed: u64,
        scene: Scene,
        store: Option<&str>,
        record: bool,
    ) -> Result<Self, String> {
        let policy = SendPolicy::default();
        let cfg = scene.session_config(policy.clone(), policy.clone(), policy);
        let (session, contact) = if me == HOST {
            (Session::host(me, cfg, Instant::ZERO), None)
        } else {
            (Session::join(me, HOST, cfg, Instant::ZERO), Some(HOST))
        };
        let config = PeerConfig {
            dt_s: DT_S,
            // as the app: paced to the wall clock, builds land once their worker is done
            land_when_ready: true,
            // hands that reach exactly, as the app gives bots
            hand: HandConfig {
                physical_controller: false,
                hover_radius_m: 0.015,
                ..HandConfig::default()
            },
            ..PeerConfig::default()
        };
        let keeper = match (store, me == HOST) {
            (Some(target), true) => {
                let opts = StoreOptions {
                    reset: true,
                    record,
                    ..StoreOptions::new(target)
                };
                let (writer, _) = open_store(&opts, &scene, session.config())?;
                Some(Keeper::hosting(opts, writer))
            }
            (Some(target), false) => Some(Keeper::joining(StoreOptions {
                record,
                ..StoreOptions::new(target)
            })),
            (None, _) => None,
        };
        let mut peer =
            Peer::new(Instant::ZERO, session, contact, scene, config).map_err(|e| e.to_string())?;
        if me == HOST {
            peer.open(Instant::ZERO).map_err(|e| e.to_string())?;
        }
        peer.set_stopwatch(Some(wall_s));
        let link = ConditionerConfig {
            seed,
            latency: Duration::from_millis(20),
            jitter: Duration::from_millis(5),
            loss: 0.01,
            ..ConditionerConfig::default()
        };
        Ok(Node {
            peer,
            link: LinkConditioner::new(hub.endpoint(me), link),
            alive: true,
            keeper,
        })
    }

    /// One frame; its sample (without `t_s` and the bench's own notes).
    fn frame(
        &mut self,
        now: Instant,
        hand: Option<HandInput>,
        warnings: &mut Vec<String>,
    ) -> Result<FrameSample, String> {
        let start = wall_s();
        while let Some((from, bytes)) = self.link.recv(now) {
            self.peer.handle_datagram(now, from, &bytes);
        }
        while let Some(e) = self.link.poll_peer_event() {
            self.peer.handle_link_event(e);
        }
        let datagrams_s = wall_s() - start;
        self.peer.pump(now).map_err(|e| e.to_string())?;
        if self.peer.joined() {
            if let Some(h) = hand {
                self.peer.set_hand_input(1, h);
            }
            self.peer.fixed_step(now);
        }
        let kept = wall_s();
        let mut said = Vec::new();
        if let Some(k) = &mut self.keeper {
            k.tick(now, &mut self.peer, &mut said);
        }
        for e in said {
            if let Event::Warning(w) = e {
                warnings.push(format!("{:?}: {w}", self.peer.me()));
            }
        }
        let out = wall_s();
        while let Some(t) = self.peer.poll_transmit(now) {
            self.link.send(now, &t);
        }
        let end = wall_s();
        let mut notes = Vec::new();
        while let Some(e) = self.peer.poll_event() {
            match e {
                Event::Warning(w) => warnings.push(format!("{:?}: {w}", self.peer.me())),
                Event::Room(softsync_net::Event::Topology { .. }) => notes.push("topology"),
                Event::Room(softsync_net::Event::HostChanged { .. }) => notes.push("host"),
                _ => {}
            }
        }
        notes.dedup();
        Ok(FrameSample {
            t_s: 0.0,
            peer: self.peer.me(),
            total_s: end - start,
            datagrams_s,
            phases_s: self.peer.take_frame_cost().seconds,
            transmit_s: end - out,
            hosting: self.peer.session().is_host(),
            store_s: out - kept,
            note: notes.join("+"),
        })
    }

    fn soft_ids(&self, except: NetId) -> Vec<NetId> {
        self.peer
            .objects()
            .iter()
            .filter(|(id, o)| **id != except && matches!(o.body, softsync_peer::LocalBody::Soft(_)))
            .map(|(id, _)| *id)
            .collect()
    }
}

fn hand(now: Instant, at: Vec3, grip: f32) -> HandInput {
    HandInput {
        sample: HandSample {
            position_m: at,
            rotation: Quat::IDENTITY,
            time_s: now.as_secs_f64(),
        },
        grip,
        trigger: 0.0,
    }
}

/// A hand on the co-held ball: the particle it holds, where it took it, which way it pulls.
struct Holder {
    start: Vec3,
    out: Vec3,
}

/// Runs the room. An error if a peer stops (it must not).
pub fn run(plan: &FramePlan) -> Result<FrameReport, String> {
    let scene = Scene::by_name("frame-budget", &plan.assets)?;
    let hub = MemoryHub::new(1200);
    let mut nodes = Vec::new();
    for (i, me) in [HOST, A, B, C].into_iter().enumerate() {
        nodes.push(Node::new(
            &hub,
            me,
            plan.seed + i as u64,
            scene.clone(),
            plan.store.as_deref(),
            plan.record,
        )?);
    }
    let mut report = FrameReport::default();
    let mut now = Instant::ZERO;
    let dt = Duration::from_secs_f32(DT_S);
    let end_s = WARMUP_S + plan.seconds;
    let mut t = 0.0f64;
    let ball_kind = scene.kind("softball");
    let mut ball: Option<NetId> = None;
    let mut holders: [Option<Holder>; 2] = [None, None];
    let (mut next_tear, mut next_cut) = (WARMUP_S, WARMUP_S + plan.cut_every_s / 2.0);
    let (mut tears, mut cuts) = (0usize, 0usize);
    // the tear stroke under way: body, segment index
    let mut stroke: Option<(NetId, usize)> = None;
    let wall_start = wall_s();
    while t < end_s {
        if plan.real_time {
            let ahead = t - (wall_s() - wall_start);
            if ahead > 0.0 {
                #[allow(clippy::disallowed_methods)] // the bench paces itself on the wall clock
                std::thread::sleep(Duration::from_secs_f64(ahead));
            }
        }
        now += dt;
        t += f64::from(DT_S);
        let measuring = t >= WARMUP_S;
        let since = t - WARMUP_S;
        if measuring && plan.kill_host_at_s.is_some_and(|k| since >= k) && nodes[0].alive {
            nodes[0].alive = false; // stopped: the others hear nothing more from it
                                    // its store goes with its process (the file's lock too)
            if let Some(st) = nodes[0].keeper.take().and_then(|k| k.status()) {
                report.store_written.push(st);
            }
        }
        // The ball (the first soft ball spawned) and the holders' grip, once C sees the room.
        if ball.is_none() && t > 1.0 {
            ball = nodes[3]
                .peer
                .objects()
                .iter()
                .find(|(_, o)| Some(o.kind) == ball_kind)
                .map(|(id, _)| *id);
        }
        let mut notes: [Vec<&str>; 4] = Default::default();
        // Peer C's blades.
        if measuring && nodes[3].alive {
            let c = &mut nodes[3];
            let except = ball.unwrap_or(NetId(u32::MAX));
            if stroke.is_none() && t >= next_tear {
                next_tear += plan.tear_every_s;
                let ids = c.soft_ids(except);
                if !ids.is_empty() {
                    stroke = Some((ids[tears % ids.len()], 0));
                    tears += 1;
                }
            }
            if let Some((id, k)) = stroke {
                match c.peer.shown_state(now, id) {
                    Some(s) if k < 8 => {
                        let x = |k: usize| -0.04 + 0.01 * k as f32;
                        let from = s.pos + s.rot * Vec3::new(x(k), 0.0, 0.0);
                        let to = s.pos + s.rot * Vec3::new(x(k + 1), 0.0, 0.0);
                        report.tears_asked += 1;
                        notes[3].push("tear");
                        if c.peer
                            .tear(now, id, from, to, s.rot * Vec3::Y * 0.08)
                            .is_err()
                        {
                            report.blades_refused += 1;
                        }
                        stroke = Some((id, k + 1));
                    }
                    Some(_) => {
                        let _ = c.peer.lift(now, id);
                        stroke = None;
                    }
                    None => stroke = None,
                }
            }
            if t >= next_cut {
                next_cut += plan.cut_every_s;
                let ids = c.soft_ids(except);
                if !ids.is_empty() {
                    let id = ids[(cuts * 3 + 1) % ids.len()];
                    cuts += 1;
                    if let Some(s) = c.peer.shown_state(now, id) {
                        report.cuts_asked += 1;
                        notes[3].push("cut");
                        if c.peer.cut(now, id, s.pos, s.rot * Vec3::X).is_err() {
                            report.blades_refused += 1;
                        }
                    }
                }
            }
        }
        for (i, node) in nodes.iter_mut().enumerate() {
            if !node.alive {
                continue;
            }
            // A and B: their right hands on the ball's leftmost and rightmost particles,
            // pulling 2 cm outward and back once a second.
            let input = match (i, ball) {
                (1 | 2, Some(id)) if t > 2.0 => {
                    let k = i - 1;
                    if holders[k].is_none() {
                        if let Some(s) = node.peer.shown_state(now, id) {
                            let pick = s.particles.iter().copied().max_by(|a, b| {
                                let side = if k == 0 { -1.0 } else { 1.0 };
                                (a.x * side).total_cmp(&(b.x * side))
                            });
                            if let Some(p) = pick {
                                let side = if k == 0 { -Vec3::X } else { Vec3::X };
                                holders[k] = Some(Holder {
                                    start: p,
                                    out: side * 0.02,
                                });
                            }
                        }
                    }
                    holders[k].as_ref().map(|h| {
                        let phase = ((t - 2.5).max(0.0) * std::f64::consts::TAU).sin();
                        let at = h.start + h.out * (0.5 - 0.5 * phase.cos() as f32);
                        let grip = if t > 2.2 { 1.0 } else { 0.0 };
                        hand(now, at, grip)
                    })
                }
                _ => None,
            };
            let mut sample = node.frame(now, input, &mut report.warnings)?;
            if measuring {
                sample.t_s = since;
                let mut all: Vec<&str> = notes[i].clone();
                if !sample.note.is_empty() {
                    all.push(&sample.note);
                }
                sample.note = all.join("+");
                report.samples.push(sample);
            }
        }
        if let Some(id) = ball {
            for n in nodes.iter().filter(|n| n.alive) {
                report.most_holders = report.most_holders.max(n.peer.holders(id).len());
            }
        }
    }
    report.topology_seen = nodes[3].peer.counters().topology_events;
    report.host_changes = nodes
        .iter()
        .filter(|n| n.alive)
        .map(|n| n.peer.counters().host_changes)
        .sum();
    report.soft_bodies_at_end = nodes[3].soft_ids(NetId(u32::MAX)).len();
    for n in &mut nodes {
        let now_end = now;
        if let Some(st) = n.keeper.as_mut().and_then(|k| k.finish(now_end, &n.peer)) {
            report.store_written.push(st);
        }
    }
    Ok(report)
}

/// Milliseconds.
fn ms(s: f64) -> f64 {
    s * 1e3
}

impl FrameReport {
    /// Frame totals in milliseconds.
    pub fn totals_ms(&self) -> Vec<f64> {
        self.samples.iter().map(|s| ms(s.total_s)).collect()
    }

    /// The sample of the costliest frame.
    pub fn worst(&self) -> Option<&FrameSample> {
        self.samples
            .iter()
            .max_by(|a, b| a.total_s.total_cmp(&b.total_s))
    }

    /// `RESULT frame.budget …`.
    pub fn result_line(&self) -> ResultLine {
        let v = self.totals_ms();
        let worst = self.worst();
        ResultLine::new("frame.budget")
            .fixed("p50_ms", percentile(&v, 0.5), 3)
            .fixed("p99_ms", percentile(&v, 0.99), 3)
            .fixed("p999_ms", percentile(&v, 0.999), 3)
            .fixed("max_ms", worst.map_or(f64::NAN, |w| ms(w.total_s)), 3)
            .field(
                "worst_phase",
                worst.map_or("none", FrameSample::worst_phase),
            )
            .field("frames", v.len())
            .field("tears", self.tears_asked)
            .field("cuts", self.cuts_asked)
            .field("host_changes", self.host_changes)
            .field("holders", self.most_holders)
    }

    /// `RESULT frame.phase …`: one line per phase, its p99 and max over every frame.
    pub fn phase_lines(&self) -> Vec<ResultLine> {
        let mut lines = Vec::new();
        let mut add = |name: &str, v: Vec<f64>| {
            let max = v.iter().copied().fold(0.0, f64::max);
            lines.push(
                ResultLine::new("frame.phase")
                    .field("phase", name)
                    .fixed("p50_ms", percentile(&v, 0.5), 4)
                    .fixed("p99_ms", percentile(&v, 0.99), 4)
                    .fixed("max_ms", max, 3),
            );
        };
        add(
            "datagrams",
            self.samples.iter().map(|s| ms(s.datagrams_s)).collect(),
        );
        for p in Phase::ALL {
            add(
                p.name(),
                self.samples
                    .iter()
                    .map(|s| ms(s.phases_s[p as usize]))
                    .collect(),
            );
        }
        add(
            "transmit",
            self.samples.iter().map(|s| ms(s.transmit_s)).collect(),
        );
        lines
    }

    /// The `n` costliest frames, costliest first, each with its phases and notes (markdown).
    pub fn spikes_md(&self, n: usize) -> String {
        let mut by: Vec<&FrameSample> = self.samples.iter().collect();
        by.sort_by(|a, b| b.total_s.total_cmp(&a.total_s));
        let mut md = String::from("| t (s) | peer | frame ms | worst phase | phases over 0.5 ms | what happened |\n|---|---|---|---|---|---|\n");
        for s in by.into_iter().take(n) {
            let mut parts = Vec::new();
            if s.datagrams_s > 5e-4 {
                parts.push(format!("datagrams {:.2}", ms(s.datagrams_s)));
            }
            for p in Phase::ALL {
                let v = s.phases_s[p as usize];
                if v > 5e-4 {
                    parts.push(format!("{} {:.2}", p.name(), ms(v)));
                }
            }
            if s.transmit_s > 5e-4 {
                parts.push(format!("transmit {:.2}", ms(s.transmit_s)));
            }
            let _ = writeln!(
                md,
                "| {:.2} | {} | {:.2} | {} | {} | {} |",
                s.t_s,
                s.peer.0,
                ms(s.total_s),
                s.worst_phase(),
                parts.join(", "),
                if s.note.is_empty() { "—" } else { &s.note }
            );
        }
        md
    }

    /// Writes under `dir`: `frame.csv` (per peer and 0.1 s: frames, median, max, the max's
    /// worst phase and notes), `slow_frames.csv` (every frame over 2 ms, phase by phase),
    /// `frame.svg` (each peer's costliest frame per 0.1 s, over time), `spikes.md` and
    /// `RESULT.txt`; returns the RESULT lines.
    pub fn write(&self, dir: &Path) -> Result<Vec<String>, String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let mut cols = vec!["t_s", "peer", "total_ms", "datagrams_ms"];
        cols.extend(Phase::ALL.iter().map(|p| p.name()));
        cols.extend(["transmit_ms", "note"]);
        let mut slow = Csv::new(&cols);
        for s in self.samples.iter().filter(|s| s.total_s > 2e-3) {
            let mut row = vec![
                format!("{:.3}", s.t_s),
                s.peer.0.to_string(),
                format!("{:.3}", ms(s.total_s)),
                format!("{:.3}", ms(s.datagrams_s)),
            ];
            row.extend(s.phases_s.iter().map(|v| format!("{:.3}", ms(*v))));
            row.push(format!("{:.3}", ms(s.transmit_s)));
            row.push(s.note.clone());
            slow.row(row);
        }
        slow.write(dir.join("slow_frames.csv"))
            .map_err(|e| format!("slow_frames.csv: {e}"))?;
        // per peer and bin of 0.1 s
        let mut bins: BTreeMap<(u64, i64), Vec<&FrameSample>> = BTreeMap::new();
        for s in &self.samples {
            bins.entry((s.peer.0, (s.t_s * 10.0).floor() as i64))
                .or_default()
                .push(s);
        }
        let mut csv = Csv::new(&[
            "t_s",
            "peer",
            "frames",
            "p50_ms",
            "max_ms",
            "max_worst_phase",
            "max_note",
        ]);
        let mut per: BTreeMap<u64, Vec<(f64, f64)>> = BTreeMap::new();
        for ((peer, bin), frames) in &bins {
            let v: Vec<f64> = frames.iter().map(|s| ms(s.total_s)).collect();
            let Some(top) = frames.iter().max_by(|a, b| a.total_s.total_cmp(&b.total_s)) else {
                continue;
            };
            let t = *bin as f64 / 10.0;
            csv.row([
                format!("{t:.1}"),
                peer.to_string(),
                frames.len().to_string(),
                format!("{:.3}", percentile(&v, 0.5)),
                format!("{:.3}", ms(top.total_s)),
                top.worst_phase().to_owned(),
                top.note.clone(),
            ]);
            per.entry(*peer).or_default().push((t, ms(top.total_s)));
        }
        csv.write(dir.join("frame.csv"))
            .map_err(|e| format!("frame.csv: {e}"))?;
        // per peer, each frame's cost over time
        let colours = [
            RGBColor(31, 119, 180),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
            RGBColor(214, 39, 40),
        ];
        let top = self
            .samples
            .iter()
            .map(|s| ms(s.total_s))
            .fold(8.5f64, f64::max);
        let span = self.samples.last().map_or(1.0, |s| s.t_s.max(1.0));
        let mut series: Vec<Series> = per
            .into_iter()
            .enumerate()
            .map(|(i, (peer, points))| {
                let who = match peer {
                    100 => "host (stopped at the migration)",
                    101 => "A (holds the ball)",
                    102 => "B (holds the ball)",
                    _ => "C (tears and cuts)",
                };
                Series::new(who, colours[i % colours.len()], points)
            })
            .collect();
        series.push(Series::new(
            "p99 target 4 ms",
            RGBColor(120, 120, 120),
            vec![(0.0, 4.0), (span, 4.0)],
        ));
        series.push(Series::new(
            "max target 8 ms",
            RGBColor(0, 0, 0),
            vec![(0.0, 8.0), (span, 8.0)],
        ));
        let chart = LineChart {
            title: "Frame cost: each peer's costliest frame per 0.1 s (everything but rendering)"
                .into(),
            x_desc: "time (s)".into(),
            y_desc: "frame (ms)".into(),
            x_range: 0.0..span,
            x_log: false,
            y_range: 0.0..top * 1.05,
            series,
            style: ChartStyle::PANEL,
        };
        write_svg(dir.join("frame.svg"), (1200, 500), &[chart])
            .map_err(|e| format!("frame.svg: {e}"))?;
        std::fs::write(dir.join("spikes.md"), self.spikes_md(15))
            .map_err(|e| format!("spikes.md: {e}"))?;
        let mut lines = vec![self.result_line().to_string()];
        lines.extend(self.phase_lines().iter().map(ToString::to_string));
        std::fs::write(dir.join("RESULT.txt"), lines.join("\n") + "\n")
            .map_err(|e| format!("RESULT.txt: {e}"))?;
        Ok(lines)
    }
}
