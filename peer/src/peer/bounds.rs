//! The room's bounds as its walls: an object we simulate whose center leaves the box positions
//! are quantized in (it rolled off the floor, was thrown away) would be shown clamped at the
//! edge by every other peer, metres from where we have it. It goes back to its class's place
//! in the scene, at rest.

use glam::{Quat, Vec3};
use softsync_net::{NetId, ObjectState};

use super::Peer;
use crate::events::Event;
use crate::mirror::LocalBody;
use crate::scene::Kind;

impl Peer {
    /// `s` (object `id`'s state, which we simulate) if its center is inside the scene's bounds;
    /// else the object is put back home ([`Event::ReturnedHome`]) and its state there.
    pub(super) fn keep_in_bounds(
        &mut self,
        id: NetId,
        body: LocalBody,
        kind: Kind,
        s: ObjectState,
    ) -> ObjectState {
        let (lo, hi) = self.scene.bounds;
        if body == LocalBody::Pose || (s.pos.cmpge(lo).all() && s.pos.cmple(hi).all()) {
            return s;
        }
        let (home_pos, home_rot) = self.home_of(kind);
        if !self.mirror.return_home(id, home_pos, home_rot) {
            return s;
        }
        self.events
            .push_back(Event::ReturnedHome { id, from: s.pos });
        self.mirror.state(id).unwrap_or(s)
    }

    /// Where an object of `kind` goes back to when it leaves the room's bounds: the first place
    /// the scene spawns that class at, else the middle of the bounds.
    fn home_of(&self, kind: Kind) -> (Vec3, Quat) {
        self.scene
            .objects
            .iter()
            .find(|p| p.kind == kind)
            .map(|p| (p.pos, p.rot))
            .unwrap_or((
                (self.scene.bounds.0 + self.scene.bounds.1) * 0.5,
                Quat::IDENTITY,
            ))
    }
}
