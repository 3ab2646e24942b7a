//! Cost of one hand per step with 1, 10 and 100 hovered candidates, and while holding a soft
//! body by a particle. `cargo run --release -p softsync-interaction --example bench -- [--quick]`
//! Writes `docs/results/interaction/step.csv`.
#![allow(
    clippy::disallowed_methods,
    clippy::unwrap_used,
    clippy::print_stdout,
    missing_docs
)]

use std::time::Instant;

use glam::{Quat, Vec3};
use softsync_benchkit::{median, Csv, ResultLine};
use softsync_interaction::*;
use softsync_softbody::rapier3d::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder};
use softsync_softbody::{ClusterMethod, Mesh, SimulationSpace, SoftBodyConfig, SoftBodySet};

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let reps = if quick { 300 } else { 3000 };
    let dt = 1.0 / 90.0;
    let mut lines = Vec::new();
    let mut csv = Csv::new(&["case", "us_per_hand_step"]);
    for n in [1usize, 10, 100] {
        let mut world = PhysicsWorld::new();
        world.gravity = Vec3::ZERO;
        // n small balls inside the hover sphere (radius 0.06) around the origin.
        for i in 0..n {
            let a = i as f32 * 2.399;
            let r = 0.05 * ((i as f32 + 0.5) / n as f32).sqrt();
            let h = world.insert_body(RigidBodyBuilder::dynamic().translation(Vec3::new(
                r * a.cos(),
                r * a.sin(),
                0.0,
            )));
            world.insert_collider(ColliderBuilder::ball(0.004), Some(h));
        }
        world.step();
        let mut soft = SoftBodySet::new();
        let mut hands = Interaction::new();
        let hand = hands.add_hand(HandConfig::default()).unwrap();
        let mut times = Vec::with_capacity(reps);
        for k in 0..reps {
            let input = HandInput {
                sample: HandSample {
                    position_m: Vec3::ZERO,
                    rotation: Quat::IDENTITY,
                    time_s: k as f64 * dt as f64,
                },
                grip: 0.0,
                trigger: 0.0,
            };
            let t = Instant::now();
            hands.set_input(hand, input).unwrap();
            hands.update(&mut world, &mut soft, &AllLocal, dt);
            times.push(t.elapsed().as_secs_f64() * 1e6);
        }
        assert_eq!(hands.hovered(hand).len(), n);
        let us = median(&times);
        println!("| hovered {n:>3} | {us:.2} µs |");
        lines.push(
            ResultLine::new("interaction.step")
                .field("hovered", n)
                .fixed("us", us, 2),
        );
        csv.row([format!("hovered={n}"), format!("{us:.2}")]);
    }
    // Holding one particle of a 2562-vertex soft body (the hold itself, without the body's step).
    let mut world = PhysicsWorld::new();
    let mut soft = SoftBodySet::new();
    let cfg = SoftBodyConfig {
        cluster: ClusterMethod::Distance { radius_m: 0.01 },
        space: SimulationSpace::Local,
        ..Default::default()
    };
    let h = soft
        .insert(&Mesh::icosphere(0.1, 4), cfg, &mut world)
        .unwrap();
    world.step();
    let start = soft
        .get(h)
        .unwrap()
        .particle_positions(&world)
        .into_iter()
        .max_by(|a, b| a.x.total_cmp(&b.x))
        .unwrap();
    let mut hands = Interaction::new();
    let hand = hands
        .add_hand(HandConfig {
            hover_radius_m: 0.01,
            ..Default::default()
        })
        .unwrap();
    let mut times = Vec::new();
    let mut step_times = Vec::new();
    for k in 0..reps.min(900) {
        let p = start + Vec3::X * 0.03 * ((k as f32 * 0.05).sin());
        let input = HandInput {
            sample: HandSample {
                position_m: p,
                rotation: Quat::IDENTITY,
                time_s: k as f64 * dt as f64,
            },
            grip: 1.0,
            trigger: 0.0,
        };
        let t = Instant::now();
        hands.set_input(hand, input).unwrap();
        hands.update(&mut world, &mut soft, &AllLocal, dt);
        times.push(t.elapsed().as_secs_f64() * 1e6);
        let t = Instant::now();
        soft.step(&mut world, dt);
        step_times.push(t.elapsed().as_secs_f64() * 1e6);
    }
    assert!(hands.held(hand).is_some());
    let us = median(&times);
    let body_us = median(&step_times);
    println!("| holding a soft-body particle | {us:.2} µs (body step {body_us:.0} µs) |");
    lines.push(
        ResultLine::new("interaction.step")
            .field("held", "soft_particle")
            .fixed("us", us, 2)
            .fixed("soft_step_us", body_us, 0)
            .fixed("frame_share_90hz", us / 11_111.0, 5),
    );
    csv.row(["held=soft_particle".to_string(), format!("{us:.2}")]);
    let out =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/results/interaction");
    std::fs::create_dir_all(&out).unwrap();
    csv.write(out.join("step.csv")).unwrap();
    for l in lines {
        println!("{l}");
    }
}
