//! What a hand can act on: rigid bodies and soft bodies (center or one particle), what it
//! hovers, and the question the app answers for it: does this peer own that object?

use softsync_softbody::rapier3d::prelude::RigidBodyHandle;
use softsync_softbody::SoftBodyHandle;

/// A networked object as the app knows it: a rigid body or a whole soft body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ObjectRef {
    /// A rigid body.
    Rigid(RigidBodyHandle),
    /// A soft body (its center and all particles).
    Soft(SoftBodyHandle),
}

/// What a hand holds or hovers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Target {
    /// A dynamic rigid body.
    Rigid(RigidBodyHandle),
    /// A soft body by its center (thesis 4.1.1).
    SoftCenter(SoftBodyHandle),
    /// One particle of a soft body (thesis 4.1.2).
    SoftParticle(SoftBodyHandle, u32),
}

impl Target {
    /// The networked object this target is part of.
    pub fn object(&self) -> ObjectRef {
        match *self {
            Target::Rigid(h) => ObjectRef::Rigid(h),
            Target::SoftCenter(h) | Target::SoftParticle(h, _) => ObjectRef::Soft(h),
        }
    }
}

/// Tells the interaction which objects the local peer owns (simulates).
pub trait Ownership {
    /// True if the local peer may move `object` now.
    fn is_local(&self, object: ObjectRef) -> bool;
}

/// Every object is local: single-user use and tests.
#[derive(Clone, Copy, Debug, Default)]
pub struct AllLocal;

impl Ownership for AllLocal {
    fn is_local(&self, _: ObjectRef) -> bool {
        true
    }
}

/// An object or particle near a hand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hovered {
    /// The target.
    pub target: Target,
    /// Distance from the hand to the target's body position, metres.
    pub distance_m: f32,
}
