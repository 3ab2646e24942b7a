//! Replication out (thesis 5.3–5.4): per-class send ticks, the entries that bring a link's
//! view of an object up to date (thresholds against the acknowledged base, deltas, rest sync,
//! staleness bound, piggyback, keyframes), and the assembly of everything due for a peer into
//! one datagram of at most the MTU.

use std::collections::BTreeMap;
use std::time::Duration;

use super::delta::{Emission, EntryRef, PartQ, SendPart, SendParts};
use super::registry::Object;
use super::{ObjectState, Role, Session, Transmit};
use crate::error::NetError;
use crate::ids::{NetId, PeerId};
use crate::policy::{ClassConfig, SoftBodyMode, StateRoute};
use crate::quant::{angle_between, dequantize_quat, VecQuantizer};
use crate::time::Instant;
use crate::wire::{
    ChunkEnc, PacketHeader, PacketWriter, PartBody, PosEnc, Pushed, StateBlockWriter, StateEntry,
};

/// Bytes of a datagram's header and a few acknowledgements, for the budget's estimates.
const HEADER_ESTIMATE: usize = 16;

/// When each class next sends, and the next heartbeat.
#[derive(Debug)]
pub(crate) struct SendSchedule {
    /// Next send tick per class.
    pub next_tick: Vec<Instant>,
    /// Next heartbeat round.
    pub next_heartbeat: Instant,
    /// When liveness was last judged (`check_liveness`): a silence deadline at or before it
    /// was acted on or is waited out on another's (a dead host while its heir takes over).
    pub judged_at: Option<Instant>,
}

impl SendSchedule {
    /// Everything due at `now`, for `classes` classes.
    pub fn new(now: Instant, classes: usize) -> Self {
        SendSchedule {
            next_tick: vec![now; classes],
            next_heartbeat: now,
            judged_at: None,
        }
    }

    /// If class `c` is due at `now`, move its tick on by `interval` (not into the past) and
    /// say so.
    fn take_due(&mut self, c: usize, now: Instant, interval: Duration) -> bool {
        let Some(t) = self.next_tick.get_mut(c) else {
            return false;
        };
        if now < *t {
            return false;
        }
        *t += interval;
        if *t <= now {
            *t = now + interval;
        }
        true
    }
}

/// Why entries for an object are queued for a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Refresh {
    /// Our own object's send tick: the class's thresholds apply while it moves.
    Owner,
    /// Relaying (or repeating) another peer's state: any grid change goes.
    Relay,
    /// Everything, absolute (a joiner learned the object, or asked for a keyframe).
    Keyframe,
}

/// What [`plan_entries`] needs to know about the link.
pub(crate) struct LinkView<'a> {
    /// The link's sending side.
    pub parts: &'a mut SendParts,
    /// How long an unacknowledged entry waits before it is repeated.
    pub ack_wait: Duration,
}

