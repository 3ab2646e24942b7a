//! Where do two resolutions of the reference part? One scenario run at two (cell, substeps)
//! pairs, compared sample by sample: the shape change (rigid fit, the accuracy metric), split
//! between the lower 60 % of the body's rest height and the top 40 % (the bunny's head and
//! ears), with the median and 90th-percentile vertex. The diagnostic behind the convergence
//! study's explanations (`examples/reference.rs` runs the ladders; this runs one pair).
//!
//! `cargo run --release -p softsync-softbody --example reference_probe -- CASE CELL_A SUBSTEPS_A CELL_B SUBSTEPS_B`
//!
//! CASE: `drop`, `squeeze`, `poke` (the bunny) or `icosphere` (its drop). Example: the
//! bunny drop's space change at impact, cell 0.1 against 0.071 at 80 substeps:
//! `… reference_probe -- drop 0.1 80 0.071 80`.
#![allow(
    clippy::disallowed_methods,
    clippy::unwrap_used,
    clippy::print_stdout,
    missing_docs
)]

use std::path::PathBuf;

use glam::Quat;
use softsync_softbody::methods::reference::{record, reference_spec, shape_change, SAMPLE_EVERY};
use softsync_softbody::metrics::rigid_fit_distances;
use softsync_softbody::scenario::ScenarioKind;
use softsync_softbody::Mesh;

const DT: f32 = 1.0 / 60.0;

fn rms_mm(d: &[f32]) -> f64 {
    let n = d.len().max(1) as f64;
    (d.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / n).sqrt() * 1e3
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: reference_probe CASE CELL_A SUBSTEPS_A CELL_B SUBSTEPS_B (CASE: drop, squeeze, poke, icosphere)";
    if args.len() != 5 {
        eprintln!("{usage}");
        std::process::exit(2);
    }
    let bunny = || {
        Mesh::load(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/bunny.obj"))
            .unwrap()
            .fit_size(0.2)
    };
    let (mesh, kind) = match args[0].as_str() {
        "drop" => (bunny(), ScenarioKind::Drop),
        "squeeze" => (bunny(), ScenarioKind::Squeeze),
        "poke" => (bunny(), ScenarioKind::Poke),
        "icosphere" => (Mesh::icosphere(0.1, 3), ScenarioKind::Drop),
        other => {
            eprintln!("unknown case {other:?}; {usage}");
            std::process::exit(2);
        }
    };
    let parse = |i: usize| -> (f32, u32) {
        match (args[i].parse::<f32>(), args[i + 1].parse::<u32>()) {
            (Ok(c), Ok(s)) if c > 0.0 && c.is_finite() && s > 0 => (c, s),
            _ => {
                eprintln!(
                    "bad cell or substeps {:?} {:?}; {usage}",
                    args[i],
                    args[i + 1]
                );
                std::process::exit(2);
            }
        }
    };
    let (a, b) = (parse(1), parse(3));
    let run = |(cell, substeps): (f32, u32)| match record(
        kind,
        &mesh,
        &reference_spec(cell, substeps),
        DT,
    ) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("cell {cell} at {substeps} substeps: {e}");
            std::process::exit(1);
        }
    };
    let (ra, rb) = (run(a), run(b));
    // The rest shape decides which vertices are "top" (the surface in the same vertex order).
    let lo = mesh.positions.iter().map(|p| p.y).fold(f32::MAX, f32::min);
    let hi = mesh.positions.iter().map(|p| p.y).fold(f32::MIN, f32::max);
    let cut = lo + 0.6 * (hi - lo);
    let top: Vec<bool> = mesh.positions.iter().map(|p| p.y >= cut).collect();
    println!(
        "{} {:?} against {:?} (cell, substeps): shape change per sample, mm",
        args[0], a, b
    );
    println!("    t_s    rms  lower60%  top40%    p50    p90    max");
    for (i, (x, y)) in ra.samples.iter().zip(&rb.samples).enumerate() {
        let d = rigid_fit_distances(x, y, Quat::IDENTITY);
        let (mut lower, mut upper) = (Vec::new(), Vec::new());
        for (k, v) in d.iter().enumerate() {
            if top.get(k).copied().unwrap_or(false) {
                upper.push(*v);
            } else {
                lower.push(*v);
            }
        }
        let mut sorted = d.clone();
        sorted.sort_by(f32::total_cmp);
        let pct = |p: usize| sorted.get(sorted.len() * p / 100).copied().unwrap_or(0.0) * 1e3;
        println!(
            "  {:5.2} {:6.2} {:9.2} {:7.2} {:6.2} {:6.2} {:6.1}",
            (i + 1) as f32 * SAMPLE_EVERY as f32 * DT,
            rms_mm(&d),
            rms_mm(&lower),
            rms_mm(&upper),
            pct(50),
            pct(90),
            sorted.last().copied().unwrap_or(0.0) * 1e3
        );
    }
    let c = shape_change(&ra.samples, &rb.samples);
    println!(
        "RESULT reference.probe case={} a_cell={} a_substeps={} b_cell={} b_substeps={} rms_change_mm={:.2} max_mm={:.1}",
        args[0], a.0, a.1, b.0, b.1, c.rms_mm, c.max_mm
    );
}
