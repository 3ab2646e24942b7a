//! Simulation behaviour: rest stability, squash and recover, world and local mode, rigid
//! rotation, restricted region, and the stability sweep over stiffness × step rate × mass.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

use glam::{Quat, Vec3};
use softsync_softbody::mesh::bounds;
use softsync_softbody::rapier3d::prelude::{PhysicsWorld, Pose};
use softsync_softbody::scenario::{Scenario, ScenarioKind};
use softsync_softbody::*;

fn sphere() -> Mesh {
    Mesh::icosphere(0.1, 3)
}

fn distance_cfg() -> SoftBodyConfig {
    SoftBodyConfig {
        cluster: ClusterMethod::Distance { radius_m: 0.012 },
        ..Default::default()
    }
}

/// A world holding one local-mode [`sphere`] of [`distance_cfg`].
fn local_sphere() -> (PhysicsWorld, SoftBodySet, SoftBodyHandle) {
    let mut world = PhysicsWorld::new();
    let mut set = SoftBodySet::new();
    let cfg = SoftBodyConfig {
        space: SimulationSpace::Local,
        ..distance_cfg()
    };
    let h = set.insert(&sphere(), cfg, &mut world).unwrap();
    (world, set, h)
}

#[test]
fn ten_seconds_at_rest_do_not_drift() {
    for cfg in [SoftBodyConfig::default(), distance_cfg()] {
        let mut s = Scenario::new(ScenarioKind::Rest, &sphere(), cfg, 1.0 / 90.0).unwrap();
        let start = s.soft_body().vertices().to_vec();
        s.run_until(10.0);
        let end = s.soft_body().vertices();
        let rms = (start
            .iter()
            .zip(end)
            .map(|(a, b)| a.distance_squared(*b))
            .sum::<f32>()
            / start.len() as f32)
            .sqrt();
        assert!(rms < 1e-5, "drift {rms} m");
        assert!(!s.metrics().non_finite);
    }
}

#[test]
fn squash_to_30_percent_and_recover_volume_within_2_s() {
    for cluster in [
        ClusterMethod::Distance { radius_m: 0.012 },
        ClusterMethod::WeightedDistance {
            radius_m: 0.012,
            soft_radius_m: 0.02,
        },
        ClusterMethod::PoissonDisk {
            radius_m: 0.012,
            seed: 1,
        },
    ] {
        let cfg = SoftBodyConfig {
            cluster,
            ..Default::default()
        };
        let mut s = Scenario::new(ScenarioKind::Squeeze, &sphere(), cfg, 1.0 / 90.0).unwrap();
        s.run_until(1.4);
        let (lo, hi) = bounds(s.soft_body().vertices());
        let height = (hi.y - lo.y) / 0.2;
        assert!(
            height < 0.37,
            "{}: squeezed to {:.0} % of the height",
            cluster.name(),
            height * 100.0
        );
        assert!(
            s.metrics().volume_ratio < 0.6,
            "{}: volume barely changed",
            cluster.name()
        );
        s.run_until(ScenarioKind::Squeeze.release_s() + 2.0);
        let m = s.metrics();
        assert!(
            (m.volume_ratio - 1.0).abs() < 0.05,
            "{}: volume {} after 2 s",
            cluster.name(),
            m.volume_ratio
        );
        assert!(
            m.rest_rms_m < 1e-3,
            "{}: shape error {} m",
            cluster.name(),
            m.rest_rms_m
        );
    }
}

