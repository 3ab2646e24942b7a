//! Prints each method's metrics over a scenario (a quick look at the dynamics).
//! `cargo run --release -p softsync-softbody --example methods_probe -- squeeze ispc bunny`
#![allow(clippy::disallowed_methods, clippy::unwrap_used, missing_docs)]
use softsync_softbody::methods::scene::ModelScene;
use softsync_softbody::methods::{MethodKind, MethodSpec};
use softsync_softbody::scenario::ScenarioKind;
use softsync_softbody::Mesh;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let kind = match args.get(1).map(String::as_str) {
        Some("drop") => ScenarioKind::Drop,
        Some("squeeze") => ScenarioKind::Squeeze,
        Some("poke") => ScenarioKind::Poke,
        _ => ScenarioKind::Rest,
    };
    let methods: Vec<MethodKind> = match args.get(2).map(String::as_str) {
        Some("all") | None => MethodKind::ALL.to_vec(),
        Some(n) => MethodKind::ALL
            .iter()
            .copied()
            .filter(|m| m.name() == n)
            .collect(),
    };
    let mesh = match args.get(3).map(String::as_str) {
        Some("bunny") => Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj"))
            .unwrap()
            .fit_size(0.2),
        Some("box") => Mesh::cuboid(glam::Vec3::new(0.08, 0.05, 0.06), 6),
        _ => Mesh::icosphere(0.1, 3),
    };
    let sub: u32 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(4);
    let it: u32 = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(4);
    let hz = 90.0;
    if args.get(1).map(String::as_str) == Some("impact") {
        // impact <method> <speed> <hz>: the stability map's throw at a thin wall.
        let speed: f32 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(5.0);
        let hz: f32 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(60.0);
        let sub: u32 = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(2);
        let it: u32 = args.get(6).and_then(|s| s.parse().ok()).unwrap_or(4);
        for m in methods {
            let spec = MethodSpec::new(m).budget(sub, it);
            let mut s =
                ModelScene::impact(&Mesh::icosphere(0.1, 2), &spec, 1.0 / hz, speed).unwrap();
            let mut worst = 0;
            for _ in 0..hz as usize {
                s.step();
                worst = worst.max(s.model.inverted_elements());
            }
            let (_, max_rest) = s.rest_error_m();
            println!(
                "{} {speed} m/s {hz} Hz: max inverted {worst}, end rest max {:.1} mm {:?}",
                s.model.name(),
                max_rest * 1e3,
                s.sanity()
            );
        }
        return;
    }
    for m in methods {
        let cell: f32 = args
            .get(6)
            .and_then(|s| s.parse().ok())
            .unwrap_or(spec_default_cell(m));
        let spec = MethodSpec::new(m).budget(sub, it).cell(cell);
        let t0 = std::time::Instant::now();
        let mut s = match ModelScene::new(kind, &mesh, &spec, 1.0 / hz) {
            Ok(s) => s,
            Err(e) => {
                println!("{}: {e}", m.name());
                continue;
            }
        };
        let build = t0.elapsed().as_secs_f64() * 1e3;
        let t0 = std::time::Instant::now();
        let steps = (kind.duration_s() * hz) as usize;
        let mut line = String::new();
        let mut worst = 0; // MAXINV
        for i in 0..steps {
            s.step();
            worst = worst.max(s.model.inverted_elements());
            if i % 27 == 26 {
                let (rms, _) = s.rest_error_m();
                let (lo, hi) = softsync_softbody::mesh::bounds(s.model.surface());
                line += &format!(
                    "\n  v={:.4} t={:.2} vol={:.3} rest_rms_mm={:.1} ylo={:.3} yhi={:.3} xhi={:.3} sleep={} {}",
                    s.model.max_speed_mps(),
                    s.time_s(),
                    s.volume_ratio(),
                    rms * 1e3,
                    lo.y, hi.y, hi.x,
                    s.model.is_sleeping(),
                    s.sanity().verdict()
                );
            }
        }
        let ms = t0.elapsed().as_secs_f64() * 1e3 / steps as f64;
        println!(
            "{} particles={} build_ms={build:.1} step_ms={ms:.3} max_inverted={worst}{line}",
            s.model.name(),
            s.model.num_particles()
        );
    }
}

fn spec_default_cell(m: MethodKind) -> f32 {
    MethodSpec::new(m).cell_frac
}
