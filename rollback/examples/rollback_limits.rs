//! Where rollback stops keeping 90 Hz on this machine (issue 38, point 5): the tick cost of
//! the deterministic world under the re-simulation a 50 ms link asks for, against the scene's
//! size (particles) and the room's (players).
//!
//! `cargo run --release -p softsync-rollback --example rollback_limits -- [--quick]
//! [--out docs/results/rollback]`
//!
//! Each configuration is the thesis room with `k` more copies of its three soft bodies (the
//! soft ball, the bunny, the soft box) on the floor around the table, and `P` players, each a
//! squeeze-and-throw bot (`script::SqueezeThrow`) over the objects. The world runs at 90 Hz
//! under ggrs's sync test with a check distance of `D` = ⌈50 ms × 90 Hz⌉ = 5 frames: every
//! tick loads the state of 5 frames ago and steps, saves and checksums 5 frames again, then the
//! new one — the steady load of a room whose other players' inputs arrive 50 ms late and
//! change every frame (their hands move), which is the bots' case (in the live two-process
//! test at 50 ms, 87 % of ticks rolled back). The cost of a tick is its wall time on one core:
//! p50 and p99 over 4 s of ticks (2 s with `--quick`). A configuration keeps 90 Hz when its p99
//! fits 11.1 ms; what is left of the frame goes to rendering, the network and the rest (a
//! headset's compositor needs most of it on a real GPU).
//!
//! Writes `limits.csv`, `limits.txt` (the RESULT lines), `limits.svg` (p99 against particles, one line per player count) and
//! `RESULT rollback.limits …` lines, then `RESULT rollback.limit …`: per player count, the
//! largest scene that kept 90 Hz.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::Instant as Wall;