#[test]
fn world_mode_falls_and_rests_on_the_floor() {
    let mut s = Scenario::new(ScenarioKind::Drop, &sphere(), distance_cfg(), 1.0 / 90.0).unwrap();
    let y0 = s.soft_body().center_pose(&s.world).0.y;
    let mut lowest = f32::MAX;
    for _ in 0..(3.0 * 90.0) as usize {
        s.step();
        let (lo, _) = bounds(s.soft_body().vertices());
        lowest = lowest.min(lo.y);
    }
    let (c, _) = s.soft_body().center_pose(&s.world);
    assert!(c.y < y0 - 0.4, "center did not fall: {y0} -> {}", c.y);
    // Never through the floor (y = 0) by more than a particle radius's worth of contact slop.
    assert!(lowest > -0.01, "mesh went {lowest} m below the floor");
    let m = s.metrics();
    assert!(
        m.kinetic_energy_j < 1e-3,
        "still moving: {} J",
        m.kinetic_energy_j
    );
    assert!(!m.non_finite && !m.exploded);
}

#[test]
fn local_mode_stays_put_under_gravity() {
    let mut s = Scenario::new(ScenarioKind::Rest, &sphere(), distance_cfg(), 1.0 / 60.0).unwrap();
    let (c0, _) = s.soft_body().center_pose(&s.world);
    s.run_until(2.0);
    let (c1, _) = s.soft_body().center_pose(&s.world);
    assert!(c0.distance(c1) < 1e-6);
    assert!(s.metrics().rest_rms_m < 1e-5);
}

#[test]
fn rotating_the_center_90_degrees_rotates_the_mesh_rigidly() {
    let mut s = Scenario::new(
        ScenarioKind::Rest,
        &Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj"))
            .unwrap()
            .fit_size(0.2),
        distance_cfg_for(0.2),
        1.0 / 90.0,
    )
    .unwrap();
    let q = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
    let center = s.soft_body().center();
    let (c, _) = s.soft_body().center_pose(&s.world);
    s.world
        .bodies
        .get_mut(center)
        .unwrap()
        .set_position(Pose::from_parts(c, q), true);
    s.run_until(2.0);
    let body = s.soft_body();
    let size = body.size_m();
    let worst = body
        .vertices()
        .iter()
        .zip(body.rest_vertices())
        .map(|(v, r)| v.distance(c + q * *r))
        .fold(0.0f32, f32::max);
    assert!(
        worst < 1e-3 * size,
        "worst vertex {worst} m off the rigid rotation (size {size} m)"
    );
}

fn distance_cfg_for(size: f32) -> SoftBodyConfig {
    SoftBodyConfig {
        cluster: ClusterMethod::Distance {
            radius_m: 0.06 * size,
        },
        ..Default::default()
    }
}

#[test]
fn restricted_region_keeps_outside_vertices_rigid() {
    let cfg = SoftBodyConfig {
        soft_region: Some(SoftRegion::Aabb {
            min_m: Vec3::new(0.03, -1.0, -1.0),
            max_m: Vec3::splat(1.0),
        }),
        ..distance_cfg()
    };
    let mut s = Scenario::new(ScenarioKind::Poke, &sphere(), cfg, 1.0 / 90.0).unwrap();
    let rest = s.soft_body().vertices().to_vec();
    s.run_until(0.8);
    let body = s.soft_body();
    let mut moved_inside = 0.0f32;
    for (i, (a, b)) in rest.iter().zip(body.vertices()).enumerate() {
        if body.particle_map().soft_vertex[i] {
            moved_inside = moved_inside.max(a.distance(*b));
        } else {
            assert!(
                a.distance(*b) < 1e-6,
                "rigid vertex {i} moved {} m",
                a.distance(*b)
            );
        }
    }
    assert!(
        moved_inside > 0.01,
        "the poke did not deform the soft part ({moved_inside} m)"
    );
}

#[test]
fn pulling_one_particle_drags_its_neighbours_less_and_it_springs_back() {
    let mut s = Scenario::new(ScenarioKind::Pull, &sphere(), distance_cfg(), 1.0 / 90.0).unwrap();
    s.run_until(0.7);
    let m = s.metrics();
    assert!(m.max_displacement_m > 0.02, "pull had no effect: {m:?}");
    s.run_until(3.0);
    let m = s.metrics();
    assert!(
        m.rest_rms_m < 1e-3 && m.max_displacement_m < 5e-3,
        "did not spring back: {m:?}"
    );
}

