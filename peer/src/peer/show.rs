//! What a peer shows: its id and session, the room's objects and the local world, counters,
//! the state it draws for each object, what its hands hold and hover.

use std::collections::{BTreeMap, BTreeSet};

use glam::{Quat, Vec3};
use softsync_interaction::Target;
use softsync_net::{DisplayedState, Instant, NetId, ObjectState, PeerId, Session};
use softsync_softbody::rapier3d::prelude::PhysicsWorld;
use softsync_softbody::SoftBodySet;

use super::{Peer, PeerConfig};
use crate::avatar;
use crate::events::Counters;
use crate::mirror::{LocalBody, MirroredObject};
use crate::scene::Scene;

impl Peer {
    /// This peer's id.
    pub fn me(&self) -> PeerId {
        self.session.local_id()
    }

    /// In the room (host, or welcomed).
    pub fn joined(&self) -> bool {
        self.joining.joined()
    }

    /// The session (membership, owners, states, traffic statistics).
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The networked objects as this peer knows them.
    pub fn objects(&self) -> &BTreeMap<NetId, MirroredObject> {
        &self.mirror.objects
    }

    /// The rapier world (static scene and the objects' bodies).
    pub fn world(&self) -> &PhysicsWorld {
        &self.mirror.world
    }

    /// The soft bodies in [`Peer::world`].
    pub fn soft_bodies(&self) -> &SoftBodySet {
        &self.mirror.soft
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The configuration.
    pub fn config(&self) -> &PeerConfig {
        &self.config
    }

    /// What this peer counted.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Simulated seconds.
    pub fn sim_time(&self) -> f64 {
        self.sim_time_s
    }

    /// Fixed steps run.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The time of the last fixed step: the time our published states stand for.
    pub fn last_step_at(&self) -> Instant {
        self.last_step_at
    }

    /// Where this peer stands: around the table, by its id.
    pub fn home(&self) -> (Vec3, Quat) {
        avatar::home(self.me())
    }

    /// Our avatar's parts (head, left hand, right hand), once spawned.
    pub fn avatar_parts(&self) -> [Option<NetId>; 3] {
        self.avatar.parts
    }

    /// How late a remote object is shown now (its interpolation delay; zero for our own).
    pub fn display_delay(&mut self, now: Instant, id: NetId) -> Option<std::time::Duration> {
        self.session.display_state(now, id).map(|d| d.delay)
    }

    /// Interpolate a remote object with its own settings
    /// ([`Session::set_object_interpolation`]).
    pub fn set_object_interpolation(
        &mut self,
        id: NetId,
        cfg: Option<softsync_net::InterpolationConfig>,
    ) -> bool {
        self.session.set_object_interpolation(id, cfg)
    }

    /// A datagram of `payload` bytes went to `to` beside the session (voice): it is paid from
    /// that link's uplink budget ([`Session::charge_uplink`]).
    pub fn charge_uplink(&mut self, now: Instant, to: PeerId, payload: usize) {
        self.session.charge_uplink(now, to, payload);
    }

    /// The state this peer shows for an object now: simulated if we own it, interpolated
    /// otherwise (what the dump writes); none for a body of ours still being built.
    pub fn shown_state(&mut self, now: Instant, id: NetId) -> Option<ObjectState> {
        if !self.mirror.objects.contains_key(&id) {
            return None;
        }
        if self.session.owner(id) == Some(self.me()) {
            // a body still being built (a cut's piece) has nothing to show yet
            let building = self
                .mirror
                .objects
                .get(&id)
                .is_some_and(|o| matches!(o.body, crate::mirror::LocalBody::Building));
            (!building).then(|| self.mirror.state(id)).flatten()
        } else {
            self.session
                .display_state(now, id)
                .map(|d| d.state)
                .or_else(|| self.session.latest_state(id))
        }
    }

    /// Where hand `hand` (0 left, 1 right) is: its newest input sample's position.
    pub fn hand_position(&self, hand: usize) -> Option<Vec3> {
        let h = *self.hand_ids.get(hand)?;
        self.hands.sample(h).map(|s| s.position_m)
    }

    /// True if hand `hand` holds a body another peer simulates (a remote hand).
    pub fn holds_remotely(&self, hand: usize) -> bool {
        self.hand_ids
            .get(hand)
            .is_some_and(|h| self.hands.remote(*h).is_some())
    }

    /// The object's body in this peer's world as the last step left it: for a body another
    /// peer simulates, the replicated state plus our remote hands' corrections (what is drawn;
    /// [`Peer::shown_state`] is the replicated state alone).
    pub fn local_state(&self, id: NetId) -> Option<ObjectState> {
        self.mirror.state(id)
    }

    /// The pose an object is drawn at now: a rigid body's simulated pose (ours, or the
    /// replica moved to the owner's interpolated state), our own avatar parts where the bot or
    /// device put them, anything else at its shown state. Soft bodies are drawn from their
    /// particles ([`SoftBodySet`]'s render positions); this is their centre.
    pub fn drawn_pose(&mut self, now: Instant, id: NetId) -> Option<(Vec3, Quat)> {
        let o = self.mirror.objects.get(&id)?;
        match o.body {
            LocalBody::Rigid(h) => {
                let b = self.mirror.world.bodies.get(h)?;
                Some((b.translation(), *b.rotation()))
            }
            LocalBody::Pose if o.avatar_of == Some(self.me()) => Some(o.pose),
            _ => self.shown_state(now, id).map(|s| (s.pos, s.rot)),
        }
    }

    /// The interpolated state of an object another peer owns, with the owner's time it
    /// stands for (see [`Session::display_state`]).
    pub fn displayed_state(&mut self, now: Instant, id: NetId) -> Option<DisplayedState> {
        self.session.display_state(now, id)
    }

    /// What a hand (0 left, 1 right) holds, as a networked id.
    pub fn held(&self, hand: usize) -> Option<(NetId, Target)> {
        let h = *self.hand_ids.get(hand)?;
        let t = self.hands.held(h).or_else(|| self.hands.remote(h))?;
        Some((self.mirror.id_of(t.object())?, t))
    }

    /// Objects our hands hover now (a view tints them).
    pub fn hovered_ids(&self) -> BTreeSet<NetId> {
        self.hand_ids
            .iter()
            .flat_map(|h| self.hands.hovered(*h))
            .filter_map(|hv| self.mirror.id_of(hv.target.object()))
            .collect()
    }

    /// How many objects we own.
    pub fn owned_count(&self) -> usize {
        let me = self.me();
        self.mirror
            .objects
            .keys()
            .filter(|id| self.session.owner(**id) == Some(me))
            .count()
    }
}
