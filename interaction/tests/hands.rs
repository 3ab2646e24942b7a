//! Hand interaction behaviour (thesis chapter 4, Table 1) on real rapier worlds.
#![allow(clippy::unwrap_used, missing_docs)]

use glam::{Quat, Vec3};
use softsync_interaction::*;
use softsync_softbody::rapier3d::prelude::{
    ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
};
use softsync_softbody::{ClusterMethod, Mesh, SimulationSpace, SoftBodyConfig, SoftBodySet};

const DT: f32 = 1.0 / 90.0;

struct Rig {
    world: PhysicsWorld,
    soft: SoftBodySet,
    hands: Interaction,
    hand: HandId,
    t: f64,
}

impl Rig {
    fn new(config: HandConfig) -> Self {
        let mut hands = Interaction::new();
        let hand = hands.add_hand(config).unwrap();
        Rig {
            world: PhysicsWorld::new(),
            soft: SoftBodySet::new(),
            hands,
            hand,
            t: 0.0,
        }
    }

    fn wall_at(&mut self, x: f32) {
        let w = self
            .world
            .insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(x + 0.05, 1.0, 0.0)));
        self.world
            .insert_collider(ColliderBuilder::cuboid(0.05, 1.0, 1.0), Some(w));
    }

    fn boxed(&mut self, at: Vec3, half: f32, density: f32) -> RigidBodyHandle {
        let b = self
            .world
            .insert_body(RigidBodyBuilder::dynamic().translation(at));
        self.world.insert_collider(
            ColliderBuilder::cuboid(half, half, half).density(density),
            Some(b),
        );
        b
    }

    /// One fixed step with the hand at `pos` and `grip`.
    fn step(&mut self, pos: Vec3, grip: f32, own: &dyn Ownership) {
        self.t += DT as f64;
        let input = HandInput {
            sample: HandSample {
                position_m: pos,
                rotation: Quat::IDENTITY,
                time_s: self.t,
            },
            grip,
            trigger: 0.0,
        };
        self.hands.set_input(self.hand, input).unwrap();
        self.hands.update(&mut self.world, &mut self.soft, own, DT);
        self.soft.step(&mut self.world, DT);
    }

    fn x(&self, b: RigidBodyHandle) -> Vec3 {
        self.world.bodies.get(b).unwrap().translation()
    }

    fn events(&mut self) -> Vec<InteractionEvent> {
        std::iter::from_fn(|| self.hands.poll_event()).collect()
    }
}

/// Grab a box at the origin (raised to y = 1), drag the hand to x = 1.5 through a wall at
/// x = 0.5; returns (final box x, box velocity right after release while moving).
fn drag_through_wall(mode: HoldMode) -> (f32, Vec3) {
    let mut r = Rig::new(HandConfig {
        hold_mode: mode,
        ..Default::default()
    });
    r.wall_at(0.5);
    let b = r.boxed(Vec3::new(0.0, 1.0, 0.0), 0.05, 100.0);
    r.world.step(); // the broad phase learns the collider
    r.step(Vec3::new(0.0, 1.0, 0.0), 1.0, &AllLocal);
    assert_eq!(r.hands.held(r.hand), Some(Target::Rigid(b)));
    for i in 0..90 {
        let x = 1.5 * (i as f32 + 1.0) / 90.0;
        r.step(Vec3::new(x, 1.0, 0.0), 1.0, &AllLocal);
    }
    let x = r.x(b).x;
    // Release while moving back toward the origin at 1 m/s.
    let mut hx = r.x(b).x;
    for _ in 0..5 {
        hx -= DT;
        r.step(Vec3::new(hx, 1.0, 0.0), 1.0, &AllLocal);
    }
    r.t += DT as f64;
    let input = HandInput {
        sample: HandSample {
            position_m: Vec3::new(hx - DT, 1.0, 0.0),
            rotation: Quat::IDENTITY,
            time_s: r.t,
        },
        grip: 0.0,
        trigger: 0.0,
    };
    r.hands.set_input(r.hand, input).unwrap();
    r.hands.update(&mut r.world, &mut r.soft, &AllLocal, DT);
    (x, r.world.bodies.get(b).unwrap().linvel())
}

