//! A room reopened from what was kept of it (a store, `softsync-store`): the host, before
//! anyone joins, puts back each object under its old id with its class, state and topology
//! log, the room's retained messages, and carries the room clock on from where it stood.
//!
//! The session only keeps the record: the caller builds each body (its class replayed through
//! the log) before it restores the object. Joiners then get everything through the usual
//! snapshot (a `Spawn` per object, its log, the retained messages), as from any host.

use std::time::Duration;

use super::{Role, Session};
use crate::error::NetError;
use crate::ids::{ClassId, NetId};
use crate::policy::AuthorityPolicy;

use crate::session::topology::MAX_TOPOLOGY_LOG;
use crate::session::ObjectState;
use crate::time::Instant;
use crate::wire::{self, AppMessage, Control, SpawnInfo, TopologyEvent};

/// One object as a room keeps it between sessions: nothing about who owned it.
#[derive(Clone, Debug, PartialEq)]
pub struct KeptObject {
    /// Its id, the same in every session of the room.
    pub id: NetId,
    /// Its class.
    pub class: ClassId,
    /// Its state (world-space particles for a soft body).
    pub state: ObjectState,
    /// Its topology log, in order (a cut's piece starts with its parent's).
    pub topology: Vec<TopologyEvent>,
}

/// A room as it is kept between sessions: its objects, its retained messages and the room
/// time it was kept at.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RoomImage {
    /// The room clock's reading when the image was taken.
    pub room_time: Duration,
    /// The objects, by id.
    pub objects: Vec<KeptObject>,
    /// The retained messages (the room's state that is not objects).
    pub retained: Vec<AppMessage>,
}

impl Session {
    /// Host, before anyone joined: object `o` exists again, owned by us, under its old id
    /// (ids later spawns get start past it). `Event::Spawned` follows, as for a spawn. Build
    /// its body first: the session keeps only the record.
    ///
    /// Errors: not hosting, members already in, an unknown class, an id in use or 0, a state
    /// that is not finite or has more particles than the wire carries, a log over
    /// [`MAX_TOPOLOGY_LOG`].
    pub fn restore_object(&mut self, now: Instant, o: KeptObject) -> Result<(), NetError> {
        self.restoring()?;
        let policy = self
            .class(o.class)
            .ok_or(NetError::UnknownClass(o.class.0))?
            .authority;
        if o.id.0 == 0 || self.objects.contains(o.id) {
            return Err(NetError::Restore("object id 0 or in use"));
        }
        let (info, rot) = self.kept_info(&o, o.id, policy)?;
        self.objects.skip_ids_through(o.id);
        self.insert_object(now, info, None);
        if let Some(obj) = self.objects.get_mut(o.id) {
            obj.topology.set_entries(o.topology);
        }
        self.publish_state(now, o.id, &ObjectState { rot, ..o.state })
    }

    /// Host, before anyone joined: a retained message the room kept is the room's state again
    /// (an `Event::Message` tells us, as a joiner is told). Messages of kinds the room's
    /// table does not have, or not retained, are refused.
    pub fn restore_retained(&mut self, msg: AppMessage) -> Result<(), NetError> {
        self.restoring()?;
        if !msg.valid()
            || msg.retain_key().is_none()
            || usize::from(msg.kind.0) >= self.cfg.messages.kinds.len()
        {
            return Err(NetError::Restore("not a retained message of the room"));
        }
        self.deliver_replay(msg);
        Ok(())
    }

    /// Host, before anyone joined: the room's clock carries on from `room_time` (the time it
    /// read when the room was last kept), so times stamped in the reopened room come after
    /// every time stamped before.
    pub fn resume_room_time(&mut self, now: Instant, room_time: Duration) -> Result<(), NetError> {
        self.restoring()?;
        self.clock.resume(now, room_time);
        Ok(())
    }

