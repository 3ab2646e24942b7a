//! `method: auto` at run time: a resolution switch in the middle of a squeeze shows no pop,
//! the probe orders the ladder, a resting body sleeps and skips its step, and something
//! moving into it wakes it.
#![allow(clippy::unwrap_used, missing_docs)]

use glam::Vec3;
use softsync_softbody::methods::auto::{AutoSettings, Ladder};
use softsync_softbody::rapier3d::prelude::*;
use softsync_softbody::{ClusterMethod, Mesh, SoftBodyConfig, SoftBodyHandle, SoftBodySet};

const DT: f32 = 1.0 / 60.0;

fn config(radius_m: f32) -> SoftBodyConfig {
    SoftBodyConfig {
        cluster: ClusterMethod::Distance { radius_m },
        stiffness: 15.0,
        ..SoftBodyConfig::default()
    }
}

/// A 10 cm soft box on a floor under a plate.
struct Press {
    world: PhysicsWorld,
    set: SoftBodySet,
    body: SoftBodyHandle,
    plate: RigidBodyHandle,
}

impl Press {
    fn new() -> Self {
        let mut world = PhysicsWorld::new();
        let floor =
            world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, -0.5, 0.0)));
        world.insert_collider(ColliderBuilder::cuboid(1.0, 0.5, 1.0), Some(floor));
        let plate = world.insert_body(
            RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(0.0, 0.12, 0.0)),
        );
        world.insert_collider(ColliderBuilder::cuboid(0.2, 0.005, 0.2), Some(plate));
        let mesh = Mesh::cuboid(Vec3::splat(0.05), 10);
        let mesh = Mesh {
            positions: mesh
                .positions
                .iter()
                .map(|p| *p + Vec3::Y * 0.052)
                .collect(),
            ..mesh
        };
        let mut set = SoftBodySet::new();
        let body = set.insert(&mesh, config(0.03), &mut world).unwrap();
        Press {
            world,
            set,
            body,
            plate,
        }
    }

    /// One step with the plate at height `y`; the mesh after it.
    fn step(&mut self, y: f32) -> Vec<Vec3> {
        self.world
            .bodies
            .get_mut(self.plate)
            .unwrap()
            .set_next_kinematic_translation(Vec3::new(0.0, y, 0.0));
        self.set.step(&mut self.world, DT);
        self.set.get(self.body).unwrap().vertices().to_vec()
    }
}

fn plate_y(step: u32) -> f32 {
    // down from 12 cm to 8 cm over 40 steps, then held
    0.12 - 0.04 * (step.min(40) as f32 / 40.0)
}

fn max_diff(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| x.distance(*y))
        .fold(0.0, f32::max)
}

#[test]
fn a_switch_to_a_finer_resolution_mid_squeeze_moves_no_vertex_more_than_a_millimetre() {
    // Two identical presses; one switches resolution at step 45 (squeezed), the other not.
    // The pop is how much more a vertex moves in a step than it does without the switch.
    let (mut a, mut b) = (Press::new(), Press::new());
    let n_before = a.set.get(a.body).unwrap().num_particles();
    let mut prev = Vec::new();
    for s in 0..45 {
        prev = a.step(plate_y(s));
        assert_eq!(prev, b.step(plate_y(s)), "the two runs are the same run");
    }
    let deepest = {
        let body = a.set.get(a.body).unwrap();
        body.activity(&a.world).max_displacement_m
    };
    assert!(deepest > 0.004, "squeezed: {deepest} m");
    a.body = a
        .set
        .reconfigure(a.body, &mut a.world, config(0.015))
        .unwrap();
    let switched = a.set.get(a.body).unwrap();
    assert!(switched.num_particles() > n_before);
    // at the switch, the mesh is where it was
    assert!(max_diff(switched.vertices(), &prev) < 1e-5);
    assert!(switched.is_blending());
    assert!(switched.blend_step_m() <= 0.0005 + 1e-6);
    let mut prev_b = prev.clone();
    let mut worst_pop = 0.0f32;
    let mut blend_steps = 0;
    for s in 45..400 {
        let blending = a.set.get(a.body).unwrap().is_blending();
        blend_steps += blending as u32;
        let va = a.step(plate_y(s));
        let vb = b.step(plate_y(s));
        if blending {
            let pop = va
                .iter()
                .zip(&prev)
                .zip(vb.iter().zip(&prev_b))
                .map(|((x1, x0), (y1, y0))| ((*x1 - *x0) - (*y1 - *y0)).length())
                .fold(0.0, f32::max);
            worst_pop = worst_pop.max(pop);
        }
        prev = va;
        prev_b = vb;
    }
    assert!(worst_pop < 1e-3, "pop {} mm", worst_pop * 1e3);
    // the blend ended: the shown mesh is the simulated one again
    assert!(!a.set.get(a.body).unwrap().is_blending());
    assert!(blend_steps > 1 && blend_steps < 300, "{blend_steps} steps");
    assert!(prev.iter().all(|v| v.is_finite()));
}

