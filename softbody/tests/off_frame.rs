//! Bodies built off the frame (`BodyBuild`): a piece replayed on a worker from its class's
//! plan through tears and a cut is the body the frame would have built — the same mesh, the
//! same particles, at the same places — and moving a body between worlds keeps it as it was.
//! A history that cannot be replayed is refused, and the world it would land in is untouched.
#![allow(clippy::unwrap_used, missing_docs)]

use glam::{Quat, Vec3};
use softsync_softbody::cut::{topology_hash, CutPlane, TearSegment};
use softsync_softbody::rapier3d::prelude::PhysicsWorld;
use softsync_softbody::*;

fn bunny() -> Mesh {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj");
    let mut m = Mesh::load(path).unwrap().fit_size(0.2);
    m.recenter();
    m
}

fn history() -> Vec<BuildStep> {
    // a 2 cm tear across the top, lifted, then a cut through the middle keeping piece 1
    let tear = |x0: f32, x1: f32| {
        BuildStep::Tear(TearSegment {
            from: Vec3::new(x0, 0.05, 0.0),
            to: Vec3::new(x1, 0.05, 0.0),
            blade: Vec3::new(0.0, 0.04, 0.0),
        })
    };
    vec![
        tear(-0.01, 0.0),
        tear(0.0, 0.01),
        BuildStep::Lift,
        BuildStep::Cut {
            plane: CutPlane::new(Vec3::ZERO, Vec3::new(1.0, 0.2, 0.1)).unwrap(),
            keep: 1,
        },
    ]
}

fn hash(set: &SoftBodySet, h: SoftBodyHandle) -> u64 {
    let b = set.get(h).unwrap();
    topology_hash(
        &Mesh {
            positions: b.rest_vertices().to_vec(),
            normals: None,
            triangles: b.welded().triangles.clone(),
        },
        1e-5,
    )
}

#[test]
fn a_piece_built_off_the_frame_is_the_piece_the_frame_builds() {
    let plan = SoftBodyPlan::new(&bunny(), SoftBodyConfig::default()).unwrap();
    let (pos, rot) = (Vec3::new(0.3, 1.0, -0.2), Quat::from_rotation_y(0.7));
    // in the frame
    let (mut set, mut world) = (SoftBodySet::new(), PhysicsWorld::new());
    let mut h = set.insert_plan_at(&plan, &mut world, pos, rot).unwrap();
    for s in history() {
        h = s.apply(&mut set, &mut world, h).unwrap();
    }
    // off it, landing in a world that has another body already
    let (mut set2, mut world2) = (SoftBodySet::new(), PhysicsWorld::new());
    let other = set2.insert_plan_at(&plan, &mut world2, -pos, rot).unwrap();
    let before = world2.bodies.len();
    let job = BodyBuild::start(plan.clone(), pos, rot, history());
    let h2 = job.land(&mut set2, &mut world2).unwrap();
    let (a, b) = (set.get(h).unwrap(), set2.get(h2).unwrap());
    assert_eq!(hash(&set, h), hash(&set2, h2));
    assert_eq!(a.num_particles(), b.num_particles());
    assert!(a.num_particles() > 10 && a.num_particles() < plan.num_particles());
    assert_eq!(
        a.particle_positions(&world),
        b.particle_positions(&world2),
        "the same particles at the same places"
    );
    assert_eq!(a.center_pose(&world), b.center_pose(&world2));
    assert_eq!(world2.bodies.len(), before + 1 + b.num_particles());
    // it is a body of its new set: it steps, and its bodies are known as its parts
    let p0 = b.particles()[0];
    assert_eq!(set2.part_of(p0), Some(SoftPart::Particle(h2, 0)));
    assert!(set2.get(other).is_some());
    for _ in 0..30 {
        set.step(&mut world, 1.0 / 60.0);
        set2.step(&mut world2, 1.0 / 60.0);
    }
    let (a, b) = (set.get(h).unwrap(), set2.get(h2).unwrap());
    let gap = a
        .particle_positions(&world)
        .iter()
        .zip(b.particle_positions(&world2))
        .map(|(x, y)| x.distance(y))
        .fold(0.0f32, f32::max);
    // both fell freely for half a second (the other body in world2 is 40 cm away)
    assert!(
        gap < 1e-3,
        "the moved body simulates as the one built here: {gap} m apart"
    );
    assert!(a.center_pose(&world).0.y < pos.y - 0.5);
}

#[test]
fn a_history_that_cannot_be_replayed_is_refused_and_lands_nothing() {
    let plan = SoftBodyPlan::new(&bunny(), SoftBodyConfig::default()).unwrap();
    let miss = BuildStep::Cut {
        plane: CutPlane::new(Vec3::new(0.0, 5.0, 0.0), Vec3::Y).unwrap(),
        keep: 0,
    };
    let past = BuildStep::Cut {
        plane: CutPlane::new(Vec3::ZERO, Vec3::X).unwrap(),
        keep: 7,
    };
    for steps in [vec![miss], vec![BuildStep::Lift, past]] {
        let (mut set, mut world) = (SoftBodySet::new(), PhysicsWorld::new());
        let job = BodyBuild::start(plan.clone(), Vec3::ZERO, Quat::IDENTITY, steps);
        let e = job.land(&mut set, &mut world).unwrap_err();
        assert!(e.contains("history entry"), "{e}");
        assert_eq!(world.bodies.len(), 0);
        assert_eq!(set.len(), 0);
    }
}