    /// Host, at any time (a recorded session played back as a room, `softsync replay
    /// --serve`): object `o` appears under a fresh id (ids of the recording are the
    /// caller's to map: spectators' avatars take ids meanwhile), owned by us, locked
    /// ([`AuthorityPolicy::Locked`]: nobody else may take it), with its class, state and log;
    /// every member is told (its `Spawn`, then each entry of its log), as for a cut's pieces.
    /// Build its body first.
    ///
    /// Errors: not hosting, an unknown class, a state that is not finite or has more
    /// particles than the wire carries, a log over [`MAX_TOPOLOGY_LOG`], ids used up.
    pub fn replay_object(&mut self, now: Instant, o: KeptObject) -> Result<NetId, NetError> {
        if self.role != Role::Host {
            return Err(NetError::NotConnected);
        }
        self.class(o.class)
            .ok_or(NetError::UnknownClass(o.class.0))?;
        // checked before an id is spent
        let (mut info, rot) = self.kept_info(&o, NetId(0), AuthorityPolicy::Locked)?;
        let id = self.objects.alloc_id().ok_or(NetError::IdsExhausted)?;
        info.id = id;
        self.insert_object(now, info.clone(), None);
        if let Some(obj) = self.objects.get_mut(id) {
            obj.topology.set_entries(o.topology.clone());
        }
        self.broadcast(now, &Control::Spawn(info), None);
        for (seq, e) in o.topology.iter().enumerate() {
            let msg = Control::Topology {
                id,
                seq: seq as u32,
                event: *e,
            };
            self.broadcast(now, &msg, None);
        }
        self.publish_state(now, id, &ObjectState { rot, ..o.state })?;
        Ok(id)
    }

    /// Host, at any time: entry `event` is appended to the log of our object `id` (a tear, a
    /// lift or a resolution change of a recorded session played back) and every member is
    /// told; `Event::Topology` follows. A cut is not an entry here: its pieces are objects of
    /// their own ([`Session::replay_object`]).
    pub fn replay_entry(
        &mut self,
        now: Instant,
        id: NetId,
        event: TopologyEvent,
    ) -> Result<(), NetError> {
        if self.role != Role::Host {
            return Err(NetError::NotConnected);
        }
        if matches!(event, TopologyEvent::Cut { .. }) || !event.valid() {
            return Err(NetError::Restore("not an entry a replay appends"));
        }
        let local = self.local;
        let o = self
            .objects
            .get_mut(id)
            .ok_or(NetError::UnknownObject(id))?;
        if o.info.owner != local {
            return Err(NetError::NotOwner(id, o.info.owner));
        }
        if o.topology.entries.len() + 1 > MAX_TOPOLOGY_LOG {
            return Err(NetError::Restore("topology log too long"));
        }
        let seq = o.topology.entries.len() as u32;
        o.topology.push(event);
        self.broadcast(now, &Control::Topology { id, seq, event }, None);
        if let TopologyEvent::Resolution { particles, .. } = event {
            self.relayout(id, particles);
        }
        self.events
            .push_back(super::Event::Topology { id, seq, event });
        Ok(())
    }

    /// The `Spawn` of kept object `o` under `id`, ours, with `policy`, and its rotation made
    /// a unit; refused for a state that is not finite or has more particles than the wire
    /// carries, or a log over [`MAX_TOPOLOGY_LOG`].
    fn kept_info(
        &self,
        o: &KeptObject,
        id: NetId,
        policy: AuthorityPolicy,
    ) -> Result<(SpawnInfo, glam::Quat), NetError> {
        let rot = o.state.checked_rotation()?;
        if o.state.particles.len() > wire::MAX_PARTICLES as usize {
            return Err(NetError::InvalidState("too many particles"));
        }
        if o.topology.len() > MAX_TOPOLOGY_LOG {
            return Err(NetError::Restore("topology log too long"));
        }
        let info = self.own_spawn(
            id,
            o.class,
            policy,
            (o.state.pos, rot),
            o.state.particles.len(),
            o.topology.len(),
        );
        Ok((info, rot))
    }

    fn restoring(&self) -> Result<(), NetError> {
        if self.role != Role::Host {
            return Err(NetError::NotConnected);
        }
        if self.members.len() > 1 {
            return Err(NetError::Restore("members joined already"));
        }
        Ok(())
    }
}
