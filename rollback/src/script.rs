//! A rollback bot's hands: [`ScriptedPlayer`] runs the bot script language on a rollback
//! player; [`SqueezeThrow`] is a fixed loop of reach → grip → squeeze → lift → throw → back,
//! over the scene's soft bodies and props in turn, made from the frame number and the world
//! the bot sees (its own, predicted). The same script drives the determinism tests (as a
//! recording), the rollback rooms of the binary (`softsync join --bot squeeze --sync
//! rollback`) and the `rollback` bench, so state sync and rollback run the same motions.

use glam::Vec3;
use softsync_interaction::HandInput;
use softsync_net::wire::TopologyEvent;
use softsync_net::{Delivery, Instant, MessageTarget, NetId, PeerId};
use softsync_peer::avatar::{home, PART_OFFSETS};
use softsync_peer::bot::{Bot, BotWorld};
use softsync_peer::device::DeviceFrame;
use softsync_peer::messages::{ReplayControl, Say};
use softsync_peer::HandTool;

use crate::input::PlayerInput;
use crate::room::RollbackPeer;
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

/// A bot script (`softsync_peer::bot`'s language) driving a rollback player: each tick the
/// script runs against the player's own (predicted) view of the world and its hands become
/// the player's input. Scalpel strokes hold the trigger along their path and sweeps hold the
/// cutter's (the world tears and cuts where the blades go, as for any player); `say` and
/// `note` send the room a message; `own`, `cut` (a plane cut without a gesture), `replay` and
/// `kick` say why they do not apply here.
#[derive(Debug)]
pub struct ScriptedPlayer {
    bot: Bot,
    tools: [HandTool; 2],
}

impl ScriptedPlayer {
    /// A player running `bot`.
    pub fn new(bot: Bot) -> Self {
        ScriptedPlayer {
            bot,
            tools: [HandTool::Scalpel; 2],
        }
    }

    /// The input for the next frame of `peer`'s world (none before its first epoch), with
    /// `device` under the script as on a state-sync peer.
    pub fn input(
        &mut self,
        now: Instant,
        peer: &mut RollbackPeer,
        device: Option<&DeviceFrame>,
    ) -> PlayerInput {
        if peer.world().is_none() {
            return PlayerInput::default();
        }
        let mut view = PlayerView {
            peer,
            frame: DeviceFrame::default(),
            tools: self.tools,
        };
        self.bot.step(now, &mut view, device);
        self.tools = view.tools;
        let mut d = view.frame;
        d.tool = self.tools;
        PlayerInput::from_device(&d)
    }

    /// The next thing the script said (oldest first).
    pub fn poll_message(&mut self) -> Option<String> {
        self.bot.poll_message()
    }

    /// The script ran to its end.
    pub fn done(&self) -> bool {
        self.bot.done
    }
}

/// A rollback player's world as its script sees it.
struct PlayerView<'a> {
    peer: &'a mut RollbackPeer,
    frame: DeviceFrame,
    tools: [HandTool; 2],
}

impl PlayerView<'_> {
    fn world(&self) -> Option<&RollbackWorld> {
        self.peer.world()
    }
}

impl BotWorld for PlayerView<'_> {
    fn sim_time(&self) -> f64 {
        // the frame this input is for
        self.world()
            .map_or(0.0, |w| f64::from(w.frame() + 1) * f64::from(w.dt_s()))
    }

    fn home(&self) -> (Vec3, glam::Quat) {
        home(self.peer.me())
    }

    fn object_list(&self) -> Vec<(NetId, String)> {
        let scene = self.peer.scene();
        self.world().map_or_else(Vec::new, |w| {
            w.objects()
                .iter()
                .enumerate()
                .map(|(i, o)| (NetId(i as u32), scene.name_of(o.kind).to_owned()))
                .collect()
        })
    }

    fn shown(&mut self, _now: Instant, id: NetId) -> Option<(Vec3, Vec<Vec3>)> {
        let w = self.world()?;
        let i = id.0 as usize;
        Some((w.object_pose(i)?.0, w.particles(i).unwrap_or_default()))
    }

    fn held(&self, hand: usize) -> Option<NetId> {
        let me = self.peer.me();
        let w = self.world()?;
        let p = w.players().iter().position(|x| *x == me)?;
        w.held(p, hand).map(|i| NetId(i as u32))
    }

    fn set_avatar_pose(&mut self, part: usize, pos: Vec3, rot: glam::Quat) {
        // the hands are their inputs' (`set_hand_input`); the head is the avatar's
        if part == 0 {
            self.frame.head = Some((pos, rot));
        }
    }

    fn set_hand_input(&mut self, hand: usize, input: HandInput) {
        if hand < 2 {
            self.frame.hands[hand] = Some((input.sample.position_m, input.sample.rotation));
            self.frame.grip[hand] = input.grip;
            self.frame.trigger[hand] = input.trigger;
        }
    }

    fn set_hand_tool(&mut self, hand: usize, tool: HandTool) {
        if let Some(t) = self.tools.get_mut(hand) {
            *t = tool;
        }
    }

    fn cut_gestures(&self) -> u64 {
        self.world().map_or(0, |w| {
            w.topology_log()
                .iter()
                .filter(|e| matches!(e.event, TopologyEvent::Cut { .. }))
                .count() as u64
        })
    }

    fn blades_are_inputs(&self) -> bool {
        true
    }

    fn owns(&self, _id: NetId) -> bool {
        // nobody owns anything in a rollback room: every hand acts at once
        true
    }

    fn ask_authority(&mut self, _now: Instant, _id: NetId) {}

    fn tear(&mut self, _: Instant, _: NetId, _: Vec3, _: Vec3, _: Vec3) -> Result<(), String> {
        Err("a rollback room tears where the scalpel goes (the stroke is the input)".into())
    }

    fn lift(&mut self, _now: Instant, _id: NetId) -> Result<(), String> {
        Err("a rollback room lifts the scalpel with the trigger".into())
    }

    fn cut(&mut self, _: Instant, _: NetId, _: Vec3, _: Vec3) -> Result<(), String> {
        Err("a rollback room cuts by the cutter's sweep: use `slice`".into())
    }

    fn say(&mut self, now: Instant, text: &str, retained: bool) -> Result<u32, String> {
        let how = if retained {
            Delivery::Retained
        } else {
            Delivery::Reliable
        };
        let msg = Say { text: text.into() };
        self.peer
            .send(now, MessageTarget::Everyone, how, &msg)
            .map_err(|e| e.to_string())
    }

    fn replay(&mut self, _now: Instant, _c: &ReplayControl) -> Result<u32, String> {
        Err("a rollback room plays back no recording".into())
    }

    fn kick(&mut self, _: Instant, _: Option<PeerId>, _: &str) -> Result<PeerId, String> {
        Err("a rollback room's host kicks no one yet (use a state-sync room)".into())
    }
}
