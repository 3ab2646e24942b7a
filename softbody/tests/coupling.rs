//! Position-based bodies push back (two-way coupling with rapier): a rigid box dropped on each
//! of them rests on it instead of falling through, and a palm lifting one feels its weight.
#![allow(clippy::unwrap_used, missing_docs)]

use glam::Vec3;
use softsync_softbody::methods::builders::build_pbd;
use softsync_softbody::methods::pbd::PbdBody;
use softsync_softbody::methods::{step_models, DeformableModel, MethodKind, MethodSpec};
use softsync_softbody::rapier3d::prelude::{
    ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
};
use softsync_softbody::Mesh;

const DT: f32 = 1.0 / 60.0;

/// The position-based methods at their default budget (4 substeps × 4 iterations), and the
/// reference at its small steps.
fn position_based() -> Vec<MethodSpec> {
    vec![
        MethodSpec::new(MethodKind::Surface).budget(4, 4),
        MethodSpec::new(MethodKind::Ispc).budget(4, 4),
        MethodSpec::new(MethodKind::Tet).budget(4, 4),
        MethodSpec::new(MethodKind::ShapeMatching).budget(4, 4),
        MethodSpec::new(MethodKind::NeoHookean)
            .cell(0.2)
            .budget(20, 1),
    ]
}

/// A soft 0.2 m cube resting on a floor (top at y = 0) and an 8 cm, `box_kg` box released
/// 3 cm above it; returns the box's lowest bottom height over the last second of `seconds`
/// and its speed at the end.
fn drop_box_on(spec: &MethodSpec, box_kg: f32, seconds: f32) -> (f32, f32) {
    let mut world = PhysicsWorld::new();
    world.integration_parameters.dt = DT;
    let floor = world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, -0.5, 0.0)));
    world.insert_collider(ColliderBuilder::cuboid(5.0, 0.5, 5.0), Some(floor));
    let mut mesh = Mesh::cuboid(Vec3::splat(0.1), 8);
    for p in &mut mesh.positions {
        p.y += 0.1 + 0.003;
    }
    let body: Box<dyn DeformableModel> = Box::new(build_pbd(spec, &mesh).unwrap());
    let mut models = vec![body];
    let half = 0.04;
    let b: RigidBodyHandle = world.insert_body(RigidBodyBuilder::dynamic().translation(Vec3::new(
        0.0,
        0.2 + 0.03 + half,
        0.0,
    )));
    world.insert_collider(
        ColliderBuilder::cuboid(half, half, half).mass(box_kg),
        Some(b),
    );
    let steps = (seconds / DT) as usize;
    let mut lowest = f32::MAX;
    for i in 0..steps {
        step_models(&mut world, &mut models, DT);
        if i + 60 >= steps {
            lowest = lowest.min(world.bodies[b].translation().y - half);
        }
    }
    (lowest, world.bodies[b].linvel().length())
}

/// A 300 g box dropped on each position-based body comes to rest on it (the body's top is at
/// 0.2 m; it may dent it): without the coupling it falls through to the floor, which the same
/// test with the coupling off checks, so the test cannot pass by accident.
#[test]
fn a_rigid_box_rests_on_each_position_based_body() {
    for spec in position_based() {
        let (lowest, speed) = drop_box_on(&spec, 0.3, 2.0);
        println!(
            "{}: box bottom at least {lowest:.3} m over the last second, speed {speed:.3} m/s",
            spec.label()
        );
        assert!(
            lowest > 0.15,
            "{}: the box sank to {lowest} m (the body's top is at 0.2 m)",
            spec.label()
        );
        assert!(
            speed < 0.3,
            "{}: the box still moves at {speed} m/s",
            spec.label()
        );
    }
    let mut one_way = MethodSpec::new(MethodKind::Tet).budget(4, 4);
    one_way.params.two_way = false;
    let (lowest, _) = drop_box_on(&one_way, 0.3, 2.0);
    assert!(
        lowest < 0.05,
        "without the coupling the box should fall through, but it is at {lowest} m"
    );
}

/// A palm (a kinematic slab) under a soft body lifts it slowly: the force the body's contacts
/// report on the palm is the body's weight, within 20 %.
#[test]
fn a_palm_lifting_a_soft_body_feels_its_weight() {
    let mut world = PhysicsWorld::new();
    world.integration_parameters.dt = DT;
    let palm = world.insert_body(
        RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(0.0, -0.01, 0.0)),
    );
    let palm_collider = world.insert_collider(ColliderBuilder::cuboid(0.2, 0.01, 0.2), Some(palm));
    let mut mesh = Mesh::icosphere(0.1, 2);
    for p in &mut mesh.positions {
        p.y += 0.1 + 0.003;
    }
    let spec = MethodSpec::new(MethodKind::Ispc).budget(4, 4);
    let mut body: PbdBody = build_pbd(&spec, &mesh).unwrap();
    let weight_n = {
        let w = mesh.weld(1e-6);
        softsync_softbody::mesh::enclosed_volume(&w.positions, &w.triangles)
            * spec.material.density_kg_m3
            * 9.81
    };
    let mut felt = Vec::new();
    for i in 0..120 {
        // Rest for 0.5 s, then lift at 5 cm/s.
        let t = i as f32 * DT;
        let y = -0.01 + 0.05 * (t - 0.5).max(0.0);
        world.bodies[palm].set_next_kinematic_translation(Vec3::new(0.0, y, 0.0));
        world.step();
        body.step(&world, DT);
        body.push_back(&mut world);
        if t > 1.2 {
            let f: Vec3 = body
                .contact_forces()
                .filter(|(h, _)| *h == palm_collider)
                .map(|(_, f)| f)
                .sum();
            felt.push(-f.y);
        }
    }
    let mean = felt.iter().sum::<f32>() / felt.len() as f32;
    println!("weight {weight_n:.1} N, felt {mean:.1} N (mean over the lift)");
    assert!(
        (mean - weight_n).abs() < 0.2 * weight_n,
        "the palm felt {mean} N of a {weight_n} N body"
    );
}

