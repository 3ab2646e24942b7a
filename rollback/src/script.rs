//! A rollback bot's hands: a fixed loop of reach → grip → squeeze → lift → throw → back,
//! over the scene's soft bodies and props in turn, made from the frame number and the world
//! the bot sees (its own, predicted). The same script drives the determinism tests (as a
//! recording), the rollback rooms of the binary (`softsync join --bot squeeze --sync
//! rollback`) and the `rollback` bench, so state sync and rollback run the same motions.

use glam::Vec3;
use softsync_net::PeerId;
use softsync_peer::avatar::{home, PART_OFFSETS};
use softsync_peer::device::DeviceFrame;

use crate::input::PlayerInput;
use crate::world::RollbackWorld;

/// Frames per cycle (4 s at 60 Hz).
pub const CYCLE_FRAMES: i32 = 240;

/// A scripted player: which hand, which objects, where it stands.
#[derive(Clone, Debug)]
pub struct SqueezeThrow {
    me: PeerId,
    /// Index of this player among the room's bots (spreads them over the objects).
    slot: usize,
    /// Where the grab started (the object's center at the grip frame).
    grabbed_at: Option<Vec3>,
}

impl SqueezeThrow {
    /// A bot standing at `me`'s place, starting with object `slot`.
    pub fn new(me: PeerId, slot: usize) -> Self {
        SqueezeThrow {
            me,
            slot,
            grabbed_at: None,
        }
    }

    /// The input for the frame after `world`'s.
    pub fn input(&mut self, world: &RollbackWorld) -> PlayerInput {
        PlayerInput::from_device(&self.device(world))
    }

    /// The same as a device frame.
    pub fn device(&mut self, world: &RollbackWorld) -> DeviceFrame {
        let n = world.objects().len();
        self.device_at(world.frame() + 1, n, &|i| world.object_pose(i).map(|p| p.0))
    }

    /// The device frame for `frame`, in a room of `objects` scene objects whose centers
    /// `center` gives (scene order) as this peer sees them: the same motions for a rollback
    /// peer and a state-sync one.
    pub fn device_at(
        &mut self,
        frame: i32,
        objects: usize,
        center: &dyn Fn(usize) -> Option<Vec3>,
    ) -> DeviceFrame {
        let (base, facing) = home(self.me);
        let head = base;
        let rest = base + facing * PART_OFFSETS[2];
        let n = objects.max(1);
        let cycle = frame.div_euclid(CYCLE_FRAMES);
        let t = frame.rem_euclid(CYCLE_FRAMES);
        let target = (self.slot + cycle as usize) % n;
        let object = center(target).unwrap_or(rest);
        let lerp = |a: Vec3, b: Vec3, s: f32| a + (b - a) * s.clamp(0.0, 1.0);
        let (hand, grip) = match t {
            // reach over 0.8 s
            0..48 => (lerp(rest, object, t as f32 / 48.0), 0.0),
            // grip and hold still
            48..60 => {
                if t == 48 {
                    self.grabbed_at = Some(object);
                }
                (object, 1.0)
            }
            // squeeze toward the table and lift 25 cm over 1 s
            60..120 => {
                let at = self.grabbed_at.unwrap_or(object);
                let s = (t - 60) as f32 / 60.0;
                (
                    at + Vec3::new(0.0, 0.25 * s, 0.0) + facing * Vec3::Z * (-0.03 * s),
                    1.0,
                )
            }
            // throw: fast sweep sideways and up, released at the end
            120..132 => {
                let at = self.grabbed_at.unwrap_or(object) + Vec3::Y * 0.25;
                let s = (t - 120) as f32 / 12.0;
                (
                    at + facing * Vec3::new(0.2 * s, 0.15 * s, 0.0),
                    if t < 130 { 1.0 } else { 0.0 },
                )
            }
            // back to rest
            _ => {
                let at = self.grabbed_at.unwrap_or(object) + Vec3::new(0.0, 0.4, 0.0);
                (lerp(at, rest, (t - 132) as f32 / 60.0), 0.0)
            }
        };
        let sway = (frame as f32 * 0.05).sin() * 0.02;
        DeviceFrame {
            head: Some((head + Vec3::X * sway, facing)),
            hands: [
                Some((base + facing * PART_OFFSETS[1], facing)),
                Some((hand, facing)),
            ],
            grip: [0.0, grip],
            trigger: [0.0, 0.0],
            tool: Default::default(),
            talk: false,
        }
    }
}
