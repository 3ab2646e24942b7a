//! A recorded session played back as a room (`softsync replay --serve`): the host is a
//! puppeteer. It simulates nothing: each object of the recording is a body of ours, built
//! from its class and its log like a reopened one ([`Peer::reopen`]), shown in the state the
//! recording has for the moment played, and published; its tears are appended to its log as
//! the recording reaches them, a cut's pieces appear as objects of their own, and what the
//! recording says is gone goes. Spectators join as into any room; the objects are locked
//! (nobody takes them) and their blades cut nothing.

use softsync_net::wire::TopologyEvent;
use softsync_net::{Instant, KeptObject, NetId, ObjectState};

use super::Peer;
use crate::events::PeerError;
use crate::mirror::LocalBody;
use crate::scene::Kind;

impl Peer {
    /// Play a recording back: from now on bodies are shown, not simulated (drive the peer
    /// with [`Peer::pump`] and the `replay_*` calls, not [`Peer::fixed_step`]), and blades of
    /// others on our objects are refused.
    pub fn set_replaying(&mut self, on: bool) {
        self.replaying = on;
    }

    /// Whether a recording is played back here.
    pub fn replaying(&self) -> bool {
        self.replaying
    }

    /// Host: object `o` of the recording appears (under a fresh id, returned): its body built
    /// from its class and replayed through its log, in the frame; an avatar part is a pose.
    /// Errors: not hosting, a class the scene lacks, a log entry that does not replay.
    pub fn replay_spawn(&mut self, now: Instant, o: &KeptObject) -> Result<NetId, PeerError> {
        let kind = Kind::of_class(o.class);
        let body = if kind.is_avatar() {
            LocalBody::Pose
        } else if self.scene.class(kind).is_some() {
            self.mirror
                .build(&self.scene, kind, o.state.pos, o.state.rot)?
        } else {
            return Err(PeerError::Build(format!(
                "replaying: object {} is of class {}, which the scene has no object class for",
                o.id.0, o.class.0
            )));
        };
        // built under a placeholder id, replayed, then named by the session
        let temp = NetId(u32::MAX);
        self.mirror.insert(temp, kind, body, None);
        self.mirror.set_pose(temp, o.state.pos, o.state.rot);
        for (seq, e) in o.topology.iter().enumerate() {
            if let Err(err) = self.mirror.apply_topology(&self.scene, temp, e) {
                self.mirror.remove(temp);
                return Err(PeerError::Build(format!(
                    "replaying: entry {seq} of object {}'s log ({e:?}) does not replay: {err}",
                    o.id.0
                )));
            }
        }
        // the body as built and shown: a recorded state that does not fit it (a piece
        // recorded while it was still being built has no particles) places it whole
        if !self.mirror.apply_shown(temp, &o.state) {
            self.counters.apply_errors += 1;
        }
        let state = self.mirror.state(temp).unwrap_or_else(|| o.state.clone());
        let id = match self
            .session
            .replay_object(now, KeptObject { state, ..o.clone() })
        {
            Ok(id) => id,
            Err(e) => {
                self.mirror.remove(temp);
                return Err(PeerError::Build(format!(
                    "replaying object {}: {e}",
                    o.id.0
                )));
            }
        };
        self.mirror.rename(temp, id);
        Ok(id)
    }

    /// Host: entry `event` of the recording is appended to our object `id`'s log (a tear, a
    /// lift, a resolution change); its body takes it at the session's `Event::Topology`, as
    /// for any entry.
    pub fn replay_entry(
        &mut self,
        now: Instant,
        id: NetId,
        event: TopologyEvent,
    ) -> Result<(), PeerError> {
        self.session
            .replay_entry(now, id, event)
            .map_err(|e| PeerError::Build(format!("replaying an entry of object {}: {e}", id.0)))
    }

    /// Host: our replayed object `id` is gone (the recording says so, or a seek went before
    /// it appeared).
    pub fn replay_remove(&mut self, now: Instant, id: NetId) {
        if self.session.despawn(now, id).is_ok() {
            self.mirror.remove(id);
        }
    }

    /// Host: our replayed object `id` shows `state` now, and every member is sent it. False
    /// when a soft body refused it (a particle count that does not fit, values not finite).
    pub fn replay_show(&mut self, now: Instant, id: NetId, state: &ObjectState) -> bool {
        let kind = self.mirror.objects.get(&id).map(|o| o.kind);
        if kind.is_some_and(Kind::is_avatar) {
            self.mirror.set_pose(id, state.pos, state.rot);
        } else if !self.mirror.apply_shown(id, state) {
            self.counters.apply_errors += 1;
            return false;
        }
        let shown = self.mirror.state(id).unwrap_or_else(|| state.clone());
        self.session.publish_state(now, id, &shown).is_ok()
    }
}

impl Peer {
    /// Host, before anyone joined: the room clock reads `room_time` now (a replay's room
    /// keeps the recording's times).
    pub fn replay_room_time(
        &mut self,
        now: Instant,
        room_time: std::time::Duration,
    ) -> Result<(), PeerError> {
        self.session
            .resume_room_time(now, room_time)
            .map_err(|e| PeerError::Build(format!("replaying: {e}")))
    }
}
