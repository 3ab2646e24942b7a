//! A body at rest costs one bounds query a step: after it settles, every particle sleeps and
//! the steps neither restore nor deform it (counted with `SoftBody::work`, not timed). Both at
//! the default settings and with the thesis room's bunny (coarser clusters, softer), whose
//! particles pressed into the table never stopped moving by a few µm in rapier's eyes.
#![allow(clippy::unwrap_used, missing_docs)]

use glam::Vec3;
use softsync_softbody::rapier3d::prelude::{ColliderBuilder, PhysicsWorld};
use softsync_softbody::{ClusterMethod, Mesh, SoftBodyConfig, SoftBodySet};

#[test]
fn a_bunny_resting_on_a_table_falls_asleep_and_its_steps_skip_it() {
    let room = SoftBodyConfig {
        cluster: ClusterMethod::Distance { radius_m: 0.03 },
        stiffness: 20.0,
        ..SoftBodyConfig::default()
    };
    for (name, config) in [("default", SoftBodyConfig::default()), ("room", room)] {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj");
        let mut mesh = Mesh::load(path).unwrap().fit_size(0.16);
        mesh.recenter();
        let lift = Vec3::new(0.0, 0.84, 0.0);
        let mesh = Mesh {
            positions: mesh.positions.iter().map(|p| *p + lift).collect(),
            ..mesh
        };
        let mut world = PhysicsWorld::new();
        world.insert_collider(
            ColliderBuilder::cuboid(0.6, 0.02, 0.4).translation(Vec3::new(0.0, 0.73, 0.0)),
            None,
        );
        let mut set = SoftBodySet::new();
        let h = set.insert(&mesh, config, &mut world).unwrap();
        let dt = 1.0 / 90.0;
        for _ in 0..(90 * 3) {
            set.step(&mut world, dt);
        }
        let before = set.get(h).unwrap().work();
        let at = set.get(h).unwrap().center_pose(&world).0;
        for _ in 0..(90 * 5) {
            set.step(&mut world, dt);
        }
        let b = set.get(h).unwrap();
        let asleep = b
            .particles()
            .iter()
            .filter(|p| world.bodies.get(**p).unwrap().is_sleeping())
            .count();
        assert_eq!(asleep, b.particles().len(), "{name}: particles awake");
        let after = b.work();
        assert_eq!(after, before, "{name}: 5 s at rest still cost steps");
        // asleep where it rested, on the table
        assert!(b.center_pose(&world).0.distance(at) < 1e-4, "{name}: moved");
        assert!(at.y > 0.78, "{name}: not on the table: {at}");
    }
}

#[test]
fn a_replica_shown_at_the_same_state_keeps_its_mesh_and_a_new_state_deforms_it() {
    // A replica (a body another peer simulates) is placed at a state before each step and
    // has its mesh updated after it: at the same state again, the mesh is kept (deforming it
    // would give the same vertices); at another, it is deformed to it.
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj");
    let mut mesh = Mesh::load(path).unwrap().fit_size(0.16);
    mesh.recenter();
    let mut world = PhysicsWorld::new();
    let mut set = SoftBodySet::new();
    let h = set
        .insert(&mesh, SoftBodyConfig::default(), &mut world)
        .unwrap();
    let b = set.get_mut(h).unwrap();
    b.set_replica(&mut world, true);
    let (c, r) = b.center_pose(&world);
    let ps = b.particle_positions(&world);
    let dt = 1.0 / 90.0;
    let frame = |set: &mut SoftBodySet, world: &mut PhysicsWorld, shift: Vec3| {
        let moved: Vec<Vec3> = ps.iter().map(|p| *p + shift).collect();
        let b = set.get_mut(h).unwrap();
        b.place_state(world, c + shift, r, &moved).unwrap();
        set.step(world, dt);
        let b = set.get_mut(h).unwrap();
        b.update_mesh(world);
        (b.work(), b.vertices().to_vec())
    };
    let (w0, v0) = frame(&mut set, &mut world, Vec3::ZERO);
    let (w1, v1) = frame(&mut set, &mut world, Vec3::ZERO);
    assert_eq!(
        w1.deformations, w0.deformations,
        "the same state deformed again"
    );
    assert_eq!(w1.meshes_kept, w0.meshes_kept + 1);
    assert_eq!(v1, v0);
    let shift = Vec3::new(0.0, 0.05, 0.0);
    let (w2, v2) = frame(&mut set, &mut world, shift);
    assert_eq!(
        w2.deformations,
        w1.deformations + 1,
        "a new state not deformed"
    );
    for (a, b) in v1.iter().zip(&v2) {
        assert!((*b - *a - shift).length() < 1e-4, "{a} -> {b}");
    }
}