/// Point 5 of the issue: stiffness 0.1–100 × 60–144 Hz × mass 0.01–10; no NaN, no explosion,
/// no drift at rest, and recovery wherever the stiffness allows it within the run.
#[test]
fn stability_sweep() {
    let mesh = Mesh::icosphere(0.1, 2);
    for &k in &[0.1f32, 1.0, 10.0, 100.0] {
        for &hz in &[60.0f32, 90.0, 144.0] {
            for &mass in &[0.01f32, 1.0, 10.0] {
                for kind in [
                    ScenarioKind::Poke,
                    ScenarioKind::Pull,
                    ScenarioKind::Rest,
                    ScenarioKind::Drop,
                ] {
                    let cfg = SoftBodyConfig {
                        stiffness: k,
                        particle_mass_kg: mass,
                        cluster: ClusterMethod::Distance { radius_m: 0.02 },
                        ..Default::default()
                    };
                    let mut s = Scenario::new(kind, &mesh, cfg, 1.0 / hz).unwrap();
                    let mut worst = 0.0f32;
                    while s.time_s() < kind.duration_s() {
                        s.step();
                        let m = s.metrics();
                        assert!(
                            !m.non_finite && !m.exploded,
                            "k={k} hz={hz} m={mass} {}: {m:?}",
                            kind.name()
                        );
                        worst = worst.max(m.max_displacement_m);
                    }
                    let m = s.metrics();
                    assert!(
                        worst < 0.2,
                        "k={k} hz={hz} m={mass} {}: displacement {worst}",
                        kind.name()
                    );
                    // Recovery time constant is 1/k: after ≥ 2 s, k ≥ 10 has recovered fully.
                    if kind == ScenarioKind::Drop {
                        // Resting on the floor: never through it, settled.
                        let (lo, _) = bounds(s.soft_body().vertices());
                        assert!(
                            lo.y > -0.02,
                            "k={k} hz={hz} m={mass} drop: {} m below the floor",
                            -lo.y
                        );
                        let (c, _) = s.soft_body().center_pose(&s.world);
                        assert!(
                            c.y < 0.2,
                            "k={k} hz={hz} m={mass} drop: did not fall ({})",
                            c.y
                        );
                    } else if k >= 10.0 {
                        assert!(
                            m.rest_rms_m < 1e-3,
                            "k={k} hz={hz} m={mass} {}: rms {}",
                            kind.name(),
                            m.rest_rms_m
                        );
                    }
                    assert_eq!(s.soft_body().non_finite_recoveries(), 0);
                }
            }
        }
    }
}

/// The thesis's scheme at k = 100 and 60 Hz (α = k·dt²·90 = 2.5, and neighbour weights
/// summing past 1) oscillates with growing amplitude; ours stays monotone at the same setting.
#[test]
fn thesis_scheme_fails_where_ours_holds() {
    let mesh = Mesh::icosphere(0.1, 2);
    let run = |restoring| {
        let cfg = SoftBodyConfig {
            stiffness: 100.0,
            restoring,
            cluster: ClusterMethod::Distance { radius_m: 0.02 },
            ..Default::default()
        };
        let mut s = Scenario::new(ScenarioKind::Pull, &mesh, cfg, 1.0 / 60.0).unwrap();
        s.run_until(ScenarioKind::Pull.release_s() + 0.01);
        let mut worst_late = 0.0f32;
        while s.time_s() < 3.0 {
            s.step();
            if s.time_s() > 2.0 {
                worst_late = worst_late.max(s.metrics().max_displacement_m);
            }
        }
        worst_late
    };
    let ours = run(RestoringScheme::Exact);
    let thesis = run(RestoringScheme::Thesis);
    assert!(ours < 1e-3, "ours did not settle: {ours}");
    assert!(
        thesis > 10.0 * ours.max(1e-4),
        "thesis scheme settled too ({thesis} m): the limit test lost its point"
    );
}

