//! What a bot script acts on ([`BotWorld`]): a state-sync [`Peer`], or another kind of room
//! (a rollback room's player, `softsync-bevy`'s `rollback.rs`), so one script language drives
//! both.

use glam::{Quat, Vec3};
use softsync_interaction::HandInput;
use softsync_net::{Delivery, Instant, MessageTarget, NetId, PeerId};

use crate::messages::{ReplayControl, Say};
use crate::peer::Peer;
use crate::HandTool;

/// The room as a bot sees and moves it. Object ids are the room's (`NetId`); a room without
/// owners, messages or kicks says so with an `Err` the bot reports.
pub trait BotWorld {
    /// Simulated seconds (the bot's clock).
    fn sim_time(&self) -> f64;
    /// Where this peer stands and which way it faces.
    fn home(&self) -> (Vec3, Quat);
    /// The room's objects a script can name (no avatar parts), with their class names.
    fn object_list(&self) -> Vec<(NetId, String)>;
    /// Object `id` as this peer shows it: its center and its particles (none for a rigid one).
    fn shown(&mut self, now: Instant, id: NetId) -> Option<(Vec3, Vec<Vec3>)>;
    /// What hand `hand` (0 left, 1 right) holds.
    fn held(&self, hand: usize) -> Option<NetId>;
    /// Sets an avatar part's pose (0 head, 1 left hand, 2 right hand).
    fn set_avatar_pose(&mut self, part: usize, pos: Vec3, rot: Quat);
    /// Sets a hand's input for the next step.
    fn set_hand_input(&mut self, hand: usize, input: HandInput);
    /// Chooses what a hand's trigger does.
    fn set_hand_tool(&mut self, hand: usize, tool: HandTool);
    /// Cuts made by the cutter's gesture so far (a slice waits for the next one).
    fn cut_gestures(&self) -> u64;
    /// True when scalpel strokes are the hands' own input (a rollback room): a `tear` holds
    /// the trigger along its path and the room tears where the blade goes, rather than asking
    /// for each segment.
    fn blades_are_inputs(&self) -> bool {
        false
    }
    /// Whether we may act on `id` alone (ours; in a room without owners, always).
    fn owns(&self, id: NetId) -> bool;
    /// Ask for authority over `id`.
    fn ask_authority(&mut self, now: Instant, id: NetId);
    /// Tear `id` along one segment of a scalpel (room frame).
    fn tear(
        &mut self,
        now: Instant,
        id: NetId,
        from: Vec3,
        to: Vec3,
        blade: Vec3,
    ) -> Result<(), String>;
    /// End `id`'s stroke.
    fn lift(&mut self, now: Instant, id: NetId) -> Result<(), String>;
    /// Cut `id` by the plane through `point` with `normal` (room frame).
    fn cut(&mut self, now: Instant, id: NetId, point: Vec3, normal: Vec3) -> Result<(), String>;
    /// Send a line of text to everyone (retained: the room keeps the latest); the message's
    /// sequence number.
    fn say(&mut self, now: Instant, text: &str, retained: bool) -> Result<u32, String>;
    /// Steer a played-back recording (to the room's host).
    fn replay(&mut self, now: Instant, c: &ReplayControl) -> Result<u32, String>;
    /// Host: kick `who` (`None`: the member that joined last) with `reason`; who was kicked.
    fn kick(&mut self, now: Instant, who: Option<PeerId>, reason: &str) -> Result<PeerId, String>;
}

impl BotWorld for Peer {
    fn sim_time(&self) -> f64 {
        Peer::sim_time(self)
    }

    fn home(&self) -> (Vec3, Quat) {
        Peer::home(self)
    }

    fn object_list(&self) -> Vec<(NetId, String)> {
        self.objects()
            .iter()
            .filter(|(_, o)| !o.kind.is_avatar())
            .map(|(id, o)| (*id, self.scene().name_of(o.kind).to_owned()))
            .collect()
    }

    fn shown(&mut self, now: Instant, id: NetId) -> Option<(Vec3, Vec<Vec3>)> {
        self.shown_state(now, id).map(|s| (s.pos, s.particles))
    }

    fn held(&self, hand: usize) -> Option<NetId> {
        Peer::held(self, hand).map(|(id, _)| id)
    }

    fn set_avatar_pose(&mut self, part: usize, pos: Vec3, rot: Quat) {
        Peer::set_avatar_pose(self, part, pos, rot);
    }

    fn set_hand_input(&mut self, hand: usize, input: HandInput) {
        Peer::set_hand_input(self, hand, input);
    }

    fn set_hand_tool(&mut self, hand: usize, tool: HandTool) {
        Peer::set_hand_tool(self, hand, tool);
    }

    fn cut_gestures(&self) -> u64 {
        self.counters().cut_gestures
    }

    fn owns(&self, id: NetId) -> bool {
        self.session().owner(id) == Some(self.me())
    }

    fn ask_authority(&mut self, now: Instant, id: NetId) {
        Peer::ask_authority(self, now, id);
    }

    fn tear(
        &mut self,
        now: Instant,
        id: NetId,
        from: Vec3,
        to: Vec3,
        blade: Vec3,
    ) -> Result<(), String> {
        Peer::tear(self, now, id, from, to, blade).map_err(|e| e.to_string())
    }

    fn lift(&mut self, now: Instant, id: NetId) -> Result<(), String> {
        Peer::lift(self, now, id).map_err(|e| e.to_string())
    }

    fn cut(&mut self, now: Instant, id: NetId, point: Vec3, normal: Vec3) -> Result<(), String> {
        Peer::cut(self, now, id, point, normal).map_err(|e| e.to_string())
    }

    fn say(&mut self, now: Instant, text: &str, retained: bool) -> Result<u32, String> {
        let how = if retained {
            Delivery::Retained
        } else {
            Delivery::Reliable
        };
        let msg = Say { text: text.into() };
        self.send(now, MessageTarget::Everyone, how, &msg)
            .map_err(|e| e.to_string())
    }

    fn replay(&mut self, now: Instant, c: &ReplayControl) -> Result<u32, String> {
        self.send(now, MessageTarget::Host, Delivery::Reliable, c)
            .map_err(|e| e.to_string())
    }

    fn kick(&mut self, now: Instant, who: Option<PeerId>, reason: &str) -> Result<PeerId, String> {
        let me = self.me();
        let target = who.or_else(|| {
            let members = self.session().members();
            members
                .iter()
                .filter(|(p, _)| **p != me)
                .max_by_key(|(_, seq)| **seq)
                .map(|(p, _)| *p)
        });
        let Some(p) = target else {
            return Err("nobody else in the room".into());
        };
        Peer::kick(self, now, p, reason).map_err(|e| e.to_string())?;
        Ok(p)
    }
}
