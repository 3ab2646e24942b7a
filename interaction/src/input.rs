//! Hand input: tracked pose samples with grip and trigger, the inputs refused (non-finite,
//! time not moving on), and the throw velocity from recent samples (thesis Figure 4.2).

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::HandId;

/// One tracked pose of a hand.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandSample {
    /// Position in world space, metres.
    pub position_m: Vec3,
    /// Orientation in world space.
    pub rotation: Quat,
    /// Sample time, seconds (any monotonic clock the caller keeps).
    pub time_s: f64,
}

/// A hand's pose with its buttons, as read from a controller, a mouse or a bot script.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandInput {
    /// The pose.
    pub sample: HandSample,
    /// Grip (squeeze) value in [0, 1].
    pub grip: f32,
    /// Trigger value in [0, 1].
    pub trigger: f32,
}

/// A pose that was refused; the hand keeps its previous state.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// No such hand.
    #[error("hand {0} does not exist")]
    NoSuchHand(HandId),
    /// Position, rotation, time, grip or trigger is NaN or infinite.
    #[error("hand {hand}: non-finite pose or button value")]
    NonFinite {
        /// The hand.
        hand: HandId,
    },
    /// The sample is not newer than the previous one.
    #[error("hand {hand}: sample time {time_s} s is not after the previous {previous_s} s")]
    TimeNotIncreasing {
        /// The hand.
        hand: HandId,
        /// The refused time.
        time_s: f64,
        /// The previous time.
        previous_s: f64,
    },
}

/// Throw velocity from samples: the mean of the last three sample-to-sample velocities
/// (thesis Figure 4.2).
pub fn throw_velocity(history: &[HandSample]) -> (Vec3, Vec3) {
    let n = history.len();
    let mut lin = Vec3::ZERO;
    let mut ang = Vec3::ZERO;
    let mut k = 0;
    for i in n.saturating_sub(3).max(1)..n {
        let (a, b) = (history[i - 1], history[i]);
        let dt = (b.time_s - a.time_s) as f32;
        if dt > 1e-5 {
            lin += (b.position_m - a.position_m) / dt;
            ang += rotation_vector(b.rotation * a.rotation.inverse()) / dt;
            k += 1;
        }
    }
    if k == 0 {
        (Vec3::ZERO, Vec3::ZERO)
    } else {
        (lin / k as f32, ang / k as f32)
    }
}

/// Axis × angle of the shortest rotation equal to `q`.
pub(crate) fn rotation_vector(q: Quat) -> Vec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let (axis, angle) = q.normalize().to_axis_angle();
    if angle.is_finite() && axis.is_finite() {
        axis * angle
    } else {
        Vec3::ZERO
    }
}
