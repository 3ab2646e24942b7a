//! A player's input for one frame: head and hand poses quantized as the state codec quantizes
//! rotations (smallest three, [`ROT_BITS`] bits), positions to the millimetre, grip and
//! trigger to 1/255. This is all that crosses the network in a rollback room; every peer
//! dequantizes the same integers into the same floats, so the step sees the same numbers
//! everywhere.

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use softsync_net::quant::{dequantize_quat, quantize_quat, QuatQ};
use softsync_peer::device::DeviceFrame;
use softsync_peer::HandTool;

/// Bits per rotation component (the state codec's default for objects).
pub const ROT_BITS: u32 = 11;
/// Position grid, metres (positions clamp to ±32.767 m).
pub const POS_STEP_M: f32 = 0.001;

/// One tracked part: position in millimetres, rotation as smallest three.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct PartInput {
    /// Position, millimetres (room frame).
    pub pos_mm: [i16; 3],
    /// Index of the dropped component (bits 0–1); bit 7: the part is tracked.
    pub rot_largest: u8,
    /// The three kept components.
    pub rot: [u16; 3],
}

impl PartInput {
    /// Quantize a pose; a non-finite pose is not tracked.
    pub fn new(pos: Vec3, rot: Quat) -> Self {
        if !(pos.is_finite() && rot.is_finite()) {
            return Self::default();
        }
        let mm = |v: f32| (v / POS_STEP_M).round().clamp(-32767.0, 32767.0) as i16;
        let q = quantize_quat(rot, ROT_BITS);
        PartInput {
            pos_mm: [mm(pos.x), mm(pos.y), mm(pos.z)],
            rot_largest: 0x80 | (q.largest & 3),
            rot: [q.comps[0] as u16, q.comps[1] as u16, q.comps[2] as u16],
        }
    }

    /// Whether the part is tracked this frame.
    pub fn tracked(&self) -> bool {
        self.rot_largest & 0x80 != 0
    }

    /// The pose, if tracked.
    pub fn pose(&self) -> Option<(Vec3, Quat)> {
        if !self.tracked() {
            return None;
        }
        let p = Vec3::new(
            f32::from(self.pos_mm[0]),
            f32::from(self.pos_mm[1]),
            f32::from(self.pos_mm[2]),
        ) * POS_STEP_M;
        let q = QuatQ {
            largest: self.rot_largest & 3,
            comps: [
                u32::from(self.rot[0]),
                u32::from(self.rot[1]),
                u32::from(self.rot[2]),
            ],
        };
        Some((p, dequantize_quat(q, ROT_BITS)))
    }
}

/// A player's input for one frame. `Default` is "no input" (nothing tracked, hands open):
/// what ggrs feeds for a disconnected player.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct PlayerInput {
    /// Head, left hand, right hand.
    pub parts: [PartInput; 3],
    /// Grip per hand, 0..=255.
    pub grip: [u8; 2],
    /// Trigger per hand, 0..=255.
    pub trigger: [u8; 2],
    /// Per hand (bit 0 left, bit 1 right): its trigger works the cutter (a sweep cuts the
    /// body in two) rather than the scalpel (the hand's path tears it). A stroke or a cut is
    /// part of the input this way: the world turns the hand's path into tears and cuts the
    /// same on every peer (`world.rs`).
    pub cutter: u8,
}

fn unit(v: f32) -> u8 {
    if v.is_finite() {
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    } else {
        0
    }
}

impl PlayerInput {
    /// Quantize a device frame (a headset, the desktop's mouse hands, or a bot's).
    pub fn from_device(d: &DeviceFrame) -> Self {
        let part =
            |p: Option<(Vec3, Quat)>| p.map(|(p, r)| PartInput::new(p, r)).unwrap_or_default();
        PlayerInput {
            parts: [part(d.head), part(d.hands[0]), part(d.hands[1])],
            grip: [unit(d.grip[0]), unit(d.grip[1])],
            trigger: [unit(d.trigger[0]), unit(d.trigger[1])],
            cutter: (0..2)
                .filter(|&h| d.tool[h] == HandTool::Cutter)
                .fold(0, |bits, h| bits | 1 << h),
        }
    }

    /// The device frame every peer reconstructs from it.
    pub fn to_device(&self) -> DeviceFrame {
        DeviceFrame {
            head: self.parts[0].pose(),
            hands: [self.parts[1].pose(), self.parts[2].pose()],
            grip: [
                f32::from(self.grip[0]) / 255.0,
                f32::from(self.grip[1]) / 255.0,
            ],
            trigger: [
                f32::from(self.trigger[0]) / 255.0,
                f32::from(self.trigger[1]) / 255.0,
            ],
            tool: [0, 1].map(|h| {
                if self.cutter & 1 << h != 0 {
                    HandTool::Cutter
                } else {
                    HandTool::Scalpel
                }
            }),
            // the talk key is not part of the game's input (voice is the room's, not ggrs's)
            talk: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_survives_quantization_to_a_millimetre_and_a_tenth_of_a_degree() {
        let rot = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.2, 2.0);
        let pos = Vec3::new(0.4123, 1.2049, -0.3333);
        let q = PartInput::new(pos, rot);
        let (p, r) = q.pose().expect("tracked");
        assert!(p.distance(pos) <= 0.0009, "{p} vs {pos}");
        assert!(softsync_net::quant::angle_between(r, rot) < 0.2f32.to_radians());
        // Same integers, same floats: what determinism rests on.
        assert_eq!(PartInput::new(p, r).pose(), Some((p, r)));
    }

    #[test]
    fn non_finite_poses_and_values_become_untracked_and_zero() {
        let d = DeviceFrame {
            head: Some((Vec3::NAN, Quat::IDENTITY)),
            hands: [
                Some((Vec3::ONE, Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0))),
                None,
            ],
            grip: [f32::NAN, 2.0],
            trigger: [-1.0, f32::INFINITY],
            tool: Default::default(),
            talk: false,
        };
        let i = PlayerInput::from_device(&d);
        assert!(!i.parts[0].tracked() && !i.parts[1].tracked() && !i.parts[2].tracked());
        assert_eq!(i.grip, [0, 255]);
        assert_eq!(i.trigger, [0, 0]);
        assert_eq!(PlayerInput::default().to_device().grip, [0.0, 0.0]);
    }

    #[test]
    fn each_hands_tool_crosses_as_a_bit() {
        let mut d = PlayerInput::default().to_device();
        d.tool = [HandTool::Scalpel, HandTool::Cutter];
        let i = PlayerInput::from_device(&d);
        assert_eq!(i.cutter, 0b10);
        assert_eq!(i.to_device().tool, d.tool);
    }
}