/// Entries that bring a link's view of object `o` up to date.
///
/// Deltas are relative to the newest state the peer acknowledged (so a lost datagram costs
/// nothing but itself); everything differing from that base by more than the threshold goes
/// out until acknowledged. `owner_thresholds`: apply the class's send thresholds (we own it
/// and it moves); otherwise send any grid change (relay, rest sync). `force_key`: keyframes.
pub(crate) fn plan_entries(
    o: &Object,
    class: &ClassConfig,
    link: LinkView<'_>,
    now: Instant,
    owner_thresholds: bool,
    force_key: bool,
) -> Vec<StateEntry> {
    let mut out = Vec::new();
    let id = o.info.id;
    let LinkView { parts, ack_wait } = link;
    let use_thr = owner_thresholds && !o.rest;
    let interval = class.send.interval();
    let max_stale = class
        .send
        .stale_after_intervals
        .map(|k| interval.mul_f32(k.clamp(0.0, 1e4)));
    // half an interval of slack so the tick phase does not alias with the bound
    let half = interval / 2;
    // a change below the threshold is still sent once its last send is this old
    let stale = |at: Instant| use_thr && max_stale.is_some_and(|m| now + half >= at + m);
    let piggy = class.send.piggyback_fraction.clamp(0.0, 1.0);
    let (pos_thr, rot_thr, part_thr) = if use_thr {
        (
            class.send.position_threshold_m / class.position_resolution_m,
            class.send.rotation_threshold_rad,
            class.send.particle_threshold_m / class.particle_resolution_m,
        )
    } else {
        (0.0, 0.0, 0.0)
    };
    let key_interval = class.send.keyframe_interval;
    let rest = o.rest;
    let tag = o.info.epoch.tag();
    let bits = class.rot_bits();
    let entry = |seq: u8, key: bool, base: u8, body: PartBody| StateEntry {
        id,
        epoch_tag: tag,
        seq,
        key,
        base,
        rest,
        body,
    };
    let key_due = |sp: Option<&SendPart>| {
        !rest && key_interval.is_some_and(|k| sp.is_some_and(|sp| now >= sp.last_key_at + k))
    };
    // particle chunks (thesis 5.4.2), skipped in center-only mode (5.4.1)
    if class.soft_body_mode == SoftBodyMode::Particles && !o.particles.is_empty() {
        let per = class.chunk_len();
        for (ci, chunk) in o.particles.chunks(per).enumerate() {
            let part = ci as u32 + 1;
            let sp = parts.get(&(id, part));
            let base = sp.and_then(SendPart::base);
            let key = force_key || base.is_none() || key_due(sp);
            let planned = match (&base, key) {
                (Some((b, PartQ::Chunk(bv))), false) if bv.len() == chunk.len() => {
                    let sent_at = sp.map(|s| s.sent_at.as_slice()).unwrap_or_default();
                    let dist: Vec<f32> = chunk
                        .iter()
                        .zip(bv.iter())
                        .map(|(c, p)| VecQuantizer::step_distance(*c, *p))
                        .collect();
                    let over = |i: usize| {
                        dist.get(i).is_some_and(|d| *d > part_thr)
                            || sent_at.get(i).is_some_and(|t| stale(*t))
                    };
                    let differs = |i: usize| chunk.get(i) != bv.get(i);
                    let triggered = (0..chunk.len()).any(|i| differs(i) && over(i));
                    // when the chunk goes out anyway, particles past a fraction of the
                    // threshold ride along (fewer particles left stale at the threshold)
                    let list: Vec<(u32, [i32; 3])> = (0..chunk.len())
                        .filter(|&i| {
                            differs(i)
                                && (over(i)
                                    || (triggered
                                        && dist.get(i).is_some_and(|d| *d > part_thr * piggy)))
                        })
                        .filter_map(|i| {
                            let (c, p) = (chunk.get(i)?, bv.get(i)?);
                            Some((i as u32, [0, 1, 2].map(|k| c[k] as i32 - p[k] as i32)))
                        })
                        .collect();
                    if list.is_empty() {
                        None
                    } else {
                        let mut after = bv.clone();
                        for (i, _) in &list {
                            if let (Some(d), Some(c)) =
                                (after.get_mut(*i as usize), chunk.get(*i as usize))
                            {
                                *d = *c;
                            }
                        }
                        let fields: Vec<usize> = list.iter().map(|(i, _)| *i as usize).collect();
                        Some((
                            false,
                            *b,
                            PartQ::Chunk(after),
                            ChunkEnc::Delta(list),
                            fields,
                        ))
                    }
                }
                _ => Some((
                    true,
                    0,
                    PartQ::Chunk(chunk.to_vec()),
                    ChunkEnc::Abs(chunk.to_vec()),
                    (0..chunk.len()).collect(),
                )),
            };
            let Some((key, base_seq, after, values, fields)) = planned else {
                continue;
            };
            let emission = Emission {
                after,
                key,
                force: force_key,
                fields: &fields,
                field_count: chunk.len(),
            };
            let Some(seq) = parts.emit((id, part), emission, now, ack_wait) else {
                continue;
            };
            let body = PartBody::Chunk {
                chunk: ci as u32,
                values,
            };
            out.push(entry(seq, key, base_seq, body));
        }
    }
    // transform part (position and rotation sent separately, thesis 5.3); when particles
    // went out, any center change rides along: particle offsets are relative to it
    let chunks_sent = !out.is_empty();
    let (pos_thr, rot_thr) = if chunks_sent {
        (0.0, 0.0)
    } else {
        (pos_thr, rot_thr)
    };
    let sp = parts.get(&(id, 0));
    let base = sp.and_then(SendPart::base);
    let key = force_key || base.is_none() || key_due(sp);
    let planned = match (&base, key) {
        (Some((b, PartQ::Transform { pos, rot })), false) => {
            let sent_at = sp.map(|s| s.sent_at.as_slice()).unwrap_or_default();
            let dpos = VecQuantizer::step_distance(*pos, o.pos);
            let ang = angle_between(dequantize_quat(*rot, bits), dequantize_quat(o.rot, bits));
            let pos_over = dpos > pos_thr || sent_at.first().is_some_and(|t| stale(*t));
            let rot_over = ang > rot_thr || sent_at.get(1).is_some_and(|t| stale(*t));
            // once an entry is paid for, smaller changes of the other field ride along
            let send_pos = *pos != o.pos && (pos_over || (rot_over && dpos > pos_thr * piggy));
            let send_rot = *rot != o.rot && (rot_over || (pos_over && ang > rot_thr * piggy));
            if send_pos || send_rot {
                let after = PartQ::Transform {
                    pos: if send_pos { o.pos } else { *pos },
                    rot: if send_rot { o.rot } else { *rot },
                };
                let body = PartBody::Transform {
                    pos: send_pos
                        .then(|| PosEnc::Delta([0, 1, 2].map(|i| o.pos[i] as i32 - pos[i] as i32))),
                    rot: send_rot.then_some(o.rot),
                };
                let mut fields = Vec::new();
                if send_pos {
                    fields.push(0);
                }
                if send_rot {
                    fields.push(1);
                }
                Some((false, *b, after, body, fields))
            } else {
                None
            }
        }
        _ => Some((
            true,
            0,
            PartQ::Transform {
                pos: o.pos,
                rot: o.rot,
            },
            PartBody::Transform {
                pos: Some(PosEnc::Abs(o.pos)),
                rot: Some(o.rot),
            },
            vec![0, 1],
        )),
    };
    if let Some((key, base_seq, after, body, fields)) = planned {
        let emission = Emission {
            after,
            key,
            force: force_key,
            fields: &fields,
            field_count: 2,
        };
        if let Some(seq) = parts.emit((id, 0), emission, now, ack_wait) {
            out.insert(0, entry(seq, key, base_seq, body));
        }
    }
    out
}

