//! What a tracked device (a headset and controllers, or the desktop's mouse hands) says this
//! frame. The desktop and VR front ends write it; the simulation reads it at each fixed step,
//! alone or under a bot script (which then moves the hands *relative* to the tracked poses).

use glam::{Quat, Vec3};
use softsync_interaction::{HandInput, HandSample};

use crate::peer::cutter::HandTool;
use crate::peer::Peer;

/// One frame of device input, in room coordinates (metres, y up).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeviceFrame {
    /// Head pose, if tracked.
    pub head: Option<(Vec3, Quat)>,
    /// Left and right hand (grip) poses, if tracked.
    pub hands: [Option<(Vec3, Quat)>; 2],
    /// Grip (squeeze) per hand, 0..1.
    pub grip: [f32; 2],
    /// Trigger per hand, 0..1.
    pub trigger: [f32; 2],
    /// What each hand's trigger does (the scalpel tears, the cutter cuts).
    pub tool: [HandTool; 2],
    /// The talk key or button is held (voice's push-to-talk).
    pub talk: bool,
}

impl DeviceFrame {
    /// The pose of avatar part `part` (0 head, 1 left, 2 right), if tracked and finite.
    pub fn part(&self, part: usize) -> Option<(Vec3, Quat)> {
        let p = match part {
            0 => self.head,
            1 => self.hands[0],
            2 => self.hands[1],
            _ => None,
        }?;
        (p.0.is_finite() && p.1.is_finite()).then_some(p)
    }

    /// Drive the avatar and the hands from this frame alone (no bot).
    pub fn apply(&self, peer: &mut Peer) {
        let t = peer.sim_time();
        for part in 0..3 {
            if let Some((p, r)) = self.part(part) {
                peer.set_avatar_pose(part, p, r);
            }
        }
        for h in 0..2 {
            peer.set_hand_tool(h, self.tool[h]);
            if let Some((p, r)) = self.part(h + 1) {
                peer.set_hand_input(
                    h,
                    HandInput {
                        sample: HandSample {
                            position_m: p,
                            rotation: r,
                            time_s: t,
                        },
                        grip: clamp01(self.grip[h]),
                        trigger: clamp01(self.trigger[h]),
                    },
                );
            }
        }
    }
}

/// NaN-safe clamp to 0..1 (a broken driver value reads as released).
pub fn clamp01(v: f32) -> f32 {
    if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_poses_and_values_are_not_tracked() {
        let f = DeviceFrame {
            head: Some((Vec3::new(f32::NAN, 0.0, 0.0), Quat::IDENTITY)),
            hands: [Some((Vec3::ONE, Quat::IDENTITY)), None],
            ..DeviceFrame::default()
        };
        assert_eq!(f.part(0), None);
        assert_eq!(f.part(1), Some((Vec3::ONE, Quat::IDENTITY)));
        assert_eq!(f.part(2), None);
        assert_eq!(f.part(3), None);
        assert_eq!(clamp01(f32::NAN), 0.0);
        assert_eq!(clamp01(2.0), 1.0);
        assert_eq!(clamp01(0.25), 0.25);
    }
}
