//! Objects coming and going: the host spawns (its own objects at once, a member's on
//! request, owned by the member), announces every spawn to the room and gives a late joiner
//! or a migrated room a snapshot; a member's requests not answered when the host died go to
//! the next host (which answers a repeated one with the object it already has).

use std::collections::BTreeMap;

use super::{Event, Role, Session};
use crate::error::NetError;
use crate::ids::{AuthorityEpoch, ClassId, NetId, PeerId};
use crate::policy::AuthorityPolicy;
use crate::session::ObjectState;
use crate::time::Instant;
use crate::wire::{self, Control, SpawnInfo};

/// Our spawn requests the host has not answered yet, by request number, with what to
/// publish once the object exists.
#[derive(Debug, Default)]
pub(crate) struct PendingSpawns {
    next_request: u32,
    pending: BTreeMap<u32, (ClassId, ObjectState)>,
}

impl PendingSpawns {
    /// A fresh request number.
    fn next(&mut self) -> u32 {
        let r = self.next_request;
        self.next_request = self.next_request.wrapping_add(1);
        r
    }

    /// Remember request `r` until answered.
    fn insert(&mut self, r: u32, class: ClassId, state: ObjectState) {
        self.pending.insert(r, (class, state));
    }

    /// Request `r` was answered: what to publish.
    fn answered(&mut self, r: u32) -> Option<ObjectState> {
        self.pending.remove(&r).map(|(_, st)| st)
    }

    /// Every unanswered request, in order.
    pub fn iter(&self) -> impl Iterator<Item = (u32, ClassId, ObjectState)> + '_ {
        self.pending.iter().map(|(r, (c, st))| (*r, *c, st.clone()))
    }

    /// Every unanswered request, taken (we became host and serve them ourselves).
    pub fn take_all(&mut self) -> Vec<(u32, ClassId, ObjectState)> {
        std::mem::take(&mut self.pending)
            .into_iter()
            .map(|(r, (c, st))| (r, c, st))
            .collect()
    }
}

/// The request to the host for an object of `class` in `state`.
pub(crate) fn spawn_request(request: u32, class: ClassId, state: &ObjectState) -> Control {
    Control::SpawnRequest {
        request,
        class,
        particles: state.particles.len() as u32,
        pos: state.pos.to_array(),
        rot: state.rot.to_array(),
    }
}

impl Session {
    /// Spawn an object. On the host it exists at once (owned by the host) and its id is
    /// returned; on a client the host is asked and `Event::Spawned { request }` follows,
    /// with the returned number as `request` (and `NetId(0)` returned here). The state is
    /// checked as in [`Session::publish_state`].
    pub fn spawn(
        &mut self,
        now: Instant,
        class: ClassId,
        state: ObjectState,
    ) -> Result<(NetId, u32), NetError> {
        if self.class(class).is_none() {
            return Err(NetError::UnknownClass(class.0));
        }
        let state = ObjectState {
            rot: state.checked_rotation()?,
            ..state
        };
        if state.particles.len() > wire::MAX_PARTICLES as usize {
            return Err(NetError::InvalidState("too many particles"));
        }
        let request = self.spawns.next();
        match self.role {
            Role::Host => {
                let id = self.host_spawn_own(now, class, &state, request)?;
                Ok((id, request))
            }
            Role::Client => {
                let host = self.host.ok_or(NetError::NotConnected)?;
                let msg = spawn_request(request, class, &state);
                self.spawns.insert(request, class, state);
                self.send_control(now, host, &msg);
                Ok((NetId(0), request))
            }
            Role::Joining | Role::Refused => Err(NetError::NotConnected),
        }
    }

    /// Despawn an object we own (or any object, on the host).
    pub fn despawn(&mut self, now: Instant, id: NetId) -> Result<(), NetError> {
        let owner = self.owner(id).ok_or(NetError::UnknownObject(id))?;
        if self.role != Role::Host && owner != self.local {
            return Err(NetError::NotOwner(id, owner));
        }
        self.ask_host(now, Control::DespawnRequest { id })
    }

    /// As host: create an object we own (our spawn request number `request`) and announce it.
    pub(super) fn host_spawn_own(
        &mut self,
        now: Instant,
        class: ClassId,
        state: &ObjectState,
        request: u32,
    ) -> Result<NetId, NetError> {
        let policy = self
            .class(class)
            .ok_or(NetError::UnknownClass(class.0))?
            .authority;
        let id = self.objects.alloc_id().ok_or(NetError::IdsExhausted)?;
        let info = self.own_spawn(
            id,
            class,
            policy,
            (state.pos, state.rot),
            state.particles.len(),
            0,
        );
        self.insert_object(now, info.clone(), Some(request));
        let _ = self.publish_state(now, id, state);
        self.broadcast(now, &Control::Spawn(info), None);
        Ok(id)
    }