/// Table 1 of the thesis as a test table: velocity hold vs parent hold.
#[test]
fn table_1_velocity_hold_vs_parent_hold() {
    struct Row {
        mode: HoldMode,
        passes_wall: bool,
        throws: bool,
    }
    for row in [
        Row {
            mode: HoldMode::Velocity,
            passes_wall: false,
            throws: true,
        },
        Row {
            mode: HoldMode::Parent,
            passes_wall: true,
            throws: false,
        },
    ] {
        let (x, v) = drag_through_wall(row.mode);
        let passed = x > 0.5;
        assert_eq!(
            passed, row.passes_wall,
            "{:?}: box ended at x = {x}",
            row.mode
        );
        if !passed {
            assert!(
                x > 0.40 && x < 0.46,
                "{:?}: box should rest against the wall, at {x}",
                row.mode
            );
        }
        let threw = v.length() > 0.5;
        assert_eq!(threw, row.throws, "{:?}: release velocity {v}", row.mode);
    }
}

#[test]
fn thrown_velocity_is_the_mean_of_the_last_three_samples() {
    let mut r = Rig::new(HandConfig::default());
    r.world.gravity = Vec3::ZERO;
    let b = r.boxed(Vec3::ZERO, 0.03, 100.0);
    r.world.step();
    r.step(Vec3::ZERO, 1.0, &AllLocal);
    assert_eq!(r.hands.held(r.hand), Some(Target::Rigid(b)));
    // Accelerating hand: positions 0.5·a·t², so sample velocities differ.
    let mut positions = Vec::new();
    for i in 1..=20 {
        let t = i as f32 * DT;
        let p = Vec3::new(0.5 * 8.0 * t * t, 0.2 * t, 0.0);
        positions.push(p);
        r.step(p, 1.0, &AllLocal);
    }
    let t = 21.0 * DT;
    let p = Vec3::new(0.5 * 8.0 * t * t, 0.2 * t, 0.0);
    positions.push(p);
    r.t += DT as f64;
    r.hands
        .set_input(
            r.hand,
            HandInput {
                sample: HandSample {
                    position_m: p,
                    rotation: Quat::IDENTITY,
                    time_s: r.t,
                },
                grip: 0.0,
                trigger: 0.0,
            },
        )
        .unwrap();
    r.hands.update(&mut r.world, &mut r.soft, &AllLocal, DT);
    let n = positions.len();
    let expected = ((positions[n - 1] - positions[n - 2])
        + (positions[n - 2] - positions[n - 3])
        + (positions[n - 3] - positions[n - 4]))
        / (3.0 * DT);
    let v = r.world.bodies.get(b).unwrap().linvel();
    assert!(
        (v - expected).length() <= 0.01 * expected.length(),
        "thrown {v}, expected {expected}"
    );
    let released = r.events().into_iter().find_map(|e| match e {
        InteractionEvent::Released { velocity_mps, .. } => Some(velocity_mps),
        _ => None,
    });
    assert_eq!(released, Some(v));
    // And the body carries it on (no gravity here).
    r.world.step();
    assert!(
        (r.world.bodies.get(b).unwrap().linvel() - expected).length() <= 0.01 * expected.length()
    );
}

#[test]
fn the_closest_of_overlapping_candidates_is_picked() {
    let mut r = Rig::new(HandConfig {
        hover_radius_m: 0.1,
        ..Default::default()
    });
    r.world.gravity = Vec3::ZERO;
    let far = r.boxed(Vec3::new(0.07, 0.0, 0.0), 0.02, 100.0);
    let near = r.boxed(Vec3::new(-0.04, 0.0, 0.0), 0.02, 100.0);
    let other = r.boxed(Vec3::new(0.0, 0.06, 0.0), 0.02, 100.0);
    r.world.step(); // the broad phase learns the colliders
    r.step(Vec3::ZERO, 0.0, &AllLocal);
    let hovered: Vec<Target> = r.hands.hovered(r.hand).iter().map(|h| h.target).collect();
    assert_eq!(
        hovered,
        vec![
            Target::Rigid(near),
            Target::Rigid(other),
            Target::Rigid(far)
        ]
    );
    r.step(Vec3::ZERO, 1.0, &AllLocal);
    assert_eq!(r.hands.held(r.hand), Some(Target::Rigid(near)));
}