/// Where the thesis's scheme fails, as its docs now say (`RestoringScheme::Thesis`): with the
/// neighbour term at the default affection range each particle's raw weights sum well past 1,
/// the uniform displacement mode grows by `1 + α(Σw − 1)` per step and it diverges at *every*
/// stiffness and rate (k = 2/s at 60 Hz and at 144 Hz here); without neighbours the per-step
/// fraction `α = k·dt²·90` decides: it settles at α ≤ 0.5 and keeps swinging at α ≥ 2.5.
/// Ours settles at every one of these settings.
#[test]
fn thesis_scheme_fails_exactly_where_its_docs_say() {
    let mesh = Mesh::icosphere(0.1, 2);
    let late_motion = |stiffness: f32, rate_hz: f32, neighbours: bool, restoring| {
        let cfg = SoftBodyConfig {
            stiffness,
            restoring,
            cluster: ClusterMethod::Distance { radius_m: 0.02 },
            // 0 derives the default range (2.5 × the particle spacing); a range below the
            // spacing leaves every particle without neighbours.
            affect_range_m: if neighbours { 0.0 } else { 1e-4 },
            ..Default::default()
        };
        let mut s = Scenario::new(ScenarioKind::Pull, &mesh, cfg, 1.0 / rate_hz).unwrap();
        s.run_until(ScenarioKind::Pull.release_s() + 0.01);
        let mut worst_late = 0.0f32;
        while s.time_s() < 2.5 {
            s.step();
            if s.time_s() > 1.8 {
                worst_late = worst_late.max(s.metrics().max_displacement_m);
            }
        }
        worst_late
    };
    // (k 1/s, rate Hz, neighbours, thesis fails): α = k·dt²·90.
    for (k, hz, neighbours, fails) in [
        (2.0f32, 60.0f32, true, true),
        (2.0, 144.0, true, true),
        (20.0, 60.0, false, false),
        (100.0, 144.0, false, false),
        (100.0, 60.0, false, true),
        (50.0, 30.0, false, true),
    ] {
        let alpha = k * 90.0 / (hz * hz);
        let thesis = late_motion(k, hz, neighbours, RestoringScheme::Thesis);
        let ours = late_motion(k, hz, neighbours, RestoringScheme::Exact);
        println!(
            "k {k} at {hz} Hz, neighbours {neighbours}: α {alpha:.2}, thesis {thesis:.4} m, ours {ours:.4} m"
        );
        assert!(
            ours < 5e-3,
            "ours did not settle (k {k}, {hz} Hz): {ours} m"
        );
        if fails {
            assert!(
                thesis > 2e-2,
                "thesis scheme settled (k {k}, {hz} Hz): {thesis} m"
            );
        } else {
            assert!(
                thesis < 5e-3,
                "thesis scheme failed (k {k}, {hz} Hz): {thesis} m"
            );
        }
    }
}

#[test]
fn invalid_config_is_rejected_with_the_field_name() {
    let mut world = PhysicsWorld::new();
    let mut set = SoftBodySet::new();
    for (cfg, field) in [
        (
            SoftBodyConfig {
                stiffness: f32::NAN,
                ..Default::default()
            },
            "stiffness",
        ),
        (
            SoftBodyConfig {
                particle_mass_kg: -1.0,
                ..Default::default()
            },
            "particle_mass_kg",
        ),
        (
            SoftBodyConfig {
                neighbour_share: 0.9,
                ..Default::default()
            },
            "neighbour_share",
        ),
    ] {
        let e = set
            .insert(&sphere(), cfg, &mut world)
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{e}");
    }
    assert!(set.is_empty());
}

