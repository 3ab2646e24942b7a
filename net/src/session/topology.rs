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

    fn push(&mut self, event: TopologyEvent) {
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
            .and_then(|o| self.cfg.classes.get(usize::from(o.info.class.0)))
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
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::ids::ClassId;
    use crate::session::registry::ObjectState;
    use crate::session::testkit::{config, Wire};
    use glam::{Quat, Vec3};

    fn tear(x: i32) -> TopologyEvent {
        TopologyEvent::Tear {
            from: [x, 0, 0],
            to: [x + 100, 0, 0],
            blade: [0, 1000, 0],
        }
    }

    /// Host 1 with members 2 and 3; peer 2 owns a soft object (returned).
    fn room() -> (Wire, NetId) {
        room_with(config())
    }

    fn room_with(cfg: crate::policy::SessionConfig) -> (Wire, NetId) {
        let mut w = Wire::new();
        w.add(Session::host(PeerId(1), cfg.clone(), w.now));
        w.add(Session::join(PeerId(2), PeerId(1), cfg.clone(), w.now));
        w.settle();
        w.add(Session::join(PeerId(3), PeerId(1), cfg, w.now));
        w.settle();
        let st = ObjectState {
            pos: Vec3::new(0.0, 1.0, 0.0),
            rot: Quat::IDENTITY,
            particles: vec![Vec3::ZERO; 4],
        };
        let now = w.now;
        w.get(2).spawn(now, ClassId(1), st).unwrap();
        w.settle();
        let id = w.get(1).object_ids()[0];
        for p in 1..=3 {
            w.events(p);
        }
        (w, id)
    }

    fn topo_events(w: &mut Wire, p: u64) -> Vec<(NetId, u32, TopologyEvent)> {
        w.events(p)
            .into_iter()
            .filter_map(|e| match e {
                Event::Topology { id, seq, event } => Some((id, seq, event)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn the_owners_tears_reach_everyone_in_order_and_late_joiners_get_the_log() {
        let (mut w, id) = room();
        let now = w.now;
        for k in 0..3 {
            w.get(2)
                .request_topology(now, id, tear(k * 100), vec![])
                .unwrap();
        }
        w.settle();
        for p in 1..=3 {
            let got = topo_events(&mut w, p);
            assert_eq!(got.len(), 3, "peer {p}");
            assert!(got.iter().enumerate().all(|(i, g)| g.1 == i as u32));
            assert_eq!(w.get(p).topology_log(id).unwrap().len(), 3);
        }
        // A late joiner gets the same log after the spawn.
        w.add(Session::join(PeerId(4), PeerId(1), config(), w.now));
        w.settle();
        let host_log = w.get(1).topology_log(id).unwrap().to_vec();
        assert_eq!(w.get(4).topology_log(id).unwrap(), host_log.as_slice());
        assert_eq!(topo_events(&mut w, 4).len(), 3);
    }

    #[test]
    fn foreign_stale_and_malformed_events_are_refused_and_counted_changing_nothing() {
        let (mut w, id) = room();
        let now = w.now;
        // Peer 3 does not own it: refused locally ...
        assert!(matches!(
            w.get(3).request_topology(now, id, tear(0), vec![]),
            Err(NetError::NotOwner(..))
        ));
        // ... and at the host when forged.
        let epoch = w.get(3).epoch(id).unwrap();
        let forged = Control::TopologyRequest {
            id,
            epoch,
            event: tear(0),
            pieces: vec![],
        };
        w.get(3).send_control(now, PeerId(1), &forged);
        // The owner with a stale epoch.
        let stale = Control::TopologyRequest {
            id,
            epoch: AuthorityEpoch {
                term: epoch.term,
                grant: epoch.grant + 7,
            },
            event: tear(0),
            pieces: vec![],
        };
        w.get(2).send_control(now, PeerId(1), &stale);
        // A tear with pieces, a cut without, an unknown object.
        for (event, pieces, obj) in [
            (tear(0), vec![3], id),
            (
                TopologyEvent::Cut {
                    point: [0; 3],
                    normal: [0, 32767, 0],
                    keep: 0,
                },
                vec![],
                id,
            ),
            (tear(0), vec![], NetId(999)),
        ] {
            let msg = Control::TopologyRequest {
                id: obj,
                epoch,
                event,
                pieces,
            };
            w.get(2).send_control(now, PeerId(1), &msg);
        }
        w.settle();
        let r = w.get(1).topology_refusals();
        assert_eq!(r.not_owner, 1, "{r:?}");
        assert_eq!(r.stale_epoch, 1, "{r:?}");
        assert_eq!(r.malformed, 2, "{r:?}");
        assert_eq!(r.unknown_object, 1, "{r:?}");
        for p in 1..=3 {
            assert!(w.get(p).topology_log(id).unwrap().is_empty());
            assert!(topo_events(&mut w, p).is_empty());
        }
    }

    #[test]
    fn a_burst_over_the_rate_is_cut_off_and_counted() {
        let (mut w, id) = room();
        let now = w.now;
        for k in 0..(MAX_TOPOLOGY_RATE + 60) {
            w.get(2)
                .request_topology(now, id, tear(k as i32), vec![])
                .unwrap();
            if k % 50 == 0 {
                w.settle();
            }
        }
        w.settle();
        assert_eq!(w.get(1).topology_refusals().rate, 60);
        assert_eq!(
            w.get(3).topology_log(id).unwrap().len(),
            MAX_TOPOLOGY_RATE as usize
        );
    }

    #[test]
    fn a_cut_replaces_the_object_by_pieces_owned_by_the_cutter() {
        let (mut w, id) = room();
        let now = w.now;
        w.get(2).request_topology(now, id, tear(0), vec![]).unwrap();
        w.settle();
        let cut = TopologyEvent::Cut {
            point: [0, 100, 0],
            normal: [0, 32767, 0],
            keep: 0,
        };
        w.get(2).request_topology(now, id, cut, vec![3, 2]).unwrap();
        w.settle();
        for p in 1..=3 {
            let ids = w.get(p).object_ids();
            assert_eq!(ids.len(), 2, "peer {p}: {ids:?}");
            assert!(!ids.contains(&id));
            for (k, piece) in ids.iter().enumerate() {
                assert_eq!(w.get(p).owner(*piece), Some(PeerId(2)));
                let log = w.get(p).topology_log(*piece).unwrap().to_vec();
                assert_eq!(log.len(), 2);
                assert_eq!(log[0], tear(0));
                assert!(matches!(log[1], TopologyEvent::Cut { keep, .. } if keep as usize == k));
            }
        }
    }

    fn state(n: usize, spread: f32) -> ObjectState {
        ObjectState {
            pos: Vec3::new(0.0, 1.0, 0.0),
            rot: Quat::IDENTITY,
            particles: (0..n)
                .map(|i| Vec3::new(0.0, 1.0, 0.0) + Vec3::X * spread * i as f32)
                .collect(),
        }
    }

    #[test]
    fn a_resolution_change_relays_the_object_out_everywhere_and_late_joiners_get_it() {
        let (mut w, id) = room();
        let now = w.now;
        w.get(2).publish_state(now, id, &state(4, 0.01)).unwrap();
        w.settle();
        assert_eq!(w.get(3).latest_state(id).unwrap().particles.len(), 4);
        let change = TopologyEvent::Resolution {
            level: 2,
            particles: 9,
        };
        w.get(2).request_topology(now, id, change, vec![]).unwrap();
        // until the host confirms, the owner's layout is the old one
        assert!(w.get(2).publish_state(now, id, &state(9, 0.01)).is_err());
        w.get(2).publish_state(now, id, &state(4, 0.02)).unwrap();
        w.settle();
        for p in 1..=3 {
            assert_eq!(topo_events(&mut w, p), vec![(id, 0, change)], "peer {p}");
        }
        let now = w.now;
        assert!(matches!(
            w.get(2).publish_state(now, id, &state(4, 0.01)),
            Err(NetError::InvalidState(_))
        ));
        for _ in 0..5 {
            w.now += Duration::from_millis(100);
            let now = w.now;
            w.get(2).publish_state(now, id, &state(9, 0.015)).unwrap();
            w.settle();
        }
        for p in [1, 3] {
            let got = w.get(p).latest_state(id).unwrap();
            assert_eq!(got.particles.len(), 9, "peer {p}");
            assert!(
                got.particles[8].distance(state(9, 0.015).particles[8]) < 1e-3,
                "peer {p}: {got:?}"
            );
            assert_eq!(w.get(p).stats().decode_errors, 0);
        }
        // a late joiner: the spawn has 9 particles, the log's change is history
        w.add(Session::join(PeerId(4), PeerId(1), config(), w.now));
        w.settle();
        for _ in 0..3 {
            w.now += Duration::from_millis(100);
            let now = w.now;
            w.get(2).publish_state(now, id, &state(9, 0.012)).unwrap();
            w.settle();
        }
        assert_eq!(w.get(4).topology_log(id).unwrap(), &[change]);
        let got = w.get(4).latest_state(id).unwrap();
        assert_eq!(got.particles.len(), 9);
        assert!(got.particles[8].distance(state(9, 0.012).particles[8]) < 1e-3);
    }

    #[test]
    fn a_resolution_over_the_owners_particle_budget_or_out_of_range_is_refused() {
        let cfg = crate::policy::SessionConfig {
            max_particles_per_peer: 100,
            ..config()
        };
        let (mut w, id) = room_with(cfg);
        let now = w.now;
        // the new layout replaces the old one in the budget: 100 fits, 101 does not
        let fits = TopologyEvent::Resolution {
            level: 1,
            particles: 100,
        };
        let too_many = TopologyEvent::Resolution {
            level: 2,
            particles: 101,
        };
        w.get(2)
            .request_topology(now, id, too_many, vec![])
            .unwrap();
        w.settle();
        assert_eq!(w.get(1).topology_refusals().no_room, 1);
        assert!(w.get(3).topology_log(id).unwrap().is_empty());
        w.get(2).request_topology(now, id, fits, vec![]).unwrap();
        w.settle();
        assert_eq!(w.get(3).topology_log(id).unwrap(), &[fits]);
        for bad in [
            TopologyEvent::Resolution {
                level: crate::wire::MAX_RESOLUTION_LEVELS,
                particles: 5,
            },
            TopologyEvent::Resolution {
                level: 0,
                particles: 0,
            },
        ] {
            let msg = Control::Topology {
                id,
                seq: 0,
                event: bad,
            };
            assert!(Control::decode(&msg.encode()).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn a_particle_chunk_of_another_layout_ends_its_block_without_an_error() {
        use crate::policy::{ClassConfig, SendPolicy, SoftBodyMode};
        use crate::wire::{
            decode_state_block, ChunkEnc, EntryLayout, PartBody, StateBlockWriter, StateEntry,
        };
        let class = ClassConfig::soft_body("s", SendPolicy::default(), SoftBodyMode::Particles);
        let layout = |generation| EntryLayout {
            class: &class,
            particles: 8,
            generation,
        };
        let chunk = |id| StateEntry {
            id: NetId(id),
            epoch_tag: 0,
            seq: 1,
            key: true,
            base: 0,
            rest: false,
            body: PartBody::Chunk {
                chunk: 0,
                values: ChunkEnc::Abs(vec![[1, 2, 3]; 8]),
            },
        };
        let mut wr = StateBlockWriter::new(10_000);
        wr.push(&chunk(1), &layout(0));
        wr.push(&chunk(2), &layout(1));
        wr.push(&chunk(3), &layout(0));
        let (count, bytes) = wr.finish();
        // the receiver is at generation 0 for objects 1 and 3, 2 for object 2 (it saw two
        // changes; the sender one): object 2's chunk ends the block, 1's is kept
        let (got, complete) = decode_state_block(count as u32, &bytes, |id| {
            Some(if id == NetId(2) { layout(2) } else { layout(0) })
        })
        .unwrap();
        assert_eq!(got.len(), 1);
        assert!(!complete);
        // and a transform part needs no layout: it never carries the generation
        let (all, complete) = decode_state_block(count as u32, &bytes, |id| {
            Some(if id == NetId(2) { layout(1) } else { layout(0) })
        })
        .unwrap();
        assert_eq!(all.len(), 3);
        assert!(complete);
    }

    #[test]
    fn out_of_range_events_do_not_decode() {
        let far = TopologyEvent::Tear {
            from: [crate::wire::MAX_TOPOLOGY_COORD + 1, 0, 0],
            to: [0; 3],
            blade: [0, 10, 0],
        };
        let zero_normal = TopologyEvent::Cut {
            point: [0; 3],
            normal: [0; 3],
            keep: 0,
        };
        let many_pieces = Control::TopologyRequest {
            id: NetId(1),
            epoch: AuthorityEpoch::default(),
            event: TopologyEvent::Cut {
                point: [0; 3],
                normal: [0, 1, 0],
                keep: 0,
            },
            pieces: vec![1; MAX_CUT_PIECES + 1],
        };
        for bad in [
            Control::Topology {
                id: NetId(1),
                seq: 0,
                event: far,
            },
            Control::Topology {
                id: NetId(1),
                seq: 0,
                event: zero_normal,
            },
            many_pieces,
        ] {
            assert!(Control::decode(&bad.encode()).is_err(), "{bad:?}");
        }
        assert_eq!(TopologyEvent::quantise([f32::NAN, 0.0, 0.0]), None);
        assert_eq!(TopologyEvent::quantise([20.0, 0.0, 0.0]), None);
        assert_eq!(
            TopologyEvent::quantise([0.1, -0.2, 0.000_004]),
            Some([10_000, -20_000, 0])
        );
        assert_eq!(TopologyEvent::quantise_normal([0.0; 3]), None);
        assert_eq!(
            TopologyEvent::quantise_normal([0.0, 2.0, 0.0]),
            Some([0, 32767, 0])
        );
    }

    #[test]
    fn a_log_entry_that_differs_rewrites_from_there_and_a_gap_is_refused() {
        let mut log = TopologyLog::default();
        assert_eq!(log.receive(0, tear(0)), Received::Appended);
        assert_eq!(log.receive(1, tear(1)), Received::Appended);
        assert_eq!(log.receive(1, tear(1)), Received::Duplicate);
        assert_eq!(log.receive(1, tear(5)), Received::Rewrote); // the new host's truth
        assert_eq!(log.entries, vec![tear(0), tear(5)]);
        assert_eq!(log.receive(5, tear(9)), Received::Gap);
        assert_eq!(log.entries.len(), 2);
    }
}
