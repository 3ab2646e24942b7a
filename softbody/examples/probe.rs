//! Prints a scenario's metrics over time (a quick look at the dynamics).
#![allow(missing_docs)]
use softsync_softbody::scenario::{Scenario, ScenarioKind};
use softsync_softbody::*;

fn main() -> Result<(), SoftBodyError> {
    let args: Vec<String> = std::env::args().collect();
    let kind = match args.get(1).map(String::as_str) {
        Some("drop") => ScenarioKind::Drop,
        Some("squeeze") => ScenarioKind::Squeeze,
        Some("poke") => ScenarioKind::Poke,
        Some("pull") => ScenarioKind::Pull,
        _ => ScenarioKind::Rest,
    };
    let stiffness: f32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(20.0);
    let hz: f32 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(90.0);
    let mesh = Mesh::icosphere(0.1, 3);
    let cluster = match std::env::var("CLUSTER").as_deref() {
        Ok("distance") => ClusterMethod::Distance { radius_m: 0.012 },
        Ok("weighted") => ClusterMethod::WeightedDistance {
            radius_m: 0.012,
            soft_radius_m: 0.02,
        },
        Ok("poisson") => ClusterMethod::PoissonDisk {
            radius_m: 0.012,
            seed: 1,
        },
        _ => ClusterMethod::ClosestN {
            vertices_per_particle: 3,
        },
    };
    let cfg = SoftBodyConfig {
        stiffness,
        cluster,
        ..Default::default()
    };
    let mut s = Scenario::new(kind, &mesh, cfg, 1.0 / hz)?;
    let steps = (kind.duration_s() * hz) as usize;
    for i in 0..steps {
        s.step();
        if i % (hz as usize / 10) == 0 {
            let m = s.metrics();
            let v = s.soft_body().vertices();
            let (lo, hi) = softsync_softbody::mesh::bounds(v);
            println!(
                "t={:.2} vol={:.3} rms={:.4} maxd={:.4} ke={:.2e} ylo={:.3} yhi={:.3} xhi={:.3}",
                s.time_s(),
                m.volume_ratio,
                m.rest_rms_m,
                m.max_displacement_m,
                m.kinetic_energy_j,
                lo.y,
                hi.y,
                hi.x
            );
        }
    }
    Ok(())
}