#[test]
fn handles_are_generational() {
    let mut world = PhysicsWorld::new();
    let mut set = SoftBodySet::new();
    let a = set.insert(&sphere(), distance_cfg(), &mut world).unwrap();
    let bodies = world.bodies.len();
    assert!(set.remove(a, &mut world).is_some());
    assert!(world.bodies.len() < bodies);
    let b = set.insert(&sphere(), distance_cfg(), &mut world).unwrap();
    assert!(set.get(a).is_none(), "stale handle still resolves");
    assert!(set.get(b).is_some());
}

#[test]
fn render_output_follows_the_welded_vertices() {
    let mesh = Mesh::uv_sphere(0.1, 12, 24);
    let mut s = Scenario::new(ScenarioKind::Poke, &mesh, distance_cfg(), 1.0 / 90.0).unwrap();
    s.run_until(0.8);
    let body = s.soft_body();
    let w = body.welded();
    for (r, &wv) in w.render_to_welded.iter().enumerate() {
        assert_eq!(
            body.render_positions()[r],
            body.vertices()[wv as usize],
            "seam cracked at {r}"
        );
        assert!((body.render_normals()[r].length() - 1.0).abs() < 1e-3);
    }
}

/// Regression: rapier does not wake sleeping particles when a kinematic plate moves into
/// them; the plate passed through the resting bunny and carried particles away on its top.
#[test]
fn regression_sleeping_particles_wake_when_a_kinematic_plate_arrives() {
    use softsync_softbody::rapier3d::prelude::{ColliderBuilder, RigidBodyBuilder};
    let (mut world, mut set, h) = local_sphere();
    let plate = world.insert_body(
        RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(0.0, 0.3, 0.0)),
    );
    world.insert_collider(ColliderBuilder::cuboid(0.2, 0.01, 0.2), Some(plate));
    let dt = 1.0 / 90.0;
    for _ in 0..270 {
        set.step(&mut world, dt);
    }
    let asleep = set
        .get(h)
        .unwrap()
        .particles()
        .iter()
        .filter(|p| world.bodies.get(**p).unwrap().is_sleeping())
        .count();
    assert!(
        asleep > 0,
        "precondition: the resting body's particles sleep"
    );
    // Down to y = 0.05 (the sphere's top is at 0.1) at 0.75 m/s, hold, back up.
    let mut y = 0.3f32;
    let mut pressed = 0.0f32;
    for i in 0..360 {
        let target = if i < 180 { 0.05 + 0.011 } else { 0.3 };
        y += (target - y).clamp(-0.75 * dt, 0.75 * dt);
        world
            .bodies
            .get_mut(plate)
            .unwrap()
            .set_next_kinematic_translation(Vec3::new(0.0, y, 0.0));
        set.step(&mut world, dt);
        pressed = pressed.max(
            softsync_softbody::metrics::measure(set.get(h).unwrap(), &world).max_displacement_m,
        );
    }
    assert!(
        pressed > 0.03,
        "the plate did not press the body ({pressed} m)"
    );
    for _ in 0..180 {
        set.step(&mut world, dt);
    }
    let m = softsync_softbody::metrics::measure(set.get(h).unwrap(), &world);
    assert!(
        m.max_displacement_m < 2e-3,
        "particles left caught on the plate: {m:?}"
    );
}

