//! Topology events: tears and cuts of an object's mesh, authoritative and replicated.
//!
//! Only an object's owner may change its topology; it asks the host
//! ([`Session::request_topology`]), which checks the sender owns the object at the epoch it
//! names, the event is within bounds, the object's log has room and its rate is sane, then
//! appends the event to the object's **topology log** and sends it to everyone (the requester
//! included) as [`Control::Topology`]. Every peer applies the log in order to the class's
//! mesh, so all end with the identical mesh; nobody applies an event the host has not put in
//! the log. A refused request changes nothing and is counted ([`TopologyRefusals`]).
//!
//! A cut replaces the object: the host gives every piece a new id (owned by the cutter) whose
//! log is the parent's plus `Cut { keep: k }`, then despawns the parent. Late joiners and the
//! members after a migration get every log in the snapshot, entry by entry after the
//! `Spawn` (whose `topology` field says how many follow). After a migration the new host's
//! logs are the truth: a member whose log disagrees from some entry on is told from there
//! (an `Event::Topology` whose `seq` is not the next one means "rebuild from the log").

use std::time::Duration;

use super::{Event, Session};
use crate::error::NetError;
use crate::ids::{AuthorityEpoch, NetId, PeerId};
use crate::time::Instant;
use crate::wire::{Control, SpawnInfo, TopologyEvent, MAX_CUT_PIECES};

/// Most entries one object's topology log may hold (a long surgical tear is a few hundred).
pub const MAX_TOPOLOGY_LOG: usize = 4096;

/// Most topology events the host accepts per object per second (a scalpel sampled at 90 Hz
/// makes 90).
pub const MAX_TOPOLOGY_RATE: u32 = 240;

/// Topology requests the host refused, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TopologyRefusals {
    /// No such object.
    pub unknown_object: u64,
    /// The sender does not own the object.
    pub not_owner: u64,
    /// The sender named an epoch that is not the object's current one.
    pub stale_epoch: u64,
    /// The event is malformed (a cut without pieces, pieces given for a tear, too many).
    pub malformed: u64,
    /// The object's log is full, or the pieces' would be.
    pub log_full: u64,
    /// Over [`MAX_TOPOLOGY_RATE`] for the object.
    pub rate: u64,
    /// The pieces cannot be created (the cutter's object or particle budget, ids used up).
    pub no_room: u64,
}

impl TopologyRefusals {
    /// All refusals.
    pub fn total(&self) -> u64 {
        self.unknown_object
            + self.not_owner
            + self.stale_epoch
            + self.malformed
            + self.log_full
            + self.rate
            + self.no_room
    }
}

/// Per object: its topology log and the host's rate window.
#[derive(Clone, Debug, Default)]
pub(crate) struct TopologyLog {
    /// The log, in order.
    pub entries: Vec<TopologyEvent>,
    /// Start of the current one-second rate window, and events accepted in it.
    window: Option<(Instant, u32)>,
    /// Resolution changes in `entries`: the object's particle layout generation.
    resolutions: u32,
}

impl TopologyLog {
    /// Counts one event against the rate; false if over it.
    fn admit(&mut self, now: Instant) -> bool {
        match &mut self.window {
            Some((start, n)) if now < *start + Duration::from_secs(1) => {
                if *n >= MAX_TOPOLOGY_RATE {
                    return false;
                }
                *n += 1;
            }
            w => *w = Some((now, 1)),
        }
        true
    }

    /// The particle layout generation: resolution changes in the log (the same on every
    /// peer that has the same log, late joiners and pieces of a cut included).
    pub(crate) fn generation(&self) -> u8 {
        self.resolutions as u8
    }

    pub(super) fn push(&mut self, event: TopologyEvent) {
        self.resolutions += u32::from(matches!(event, TopologyEvent::Resolution { .. }));
        self.entries.push(event);
    }

    /// Replaces the log (a cut's piece starts with its parent's).
    pub(crate) fn set_entries(&mut self, entries: Vec<TopologyEvent>) {
        self.resolutions = entries
            .iter()
            .filter(|e| matches!(e, TopologyEvent::Resolution { .. }))
            .count() as u32;
        self.entries = entries;
    }

    /// A log entry `seq` from our host.
    fn receive(&mut self, seq: u32, event: TopologyEvent) -> Received {
        let seq = seq as usize;
        if seq > self.entries.len() || seq >= MAX_TOPOLOGY_LOG {
            return Received::Gap;
        }
        if self.entries.get(seq) == Some(&event) {
            return Received::Duplicate;
        }
        let rewrote = seq < self.entries.len();
        if rewrote {
            let mut kept = std::mem::take(&mut self.entries);
            kept.truncate(seq);
            self.set_entries(kept);
        }
        self.push(event);
        if rewrote {
            Received::Rewrote
        } else {
            Received::Appended
        }
    }
}

