//! The particle method's volume term in the squeeze (issue 33 point 4): the bunny squeezed to
//! 30 % of its height at 90 Hz, the particle method with its volume term (the default,
//! `SoftBodyConfig::volume_stiffness`) and without it (0, as before), side by side in one run
//! and interleaved, against the accuracy reference (stable Neo-Hookean tets, its volume floor
//! counted).
//!
//! `cargo run --release -p softsync-softbody --example volume_squeeze [-- --quick]`
//!
//! Prints `RESULT volume.squeeze …` lines (one per particle config) and writes
//! `docs/results/methods/volume.csv` (the volume over time of every run), `volume.svg` and
//! `volume.txt` (the RESULT lines). Step times: the median over 5 runs of each run's median
//! step (the whole step: props, rapier, the method), single thread. `--quick`: 2 runs each,
//! no reference run (its figure is then read from `speed_accuracy.csv`), nothing written.
#![allow(clippy::disallowed_methods, clippy::unwrap_used, missing_docs)]

use std::time::Instant;

use softsync_benchkit::plotters::style::RGBColor;
use softsync_benchkit::stats::median;
use softsync_benchkit::{write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_softbody::methods::reference::verified_reference;
use softsync_softbody::methods::scene::ModelScene;
use softsync_softbody::methods::{MethodKind, MethodSpec};
use softsync_softbody::scenario::ScenarioKind;
use softsync_softbody::Mesh;

const HZ: f32 = 90.0;

struct Run {
    min_vol: f32,
    step_ms: f64,
    /// (time s, volume ratio)
    curve: Vec<(f64, f64)>,
    floor_hits: (u64, u64),
}

fn run(spec: &MethodSpec, mesh: &Mesh) -> Run {
    let mut s = ModelScene::new(ScenarioKind::Squeeze, mesh, spec, 1.0 / HZ).unwrap();
    let mut min_vol = f32::INFINITY;
    let mut times = Vec::new();
    let mut curve = Vec::new();
    while s.time_s() < ScenarioKind::Squeeze.duration_s() {
        let t0 = Instant::now();
        s.step();
        times.push(t0.elapsed().as_secs_f64() * 1e3);
        let v = s.volume_ratio();
        min_vol = min_vol.min(v);
        curve.push((f64::from(s.time_s()), f64::from(v)));
    }
    Run {
        min_vol,
        step_ms: median(&times),
        curve,
        floor_hits: s.model.volume_floor_hits(),
    }
}

/// The reference's smallest squeeze volume in the committed evidence.
fn committed_reference_min_vol() -> Option<f64> {
    let csv = std::fs::read_to_string("docs/results/methods/speed_accuracy.csv").ok()?;
    csv.lines()
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|c| c.first() == Some(&"squeeze") && c.get(2) == Some(&"neo_hookean"))
        .and_then(|c| c.get(8)?.parse().ok())
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let mesh = Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj"))
        .unwrap()
        .fit_size(0.2);
    let repeats = if quick { 2 } else { 5 };
    let reference = if quick {
        None
    } else {
        println!("reference squeeze, with its volume floor and without (about a minute each)…");
        let mut no_floor = verified_reference();
        no_floor.params.volume_floor = 0.0;
        Some((run(&verified_reference(), &mesh), run(&no_floor, &mesh)))
    };
    let reference_min_vol = reference
        .as_ref()
        .map(|(r, _)| f64::from(r.min_vol))
        .or_else(committed_reference_min_vol)
        .unwrap_or(f64::NAN);
    let mut lines = Vec::new();
    let mut csv = Csv::new(&["run", "time_s", "volume_ratio"]);
    let mut series = Vec::new();
    let colors = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
    ];
    for (ci, cell) in [0.06f32, 0.1].into_iter().enumerate() {
        let on = MethodSpec::new(MethodKind::Particle)
            .cell(cell)
            .volume_stiffness(250.0);
        let off = on.volume_stiffness(0.0);
        let (mut with, mut without) = (Vec::new(), Vec::new());
        for _ in 0..repeats {
            with.push(run(&on, &mesh));
            without.push(run(&off, &mesh));
        }
        let ms = |runs: &[Run]| median(&runs.iter().map(|r| r.step_ms).collect::<Vec<_>>());
        let (ms_on, ms_off) = (ms(&with), ms(&without));
        let config = format!("c{cell:.3}");
        let line = ResultLine::new("volume.squeeze")
            .field("method", "particle")
            .field("config", &config)
            .field("volume_stiffness", on.volume_stiffness)
            .fixed("min_vol", with[0].min_vol, 3)
            .fixed("step_ms", ms_on, 3)
            .fixed("min_vol_without", without[0].min_vol, 3)
            .fixed("step_ms_without", ms_off, 3)
            .fixed("step_ratio", ms_on / ms_off, 2)
            .fixed("reference_min_vol", reference_min_vol, 3);
        println!("{line}");
        lines.push(line.to_string());
        for (name, r, color) in [
            (
                format!("particle {config}, volume term"),
                &with[0],
                colors[2 * ci],
            ),
            (
                format!("particle {config}, without"),
                &without[0],
                colors[2 * ci + 1],
            ),
        ] {
            for (t, v) in &r.curve {
                csv.row([name.clone(), format!("{t:.4}"), format!("{v:.4}")]);
            }
            series.push(Series::new(name, color, r.curve.clone()));
        }
    }
    if let Some((r, bare)) = &reference {
        for (name, run, color) in [
            ("reference (stable Neo-Hookean tets)", r, RGBColor(0, 0, 0)),
            (
                "reference without its volume floor",
                bare,
                RGBColor(140, 140, 140),
            ),
        ] {
            for (t, v) in &run.curve {
                csv.row([name.to_string(), format!("{t:.4}"), format!("{v:.4}")]);
            }
            series.push(Series::new(name.to_string(), color, run.curve.clone()));
        }
        // What the floor holds up: the volume the reference keeps with it, less what it keeps
        // without it (the material's own bulk response).
        let line = ResultLine::new("volume.reference_floor")
            .field("method", "neo_hookean")
            .fixed("min_vol", r.min_vol, 3)
            .fixed("min_vol_no_floor", bare.min_vol, 3)
            .fixed("floor_share", r.min_vol - bare.min_vol, 3)
            .field("floor_hits", r.floor_hits.0)
            .field("floor_hits_material", r.floor_hits.1);
        println!("{line}");
        lines.push(line.to_string());
    }
    if quick {
        return;
    }
    let dir = "docs/results/methods";
    csv.write(format!("{dir}/volume.csv")).unwrap();
    std::fs::write(format!("{dir}/volume.txt"), lines.join("\n") + "\n").unwrap();
    let chart = LineChart {
        title: "bunny squeezed to 30 % of its height at 90 Hz: enclosed volume / rest".into(),
        x_desc: "time, s (plates close by 0.8 s, open at 1.5 s)".into(),
        y_desc: "volume ratio".into(),
        x_range: 0.0..f64::from(ScenarioKind::Squeeze.duration_s()),
        x_log: false,
        y_range: 0.3..1.1,
        series,
        style: ChartStyle::FIGURE,
    };
    write_svg(format!("{dir}/volume.svg"), (900, 520), &[chart]).unwrap();
    println!("wrote {dir}/volume.csv, volume.svg, volume.txt");
}