fn soft_rig(grab: SoftGrab) -> (Rig, softsync_softbody::SoftBodyHandle) {
    let mut r = Rig::new(HandConfig {
        soft_grab: grab,
        hover_radius_m: 0.01,
        ..Default::default()
    });
    let cfg = SoftBodyConfig {
        cluster: ClusterMethod::WeightedDistance {
            radius_m: 0.012,
            soft_radius_m: 0.02,
        },
        space: SimulationSpace::Local,
        ..Default::default()
    };
    let h = r
        .soft
        .insert(&Mesh::icosphere(0.1, 3), cfg, &mut r.world)
        .unwrap();
    r.world.step();
    (r, h)
}

#[test]
fn particle_grab_moves_that_particle_and_its_neighbours_less_by_weight() {
    let (mut r, h) = soft_rig(SoftGrab::Particle);
    let body = r.soft.get(h).unwrap();
    let rest = body.particle_positions(&r.world);
    // The particle farthest along +x.
    let (gi, gp) = rest
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.x.total_cmp(&b.1.x))
        .map(|(i, p)| (i, *p))
        .unwrap();
    r.step(gp, 0.0, &AllLocal);
    r.step(gp, 1.0, &AllLocal);
    assert_eq!(
        r.hands.held(r.hand),
        Some(Target::SoftParticle(h, gi as u32))
    );
    for i in 1..=45 {
        r.step(gp + Vec3::X * 0.05 * i as f32 / 45.0, 1.0, &AllLocal);
    }
    let body = r.soft.get(h).unwrap();
    let now = body.particle_positions(&r.world);
    let moved = |i: usize| now[i].distance(rest[i]);
    assert!(
        moved(gi) > 0.045,
        "grabbed particle moved only {}",
        moved(gi)
    );
    let (ids, ws) = body.particle_map().neighbours.row(gi);
    assert!(!ids.is_empty());
    let mut strong = (0.0, 0);
    let mut weak = (0.0, 0);
    for (&j, &w) in ids.iter().zip(ws) {
        let m = moved(j as usize);
        assert!(
            m < moved(gi),
            "neighbour {j} moved {m} ≥ grabbed {}",
            moved(gi)
        );
        if w > 0.5 {
            strong = (strong.0 + m, strong.1 + 1);
        } else {
            weak = (weak.0 + m, weak.1 + 1);
        }
    }
    assert!(strong.1 > 0 && weak.1 > 0);
    let (s, w) = (strong.0 / strong.1 as f32, weak.0 / weak.1 as f32);
    assert!(
        s > w && w > 1e-4,
        "mean neighbour motion: strong {s}, weak {w}"
    );
    // Particles far from the grab stay put.
    let far = (0..now.len())
        .max_by(|&a, &b| {
            rest[gi]
                .distance(rest[a])
                .total_cmp(&rest[gi].distance(rest[b]))
        })
        .unwrap();
    assert!(moved(far) < 1e-3);
}

#[test]
fn physical_controller_pushes_a_box_and_stops_at_a_wall() {
    let mut r = Rig::new(HandConfig::default());
    r.world.gravity = Vec3::ZERO;
    r.wall_at(0.5);
    let b = r.boxed(Vec3::new(0.2, 1.0, 0.0), 0.05, 10.0);
    r.world.step();
    // Grip in empty space at x = 0, then sweep to x = 1.
    r.step(Vec3::new(0.0, 1.0, 0.0), 1.0, &AllLocal);
    let ctrl = r
        .hands
        .controller_body(r.hand)
        .expect("physical controller");
    assert!(r
        .events()
        .contains(&InteractionEvent::PhysicalControllerStarted { hand: r.hand }));
    let (mut box_max, mut ctrl_max) = (0.0f32, 0.0f32);
    for i in 0..120 {
        r.step(
            Vec3::new((i as f32 + 1.0) / 120.0, 1.0, 0.0),
            1.0,
            &AllLocal,
        );
        box_max = box_max.max(r.x(b).x);
        ctrl_max = ctrl_max.max(r.x(ctrl).x);
    }
    // Pushed up to the wall (the box's face at 0.5 − 0.05), never through it; the hand went on
    // to x = 1, the controller stopped at the wall (its radius is 0.04).
    assert!(box_max > 0.43, "box was not pushed to the wall: {box_max}");
    // Squeezed between the driven controller and the wall, rapier's soft contacts let the box
    // sink in by a few centimetres before it is squeezed out sideways; never through.
    assert!(box_max < 0.5, "box went through the wall: {box_max}");
    assert!(
        ctrl_max < 0.475,
        "controller went into the wall: {ctrl_max}"
    );
    r.step(Vec3::new(1.0, 1.0, 0.0), 0.0, &AllLocal);
    assert!(
        r.world.bodies.get(ctrl).is_none(),
        "controller body not removed on release"
    );
}

