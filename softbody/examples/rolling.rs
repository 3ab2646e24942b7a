//! What rolling resistance (`SoftBodyConfig::rolling_resistance`) does to the particle method:
//! how far the thesis room's soft ball rolls when pushed, whether a throw still flies its
//! ballistic path, and what it costs per step — each with the setting off and at several
//! values, side by side in one run. Its effect on the stability maps is in the evidence run
//! (`particle c0.060 roll0` beside `particle c0.060`).
//!
//! `cargo run --release -p softsync-softbody --example rolling`
//!
//! Writes `docs/results/methods/rolling.{md,csv,svg}` and prints `RESULT` lines (also in
//! `rolling.md`, one per line).
#![allow(
    clippy::disallowed_methods,
    clippy::unwrap_used,
    clippy::print_stdout,
    missing_docs
)]

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use softsync_benchkit::plotters::style::RGBColor;
use softsync_benchkit::{median, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_softbody::rapier3d::prelude::PhysicsWorld;
use softsync_softbody::{ClusterMethod, Mesh, SoftBodyConfig, SoftBodyHandle, SoftBodySet};

const HZ: f32 = 90.0;
const G: f32 = 9.81;
const RADIUS: f32 = 0.06;

/// The thesis room's soft ball (12 cm, 60 Poisson-disk particles) at rolling resistance `mu`.
fn ball_cfg(mu: f32) -> SoftBodyConfig {
    SoftBodyConfig {
        cluster: ClusterMethod::PoissonDisk {
            radius_m: 0.0215,
            seed: 1,
        },
        rolling_resistance: mu,
        ..Default::default()
    }
}

/// A floor (top at y = 0) and `mesh` (centred on the origin) moved to `at`, moving rigidly at
/// `v`, spinning at `w`.
fn world_with(
    mesh: &Mesh,
    cfg: SoftBodyConfig,
    at: Vec3,
    v: Vec3,
    w: Vec3,
) -> (PhysicsWorld, SoftBodySet, SoftBodyHandle) {
    softsync_softbody::scenario::on_floor(mesh, cfg, at, v, w).unwrap()
}

fn center(world: &PhysicsWorld, set: &SoftBodySet, h: SoftBodyHandle) -> (Vec3, Vec3) {
    let b = world.bodies.get(set.get(h).unwrap().center()).unwrap();
    (b.translation(), b.linvel())
}

/// The ball rolled along +x at `v0` (rolling, or sliding without spin): its distance over
/// time (s, m) for `seconds`, and the time it came to rest (speed < 5 mm/s), if it did.
fn push(mu: f32, v0: f32, rolling: bool, seconds: f32) -> (Vec<(f64, f64)>, Option<f32>) {
    let w = if rolling {
        Vec3::new(0.0, 0.0, -v0 / RADIUS)
    } else {
        Vec3::ZERO
    };
    let (mut world, mut set, h) = world_with(
        &Mesh::icosphere(RADIUS, 3),
        ball_cfg(mu),
        Vec3::new(0.0, RADIUS, 0.0),
        Vec3::new(v0, 0.0, 0.0),
        w,
    );
    let x0 = center(&world, &set, h).0.x;
    let mut track = Vec::new();
    let mut rest = None;
    for k in 1..=(seconds * HZ) as usize {
        set.step(&mut world, 1.0 / HZ);
        let (c, v) = center(&world, &set, h);
        let t = k as f32 / HZ;
        track.push((f64::from(t), f64::from(c.x - x0)));
        if rest.is_none() && v.length() < 0.005 {
            rest = Some(t);
        }
        if rest.is_some() && v.length() >= 0.005 {
            rest = None; // it moved again
        }
    }
    (track, rest)
}

/// A throw from 1 m at (3, 2) m/s: where the center first comes within a radius of the floor,
/// and where a point mass would.
fn throw(mu: f32) -> (f32, f32) {
    let (y0, vx, vy) = (1.0f32, 3.0f32, 2.0f32);
    let t_land = (vy + (vy * vy + 2.0 * G * (y0 - RADIUS)).sqrt()) / G;
    let (mut world, mut set, h) = world_with(
        &Mesh::icosphere(RADIUS, 3),
        ball_cfg(mu),
        Vec3::new(0.0, y0, 0.0),
        Vec3::new(vx, vy, 0.0),
        Vec3::new(0.0, 0.0, -4.0),
    );
    for _ in 0..(3.0 * HZ) as usize {
        set.step(&mut world, 1.0 / HZ);
        let (c, _) = center(&world, &set, h);
        if c.y <= RADIUS + 0.005 {
            return (c.x, vx * t_land);
        }
    }
    (f32::NAN, vx * t_land)
}

/// Median step time, ms, of `mesh` rolling at 1 m/s with every particle awake, for `mu` and
/// without rolling resistance, runs interleaved: (with, without).
fn step_cost(mesh: &Mesh, cfg: &SoftBodyConfig, mu: f32) -> (f64, f64) {
    let (lo, hi) = softsync_softbody::mesh::bounds(&mesh.positions);
    let r = (hi - lo).max_element() / 2.0;
    let mut with = Vec::new();
    let mut without = Vec::new();
    for _ in 0..6 {
        for (m, out) in [(mu, &mut with), (0.0, &mut without)] {
            let cfg = SoftBodyConfig {
                rolling_resistance: m,
                particles_can_sleep: false,
                ..cfg.clone()
            };
            let (mut world, mut set, _) = world_with(
                mesh,
                cfg,
                Vec3::new(0.0, 0.001 - lo.y, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 0.0, -1.0 / r),
            );
            for k in 0..(1.5 * HZ) as usize {
                let t = Instant::now();
                set.step(&mut world, 1.0 / HZ);
                // the first half second settles the contact; every run times the same steps
                if k >= (0.5 * HZ) as usize {
                    out.push(t.elapsed().as_secs_f64() * 1e3);
                }
            }
        }
    }
    (median(&with), median(&without))
}

fn main() {
    let out = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/results/methods"
    ));
    std::fs::create_dir_all(&out).unwrap();
    let default_mu = SoftBodyConfig::default().rolling_resistance;
    let mus = [0.0f32, 0.02, default_mu, 0.1];
    let mut results = Vec::new();
    let mut csv = Csv::new(&["mu", "start", "t_s", "distance_m"]);
    let mut series = Vec::new();
    let colours = [
        RGBColor(214, 39, 40),
        RGBColor(255, 127, 14),
        RGBColor(31, 119, 180),
        RGBColor(44, 160, 44),
    ];
    let mut md = String::new();
    writeln!(md, "# Rolling resistance of the particle method\n\n`cargo run --release -p softsync-softbody --example rolling`\n\nThe thesis room's soft ball (12 cm, 60 particles, center 1 kg) on a floor of friction 0.5 at {HZ:.0} Hz. `SoftBodyConfig::rolling_resistance` μ_r puts a torque of μ_r · N · r against the center's spin while it touches something (N from the contacts' normal impulses of the last step); for a rolling ball the model says it slows at 5/7 · μ_r · g and stops after v₀² / (2 · 5/7 · μ_r · g). Default μ_r = {default_mu}.\n\n## Pushed at 0.5 m/s\n\n![distance](rolling.svg)\n\n| μ_r | start | distance after 8 s, m | at rest after, s | model's distance, m |\n|---|---|---|---|---|").unwrap();
    for (i, &mu) in mus.iter().enumerate() {
        for rolling in [true, false] {
            let (track, rest) = push(mu, 0.5, rolling, 8.0);
            let d = track.last().map_or(f64::NAN, |p| p.1);
            let start = if rolling { "rolling" } else { "sliding" };
            let model = if mu > 0.0 && rolling {
                format!("{:.2}", 0.25 / (2.0 * 5.0 / 7.0 * mu * G))
            } else if mu > 0.0 {
                "—".into()
            } else {
                "∞".into()
            };
            writeln!(
                md,
                "| {mu} | {start} | {d:.3} | {} | {model} |",
                rest.map_or("never".into(), |t| format!("{t:.2}"))
            )
            .unwrap();
            for (t, x) in track.iter().step_by(9) {
                csv.row([
                    mu.to_string(),
                    start.to_string(),
                    format!("{t:.3}"),
                    format!("{x:.4}"),
                ]);
            }
            let r = ResultLine::new("rolling.push")
                .field("mu", mu)
                .field("v0_mps", 0.5)
                .field("start", start)
                .fixed("distance_m", d, 3)
                .field("rest_s", rest.map_or("never".into(), |t| format!("{t:.2}")));
            println!("{r}");
            results.push(r);
            if rolling {
                series.push(Series::new(
                    format!("μ_r = {mu}"),
                    colours[i % colours.len()],
                    track,
                ));
            }
        }
    }
    writeln!(md, "\n## Thrown from 1 m at (3, 2) m/s\n\nWhere the center first comes within a radius of the floor, against a point mass's ballistic landing: rolling resistance acts only through contacts, so a throw flies the same path.\n\n| μ_r | landed at, m | ballistic, m | difference |\n|---|---|---|---|").unwrap();
    for &mu in &[0.0, default_mu, 1.0] {
        let (x, b) = throw(mu);
        let err = 100.0 * (x - b) / b;
        writeln!(md, "| {mu} | {x:.3} | {b:.3} | {err:+.1} % |").unwrap();
        let r = ResultLine::new("rolling.throw")
            .field("mu", mu)
            .fixed("landed_m", x, 3)
            .fixed("ballistic_m", b, 3)
            .fixed("err_pct", err, 1);
        println!("{r}");
        results.push(r);
    }
    writeln!(md, "\n## What it costs per step\n\nMedian wall-clock step (the whole `SoftBodySet::step`: the restoring pass, rapier, the deformation) of a body rolling at 1 m/s with every particle awake, with μ_r = {default_mu} and without, runs interleaved (6 each, 90 timed steps a run), single thread.\n\n| body | particles | with, ms | without, ms | ratio |\n|---|---|---|---|---|").unwrap();
    let bunny = Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj"))
        .map(|m| m.fit_size(0.16))
        .unwrap();
    let bunny_cfg = SoftBodyConfig {
        cluster: ClusterMethod::Distance { radius_m: 0.03 },
        ..Default::default()
    };
    for (name, mesh, cfg) in [
        ("softball", Mesh::icosphere(RADIUS, 3), ball_cfg(default_mu)),
        ("bunny", bunny, bunny_cfg),
    ] {
        let particles = {
            let mut world = PhysicsWorld::new();
            let mut set = SoftBodySet::new();
            let h = set.insert(&mesh, cfg.clone(), &mut world).unwrap();
            set.get(h).unwrap().particles().len()
        };
        let (with, without) = step_cost(&mesh, &cfg, default_mu);
        writeln!(
            md,
            "| {name} | {particles} | {with:.4} | {without:.4} | {:.3} |",
            with / without
        )
        .unwrap();
        let r = ResultLine::new("rolling.step")
            .field("body", name)
            .field("particles", particles)
            .fixed("step_ms_with", with, 4)
            .fixed("step_ms_without", without, 4)
            .fixed("ratio", with / without, 3);
        println!("{r}");
        results.push(r);
    }
    writeln!(md, "\n## RESULT lines\n\n```").unwrap();
    for r in &results {
        writeln!(md, "{r}").unwrap();
    }
    writeln!(md, "```").unwrap();
    std::fs::write(out.join("rolling.md"), md).unwrap();
    csv.write(out.join("rolling.csv")).unwrap();
    let chart = LineChart {
        title: "soft ball rolled at 0.5 m/s: distance over time".into(),
        x_desc: "time (s)".into(),
        y_desc: "distance (m)".into(),
        x_range: 0.0..8.0,
        x_log: false,
        y_range: 0.0..4.2,
        series,
        style: ChartStyle::PANEL,
    };
    write_svg(out.join("rolling.svg"), (800, 420), &[chart]).unwrap();
}