use ggrs::{GgrsRequest, PlayerType, SessionBuilder};
use glam::{Quat, Vec3};
use softsync_benchkit::{percentile, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_net::PeerId;
use softsync_peer::scene::Placed;
use softsync_peer::Scene;
use softsync_rollback::script::SqueezeThrow;
use softsync_rollback::{GgrsConfig, PlayerInput, RollbackWorld};

const HZ: f32 = 90.0;
/// Frames of re-simulation a 50 ms one-way link asks for at 90 Hz.
const DEPTH: usize = 5;
/// The frame budget at 90 Hz, ms.
const BUDGET_MS: f64 = 1000.0 / 90.0;

/// The thesis room with `k` more copies of its soft bodies, placed on the floor in a ring.
fn scene(k: usize) -> Scene {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let mut s = Scene::by_name("thesis-room", &assets).unwrap();
    let soft: Vec<_> = s
        .objects
        .iter()
        .filter(|o| s.soft_config(o.kind).is_some())
        .map(|o| o.kind)
        .collect();
    for i in 0..k {
        for (j, kind) in soft.iter().enumerate() {
            let n = i * soft.len() + j;
            let a = n as f32 * 0.61;
            let r = 1.0 + 0.25 * (n / 10) as f32;
            s.objects.push(Placed {
                kind: *kind,
                pos: Vec3::new(r * a.cos(), 0.12, r * a.sin()),
                rot: Quat::IDENTITY,
            });
        }
    }
    s
}

/// Tick costs (ms) of `players` bots in `scene` under the sync test, over `frames` ticks
/// (after 1 s of warm-up), and the scene's particles.
fn run(scene: &Scene, players: usize, frames: usize) -> (usize, Vec<f64>) {
    let ids: Vec<PeerId> = (1..=players as u64).map(PeerId).collect();
    let mut world = RollbackWorld::new(scene, 1.0 / HZ, &ids).unwrap();
    let particles: usize = world
        .soft_bodies()
        .iter()
        .map(|(_, b)| b.num_particles())
        .sum();
    let mut b = SessionBuilder::<GgrsConfig>::new()
        .with_num_players(players)
        .unwrap()
        .with_check_distance(DEPTH);
    for p in 0..players {
        b = b.add_player(PlayerType::Local, p).unwrap();
    }
    let mut s = b.start_synctest_session().unwrap();
    let objects = world.objects().len();
    let mut bots: Vec<SqueezeThrow> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| SqueezeThrow::new(*id, (2 * i + 1) % objects))
        .collect();
    let warm = HZ as usize;
    let mut costs = Vec::with_capacity(frames);
    for f in 0..warm + frames {
        let inputs: Vec<PlayerInput> = bots.iter_mut().map(|b| b.input(&world)).collect();
        let t = Wall::now();
        for (p, i) in inputs.iter().enumerate() {
            s.add_local_input(p, *i).unwrap();
        }
        for r in s.advance_frame().unwrap() {
            match r {
                GgrsRequest::SaveGameState { cell, frame } => {
                    cell.save(frame, Some(Rc::new(world.save())), Some(world.checksum()))
                }
                GgrsRequest::LoadGameState { cell, .. } => world.load(&cell.load().unwrap()),
                GgrsRequest::AdvanceFrame { inputs } => {
                    let i: Vec<PlayerInput> = inputs.iter().map(|x| x.0).collect();
                    world.step(&i)
                }
            }
        }
        if f >= warm {
            costs.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    (particles, costs)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let out = PathBuf::from(
        args.iter()
            .position(|a| a == "--out")
            .and_then(|i| args.get(i + 1))
            .cloned()
            .unwrap_or_else(|| "docs/results/rollback".into()),
    );
    std::fs::create_dir_all(&out).unwrap();
    let frames = if quick { 180 } else { 360 };
    let copies: &[usize] = if quick {
        &[0, 3, 7]
    } else {
        &[0, 1, 3, 4, 5, 6, 7, 15]
    };
    let players: &[usize] = if quick { &[2, 4] } else { &[2, 4, 8] };
    let mut csv = Csv::new(&[
        "players",
        "copies",
        "particles",
        "tick_ms_p50",
        "tick_ms_p99",
        "keeps_90hz",
    ]);
    let mut lines: Vec<(usize, Vec<(f64, f64)>)> = Vec::new();
    let mut results: Vec<String> = Vec::new();
    let mut limits = Vec::new();
    for &p in players {
        let mut points = Vec::new();
        let mut largest: Option<usize> = None;
        for &k in copies {
            let (particles, costs) = run(&scene(k), p, frames);
            let (p50, p99) = (percentile(&costs, 0.5), percentile(&costs, 0.99));
            let keeps = p99 <= BUDGET_MS;
            if keeps {
                largest = Some(largest.map_or(particles, |l| l.max(particles)));
            }
            let line = ResultLine::new("rollback.limits")
                .field("players", p)
                .field("particles", particles)
                .field("lat_ms", 50)
                .field("hz", 90)
                .fixed("tick_ms_p50", p50, 2)
                .fixed("tick_ms_p99", p99, 2)
                .field("keeps_90hz", keeps)
                .to_string();
            println!("{line}");
            results.push(line);
            csv.row([
                p.to_string(),
                k.to_string(),
                particles.to_string(),
                format!("{p50:.3}"),
                format!("{p99:.3}"),
                keeps.to_string(),
            ]);
            points.push((particles as f64, p99));
            // past the budget by far: larger scenes only cost more
            if p99 > 3.0 * BUDGET_MS {
                break;
            }
        }
        lines.push((p, points));
        limits.push((p, largest));
    }
    for (p, largest) in &limits {
        let line = ResultLine::new("rollback.limit")
            .field("players", p)
            .field("lat_ms", 50)
            .field("hz", 90)
            .field(
                "max_particles",
                largest.map_or("none".to_owned(), |l| l.to_string()),
            )
            .to_string();
        println!("{line}");
        results.push(line);
    }
    csv.write(out.join("limits.csv")).unwrap();
    std::fs::write(out.join("limits.txt"), results.join("\n") + "\n").unwrap();
    let colors = [(31u8, 119u8, 180u8), (214, 39, 40), (44, 160, 44)];
    let x_max = lines
        .iter()
        .flat_map(|(_, v)| v.iter().map(|p| p.0))
        .fold(100.0, f64::max);
    let y_max = lines
        .iter()
        .flat_map(|(_, v)| v.iter().map(|p| p.1))
        .fold(BUDGET_MS * 1.5, f64::max);
    let mut series: Vec<Series> = lines
        .iter()
        .zip(colors)
        .map(|((p, v), (r, g, b))| {
            Series::new(
                format!("{p} players"),
                softsync_benchkit::plotters::style::RGBColor(r, g, b),
                v.clone(),
            )
        })
        .collect();
    series.push(Series::new(
        "90 Hz budget (11.1 ms)",
        softsync_benchkit::plotters::style::RGBColor(0, 0, 0),
        vec![(0.0, BUDGET_MS), (x_max * 1.05, BUDGET_MS)],
    ));
    let chart = LineChart {
        title: "rollback tick at 90 Hz under 50 ms (5 frames re-simulated), p99".into(),
        x_desc: "particles in the scene".into(),
        y_desc: "tick ms, p99".into(),
        x_range: 0.0..x_max * 1.05,
        x_log: false,
        y_range: 0.0..y_max * 1.05,
        series,
        style: ChartStyle::PANEL,
    };
    write_svg(out.join("limits.svg"), (800, 480), &[chart]).unwrap();
    println!("wrote {}/limits.csv and limits.svg", out.display());
}