#[test]
fn a_torn_body_and_an_unknown_handle_are_refused_and_nothing_changes() {
    let mut p = Press::new();
    let n = p.set.len();
    let gone = p
        .set
        .reconfigure(p.body, &mut p.world, config(0.02))
        .unwrap();
    assert!(p
        .set
        .reconfigure(p.body, &mut p.world, config(0.02))
        .is_err());
    assert!(p.set.get(gone).is_some());
    assert_eq!(p.set.len(), n);
    let bad = SoftBodyConfig {
        stiffness: f32::NAN,
        ..config(0.02)
    };
    assert!(p.set.reconfigure(gone, &mut p.world, bad).is_err());
    assert!(p.set.get(gone).is_some());
    let seg = softsync_softbody::cut::TearSegment {
        from: Vec3::new(-0.03, 0.05, 0.0),
        to: Vec3::new(0.03, 0.05, 0.0),
        blade: Vec3::new(0.0, -0.03, 0.0),
    };
    p.set.tear(gone, &mut p.world, &seg).unwrap();
    let e = p
        .set
        .reconfigure(gone, &mut p.world, config(0.015))
        .unwrap_err();
    assert!(e.to_string().contains("torn"), "{e}");
    assert!(p.set.get(gone).is_some());
}

#[test]
fn the_probe_orders_the_ladder_and_picks_levels_within_the_budgets() {
    // a virtual clock: every reading 1 ms later than the last (time is an argument)
    fn clock() -> f64 {
        use std::sync::atomic::{AtomicU64, Ordering};
        static T: AtomicU64 = AtomicU64::new(0);
        T.fetch_add(1, Ordering::Relaxed) as f64
    }
    let mesh = Mesh::cuboid(Vec3::splat(0.05), 6);
    let settings = AutoSettings {
        error_budget_mm: 1000.0,
        cost_budget_ms: 1000.0,
        ..AutoSettings::default()
    };
    let mut ladder = Ladder::new(&mesh, &config(0.03), &settings).unwrap();
    assert_eq!(ladder.configs.len(), 3);
    assert!(ladder.particles[0] < ladder.particles[1] && ladder.particles[1] < ladder.particles[2]);
    ladder.probe(&mesh, &settings, clock).unwrap();
    let p = &ladder.probed;
    assert_eq!(
        p[2].error_mm, 0.0,
        "the finest level is the probe's reference"
    );
    assert!(p
        .iter()
        .all(|c| c.error_mm.is_finite() && c.cost_ms.is_finite()));
    assert!(p[0].error_mm > 0.0);
    // everything fits a lax budget: touch is the cheapest, squeeze the most accurate
    let cheapest = (0..3)
        .min_by(|&a, &b| p[a].cost_ms.total_cmp(&p[b].cost_ms))
        .unwrap();
    assert_eq!(ladder.touch, cheapest);
    assert_eq!(ladder.squeeze, 2);
    // a budget nothing but the finest meets: touch goes there; no cost budget: squeeze = touch
    let tight = AutoSettings {
        error_budget_mm: p[1].error_mm.min(p[0].error_mm) * 0.5,
        cost_budget_ms: 1e-3,
        ..AutoSettings::default()
    };
    ladder.pick(&tight);
    assert_eq!(ladder.touch, 2);
    assert_eq!(ladder.squeeze, 2);
}

#[test]
fn a_sleeping_body_skips_its_step_and_wakes_when_something_moves_into_it() {
    let mut p = Press::new();
    for _ in 0..120 {
        p.step(0.3);
    }
    p.set.get_mut(p.body).unwrap().sleep(&mut p.world);
    let before = p.step(0.3);
    assert!(p.set.get(p.body).unwrap().activity(&p.world).asleep);
    for _ in 0..30 {
        assert_eq!(p.step(0.3), before);
    }
    // the plate comes down on it: it wakes and deforms
    let mut moved = 0.0f32;
    for s in 0..60 {
        let v = p.step(0.3 - (0.3 - 0.085) * (s as f32 / 30.0).min(1.0));
        moved = moved.max(max_diff(&v, &before));
    }
    assert!(!p.set.get(p.body).unwrap().activity(&p.world).asleep);
    assert!(moved > 0.005, "moved {moved}");
    // and it rests where it did, on the floor under the plate, not through it
    let c = p.set.get(p.body).unwrap().center_pose(&p.world).0;
    assert!(c.y > 0.03 && c.y < 0.07, "center at {c}");
}