struct NotMine;
impl Ownership for NotMine {
    fn is_local(&self, _: ObjectRef) -> bool {
        false
    }
}

#[test]
fn a_foreign_grab_waits_for_the_grant_and_does_nothing_on_denial() {
    let mut r = Rig::new(HandConfig::default());
    r.world.gravity = Vec3::ZERO;
    let b = r.boxed(Vec3::ZERO, 0.03, 100.0);
    r.world.step();
    r.step(Vec3::ZERO, 1.0, &NotMine);
    assert_eq!(
        r.events(),
        vec![InteractionEvent::AuthorityRequested {
            hand: r.hand,
            object: ObjectRef::Rigid(b)
        }]
    );
    assert!(r.hands.is_waiting(r.hand));
    for i in 0..20 {
        r.step(Vec3::X * 0.01 * i as f32, 1.0, &NotMine);
    }
    assert!(r.x(b).length() < 1e-6, "moved before the grant");
    r.hands.deny(ObjectRef::Rigid(b));
    assert_eq!(
        r.events(),
        vec![InteractionEvent::GrabDenied {
            hand: r.hand,
            object: ObjectRef::Rigid(b)
        }]
    );
    for _ in 0..10 {
        r.step(Vec3::X * 0.3, 1.0, &NotMine);
    }
    assert!(r.x(b).length() < 1e-6, "moved after the denial");
    // Second try: granted this time.
    r.step(Vec3::X * 0.3, 0.0, &NotMine);
    r.step(Vec3::ZERO, 1.0, &NotMine);
    r.hands.grant(ObjectRef::Rigid(b));
    for i in 0..30 {
        r.step(Vec3::Y * 0.01 * i as f32, 1.0, &NotMine);
    }
    assert!(r.x(b).y > 0.2, "did not follow after the grant: {}", r.x(b));
    assert!(r
        .events()
        .iter()
        .any(|e| matches!(e, InteractionEvent::Grabbed { .. })));
}

#[test]
fn nan_and_stale_poses_change_nothing_and_teleports_are_clamped() {
    let mut r = Rig::new(HandConfig::default());
    r.world.gravity = Vec3::ZERO;
    let b = r.boxed(Vec3::ZERO, 0.03, 100.0);
    r.world.step();
    r.step(Vec3::ZERO, 1.0, &AllLocal);
    r.step(Vec3::ZERO, 1.0, &AllLocal);
    let before = r.x(b);
    for bad in [
        HandInput {
            sample: HandSample {
                position_m: Vec3::NAN,
                rotation: Quat::IDENTITY,
                time_s: r.t + 1.0,
            },
            grip: 1.0,
            trigger: 0.0,
        },
        HandInput {
            sample: HandSample {
                position_m: Vec3::ZERO,
                rotation: Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0),
                time_s: r.t + 1.0,
            },
            grip: 1.0,
            trigger: 0.0,
        },
        HandInput {
            sample: HandSample {
                position_m: Vec3::ZERO,
                rotation: Quat::IDENTITY,
                time_s: f64::INFINITY,
            },
            grip: 1.0,
            trigger: 0.0,
        },
        HandInput {
            sample: HandSample {
                position_m: Vec3::ZERO,
                rotation: Quat::IDENTITY,
                time_s: r.t + 1.0,
            },
            grip: f32::NAN,
            trigger: 0.0,
        },
        HandInput {
            sample: HandSample {
                position_m: Vec3::X,
                rotation: Quat::IDENTITY,
                time_s: r.t - 1.0,
            },
            grip: 1.0,
            trigger: 0.0,
        },
    ] {
        assert!(r.hands.set_input(r.hand, bad).is_err());
    }
    r.hands.update(&mut r.world, &mut r.soft, &AllLocal, DT);
    r.world.step();
    assert!(
        (r.x(b) - before).length() < 1e-6,
        "a refused pose moved the body"
    );
    assert!(r.x(b).is_finite());
    // A 50 m jump while holding: the body follows at most at the speed limit.
    r.step(Vec3::X * 50.0, 1.0, &AllLocal);
    assert!(r
        .events()
        .iter()
        .any(|e| matches!(e, InteractionEvent::HandTeleported { .. })));
    let v = r.world.bodies.get(b).unwrap().linvel().length();
    assert!(
        v <= HandConfig::default().max_linear_speed_mps + 1e-3,
        "yanked at {v} m/s"
    );
}