/// What a log entry from the host did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Received {
    /// The next entry.
    Appended,
    /// It differed from ours at its position: ours from there on are replaced (after a
    /// migration, the new host's log is the truth).
    Rewrote,
    /// We had it (the snapshot after a migration repeats the log).
    Duplicate,
    /// Beyond the end of our log: reliable order makes this a forgery or a bug.
    Gap,
}

impl Session {
    /// Asks the host to apply `event` to our object `id` (a tear segment, a lift, or a cut
    /// into `pieces.len()` pieces of the given particle counts). Nothing changes here until
    /// the host confirms with an [`Event::Topology`]; a refusal is silent for us and counted
    /// at the host.
    pub fn request_topology(
        &mut self,
        now: Instant,
        id: NetId,
        event: TopologyEvent,
        pieces: Vec<u32>,
    ) -> Result<(), NetError> {
        let o = self.objects.get(id).ok_or(NetError::UnknownObject(id))?;
        if o.info.owner != self.local {
            return Err(NetError::NotOwner(id, o.info.owner));
        }
        let epoch = o.info.epoch;
        self.ask_host(
            now,
            Control::TopologyRequest {
                id,
                epoch,
                event,
                pieces,
            },
        )
    }

    /// The topology log of object `id` as this peer has it (empty for an untouched object).
    pub fn topology_log(&self, id: NetId) -> Option<&[TopologyEvent]> {
        self.objects.get(id).map(|o| o.topology.entries.as_slice())
    }

    /// Topology requests this host refused, by reason.
    pub fn topology_refusals(&self) -> TopologyRefusals {
        self.topology_refused
    }

    /// Host: `from` asks to apply `event` to `id`.
    pub(super) fn host_topology_request(
        &mut self,
        now: Instant,
        from: PeerId,
        id: NetId,
        epoch: AuthorityEpoch,
        event: TopologyEvent,
        pieces: Vec<u32>,
    ) {
        let refused = &mut self.topology_refused;
        let Some(o) = self.objects.get_mut(id) else {
            refused.unknown_object += 1;
            return;
        };
        if o.info.owner != from {
            refused.not_owner += 1;
            return;
        }
        if o.info.epoch != epoch {
            refused.stale_epoch += 1;
            return;
        }
        let is_cut = matches!(event, TopologyEvent::Cut { .. });
        let well_formed = match event {
            TopologyEvent::Cut { keep, .. } => {
                keep == 0 && !pieces.is_empty() && pieces.len() <= MAX_CUT_PIECES
            }
            _ => pieces.is_empty(),
        } && event.valid();
        let old_particles = o.info.particles;
        if !well_formed {
            refused.malformed += 1;
            return;
        }
        if o.topology.entries.len() + 1 > MAX_TOPOLOGY_LOG {
            refused.log_full += 1;
            return;
        }
        if !o.topology.admit(now) {
            refused.rate += 1;
            return;
        }
        if is_cut {
            self.host_cut(now, from, id, event, &pieces);
            return;
        }
        if let TopologyEvent::Resolution { particles, .. } = event {
            // the new layout replaces the old one in the owner's particle budget
            let owned: u64 = self
                .objects
                .iter()
                .filter(|o| o.info.owner == from)
                .map(|o| u64::from(o.info.particles))
                .sum();
            let after = owned - u64::from(old_particles) + u64::from(particles);
            if after > self.cfg.max_particles_per_peer as u64 {
                self.topology_refused.no_room += 1;
                return;
            }
        }
        let Some(o) = self.objects.get_mut(id) else {
            return;
        };
        let seq = o.topology.entries.len() as u32;
        o.topology.push(event);
        self.broadcast(now, &Control::Topology { id, seq, event }, None);
        if let TopologyEvent::Resolution { particles, .. } = event {
            self.relayout(id, particles);
        }
        self.events.push_back(Event::Topology { id, seq, event });
    }

    /// Object `id`'s particle layout changed to `particles` (a live resolution change): its
    /// grid state, snapshots, what we published, the entries waiting to go and the delta
    /// chains on every link are of the old layout and go; the owner publishes anew.
    pub(super) fn relayout(&mut self, id: NetId, particles: u32) {
        let Some(class) = self
            .objects
            .get(id)
            .and_then(|o| self.cfg.class(o.info.class))
        else {
            return;
        };
        let zero = class.particle_quantizer().quantize(glam::Vec3::ZERO);
        if let Some(o) = self.objects.get_mut(id) {
            o.info.particles = particles;
            o.particles = vec![zero; particles as usize];
            o.published = None;
            o.buffer = Default::default();
            o.rest = false;
        }
        for l in self.links.values_mut() {
            l.pending.retain(|e| e.id != id);
            l.send.forget_object(id);
            l.recv.forget_object(id);
        }
    }

