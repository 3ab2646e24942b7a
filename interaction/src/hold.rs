//! Holding and letting go (thesis 4.1): the velocity-based hold that reaches the goal in one
//! step within limits (contacts still act), the parent-based hold kept to compare (Table 1),
//! and the throw on release.

use glam::{Quat, Vec3};
use softsync_softbody::rapier3d::prelude::{PhysicsWorld, Pose, RigidBodyHandle};
use softsync_softbody::SoftBodySet;

use crate::input::rotation_vector;
use crate::{HandConfig, Target};

pub(crate) fn clamp_len(v: Vec3, max: f32) -> Vec3 {
    let l = v.length();
    if l > max && l > 0.0 {
        v * (max / l)
    } else {
        v
    }
}

pub(crate) fn target_body(soft: &SoftBodySet, target: Target) -> Option<RigidBodyHandle> {
    match target {
        Target::Rigid(h) => Some(h),
        Target::SoftCenter(h) => soft.get(h).map(|b| b.center()),
        Target::SoftParticle(h, i) => soft
            .get(h)
            .and_then(|b| b.particles().get(i as usize).copied()),
    }
}

pub(crate) fn target_pose(
    world: &PhysicsWorld,
    soft: &SoftBodySet,
    target: Target,
) -> Option<(Vec3, Quat)> {
    let b = world.bodies.get(target_body(soft, target)?)?;
    Some((b.translation(), *b.rotation()))
}

/// Thesis 4.1: set the velocity that reaches the goal in one step (gravity compensated),
/// limited, so contacts and masses still act: a held box stops at a wall.
pub(crate) fn velocity_hold(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    target: Target,
    goal: Vec3,
    goal_rot: Quat,
    cfg: &HandConfig,
    dt: f32,
) {
    let gravity = world.gravity;
    match target {
        Target::SoftParticle(h, i) => {
            let Some(x) = soft
                .get(h)
                .and_then(|b| b.particles().get(i as usize).copied())
                .and_then(|p| world.bodies.get(p))
                .map(|b| b.translation())
            else {
                return;
            };
            let step = clamp_len(goal - x, cfg.max_linear_speed_mps * dt);
            if let Some(b) = soft.get_mut(h) {
                b.set_particle_drive(i as usize, Some(x + step));
            }
        }
        _ => {
            let Some(bh) = target_body(soft, target) else {
                return;
            };
            let Some(b) = world.bodies.get_mut(bh) else {
                return;
            };
            let v = (goal - b.translation()) / dt - gravity * b.gravity_scale() * dt;
            let w = rotation_vector(goal_rot * b.rotation().inverse()) / dt;
            b.set_linvel(clamp_len(v, cfg.max_linear_speed_mps), true);
            b.set_angvel(clamp_len(w, cfg.max_angular_speed_radps), true);
        }
    }
}

/// Thesis 4.2, kept to compare: the pose is set, velocity zeroed; physics is skipped.
pub(crate) fn parent_hold(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    target: Target,
    goal: Vec3,
    goal_rot: Quat,
) {
    let Some(bh) = target_body(soft, target) else {
        return;
    };
    let Some(b) = world.bodies.get_mut(bh) else {
        return;
    };
    match target {
        Target::SoftParticle(..) => b.set_translation(goal, true),
        _ => b.set_position(Pose::from_parts(goal, goal_rot), true),
    }
    b.set_linvel(Vec3::ZERO, true);
    b.set_angvel(Vec3::ZERO, true);
}

pub(crate) fn apply_release(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    target: Target,
    lin: Vec3,
    ang: Vec3,
) {
    if let Target::SoftParticle(h, i) = target {
        if let Some(b) = soft.get_mut(h) {
            b.set_particle_drive(i as usize, None);
        }
    }
    if let Some(b) = target_body(soft, target).and_then(|h| world.bodies.get_mut(h)) {
        b.set_linvel(lin, true);
        if !matches!(target, Target::SoftParticle(..)) {
            b.set_angvel(ang, true);
        }
    }
}

pub(crate) fn release_without_throw(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    target: Target,
) {
    apply_release(world, soft, target, Vec3::ZERO, Vec3::ZERO);
}

/// Drives particle `i` of soft body `body` toward `goal` exactly as a hand of this peer
/// holding it would ([`HandConfig`]'s speed limit, one step of `dt_s`): for a hand of
/// another peer, applied by the body's owner (a remote hand). False if there is no such
/// particle or `goal` is not finite.
pub fn drive_particle(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    body: softsync_softbody::SoftBodyHandle,
    i: u32,
    goal: Vec3,
    cfg: &HandConfig,
    dt_s: f32,
) -> bool {
    let exists = soft
        .get(body)
        .is_some_and(|b| (i as usize) < b.num_particles());
    if !exists || !goal.is_finite() {
        return false;
    }
    let target = Target::SoftParticle(body, i);
    velocity_hold(
        world,
        soft,
        target,
        goal,
        Quat::IDENTITY,
        cfg,
        dt_s.max(1e-5),
    );
    true
}

/// Lets go of particle `i` of `body` as a hand would, giving it `throw` (m/s; zero: no
/// throw). Non-finite throws are dropped.
pub fn release_particle(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    body: softsync_softbody::SoftBodyHandle,
    i: u32,
    throw: Vec3,
) {
    let throw = if throw.is_finite() { throw } else { Vec3::ZERO };
    apply_release(
        world,
        soft,
        Target::SoftParticle(body, i),
        throw,
        Vec3::ZERO,
    );
}