#[test]
fn a_released_object_reports_when_it_comes_to_rest() {
    let mut r = Rig::new(HandConfig::default());
    let floor = r.world.insert_body(RigidBodyBuilder::fixed());
    r.world
        .insert_collider(ColliderBuilder::cuboid(5.0, 0.05, 5.0), Some(floor));
    let b = r.boxed(Vec3::new(0.0, 0.5, 0.0), 0.05, 100.0);
    r.world.step();
    r.step(Vec3::new(0.0, 0.5, 0.0), 1.0, &AllLocal);
    r.step(Vec3::new(0.0, 0.5, 0.0), 0.0, &AllLocal);
    let mut rested = None;
    for i in 0..400 {
        r.step(Vec3::new(0.0, 1.5, 0.0), 0.0, &AllLocal);
        if r.events().contains(&InteractionEvent::CameToRest {
            object: ObjectRef::Rigid(b),
        }) {
            rested = Some(i);
            break;
        }
    }
    let i = rested.expect("never came to rest");
    assert!(i > 30, "reported rest while falling (step {i})");
    assert!(r.world.bodies.get(b).unwrap().linvel().length() < 0.02);
}

#[test]
fn center_grab_carries_a_world_mode_soft_body() {
    let mut r = Rig::new(HandConfig {
        soft_grab: SoftGrab::Center,
        hover_radius_m: 0.02,
        ..Default::default()
    });
    let cfg = SoftBodyConfig {
        cluster: ClusterMethod::Distance { radius_m: 0.015 },
        ..Default::default()
    };
    let mesh = Mesh::icosphere(0.08, 3).bake(&softsync_softbody::Placement {
        translation_m: Vec3::new(0.0, 1.0, 0.0),
        ..Default::default()
    });
    let h = r.soft.insert(&mesh, cfg, &mut r.world).unwrap();
    r.world.step();
    let top = r
        .soft
        .get(h)
        .unwrap()
        .particle_positions(&r.world)
        .into_iter()
        .max_by(|a, b| a.y.total_cmp(&b.y))
        .unwrap();
    r.step(top, 1.0, &AllLocal);
    assert_eq!(r.hands.held(r.hand), Some(Target::SoftCenter(h)));
    for i in 0..90 {
        r.step(
            top + Vec3::new(0.3 * i as f32 / 90.0, 0.0, 0.0),
            1.0,
            &AllLocal,
        );
    }
    let (c, _) = r.soft.get(h).unwrap().center_pose(&r.world);
    assert!(
        (c.x - 0.3).abs() < 0.02 && (c.y - 1.0).abs() < 0.02,
        "center at {c}"
    );
    let m = softsync_softbody::metrics::measure(r.soft.get(h).unwrap(), &r.world);
    assert!(
        m.rest_rms_m < 0.005,
        "carried body deformed by {} m",
        m.rest_rms_m
    );
}

#[test]
fn bad_hand_settings_are_refused_with_the_field_name() {
    let mut hands = Interaction::new();
    for (cfg, field) in [
        (
            HandConfig {
                hover_radius_m: f32::NAN,
                ..Default::default()
            },
            "hover_radius_m",
        ),
        (
            HandConfig {
                grip_off: 0.9,
                grip_on: 0.5,
                ..Default::default()
            },
            "grip_off",
        ),
        (
            HandConfig {
                max_linear_speed_mps: -1.0,
                ..Default::default()
            },
            "max_linear_speed_mps",
        ),
    ] {
        let e = hands.add_hand(cfg).unwrap_err();
        assert_eq!(e.field, field);
        assert!(e.to_string().contains(field));
    }
    assert!(hands.add_hand(HandConfig::default()).is_ok());
}