#[test]
fn configs_from_json_refuse_unknown_fields_and_bad_values() {
    let ok: SoftBodyConfig = serde_json::from_str(
        r#"{"cluster": {"method": "weighted_distance", "radius_m": 0.01, "soft_radius_m": 0.02}, "stiffness": 30, "space": "local"}"#,
    )
    .unwrap();
    assert_eq!(ok.stiffness, 30.0);
    assert!(ok.validate().is_ok());
    let typo = serde_json::from_str::<SoftBodyConfig>(r#"{"stifness": 30}"#)
        .unwrap_err()
        .to_string();
    assert!(typo.contains("stifness"), "{typo}");
    let bad: SoftBodyConfig = serde_json::from_str(r#"{"stiffness": -5}"#).unwrap();
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("stiffness"));
}

#[test]
fn apply_state_moves_the_body_and_refuses_bad_states() {
    let (mut world, mut set, h) = local_sphere();
    let b = set.get_mut(h).unwrap();
    let (c, q) = b.center_pose(&world);
    let mut particles = b.particle_positions(&world);
    let i = (0..particles.len())
        .max_by(|&a, &z| particles[a].x.total_cmp(&particles[z].x))
        .unwrap();
    particles[i] += Vec3::X * 0.03;
    b.apply_state(&mut world, c, q, &particles).unwrap();
    assert!(b.particle_positions(&world)[i].distance(particles[i]) < 1e-6);
    assert!(
        b.vertices().iter().any(|v| v.x > 0.1 + 0.01),
        "the mesh did not follow the particle"
    );
    let before = b.particle_positions(&world);
    assert!(b.apply_state(&mut world, c, q, &particles[1..]).is_err());
    particles[3] = Vec3::NAN;
    assert!(b.apply_state(&mut world, c, q, &particles).is_err());
    assert!(b
        .apply_state(&mut world, c, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0), &before)
        .is_err());
    assert_eq!(
        b.particle_positions(&world),
        before,
        "a refused state changed the body"
    );
}

#[test]
fn a_body_from_a_plan_is_the_body_insert_builds() {
    let mesh = Mesh::icosphere(0.1, 2);
    let cfg = SoftBodyConfig::default();
    let plan = SoftBodyPlan::new(&mesh, cfg.clone()).unwrap();
    let mut world = softsync_softbody::rapier3d::prelude::PhysicsWorld::new();
    let mut set = SoftBodySet::new();
    let a = set.insert(&mesh, cfg.clone(), &mut world).unwrap();
    let b = set.insert_plan(&plan, &mut world);
    let c = set.insert_plan(&plan, &mut world);
    let (a, b, c) = (
        set.get(a).unwrap(),
        set.get(b).unwrap(),
        set.get(c).unwrap(),
    );
    assert_eq!(plan.num_particles(), a.num_particles());
    for other in [b, c] {
        assert_eq!(a.rest_offsets(), other.rest_offsets());
        assert_eq!(a.rest_vertices(), other.rest_vertices());
        assert_eq!(
            a.particle_positions(&world),
            other.particle_positions(&world)
        );
    }
    // what insert refuses, a plan refuses
    let bad = SoftBodyConfig {
        tear_width_m: -1.0,
        ..cfg
    };
    assert!(SoftBodyPlan::new(&mesh, bad).is_err());
}

/// A centre-only state (no particles: thesis §5.4.1) moves the centre, and the particles
/// come along rigidly, keeping their shape around it; a non-finite centre changes nothing.
#[test]
fn a_centre_only_state_carries_the_particles_along_rigidly() {
    let (mut world, mut set, h) = local_sphere();
    let b = set.get_mut(h).unwrap();
    let (c, q) = b.center_pose(&world);
    let before = b.particle_positions(&world);
    let turn = Quat::from_rotation_y(0.7);
    let (c2, q2) = (c + Vec3::new(0.1, 0.2, -0.05), turn * q);
    b.apply_state(&mut world, c2, q2, &[]).unwrap();
    let after = b.particle_positions(&world);
    let (got_c, got_q) = b.center_pose(&world);
    assert!(got_c.distance(c2) < 1e-6 && got_q.angle_between(q2) < 1e-5);
    for (p, p2) in before.iter().zip(&after) {
        let expect = c2 + turn * (*p - c);
        assert!(p2.distance(expect) < 1e-5, "{p2} != {expect}");
    }
    assert!(b.apply_state(&mut world, Vec3::NAN, q2, &[]).is_err());
    assert_eq!(b.particle_positions(&world), after);
}
