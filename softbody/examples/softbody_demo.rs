//! Headless soft-body demo: the bunny, an icosphere and a soft box dropped on a table in one
//! rapier world; a plate squeezes the bunny; prints what it simulates twice a second.
//!
//! `cargo run --release -p softsync-softbody --example softbody_demo -- [--seconds 6] [--hz 90]`
#![allow(
    clippy::disallowed_methods,
    clippy::unwrap_used,
    clippy::print_stdout,
    missing_docs
)]

use std::path::PathBuf;

use glam::{Quat, Vec3};
use softsync_softbody::metrics::measure;
use softsync_softbody::rapier3d::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder};
use softsync_softbody::{ClusterMethod, Mesh, Placement, SoftBodyConfig, SoftBodySet};

fn arg(name: &str, default: f32) -> f32 {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let seconds = arg("--seconds", 6.0);
    let hz = arg("--hz", 90.0);
    let dt = 1.0 / hz;
    let mut world = PhysicsWorld::new();
    // Table top at y = 0.75 m.
    let table =
        world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, 0.725, 0.0)));
    world.insert_collider(
        ColliderBuilder::cuboid(0.8, 0.025, 0.5).friction(0.8),
        Some(table),
    );
    let mut set = SoftBodySet::new();
    let assets = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let bunny = Mesh::load(assets.join("bunny.obj")).unwrap().fit_size(0.2);
    let bunny = bunny.bake(&Placement {
        translation_m: Vec3::new(-0.3, 1.0, 0.0),
        rotation: Quat::from_rotation_y(0.5),
        ..Default::default()
    });
    let ico = Mesh::icosphere(0.08, 3).bake(&Placement {
        translation_m: Vec3::new(0.0, 1.1, 0.0),
        ..Default::default()
    });
    let cube = Mesh::cuboid(Vec3::splat(0.07), 6).bake(&Placement {
        translation_m: Vec3::new(0.3, 0.95, 0.0),
        ..Default::default()
    });
    let bodies = [
        (
            "bunny",
            set.insert(
                &bunny,
                SoftBodyConfig {
                    cluster: ClusterMethod::WeightedDistance {
                        radius_m: 0.012,
                        soft_radius_m: 0.02,
                    },
                    stiffness: 15.0,
                    ..Default::default()
                },
                &mut world,
            )
            .unwrap(),
        ),
        (
            "icosphere",
            set.insert(
                &ico,
                SoftBodyConfig {
                    cluster: ClusterMethod::Distance { radius_m: 0.015 },
                    stiffness: 30.0,
                    ..Default::default()
                },
                &mut world,
            )
            .unwrap(),
        ),
        (
            "soft_box",
            set.insert(
                &cube,
                SoftBodyConfig {
                    cluster: ClusterMethod::PoissonDisk {
                        radius_m: 0.02,
                        seed: 1,
                    },
                    center_collider: softsync_softbody::CenterCollider::ConvexHull,
                    stiffness: 40.0,
                    ..Default::default()
                },
                &mut world,
            )
            .unwrap(),
        ),
    ];
    for (name, h) in &bodies {
        let b = set.get(*h).unwrap();
        println!(
            "{name}: {} vertices, {} particles, rest volume {:.1} cm³",
            b.vertices().len(),
            b.num_particles(),
            b.rest_volume_m3() * 1e6
        );
    }
    // A kinematic plate that comes down on the bunny between 2 s and 3 s, then lifts.
    let plate = world.insert_body(
        RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(-0.3, 1.3, 0.0)),
    );
    world.insert_collider(ColliderBuilder::cuboid(0.15, 0.01, 0.15), Some(plate));
    let steps = (seconds * hz) as usize;
    let mut worst_ms = 0.0f64;
    let mut total_ms = 0.0f64;
    for i in 0..steps {
        let t = i as f32 * dt;
        let down = ((t - 2.0) / 0.6).clamp(0.0, 1.0) - ((t - 3.2) / 0.4).clamp(0.0, 1.0);
        // Down to 9 cm above the table: the bunny (about 19 cm tall) is pressed to half height.
        let y = 1.3 - down * (1.3 - 0.85);
        if let Some(p) = world.bodies.get_mut(plate) {
            p.set_next_kinematic_translation(Vec3::new(-0.3, y, 0.0));
        }
        let start = std::time::Instant::now();
        set.step(&mut world, dt);
        let ms = start.elapsed().as_secs_f64() * 1e3;
        worst_ms = worst_ms.max(ms);
        total_ms += ms;
        if (i + 1) % (hz as usize / 2) == 0 {
            let mut line = format!("t={:4.1}s", t + dt);
            for (name, h) in &bodies {
                let b = set.get(*h).unwrap();
                let m = measure(b, &world);
                let (c, _) = b.center_pose(&world);
                line += &format!(
                    " | {name} y={:.3} vol={:.2} shape_err={:.1}mm",
                    c.y,
                    m.volume_ratio,
                    m.rest_rms_m * 1e3
                );
            }
            println!("{line}");
        }
    }
    println!(
        "{steps} steps at {hz} Hz: mean {:.3} ms/step, worst {:.3} ms",
        total_ms / steps as f64,
        worst_ms
    );
}
