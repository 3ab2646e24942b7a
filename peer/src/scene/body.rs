//! Where a scene's class becomes a body in a world: [`build_body`] makes the rigid body, the
//! soft body (from the class's plan, clustered once per class) or nothing (an avatar part) of
//! an object, and [`LocalBody`] says which it is. The mirror builds a room's objects with it;
//! a rollback world (`softsync-rollback`) builds the same bodies.

use glam::{Quat, Vec3};
use softsync_softbody::rapier3d::prelude::{PhysicsWorld, RigidBodyHandle};
use softsync_softbody::{SoftBodyHandle, SoftBodySet};

use super::{Kind, Scene};
use crate::events::PeerError;

/// How a networked object exists in the local world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LocalBody {
    /// A pose only (avatar parts).
    Pose,
    /// A rigid body.
    Rigid(RigidBodyHandle),
    /// A soft body.
    Soft(SoftBodyHandle),
    /// A soft body being built off the frame: an object that came with a topology history
    /// (a cut's piece, a torn body at a late join), replayed on a worker thread. Nothing is
    /// in the world until it lands (then it is `Soft`).
    Building,
}

/// Build a body of `kind` at a pose in a world: a rigid body, or a soft body built around the
/// origin and then placed (its rest shape stays in its own frame); avatar parts have no body.
/// The mirror builds the room's objects with it, and a rollback world (`softsync-rollback`)
/// builds the same bodies.
pub fn build_body(
    scene: &Scene,
    kind: Kind,
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    pos: Vec3,
    rot: Quat,
) -> Result<LocalBody, PeerError> {
    if kind.is_avatar() {
        return Ok(LocalBody::Pose);
    }
    if scene.soft_config(kind).is_none() {
        return scene
            .build_rigid(kind, world, pos, rot)
            .map(LocalBody::Rigid)
            .ok_or_else(|| {
                PeerError::Build(format!("class {} is not in scene {}", kind.0, scene.name))
            });
    }
    // planned once per class (the clustering), copied into the world each time
    let plan = scene.soft_plan(kind).map_err(PeerError::Build)?;
    let h = soft
        .insert_plan_at(&plan, world, pos, rot)
        .map_err(|e| PeerError::Build(e.to_string()))?;
    Ok(LocalBody::Soft(h))
}