#[test]
fn physical_controller_dents_a_soft_body() {
    let mut r = Rig::new(HandConfig::default());
    let cfg = SoftBodyConfig {
        cluster: ClusterMethod::Distance { radius_m: 0.012 },
        space: SimulationSpace::Local,
        ..Default::default()
    };
    let h = r
        .soft
        .insert(&Mesh::icosphere(0.1, 3), cfg, &mut r.world)
        .unwrap();
    r.world.step();
    // Grip in empty air beside the body, then push the 4 cm ball until its surface is 4 cm
    // inside the body's +x side (ball center from x = 0.25 to 0.10).
    let start = Vec3::new(0.25, 0.0, 0.0);
    r.step(start, 1.0, &AllLocal);
    assert!(r.hands.controller_body(r.hand).is_some());
    for i in 1..=60 {
        let x = 0.25 - 0.15 * i as f32 / 60.0;
        r.step(Vec3::new(x, 0.0, 0.0), 1.0, &AllLocal);
    }
    let dent =
        softsync_softbody::metrics::measure(r.soft.get(h).unwrap(), &r.world).max_displacement_m;
    assert!(
        dent > 0.01,
        "the controller did not dent the body ({dent} m)"
    );
    // Let go: the controller disappears and the body springs back.
    r.step(start, 0.0, &AllLocal);
    for _ in 0..180 {
        r.step(start, 0.0, &AllLocal);
    }
    let after =
        softsync_softbody::metrics::measure(r.soft.get(h).unwrap(), &r.world).max_displacement_m;
    assert!(after < 1e-3, "did not recover: {after} m");
}

/// Regression from review: with two hands on one box, letting go with one threw the box out of
/// the other hand and reported it at rest while still held.
#[test]
fn two_hands_on_one_object_release_one_at_a_time() {
    let mut r = Rig::new(HandConfig::default());
    r.world.gravity = Vec3::ZERO;
    let other = r.hands.add_hand(HandConfig::default()).unwrap();
    let b = r.boxed(Vec3::ZERO, 0.03, 100.0);
    r.world.step();
    let mut t = 0.0f64;
    let mut step = |r: &mut Rig, a: (Vec3, f32), o: (Vec3, f32)| {
        t += DT as f64;
        for (hand, (p, grip)) in [(r.hand, a), (other, o)] {
            let input = HandInput {
                sample: HandSample {
                    position_m: p,
                    rotation: Quat::IDENTITY,
                    time_s: t,
                },
                grip,
                trigger: 0.0,
            };
            r.hands.set_input(hand, input).unwrap();
        }
        r.hands.update(&mut r.world, &mut r.soft, &AllLocal, DT);
        r.soft.step(&mut r.world, DT);
    };
    step(&mut r, (Vec3::ZERO, 1.0), (Vec3::new(0.01, 0.0, 0.0), 1.0));
    assert_eq!(r.hands.held(r.hand), Some(Target::Rigid(b)));
    assert_eq!(r.hands.held(other), Some(Target::Rigid(b)));
    // Hand A swings away fast and lets go; hand B holds still.
    for i in 1..=5 {
        step(
            &mut r,
            (Vec3::X * 0.05 * i as f32, 1.0),
            (Vec3::new(0.01, 0.0, 0.0), 1.0),
        );
    }
    step(
        &mut r,
        (Vec3::X * 0.3, 0.0),
        (Vec3::new(0.01, 0.0, 0.0), 1.0),
    );
    let released: Vec<Vec3> = r
        .events()
        .into_iter()
        .filter_map(|e| match e {
            InteractionEvent::Released { velocity_mps, .. } => Some(velocity_mps),
            _ => None,
        })
        .collect();
    assert_eq!(
        released,
        vec![Vec3::ZERO],
        "the box was thrown out of the other hand"
    );
    for _ in 0..90 {
        step(
            &mut r,
            (Vec3::X * 0.3, 0.0),
            (Vec3::new(0.01, 0.0, 0.0), 1.0),
        );
        assert!(
            !r.events()
                .iter()
                .any(|e| matches!(e, InteractionEvent::CameToRest { .. })),
            "at rest while held"
        );
    }
    assert!(
        r.x(b).distance(Vec3::new(0.01, 0.0, 0.0)) < 0.02,
        "box left hand B: {}",
        r.x(b)
    );
    // B lets go too: now it is watched and comes to rest.
    step(
        &mut r,
        (Vec3::X * 0.3, 0.0),
        (Vec3::new(0.01, 0.0, 0.0), 0.0),
    );
    let mut rested = false;
    for _ in 0..120 {
        step(
            &mut r,
            (Vec3::X * 0.3, 0.0),
            (Vec3::new(0.01, 0.0, 0.0), 0.0),
        );
        rested |= r.events().contains(&InteractionEvent::CameToRest {
            object: ObjectRef::Rigid(b),
        });
    }
    assert!(rested);
}