    /// The `Spawn` of an object of ours made now (this term, no grant yet, not held): `id` of
    /// `class` with `policy`, at `pose`, of `particles` particles, its log `topology` entries
    /// long.
    pub(super) fn own_spawn(
        &self,
        id: NetId,
        class: ClassId,
        policy: AuthorityPolicy,
        pose: (glam::Vec3, glam::Quat),
        particles: usize,
        topology: usize,
    ) -> SpawnInfo {
        SpawnInfo {
            id,
            class,
            owner: self.local,
            epoch: AuthorityEpoch {
                term: self.term.0,
                grant: 0,
            },
            held: false,
            policy,
            particles: particles as u32,
            pos: pose.0.to_array(),
            rot: pose.1.to_array(),
            request: None,
            topology: topology as u32,
        }
    }

    /// Host: a member asks for an object it will own.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn on_spawn_request(
        &mut self,
        now: Instant,
        from: PeerId,
        request: u32,
        class: ClassId,
        particles: u32,
        pos: [f32; 3],
        rot: [f32; 4],
    ) {
        let Some(c) = self.class(class) else { return };
        let policy = c.authority;
        // a request repeated after a migration whose object we already have
        let existing = self
            .objects
            .iter()
            .find(|o| o.info.owner == from && o.info.request == Some(request))
            .map(|o| o.info.clone());
        if let Some(info) = existing {
            self.send_spawn(now, from, info);
            return;
        }
        if !self.may_create_for(from, particles) {
            self.stats.refused_controls += 1;
            return;
        }
        let Some(id) = self.objects.alloc_id() else {
            self.stats.refused_controls += 1;
            return;
        };
        let info = SpawnInfo {
            id,
            class,
            owner: from,
            epoch: AuthorityEpoch {
                term: self.term.0,
                grant: 0,
            },
            held: true,
            policy,
            particles,
            pos,
            rot,
            request: Some(request),
            topology: 0,
        };
        self.insert_object(now, info.clone(), None);
        self.broadcast(now, &Control::Spawn(info.clone()), Some(from));
        self.send_spawn(now, from, info);
        if let Some(o) = self.objects.get_mut(id) {
            o.source = Some(from);
        }
    }

    /// Host: a member claims an object we do not know (after our takeover): created only with
    /// an id the old host may have spawned unseen by us, and within the per-peer limits.
    pub(super) fn create_claimed(&mut self, now: Instant, from: PeerId, info: SpawnInfo) {
        if !self.objects.is_lost_id(info.id) || !self.may_create_for(from, info.particles) {
            self.stats.refused_controls += 1;
            return;
        }
        let id = info.id;
        self.insert_object(now, info.clone(), None);
        if let Some(o) = self.objects.get_mut(id) {
            o.source = Some(from);
        }
        self.broadcast(now, &Control::Spawn(info), Some(from));
    }

    /// Host: may one more object of `particles` particles be created for `p`?
    fn may_create_for(&self, p: PeerId, particles: u32) -> bool {
        self.objects.may_create_for(
            p,
            particles,
            self.cfg.max_objects_per_peer,
            self.cfg.max_particles_per_peer,
        )
    }

    /// Send one `Spawn` to `to`, remembered until acknowledged (no state flows before).
    fn send_spawn(&mut self, now: Instant, to: PeerId, info: SpawnInfo) {
        let id = info.id;
        let seq = self.send_control(now, to, &Control::Spawn(info));
        if let (Some(l), Some(seq)) = (self.links.get_mut(&to), seq) {
            l.spawn_pending.insert(id, seq);
        }
    }

    /// Host: every object, as `Spawn`s at their current pose, to `to` (a joiner, or a member
    /// after we took over).
    pub(super) fn send_snapshot(&mut self, now: Instant, to: PeerId) {
        let infos: Vec<SpawnInfo> = self
            .objects
            .iter()
            .map(|o| {
                let mut i = o.info.clone();
                i.topology = o.topology.entries.len() as u32;
                if let Some(class) = self.class(o.info.class) {
                    let st = o.compose(class);
                    i.pos = st.pos.to_array();
                    i.rot = st.rot.to_array();
                }
                i
            })
            .collect();
        for info in infos {
            let id = info.id;
            self.send_spawn(now, to, info);
            self.send_topology_log(now, to, id);
        }
        self.send_control(now, to, &Control::SnapshotEnd);
    }

    /// Add a replica of `info`; `request`: our spawn request it answers.
    pub(super) fn insert_object(&mut self, now: Instant, info: SpawnInfo, request: Option<u32>) {
        let Some(class) = self.cfg.class(info.class) else {
            return;
        };
        let ev = Event::Spawned {
            id: info.id,
            class: info.class,
            owner: info.owner,
            request,
        };
        self.objects.insert(now, info, class);
        self.events.push_back(ev);
    }

    /// Our host announces an object (a spawn, the snapshot, or a member's repeated request
    /// answered); one we know already only updates its owner.
    pub(super) fn on_spawn_from_host(&mut self, now: Instant, info: SpawnInfo) {
        if self.class(info.class).is_none() {
            return;
        }
        // named by a new host's snapshot: its record of the owner stands, even at an older
        // epoch than ours (it missed the old host's last grant) — unless we claimed the
        // object (`Resync`), which settles it
        let confirmed = self.succession.confirm(info.id);
        if let Some(o) = self.objects.get_mut(info.id) {
            if o.info.class == info.class && o.info.particles == info.particles {
                if confirmed && info.epoch < o.info.epoch {
                    o.info.epoch = info.epoch;
                }
                self.set_owner(info.id, info.owner, info.epoch, info.held);
                return;
            }
            self.objects.remove(info.id);
        }
        // a spawn we asked for: the host names our request
        let mut request = None;
        let mut published = None;
        if info.owner == self.local {
            if let Some(r) = info.request {
                if let Some(st) = self.spawns.answered(r) {
                    request = Some(r);
                    published = Some(st);
                }
            }
        }
        let id = info.id;
        self.insert_object(now, info, request);
        if let Some(st) = published {
            let _ = self.publish_state(now, id, &st);
        } else if self.owner(id) == Some(self.local) {
            self.adopt_replica(id);
        }
    }

    /// Our host's snapshot is whole: after a takeover, the replicas it did not name that we
    /// did not claim go (the heir never had them, or had the old host's `Despawn` of them).
    pub(super) fn on_snapshot_end(&mut self) {
        for id in self.succession.unconfirmed() {
            self.on_despawn_from_host(id);
        }
    }

    /// Our host removed an object.
    pub(super) fn on_despawn_from_host(&mut self, id: NetId) {
        if self.objects.remove(id) {
            self.forget_object_messages(id);
            self.events.push_back(Event::Despawned(id));
            // its delta state on every link goes with it (the fuzzer found it kept)
            for l in self.links.values_mut() {
                l.spawn_pending.remove(&id);
                l.pending.retain(|e| e.id != id);
                l.send.forget_object(id);
                l.recv.forget_object(id);
                l.keyframes.forget(id);
            }
        }
    }

    /// Host: remove an object everywhere.
    pub(super) fn host_despawn(&mut self, now: Instant, id: NetId) {
        if self.objects.remove(id) {
            self.forget_object_messages(id);
            self.events.push_back(Event::Despawned(id));
            for l in self.links.values_mut() {
                l.spawn_pending.remove(&id);
                l.pending.retain(|e| e.id != id);
                l.send.forget_object(id);
                l.recv.forget_object(id);
                l.keyframes.forget(id);
            }
            self.asks.clear(id);
            self.broadcast(now, &Control::Despawn { id }, None);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use glam::{Quat, Vec3};

    #[test]
    fn requests_are_numbered_kept_until_answered_and_taken_in_order() {
        let mut p = PendingSpawns::default();
        let st = ObjectState::rigid(Vec3::X, Quat::IDENTITY);
        let (a, b, c) = (p.next(), p.next(), p.next());
        assert_eq!((a, b, c), (0, 1, 2));
        p.insert(b, ClassId(1), st.clone());
        p.insert(a, ClassId(0), st.clone());
        p.insert(c, ClassId(2), st.clone());
        assert_eq!(p.answered(b), Some(st.clone()));
        assert_eq!(p.answered(b), None, "answered once");
        let left: Vec<u32> = p.iter().map(|(r, _, _)| r).collect();
        assert_eq!(left, vec![0, 2]);
        assert_eq!(p.take_all().len(), 2);
        assert_eq!(p.iter().count(), 0);
        p.next_request = u32::MAX;
        assert_eq!((p.next(), p.next()), (u32::MAX, 0), "numbers wrap");
    }
}