impl Session {
    /// Publish the current state of an object we own (call every frame; the send policy
    /// decides what goes on the wire). The rotation must be a unit quaternion up to rounding
    /// (|q|² within [0.98, 1.02], else [`NetError::InvalidState`]); it is normalized.
    pub fn publish_state(
        &mut self,
        now: Instant,
        id: NetId,
        state: &ObjectState,
    ) -> Result<(), NetError> {
        let o = self.objects.get(id).ok_or(NetError::UnknownObject(id))?;
        if o.info.owner != self.local {
            return Err(NetError::NotOwner(id, o.info.owner));
        }
        let unit = state.checked_rotation()?;
        if state.particles.len() != o.info.particles as usize {
            return Err(NetError::InvalidState("particle count differs from spawn"));
        }
        let class = self
            .cfg
            .classes
            .get(usize::from(o.info.class.0))
            .ok_or(NetError::UnknownClass(o.info.class.0))?;
        let o = self
            .objects
            .get_mut(id)
            .ok_or(NetError::UnknownObject(id))?;
        o.publish(now, state, unit, class);
        Ok(())
    }

    /// Send ticks of every class that is due.
    pub(super) fn send_ticks(&mut self, now: Instant) {
        for c in 0..self.schedule.next_tick.len() {
            let interval = self
                .cfg
                .classes
                .get(c)
                .map_or(Duration::from_millis(50), |cl| cl.send.interval());
            if self.schedule.take_due(c, now, interval) {
                self.owner_tick(now, c as u16);
            }
        }
    }

