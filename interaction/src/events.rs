//! What the interaction tells the app: authority requests it must answer, and grabs,
//! releases, throws and rests it may show.

use glam::Vec3;

use crate::{HandId, ObjectRef, Target};

/// Something the app must act on (authority) or may show (HUD).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InteractionEvent {
    /// The hand wants `object`, which the local peer does not own: ask for authority, then
    /// call [`Interaction::grant`](crate::Interaction::grant) or [`Interaction::deny`](crate::Interaction::deny).
    AuthorityRequested {
        /// The hand.
        hand: HandId,
        /// The object.
        object: ObjectRef,
    },
    /// The hand started holding `target`.
    Grabbed {
        /// The hand.
        hand: HandId,
        /// What it holds.
        target: Target,
    },
    /// Authority for the grab was denied.
    GrabDenied {
        /// The hand.
        hand: HandId,
        /// The object.
        object: ObjectRef,
    },
    /// The grip opened while authority was still pending: the app may release it when granted.
    GrabCancelled {
        /// The hand.
        hand: HandId,
        /// The object.
        object: ObjectRef,
    },
    /// The hand let go, throwing with `velocity_mps`.
    Released {
        /// The hand.
        hand: HandId,
        /// What it held.
        target: Target,
        /// Throw velocity given to the target.
        velocity_mps: Vec3,
    },
    /// A hand holding a body another peer simulates (a remote hand, see
    /// [`Interaction::hold_remote`](crate::Interaction::hold_remote)) let go: nothing was
    /// applied here; the app tells the owner, which throws with `velocity_mps`.
    RemoteReleased {
        /// The hand.
        hand: HandId,
        /// What it held.
        target: Target,
        /// The hand's throw velocity (mean of its last samples' velocities).
        velocity_mps: Vec3,
    },
    /// A released object has been at rest for `rest_time_s`: its authority may go back.
    CameToRest {
        /// The object.
        object: ObjectRef,
    },
    /// The hand became a physical body (4.1.3).
    PhysicalControllerStarted {
        /// The hand.
        hand: HandId,
    },
    /// The hand's physical body was removed.
    PhysicalControllerEnded {
        /// The hand.
        hand: HandId,
    },
    /// A pose jumped further than `teleport_distance_m`; the hand restarted there.
    HandTeleported {
        /// The hand.
        hand: HandId,
        /// Length of the jump, metres.
        distance_m: f32,
    },
}