    /// Host: a cut of `id` by `from` into pieces of `pieces` particles each.
    fn host_cut(
        &mut self,
        now: Instant,
        from: PeerId,
        id: NetId,
        event: TopologyEvent,
        pieces: &[u32],
    ) {
        let Some(parent) = self.objects.get(id) else {
            return;
        };
        let parent_info = parent.info.clone();
        let parent_log = parent.topology.entries.clone();
        let pose = self
            .class(parent_info.class)
            .map(|c| parent.compose(c))
            .map(|st| (st.pos.to_array(), st.rot.to_array()))
            .unwrap_or((parent_info.pos, parent_info.rot));
        // The pieces replace the parent in the cutter's budget.
        let budget_ok = {
            let total: u64 = pieces.iter().map(|&p| u64::from(p)).sum();
            let max = self.cfg.max_particles_per_peer as u64;
            let parent_id = id;
            let owned: u64 = self
                .objects
                .iter()
                .filter(|o| o.info.owner == from && o.info.id != parent_id)
                .map(|o| u64::from(o.info.particles))
                .sum();
            let count = self.objects.owned_by(from).len().saturating_sub(1) + pieces.len();
            owned + total <= max && count <= self.cfg.max_objects_per_peer
        };
        if !budget_ok {
            self.topology_refused.no_room += 1;
            return;
        }
        let mut ids = Vec::with_capacity(pieces.len());
        for _ in pieces {
            match self.objects.alloc_id() {
                Some(n) => ids.push(n),
                None => {
                    self.topology_refused.no_room += 1;
                    return;
                }
            }
        }
        // The parent goes first: no peer ever has the parent and a piece in its world at once.
        self.host_despawn(now, id);
        for (k, (&piece_id, &particles)) in ids.iter().zip(pieces).enumerate() {
            let TopologyEvent::Cut { point, normal, .. } = event else {
                return;
            };
            let mut log = parent_log.clone();
            log.push(TopologyEvent::Cut {
                point,
                normal,
                keep: k as u8,
            });
            let info = SpawnInfo {
                id: piece_id,
                class: parent_info.class,
                owner: from,
                epoch: AuthorityEpoch {
                    term: self.term.0,
                    grant: 0,
                },
                held: parent_info.held,
                policy: parent_info.policy,
                particles,
                pos: pose.0,
                rot: pose.1,
                request: None,
                topology: log.len() as u32,
            };
            self.insert_object(now, info.clone(), None);
            if let Some(o) = self.objects.get_mut(piece_id) {
                o.topology.set_entries(log.clone());
                if from != self.local {
                    o.source = Some(from);
                }
            }
            self.broadcast(now, &Control::Spawn(info), None);
            for (seq, e) in log.iter().enumerate() {
                let msg = Control::Topology {
                    id: piece_id,
                    seq: seq as u32,
                    event: *e,
                };
                self.broadcast(now, &msg, None);
                self.events.push_back(Event::Topology {
                    id: piece_id,
                    seq: seq as u32,
                    event: *e,
                });
            }
        }
    }

    /// Host: object `id`'s log entries, after its `Spawn`, to `to`.
    pub(super) fn send_topology_log(&mut self, now: Instant, to: PeerId, id: NetId) {
        let Some(entries) = self.objects.get(id).map(|o| o.topology.entries.clone()) else {
            return;
        };
        for (seq, event) in entries.into_iter().enumerate() {
            self.send_control(
                now,
                to,
                &Control::Topology {
                    id,
                    seq: seq as u32,
                    event,
                },
            );
        }
    }

    /// A log entry from our host.
    pub(super) fn on_topology_from_host(&mut self, id: NetId, seq: u32, event: TopologyEvent) {
        let Some(o) = self.objects.get_mut(id) else {
            self.stats.refused_controls += 1;
            return;
        };
        // entries the object's spawn announced are its history (a late join, a cut's piece):
        // its spawn already has their particle count; later ones are live
        let live = seq >= o.info.topology;
        match o.topology.receive(seq, event) {
            Received::Appended | Received::Rewrote => {
                if let (true, TopologyEvent::Resolution { particles, .. }) = (live, event) {
                    self.relayout(id, particles);
                }
                self.events.push_back(Event::Topology { id, seq, event });
            }
            Received::Duplicate => {}
            Received::Gap => self.stats.refused_controls += 1,
        }
    }
}

#[cfg(test)]
mod tests;
