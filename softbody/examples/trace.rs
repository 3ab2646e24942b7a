//! Records a 60-particle soft body being squeezed, poked and pulled (the scenarios of this
//! crate, one after the other, each starting and ending at rest) for the network benchmark:
//! `cargo run --release -p softsync-softbody --example trace -- [OUT]`
//! (default `assets/traces/softbody60.sstr`).
//!
//! Format (little endian): magic `SSTR`, u32 version = 1, u32 frames, u32 particles,
//! f32 dt_s, then per frame: center position (3 × f32), center rotation xyzw (4 × f32),
//! particle positions in world space (3 × f32 each).
#![allow(clippy::unwrap_used, clippy::print_stdout, missing_docs)]

use std::path::PathBuf;

use softsync_softbody::scenario::{Scenario, ScenarioKind};
use softsync_softbody::{build_particle_map, ClusterMethod, Mesh, SoftBodyConfig};

fn main() {
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/traces/softbody60.sstr")
        });
    let mesh = Mesh::icosphere(0.1, 3);
    let w = mesh.weld(1e-6);
    // Bisect the Poisson-disk radius to 60 particles (counts are discrete: keep the closest).
    let all = vec![true; w.positions.len()];
    let count = |r: f32| {
        build_particle_map(
            &w.positions,
            &w.triangles,
            &all,
            ClusterMethod::PoissonDisk {
                radius_m: r,
                seed: 1,
            },
            0.0,
        )
        .unwrap()
        .len()
    };
    let (mut lo, mut hi) = (0.005f32, 0.2f32);
    let mut best = (usize::MAX, 0.05f32);
    for _ in 0..40 {
        let r = 0.5 * (lo + hi);
        let n = count(r);
        if n.abs_diff(60) < best.0 {
            best = (n.abs_diff(60), r);
        }
        if n > 60 {
            lo = r;
        } else {
            hi = r;
        }
    }
    let radius = best.1;
    let cfg = SoftBodyConfig {
        cluster: ClusterMethod::PoissonDisk {
            radius_m: radius,
            seed: 1,
        },
        ..Default::default()
    };
    let dt = 1.0f32 / 90.0;
    let mut frames: Vec<f32> = Vec::new();
    let mut count = 0u32;
    let mut particles = 0u32;
    for kind in [
        ScenarioKind::Squeeze,
        ScenarioKind::Poke,
        ScenarioKind::Pull,
        ScenarioKind::Squeeze,
    ] {
        let mut s = Scenario::new(kind, &mesh, cfg.clone(), dt).unwrap();
        while s.time_s() < kind.duration_s() {
            s.step();
            let b = s.soft_body();
            let (c, q) = b.center_pose(&s.world);
            let pos = b.particle_positions(&s.world);
            particles = pos.len() as u32;
            frames.extend_from_slice(&c.to_array());
            frames.extend_from_slice(&q.to_array());
            for p in pos {
                frames.extend_from_slice(&p.to_array());
            }
            count += 1;
        }
    }
    let mut bytes = Vec::with_capacity(20 + frames.len() * 4);
    bytes.extend_from_slice(b"SSTR");
    bytes.extend_from_slice(&1u32.to_le_bytes());
    bytes.extend_from_slice(&count.to_le_bytes());
    bytes.extend_from_slice(&particles.to_le_bytes());
    bytes.extend_from_slice(&dt.to_le_bytes());
    for f in frames {
        bytes.extend_from_slice(&f.to_le_bytes());
    }
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    std::fs::write(&out, &bytes).unwrap();
    println!("{}: {count} frames at {:.0} Hz, {particles} particles (Poisson-disk clustering, radius {radius:.4} m), {} bytes", out.display(), 1.0 / dt, bytes.len());
}