    /// One send tick of class `c`: replicate the objects we own; the host also repeats, for
    /// each member, what a client's updates it relays have not got acknowledged yet.
    fn owner_tick(&mut self, now: Instant, c: u16) {
        let Some(class) = self.cfg.classes.get(usize::from(c)) else {
            return;
        };
        let rest_after = class.send.rest_after;
        let of_class: Vec<(NetId, PeerId)> = self
            .objects
            .iter()
            .filter(|o| o.info.class.0 == c)
            .map(|o| (o.info.id, o.info.owner))
            .collect();
        let members: Vec<PeerId> = self
            .members
            .keys()
            .copied()
            .filter(|p| *p != self.local)
            .collect();
        for (id, owner) in of_class {
            let mine = owner == self.local;
            let direct = self.cfg.state_route == StateRoute::Direct;
            let targets: Vec<PeerId> = match (self.role, mine) {
                (Role::Host, true) => members.clone(),
                // relay tick: repeat what a client's peers have not acknowledged yet
                (Role::Host, false) if !direct => {
                    members.iter().copied().filter(|p| *p != owner).collect()
                }
                // direct: every member hears the owner itself
                (Role::Client, true) if direct => members.clone(),
                (Role::Client, true) => self.host.into_iter().collect(),
                _ => Vec::new(),
            };
            if let Some(o) = self.objects.get_mut(id) {
                // let go of since the last tick: the budget's release boost starts now
                if std::mem::take(&mut o.released) {
                    o.boost_until = Some(now + super::budget::RELEASE_BOOST);
                }
            }
            if mine {
                if let Some(o) = self.objects.get_mut(id) {
                    // rest sync: an object unchanged for `rest_after` drops its thresholds,
                    // so its exact pose goes out (and is repeated until acknowledged)
                    if !o.rest && now.saturating_since(o.last_change) >= rest_after {
                        o.rest = true;
                    }
                }
            }
            let how = if mine { Refresh::Owner } else { Refresh::Relay };
            for &p in &targets {
                self.queue_entries(now, p, id, how);
            }
        }
    }

    /// Queue for `to` the entries that bring its view of `id` up to date (see
    /// [`plan_entries`]); none while the peer does not know the object yet. True if any.
    pub(super) fn queue_entries(
        &mut self,
        now: Instant,
        to: PeerId,
        id: NetId,
        how: Refresh,
    ) -> bool {
        let Some(o) = self.objects.get(id) else {
            return false;
        };
        let Some(class) = self.cfg.class(o.info.class) else {
            return false;
        };
        let Some(link) = self.links.get_mut(&to) else {
            return false;
        };
        if link.spawn_pending.contains_key(&id) {
            return false; // the peer does not know the object yet
        }
        if self.cfg.uplink_bytes_per_s.is_some() {
            // under a budget the object waits its turn: planned when a datagram takes it
            // (so no entry number is spent on an entry that never goes), gaining priority
            // meanwhile
            let merged = match link.dirty.get(&id) {
                Some(Refresh::Keyframe) => Refresh::Keyframe,
                _ => how,
            };
            link.dirty.insert(id, merged);
            let w = super::budget::weight(o, class, now, link.interest);
            link.priorities
                .accumulate(id, w, class.send.interval(), now);
            return true;
        }
        let view = LinkView {
            ack_wait: link.rtt.ack_wait(),
            parts: &mut link.send,
        };
        let owner = how == Refresh::Owner;
        let entries = plan_entries(o, class, view, now, owner, how == Refresh::Keyframe);
        if entries.is_empty() {
            return false;
        }
        if owner {
            // the datagram is stamped with the time the owner's samples describe
            let sampled = o.published_at;
            link.pending_sample = Some(link.pending_sample.map_or(sampled, |t| t.max(sampled)));
        }
        link.pending.extend(entries);
        true
    }

    /// Each link's share of the uplink budget, bytes a second (`None`: no budget).
    pub fn uplink_share(&self) -> Option<f64> {
        self.cfg
            .uplink_bytes_per_s
            .map(|cap| f64::from(cap) / self.links.len().max(1) as f64)
    }