#[test]
fn release_all_forgets_holds_and_waits_without_a_throw() {
    let mut r = Rig::new(HandConfig::default());
    r.world.gravity = Vec3::ZERO;
    let other = r.hands.add_hand(HandConfig::default()).unwrap();
    let b = r.boxed(Vec3::ZERO, 0.03, 100.0);
    let far = r.boxed(Vec3::X * 2.0, 0.03, 100.0);
    r.world.step();
    // hand A holds its box (moving it), hand B waits for authority over the far one
    for i in 0..5 {
        r.step(Vec3::Y * 0.02 * i as f32, 1.0, &AllLocal);
    }
    assert_eq!(r.hands.held(r.hand), Some(Target::Rigid(b)));
    let wait = HandInput {
        sample: HandSample {
            position_m: Vec3::X * 2.0,
            rotation: Quat::IDENTITY,
            time_s: r.t,
        },
        grip: 1.0,
        trigger: 0.0,
    };
    r.hands.set_input(other, wait).unwrap();
    r.hands.update(&mut r.world, &mut r.soft, &NotMine, DT);
    assert!(r.hands.is_waiting(other));
    r.events();
    r.hands.release_all();
    assert_eq!(r.hands.held(r.hand), None);
    assert!(!r.hands.is_waiting(other));
    assert!(r.hands.hovered(r.hand).is_empty());
    // A grant that comes late finds nobody waiting; the grip still down grabs nothing.
    r.hands.grant(ObjectRef::Rigid(far));
    let at = r.x(b);
    for _ in 0..10 {
        r.step(Vec3::Y * 0.5, 1.0, &AllLocal);
    }
    assert_eq!(r.hands.held(r.hand), None);
    assert!(!r.hands.is_waiting(other));
    assert!(
        r.events().iter().all(|e| !matches!(
            e,
            InteractionEvent::Released { .. } | InteractionEvent::Grabbed { .. }
        )),
        "release_all threw or grabbed"
    );
    assert!(r.x(b).distance(at) < 0.05, "the box was carried on");
    // Let go and grip again: a fresh grab works.
    r.step(Vec3::ZERO + at, 0.0, &AllLocal);
    r.step(Vec3::ZERO + at, 1.0, &AllLocal);
    assert_eq!(r.hands.held(r.hand), Some(Target::Rigid(b)));
}

/// A rigid prop another peer owns is kinematic here (driven to the owner's state): the hand
/// hovers it and a grip asks for authority, as for a dynamic one. A kinematic body of our own
/// (a moving platform, a controller) is no target.
#[test]
fn a_kinematic_prop_someone_else_owns_is_a_target_and_asks_for_authority() {
    let mut r = Rig::new(HandConfig::default());
    r.world.gravity = Vec3::ZERO;
    let b = r
        .world
        .insert_body(RigidBodyBuilder::kinematic_position_based().translation(Vec3::ZERO));
    r.world
        .insert_collider(ColliderBuilder::cuboid(0.03, 0.03, 0.03), Some(b));
    r.world.step();
    // Ours: not hovered, nothing asked.
    r.step(Vec3::ZERO, 0.0, &AllLocal);
    assert!(r.hands.hovered(r.hand).is_empty());
    r.step(Vec3::ZERO, 1.0, &AllLocal);
    assert!(
        !r.events().iter().any(|e| matches!(
            e,
            InteractionEvent::AuthorityRequested { .. } | InteractionEvent::Grabbed { .. }
        )),
        "our own kinematic body was taken"
    );
    r.step(Vec3::ZERO, 0.0, &AllLocal);
    let _ = r.events();
    // Someone else's: hovered, and the grip asks for it.
    r.step(Vec3::ZERO, 0.0, &NotMine);
    assert_eq!(r.hands.hovered(r.hand).len(), 1);
    r.step(Vec3::ZERO, 1.0, &NotMine);
    assert!(
        r.events().contains(&InteractionEvent::AuthorityRequested {
            hand: r.hand,
            object: ObjectRef::Rigid(b)
        }),
        "no authority request for someone else's kinematic prop"
    );
}