/// A lever: a 0.5 m bar (`LEVER_KG`) on a hinge about z at its middle, 0.3 m up, level and
/// balanced; `drop` is called with the world and the x of the point over its right arm, and
/// steps the world with whatever it dropped there. Returns the bar's most negative turn about
/// z (its right arm going down), degrees, over `seconds`.
fn lever_turn(
    seconds: f32,
    drop: impl FnOnce(&mut PhysicsWorld, f32) -> Box<dyn FnMut(&mut PhysicsWorld)>,
) -> f32 {
    use softsync_softbody::rapier3d::prelude::RevoluteJointBuilder;
    let mut world = PhysicsWorld::new();
    world.integration_parameters.dt = DT;
    let pivot = Vec3::new(0.0, 0.3, 0.0);
    let anchor = world.insert_body(RigidBodyBuilder::fixed().translation(pivot));
    let bar = world.insert_body(RigidBodyBuilder::dynamic().translation(pivot));
    world.insert_collider(
        ColliderBuilder::cuboid(0.25, 0.01, 0.05).mass(LEVER_KG),
        Some(bar),
    );
    world.insert_impulse_joint(anchor, bar, RevoluteJointBuilder::new(Vec3::Z));
    let mut step = drop(&mut world, 0.17);
    for _ in 0..(seconds / DT).round() as usize {
        step(&mut world);
    }
    let arm = *world.bodies[bar].rotation() * Vec3::X;
    arm.y.atan2(arm.x).to_degrees()
}

/// The same lever under a rigid 10 cm cube of `kg`, released as the soft ones are.
fn rigid_cube_on_lever(kg: f32, seconds: f32) -> f32 {
    lever_turn(seconds, move |world, x| {
        let b = world.insert_body(RigidBodyBuilder::dynamic().translation(Vec3::new(
            x,
            0.31 + 0.05 + 0.01,
            0.0,
        )));
        world.insert_collider(ColliderBuilder::cuboid(0.05, 0.05, 0.05).mass(kg), Some(b));
        Box::new(|world: &mut PhysicsWorld| world.step())
    })
}

const LEVER_KG: f32 = 0.2;

/// A 10 cm soft cube of `spec` released 1 cm over the lever's right arm.
fn soft_cube_on_lever(spec: MethodSpec, seconds: f32) -> f32 {
    lever_turn(seconds, move |_, x| {
        let mut mesh = Mesh::cuboid(Vec3::splat(0.05), 6);
        for p in &mut mesh.positions {
            *p += Vec3::new(x, 0.31 + 0.05 + 0.01, 0.0);
        }
        let body: Box<dyn DeformableModel> = Box::new(build_pbd(&spec, &mesh).unwrap());
        let mut models = vec![body];
        Box::new(move |world: &mut PhysicsWorld| step_models(world, &mut models, DT))
    })
}

/// Two-way coupling gives back the contacts' torque: a soft cube dropped on one arm of a
/// balanced lever turns it as a rigid cube of the same mass does (within 15 % after 0.3 s —
/// measured 93–99° against 97°), for every position-based method. A linear-only coupling
/// could not turn it at all: the hinge holds the bar's centre, where a linear impulse acts.
/// Without the coupling the bar does not move, which the same test checks, so it cannot pass
/// by accident.
#[test]
fn a_soft_body_dropped_on_a_lever_turns_it() {
    for spec in position_based() {
        let turn = soft_cube_on_lever(spec, 0.3);
        let rigid = rigid_cube_on_lever(spec.material.density_kg_m3 * 1e-3, 0.3);
        println!(
            "{}: the lever turned {turn:.1}° (under a rigid cube of its mass {rigid:.1}°)",
            spec.label()
        );
        assert!(
            turn < -10.0 && (turn - rigid).abs() < 0.15 * rigid.abs(),
            "{}: the lever turned {turn:.1}° under the body, {rigid:.1}° under a rigid cube of its mass",
            spec.label()
        );
    }
    let mut one_way = MethodSpec::new(MethodKind::Tet).budget(4, 4);
    one_way.params.two_way = false;
    let turn = soft_cube_on_lever(one_way, 0.3);
    assert!(
        turn.abs() < 0.5,
        "without the coupling the lever should stay level, but it turned {turn}°"
    );
}

/// The thesis's particle method turns it too: its particles are rapier bodies, so rapier's
/// own contacts carry the torque.
#[test]
fn a_particle_body_dropped_on_a_lever_turns_it() {
    let turn = lever_turn(0.3, |world, x| {
        let mut mesh = Mesh::cuboid(Vec3::splat(0.05), 6);
        for p in &mut mesh.positions {
            *p += Vec3::new(x, 0.31 + 0.05 + 0.01, 0.0);
        }
        let mut set = softsync_softbody::SoftBodySet::new();
        set.insert(&mesh, softsync_softbody::SoftBodyConfig::default(), world)
            .unwrap();
        Box::new(move |world: &mut PhysicsWorld| set.step(world, DT))
    });
    println!("particle: the lever turned {turn:.1}°");
    assert!(turn < -10.0, "the lever turned only {turn:.1}°");
}
