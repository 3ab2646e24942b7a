//! What rapier's `enhanced-determinism` costs the step (issue 33 point 6): the particle
//! method's step in the drop, squeeze and poke (the bunny, thesis defaults, 60 Hz), timed as
//! built — this binary is built once without and once with the crate's `deterministic` feature
//! by `scripts/bench-determinism`, which runs the two alternately and compares their medians.
//! Every room binary (`softsync`) is built with the feature on: the rollback crate asks for it,
//! and cargo unifies features across the workspace.
//!
//! `cargo run --release -p softsync-softbody --example determinism [--features deterministic]`
//!
//! Prints one `RESULT determinism.step scenario=… deterministic=… median_ms=…` line per
//! scenario (the median over the run's awake steps, after a 0.5 s warm-up) and a checksum of
//! the final positions (the two builds' differ: the feature changes the arithmetic).
#![allow(
    clippy::disallowed_methods,
    clippy::unwrap_used,
    clippy::print_stdout,
    missing_docs
)]

use std::time::Instant;

use softsync_benchkit::stats::median;
use softsync_benchkit::ResultLine;
use softsync_softbody::scenario::{Scenario, ScenarioKind};
use softsync_softbody::{Mesh, SoftBodyConfig};

const DT: f32 = 1.0 / 60.0;

fn main() {
    let bunny = Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj"))
        .unwrap()
        .fit_size(0.2);
    let deterministic = cfg!(feature = "deterministic");
    for kind in [
        ScenarioKind::Drop,
        ScenarioKind::Squeeze,
        ScenarioKind::Poke,
    ] {
        let mut s = Scenario::new(kind, &bunny, SoftBodyConfig::default(), DT).unwrap();
        let steps = (kind.duration_s() / DT).round() as usize;
        let warm = (0.5 / DT) as usize;
        let mut times = Vec::with_capacity(steps);
        for i in 0..steps {
            let t = Instant::now();
            s.step();
            if i >= warm {
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
        }
        let checksum: f64 = s
            .soft_body()
            .vertices()
            .iter()
            .map(|v| f64::from(v.x + 2.0 * v.y + 3.0 * v.z))
            .sum();
        println!(
            "{}",
            ResultLine::new("determinism.step")
                .field("scenario", kind.name())
                .field("deterministic", deterministic)
                .fixed("median_ms", median(&times), 4)
                .field("steps", times.len())
                .fixed("checksum", checksum, 6)
        );
    }
}