    /// A datagram of `payload` bytes that went to `to` outside the session (a voice frame):
    /// under an uplink budget it is paid from that link's bucket, so it goes first and the
    /// state waits (the bucket may go into debt, as for control).
    pub fn charge_uplink(&mut self, now: Instant, to: PeerId, payload: usize) {
        let (Some(rate), mtu) = (self.uplink_share(), self.cfg.mtu) else {
            return;
        };
        if let Some(link) = self.links.get_mut(&to) {
            link.bucket.refill(now, rate, mtu);
            link.bucket.spend(payload);
        }
    }

    /// Everything due for `to` in one datagram: acks, pong, ping, keyframe requests, reliable
    /// control messages, then as many state entries as fit.
    pub(super) fn build_datagram(&mut self, now: Instant, to: PeerId) -> Option<Transmit> {
        let mtu = self.cfg.mtu;
        let term = self.term;
        let min_rto = self.cfg.min_rto;
        // this link's share of the uplink budget, if there is one
        let share = self
            .cfg
            .uplink_bytes_per_s
            .map(|cap| f64::from(cap) / self.links.len().max(1) as f64);
        let objects = &self.objects;
        let held = |id: NetId| objects.get(id).is_some_and(|o| o.info.held);
        let room_us = self.clock.stamp_us(now);
        let link = self.links.get_mut(&to)?;
        // under a budget, state goes once the bucket holds a datagram's worth (or is full);
        // held objects' entries go at once when the bucket holds them all (in one datagram,
        // not one by one: each datagram costs its header and the transport's)
        let batch_ok = share.is_none_or(|rate| link.bucket.refill(now, rate, mtu));
        let held_dirty = link.dirty.keys().filter(|id| held(**id)).count();
        let held_only = !batch_ok
            && held_dirty > 0
            && link.bucket.room_for_state(HEADER_ESTIMATE)
                >= held_dirty * super::budget::ENTRY_ESTIMATE;
        let state_ok = batch_ok || held_only;
        if !link.has_work(now, state_ok) {
            return None;
        }
        let rto = link.rtt.rto(min_rto);
        let header = PacketHeader {
            term,
            seq: link.seq.next_out(),
            time_ms: now.wire_ms(),
        };
        let mut w = PacketWriter::new(&header, mtu);
        if link.reliable.ack_pending {
            w.ack(link.reliable.next_expected());
            link.reliable.ack_pending = false;
        }
        if let Some((latest, mask)) = link.state_acks.take_owed() {
            w.state_ack(latest, mask);
        }
        if let Some((t, pinged)) = link.pong_due.take() {
            // how long the ping waited here for this datagram: not part of the way back
            let held_us = now.saturating_since(pinged).as_micros() as u64;
            w.pong(t, room_us.map(|r| (r, held_us)));
        }
        if link.ping_due {
            link.ping_due = false;
            link.last_ping = Some(now);
            w.ping(((now.as_micros() / 1000) & 0xFFFF_FFFF) as u32);
        }
        if link.keyframes.any_due() {
            let ids = link.keyframes.due();
            if w.keyframe_request(&ids) {
                link.keyframes.sent(&ids);
            }
        }
        link.reliable
            .take_due(now, rto, |seq, bytes| w.reliable(seq, bytes));
        // unreliable messages next, before state; one too big for any datagram is dropped
        while let Some(m) = link.unreliable.front() {
            if w.message(m) {
                link.unreliable.pop_front();
            } else if w.is_empty() {
                link.unreliable.pop_front();
                self.stats.messages.unreliable_dropped += 1;
            } else {
                break;
            }
        }
        if state_ok && share.is_some() {
            let filled = super::budget::fill_state(
                link,
                &self.objects,
                &self.cfg.classes,
                now,
                &w,
                held_only,
            );
            self.stats.oversize_dropped += filled.oversize;
            if !filled.carried.is_empty() {
                link.in_flight.record(link.seq.next_out(), filled.carried);
            }
            if let Some(ts) = filled.sampled {
                w.restamp(ts.wire_ms());
            }
            if let Some((count, bytes)) = filled.block {
                w.state(count, &bytes);
                self.stats
                    .add_class_bits(&self.cfg.classes, filled.class_bits);
            }
        } else if state_ok && !link.pending.is_empty() {
            link.pending.sort_by_key(|e| e.id);
            let mut block = StateBlockWriter::new(w.state_budget_bits());
            let mut taken = 0usize;
            let mut oversize = 0u64;
            let mut carried: Vec<EntryRef> = Vec::new();
            let mut class_bits: BTreeMap<u16, usize> = BTreeMap::new();
            for (i, e) in link.pending.iter().enumerate() {
                let layout = self
                    .objects
                    .get(e.id)
                    .and_then(|o| super::budget::layout_of(o, &self.cfg.classes));
                let Some((class_id, layout)) = layout else {
                    taken = i + 1;
                    continue;
                };
                match block.push(e, &layout) {
                    Pushed::Oversize => {
                        oversize += 1;
                        taken = i + 1;
                        continue;
                    }
                    Pushed::Full => break,
                    Pushed::Written(bits) => {
                        *class_bits.entry(class_id).or_default() += bits;
                    }
                }
                // the entry's number: the unacknowledged one with its wire sequence
                let part = e.part();
                if let Some(n) = link.send.number_of(&(e.id, part), e.seq) {
                    carried.push((e.id, part, n));
                }
                taken = i + 1;
            }
            self.stats.oversize_dropped += oversize;
            if !carried.is_empty() {
                link.in_flight.record(link.seq.next_out(), carried);
            }
            link.pending.drain(..taken);
            if link.pending.is_empty() {
                if let Some(ts) = link.pending_sample.take() {
                    // stamp the datagram with the time its samples describe
                    w.restamp(ts.wire_ms());
                }
            }
            if !block.is_empty() {
                let (count, bytes) = block.finish();
                w.state(count, &bytes);
                self.stats.add_class_bits(&self.cfg.classes, class_bits);
            }
        }
        if w.is_empty() {
            return None;
        }
        link.seq.sent();
        link.last_sent = Some(now);
        let (payload, reliable) = w.finish();
        if share.is_some() {
            link.bucket.spend(payload.len());
        }
        self.stats.on_send(to, payload.len(), mtu);
        Some(Transmit {
            to,
            payload,
            reliable,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::ids::{AuthorityEpoch, ClassId};
    use crate::policy::{AuthorityPolicy, SendPolicy};
    use crate::session::registry::Registry;
    use crate::wire::SpawnInfo;
    use glam::{Quat, Vec3};

    fn object(class: &ClassConfig, particles: u32) -> Registry {
        let mut reg = Registry::default();
        let info = SpawnInfo {
            id: NetId(4),
            class: ClassId(0),
            owner: PeerId(1),
            epoch: AuthorityEpoch::default(),
            held: false,
            policy: AuthorityPolicy::Free,
            particles,
            pos: [0.0, 1.0, 0.0],
            rot: [0.0, 0.0, 0.0, 1.0],
            request: None,
            topology: 0,
        };
        reg.insert(Instant::ZERO, info, class);
        reg
    }

    fn plan(
        reg: &Registry,
        class: &ClassConfig,
        parts: &mut SendParts,
        now: Instant,
    ) -> Vec<StateEntry> {
        let view = LinkView {
            parts,
            ack_wait: Duration::from_millis(100),
        };
        plan_entries(reg.get(NetId(4)).unwrap(), class, view, now, true, false)
    }

    fn ack_all(parts: &mut SendParts, entries: &[StateEntry]) {
        for e in entries {
            let key = (e.id, e.part());
            let n = parts.number_of(&key, e.seq).unwrap();
            parts.on_acked(&key, n);
        }
    }

    fn move_to(reg: &mut Registry, class: &ClassConfig, x: f32, now: Instant) {
        let st = crate::session::ObjectState::rigid(Vec3::new(x, 1.0, 0.0), Quat::IDENTITY);
        reg.get_mut(NetId(4))
            .unwrap()
            .publish(now, &st, Quat::IDENTITY, class);
    }

    #[test]
    fn the_first_entry_is_a_keyframe_then_only_changes_past_the_threshold_go_out_as_deltas() {
        let class = ClassConfig::rigid("r", SendPolicy::default()); // 5 mm threshold
        let mut reg = object(&class, 0);
        let mut parts = SendParts::default();
        let t = Instant::from_millis(10);
        let first = plan(&reg, &class, &mut parts, t);
        assert_eq!(first.len(), 1);
        assert!(first[0].key);
        ack_all(&mut parts, &first);
        move_to(&mut reg, &class, 0.003, t);
        assert!(plan(&reg, &class, &mut parts, t).is_empty(), "3 mm < 5 mm");
        move_to(&mut reg, &class, 0.008, t);
        let d = plan(&reg, &class, &mut parts, t);
        assert_eq!(d.len(), 1);
        assert!(!d[0].key);
        assert_eq!(
            d[0].base, first[0].seq,
            "relative to the acknowledged keyframe"
        );
        let PartBody::Transform {
            pos: Some(PosEnc::Delta(dx)),
            rot: None,
        } = d[0].body
        else {
            panic!("{:?}", d[0].body)
        };
        assert_eq!(dx, [16, 0, 0], "8 mm on a 0.5 mm grid");
    }

    #[test]
    fn a_small_change_goes_out_once_stale_and_at_rest_thresholds_drop() {
        let class = ClassConfig::rigid("r", SendPolicy::default()); // 20 Hz, stale after 4
        let mut reg = object(&class, 0);
        let mut parts = SendParts::default();
        let t0 = Instant::from_millis(10);
        let first = plan(&reg, &class, &mut parts, t0);
        ack_all(&mut parts, &first);
        move_to(&mut reg, &class, 0.002, t0);
        assert!(plan(&reg, &class, &mut parts, t0 + Duration::from_millis(100)).is_empty());
        assert_eq!(
            plan(&reg, &class, &mut parts, t0 + Duration::from_millis(180)).len(),
            1,
            "4 intervals (200 ms) less half an interval after the last send"
        );
        let mut reg = object(&class, 0);
        let mut parts = SendParts::default();
        let first = plan(&reg, &class, &mut parts, t0);
        ack_all(&mut parts, &first);
        move_to(&mut reg, &class, 0.001, t0);
        reg.get_mut(NetId(4)).unwrap().rest = true;
        assert_eq!(
            plan(&reg, &class, &mut parts, t0).len(),
            1,
            "at rest: any change"
        );
    }

    #[test]
    fn particle_chunks_split_a_soft_body_and_the_center_rides_along() {
        let mut class = ClassConfig::soft_body("s", SendPolicy::default(), SoftBodyMode::Particles);
        class.particles_per_chunk = 4;
        let reg = object(&class, 10);
        let mut parts = SendParts::default();
        let entries = plan(&reg, &class, &mut parts, Instant::from_millis(1));
        let parts_sent: Vec<u32> = entries.iter().map(StateEntry::part).collect();
        assert_eq!(
            parts_sent,
            vec![0, 1, 2, 3],
            "transform first, then 3 chunks"
        );
        let mut center_only = class.clone();
        center_only.soft_body_mode = SoftBodyMode::CenterOnly;
        let mut parts = SendParts::default();
        let entries = plan(&reg, &center_only, &mut parts, Instant::from_millis(1));
        assert_eq!(entries.len(), 1);
    }

    #[test]
    fn due_ticks_move_on_by_their_interval_and_never_into_the_past() {
        let mut s = SendSchedule::new(Instant::ZERO, 1);
        let i = Duration::from_millis(50);
        assert!(s.take_due(0, Instant::ZERO, i));
        assert!(!s.take_due(0, Instant::from_millis(49), i));
        assert!(s.take_due(0, Instant::from_millis(51), i));
        assert_eq!(s.next_tick[0], Instant::from_millis(100));
        assert!(s.take_due(0, Instant::from_millis(400), i));
        assert_eq!(
            s.next_tick[0],
            Instant::from_millis(450),
            "a stall skips ticks"
        );
        assert!(
            !s.take_due(3, Instant::from_millis(400), i),
            "no such class"
        );
    }
}
