//! Rolling resistance (`SoftBodyConfig::rolling_resistance`): a soft ball rolled across a
//! floor comes to rest, where without it rapier's ball center rolled for ever (a long room's
//! soft ball ended at the wall of the world); a thrown ball still flies its ballistic path.
#![allow(clippy::unwrap_used, missing_docs)]

use glam::Vec3;
use softsync_softbody::rapier3d::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder};
use softsync_softbody::*;

const HZ: f32 = 90.0;
const G: f32 = 9.81;

/// The thesis room's soft ball: 12 cm, 60 Poisson-disk particles.
fn ball() -> Mesh {
    Mesh::icosphere(0.06, 3)
}

fn ball_cfg(rolling_resistance: f32) -> SoftBodyConfig {
    SoftBodyConfig {
        cluster: ClusterMethod::PoissonDisk {
            radius_m: 0.0215,
            seed: 1,
        },
        rolling_resistance,
        ..Default::default()
    }
}

/// The ball with its center at `at` on a floor, moving at `v` and spinning at `w`.
fn world_with_ball(
    cfg: SoftBodyConfig,
    at: Vec3,
    v: Vec3,
    w: Vec3,
) -> (PhysicsWorld, SoftBodySet, SoftBodyHandle) {
    softsync_softbody::scenario::on_floor(&ball(), cfg, at, v, w).unwrap()
}

fn center(world: &PhysicsWorld, set: &SoftBodySet, h: SoftBodyHandle) -> (Vec3, Vec3) {
    let rb = world.bodies.get(set.get(h).unwrap().center()).unwrap();
    (rb.translation(), rb.linvel())
}

/// Rolls the ball along +x at `v0` (rolling, no slip) for `seconds`: (distance travelled, m;
/// speed at the end, m/s).
fn roll(rolling_resistance: f32, v0: f32, seconds: f32) -> (f32, f32) {
    let r = 0.06;
    let (mut world, mut set, h) = world_with_ball(
        ball_cfg(rolling_resistance),
        Vec3::new(0.0, r, 0.0),
        Vec3::new(v0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -v0 / r),
    );
    let x0 = center(&world, &set, h).0;
    for _ in 0..(seconds * HZ) as usize {
        set.step(&mut world, 1.0 / HZ);
    }
    let (x, v) = center(&world, &set, h);
    let d = Vec3::new(x.x - x0.x, 0.0, x.z - x0.z).length();
    (d, v.length())
}

#[test]
fn a_ball_pushed_at_half_a_metre_a_second_comes_to_rest_within_a_metre() {
    let (d, v) = roll(SoftBodyConfig::default().rolling_resistance, 0.5, 6.0);
    assert!(d < 1.0, "rolled {d:.3} m");
    assert!(d > 0.05, "did not roll at all: {d:.3} m");
    assert!(
        v < 1e-3,
        "still moving at {v:.4} m/s after 6 s (asleep is 0)"
    );
    // the model says a = 5/7 · μ_r · g: 0.5² / (2a) = 0.36 m at μ_r = 0.05
    let mu = SoftBodyConfig::default().rolling_resistance;
    let expected = 0.5f32.powi(2) / (2.0 * 5.0 / 7.0 * mu * G);
    assert!(
        (d - expected).abs() < 0.35 * expected,
        "rolled {d:.3} m, the model says {expected:.3} m"
    );
    // without it, rapier's ball rolls on: the defect this setting removes
    let (d0, v0) = roll(0.0, 0.5, 6.0);
    assert!(
        d0 > 2.0 && v0 > 0.3,
        "without rolling resistance: {d0:.3} m, {v0:.3} m/s"
    );
}

#[test]
fn a_thrown_ball_flies_its_ballistic_distance() {
    let r = 0.06;
    let (y0, vx, vy) = (1.0f32, 3.0f32, 2.0f32);
    // time until the center is one radius above the floor: y0 + vy t − g t²/2 = r
    let t_land = (vy + (vy * vy + 2.0 * G * (y0 - r)).sqrt()) / G;
    let ballistic = vx * t_land;
    for mu in [0.0, SoftBodyConfig::default().rolling_resistance, 1.0] {
        let (mut world, mut set, h) = world_with_ball(
            ball_cfg(mu),
            Vec3::new(0.0, y0, 0.0),
            Vec3::new(vx, vy, 0.0),
            Vec3::new(0.0, 0.0, -4.0),
        );
        let mut landed = None;
        for _ in 0..(3.0 * HZ) as usize {
            set.step(&mut world, 1.0 / HZ);
            let (c, _) = center(&world, &set, h);
            if c.y <= r + 0.005 {
                landed = Some(c.x);
                break;
            }
        }
        let x = landed.expect("the ball never landed");
        assert!(
            (x - ballistic).abs() < 0.1 * ballistic,
            "rolling resistance {mu}: landed at {x:.3} m, ballistic {ballistic:.3} m"
        );
    }
}

#[test]
fn rolling_resistance_out_of_range_is_refused_with_its_name() {
    let mut world = PhysicsWorld::new();
    let mut set = SoftBodySet::new();
    for bad in [-0.1, 1.5, f32::NAN] {
        let e = set.insert(&ball(), ball_cfg(bad), &mut world).unwrap_err();
        assert!(e.to_string().contains("rolling_resistance"), "{e}");
    }
}

/// A soft ball resting on a dynamic plate (the thesis room's plate on its table): the ball's
/// own particles keep the plate from sleeping and jiggle it a little, and the ball spins a
/// little in place. Rolling resistance must not stop that spin: the jiggling would then carry
/// the ball away (seen live: 11 mm in 20 s, where it used to stay within a fraction of one).
#[test]
fn a_ball_resting_on_a_jiggling_plate_stays_put() {
    let mut world = PhysicsWorld::new();
    let floor = world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, -0.5, 0.0)));
    world.insert_collider(
        ColliderBuilder::cuboid(20.0, 0.5, 20.0).friction(0.5),
        Some(floor),
    );
    let plate = world.insert_body(
        RigidBodyBuilder::dynamic()
            .translation(Vec3::new(0.0, 0.011, 0.0))
            .linear_damping(0.05)
            .angular_damping(0.2),
    );
    world.insert_collider(
        ColliderBuilder::cylinder(0.01, 0.12)
            .density(800.0)
            .friction(0.5),
        Some(plate),
    );
    let mut mesh = ball();
    for p in &mut mesh.positions {
        *p += Vec3::new(0.0, 0.092, 0.0);
    }
    let mut set = SoftBodySet::new();
    let h = set
        .insert(
            &mesh,
            ball_cfg(SoftBodyConfig::default().rolling_resistance),
            &mut world,
        )
        .unwrap();
    for _ in 0..(3.0 * HZ) as usize {
        set.step(&mut world, 1.0 / HZ);
    }
    let settled = center(&world, &set, h).0;
    for _ in 0..(20.0 * HZ) as usize {
        set.step(&mut world, 1.0 / HZ);
    }
    let moved = center(&world, &set, h).0.distance(settled);
    assert!(
        moved < 0.002,
        "the ball moved {:.1} mm in 20 s",
        moved * 1e3
    );
}
