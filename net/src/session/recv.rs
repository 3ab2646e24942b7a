//! Datagrams in: decoded once ([`decode_datagram`]), then, in order: who may be heard (peers
//! that left, peers the host dropped, strangers beyond [`MAX_STRANGERS`]), refusals, the
//! term, the link's sequence and clock, the sections (acks, pings, keyframe requests,
//! control messages), and last the state entries, applied against their delta bases and
//! relayed by the host.

use std::collections::BTreeSet;
use std::time::Duration;

use super::delta::PartQ;
use super::liveness::DropWhy;
use super::send::Refresh;
use super::{Event, Role, Session, Transmit, MAX_STRANGERS};
use crate::error::NetError;
use crate::ids::{NetId, PeerId};
use crate::policy::StateRoute;
use crate::time::Instant;

/// Refusals a host sends peers of another protocol version, per second in all (the rest of
/// such datagrams are dropped unanswered: a flood of them gets no flood back).
pub const MAX_VERSION_REFUSALS_PER_S: u32 = 10;
use crate::wire::{
    decode_datagram, decode_state_block_sized, encode_refusal, ChunkEnc, Control, Datagram,
    EntryLayout, PacketHeader, PartBody, PosEnc, Refusal, Section, StateEntry,
};

/// What an entry did.
enum Applied {
    /// Applied, or kept as a delta base.
    Kept,
    /// Dropped (unknown object, not from its source, stale epoch, base missing).
    Dropped,
}

impl Session {
    /// A datagram from `from`.
    pub(super) fn receive(&mut self, now: Instant, from: PeerId, bytes: &[u8]) {
        if self.departed.contains(from) || self.refuse_if_banned(now, from) {
            return;
        }
        let datagram = decode_datagram(bytes);
        // A beacon of another room of ours (a partition healed) is heard whoever sends it: a
        // peer our room dropped, a stranger, another term (see `heal`).
        if let Ok(Datagram::Packet { header, sections }) = &datagram {
            if let [Section::Beacon(summary)] = sections.as_slice() {
                return self.on_beacon(now, from, header.term, *summary);
            }
        }
        if self.role == Role::Host && self.dropped.contains(from) {
            // A fresh session of the dropped peer (term 0: it joins again) is heard out as any
            // joiner, with fresh link state (its sequences start over); the rest is answered
            // with the refusal.
            let rejoining =
                matches!(&datagram, Ok(Datagram::Packet { header, .. }) if header.term.0 == 0);
            if !rejoining {
                self.tell_dropped(now, from);
                return;
            }
            self.dropped.remove(from);
            self.links.remove(&from);
            self.stats.links.remove(&from);
        }
        // State is kept for members and at most MAX_STRANGERS others (joiners, peers we have
        // not heard of yet): a flood of datagrams from made-up ids costs no memory.
        let known = self.links.contains_key(&from)
            || self.members.contains_key(&from)
            || Some(from) == self.host;
        if known {
            self.stats.on_recv(from, bytes.len());
        } else {
            // Per-peer statistics start once the sender has link state (below).
            self.stats.down.add(bytes.len());
            if self.stranger_count() >= MAX_STRANGERS && !self.evict_oldest_stranger(now) {
                self.stats.dropped_strangers += 1;
                return;
            }
        }
        let (header, sections) = match datagram {
            Ok(Datagram::Packet { header, sections }) => (header, sections),
            Ok(Datagram::Refusal(refusal)) => return self.on_refusal(now, from, refusal),
            Err(NetError::VersionMismatch { ours, theirs }) => {
                self.stats.decode_errors += 1;
                // at most MAX_VERSION_REFUSALS_PER_S in all: a flood of datagrams of other
                // versions must not make the host send one refusal for each
                let second = now.as_micros() / 1_000_000;
                let (at, n) = self.version_refusals;
                let n = if at == second { n } else { 0 };
                if self.role == Role::Host && n < MAX_VERSION_REFUSALS_PER_S {
                    self.version_refusals = (second, n + 1);
                    let reason = format!(
                        "protocol version mismatch: host speaks {ours}, you speak {theirs}"
                    );
                    self.raw_out.push_back(Transmit {
                        to: from,
                        payload: encode_refusal(&reason, self.term),
                        reliable: true,
                    });
                }
                return;
            }
            Err(_) => {
                self.stats.decode_errors += 1;
                return;
            }
        };
        let is_member = self.members.contains_key(&from) || Some(from) == self.host;
        // A non-member speaking for an older term of this room: it was out of touch while the
        // room elected this host (a stalled old host, or a member the election left out as
        // dead). Its objects have new owners; it is told, and ignored until it joins again.
        // A member tells it too, naming our host: it may still follow us as its host of that
        // term (we were its host, stalled, and rejoined the room that went on; or it never
        // learned we left), and answering its pings as a stranger's would keep it following
        // us for good (the fuzzer's known issues 5 and 6).
        if !is_member
            && matches!(self.role, Role::Host | Role::Client)
            && header.term.0 != 0
            && header.term < self.term
        {
            self.dropped.insert(from, DropWhy::OlderTerm(header.term));
            self.tell_dropped(now, from);
            return;
        }
        // term 0: a joiner's datagrams before it learned the term
        if is_member && header.term < self.term && header.term.0 != 0 {
            self.stats.dropped_old_term += 1;
            return;
        }
        // A non-member of our term or a newer one (not a joiner): a member of a rival room of
        // the same term, or of one that went on without us, or a member our host has not
        // told us of yet. Heard, but its pings are not answered: our pongs would keep us a
        // live member of its room, which then never loses us, and beacons count only from
        // peers a room lost, so the two rooms would never merge (the fuzzer's known issue 6).
        let sections =
            if !is_member && header.term.0 != 0 && matches!(self.role, Role::Host | Role::Client) {
                sections
                    .into_iter()
                    .filter(|s| !matches!(s, Section::Ping { .. }))
                    .collect()
            } else {
                sections
            };
        self.on_packet(now, from, known, bytes.len(), &header, sections);
    }

    /// A refusal: a joiner refused, or a member the host dropped (it stalled past the
    /// timeout), or the host of a newer term telling a peer that stalled.
    fn on_refusal(&mut self, now: Instant, from: PeerId, refusal: Refusal) {
        // A drop notice (it names a host to join) is for a member; a joining session gets one
        // when its old session, out of the room, still spoke after we asked to join again.
        if self.role == Role::Joining && refusal.rejoin.is_some() {
            return;
        }
        let from_our_host =
            matches!(self.role, Role::Joining | Role::Client) && Some(from) == self.host;
        // Or the host of a newer term: the room elected it while this peer was silent
        // (a host or member that stalled past the peer timeout, or was cut off that long).
        // Only after a stall of our own: a peer cut off from the room elects itself host of
        // a newer term too, and must not depose a host that never stopped.
        let newer = matches!(self.role, Role::Host | Role::Client)
            && refusal.term.is_some_and(|t| t > self.term)
            && self.stalled_recently(now);
        if from_our_host || newer {
            let was_in = matches!(self.role, Role::Host | Role::Client);
            self.role = Role::Refused;
            self.events.push_back(if was_in {
                Event::Dropped {
                    // our host yielding to another room names it (a partition healed)
                    host: refusal.rejoin.filter(|_| from_our_host).unwrap_or(from),
                    reason: refusal.reason,
                }
            } else {
                Event::Refused {
                    reason: refusal.reason,
                }
            });
        }
    }

    /// A datagram of this room's protocol and term from `from`.
    fn on_packet(
        &mut self,
        now: Instant,
        from: PeerId,
        known: bool,
        len: usize,
        header: &PacketHeader,
        sections: Vec<Section<'_>>,
    ) {
        let link = self.links.entry(from).or_default();
        if let Some(before) = link.last_heard {
            link.gaps.record(now.saturating_since(before));
        }
        link.last_heard = Some(now);
        link.first_heard.get_or_insert(now);
        let ls = self.stats.links.entry(from).or_default();
        if !known {
            ls.down.add(len);
        }
        let arrival = link.seq.on_receive(now, header.seq, ls);
        let sample_time = link.clock.observe(now, header.time_ms);

        let mut states = Vec::new();
        let mut controls = Vec::new();
        let mut unreliable = Vec::new();
        for s in sections {
            match s {
                Section::Ack { next_expected } => self.on_reliable_ack(now, from, next_expected),
                Section::Reliable { seq, bytes } => {
                    if let Some(l) = self.links.get_mut(&from) {
                        for m in l.reliable.on_receive(seq, bytes) {
                            match Control::decode(&m) {
                                Ok(c) => controls.push(c),
                                Err(_) => self.stats.decode_errors += 1,
                            }
                        }
                    }
                }
                Section::Ping { time_ms } => {
                    if let Some(l) = self.links.get_mut(&from) {
                        l.pong_due = Some((time_ms, now));
                    }
                }
                Section::Pong { time_ms, room_us } => {
                    let now_ms = (now.as_micros() / 1000) & 0xFFFF_FFFF;
                    let rtt_ms = (now_ms as u32).wrapping_sub(time_ms);
                    if rtt_ms < 60_000 {
                        if let Some(l) = self.links.get_mut(&from) {
                            l.rtt.on_sample(Duration::from_millis(u64::from(rtt_ms)));
                            self.stats.links.entry(from).or_default().rtt = l.rtt.srtt();
                            // the room clock, from our host's answer to our last ping (its
                            // exact send time; an older ping's echo is not used)
                            let sent = l.last_ping.filter(|t| {
                                (t.as_micros() / 1000) & 0xFFFF_FFFF == u64::from(time_ms)
                            });
                            if let (Some(sent), Some((room, held)), true, false) = (
                                sent,
                                room_us,
                                Some(from) == self.host,
                                self.role == Role::Host,
                            ) {
                                self.clock.on_pong(now, sent, room, held);
                            }
                        }
                    }
                }
                // only a member (or our host) is answered: a stranger's request would read a
                // keyed room's objects without the key
                Section::KeyframeRequest { ids }
                    if self.members.contains_key(&from) || Some(from) == self.host =>
                {
                    let admitted = self.links.get_mut(&from).is_none_or(|l| {
                        l.keyframe_asks
                            .admit(now, super::link::MAX_KEYFRAME_REQUESTS_PER_S)
                    });
                    if !admitted {
                        self.stats.requests_rate_limited += 1;
                        self.drop_if_flooding(now, from);
                        continue;
                    }
                    for id in ids {
                        let sends = self
                            .objects
                            .get(id)
                            .is_some_and(|o| o.info.owner == self.local || self.role == Role::Host);
                        if sends {
                            self.queue_entries(now, from, id, Refresh::Keyframe);
                        }
                    }
                }
                Section::KeyframeRequest { .. } => self.stats.refused_controls += 1,
                Section::State { count, bits } => states.push((count, bits)),
                Section::StateAck { latest, mask } => self.on_state_ack(from, latest, mask),
                Section::Message(m) => unreliable.push(m),
                // only ever alone in its datagram (handled above); mixed in, ignored
                Section::Beacon(_) => {}
            }
        }
        for c in controls {
            self.deliver_control(now, from, c);
        }
        for m in unreliable {
            if self.is_member_client(from) {
                self.host_relay(now, from, m);
            } else if Some(from) == self.host && self.role == Role::Client {
                self.deliver_message(m);
            }
        }
        if !self.members.contains_key(&from) && Some(from) != self.host {
            return; // state only from members
        }
        let mut touched = BTreeSet::new();
        let carried_state = !states.is_empty();
        let mut complete = !arrival.too_late;
        for (count, bits) in states {
            if arrival.too_late {
                break;
            }
            let cfg = &self.cfg;
            let objects = &self.objects;
            let parsed = decode_state_block_sized(count, bits, |id| {
                let o = objects.get(id)?;
                Some(EntryLayout {
                    class: cfg.class(o.info.class)?,
                    particles: o.info.particles,
                    generation: o.topology.generation(),
                })
            });
            let entries = match parsed {
                Ok((e, all)) => {
                    complete &= all;
                    e
                }
                Err(_) => {
                    self.stats.decode_errors += 1;
                    complete = false;
                    continue;
                }
            };
            for (e, body_bits) in entries {
                // per-class down bytes: what the entry's body took on the wire
                if let Some(class) = self
                    .objects
                    .get(e.id)
                    .and_then(|o| self.cfg.class(o.info.class))
                {
                    *self
                        .stats
                        .class_down_bytes
                        .entry(class.name.clone())
                        .or_default() += body_bits as f64 / 8.0;
                }
                let (id, part, seq) = (e.id, e.part(), e.seq);
                if let Applied::Dropped =
                    self.apply_entry(now, from, e, arrival.fresh, &mut touched)
                {
                    // its datagram is still acknowledged: see DeltaBases::forget_entry
                    if let Some(l) = self.links.get_mut(&from) {
                        l.recv.forget_entry(&(id, part), seq);
                    }
                }
            }
        }
        // acknowledge the datagram (its entries become delta bases at the sender) unless
        // we could not read all of it
        if carried_state && complete {
            if let Some(l) = self.links.get_mut(&from) {
                l.state_acks.record(header.seq);
            }
        }
        for id in touched {
            self.after_update(now, from, id, sample_time);
        }
    }

    /// The peer's cumulative ack of our reliable messages. Objects whose `Spawn` it now
    /// acknowledged get their current state at once (a resting object would otherwise never
    /// be sent again).
    fn on_reliable_ack(&mut self, now: Instant, from: PeerId, next_expected: u16) {
        let Some(l) = self.links.get_mut(&from) else {
            return;
        };
        if !l.reliable.on_ack(next_expected) {
            self.stats.implausible_acks += 1;
            return;
        }
        let acked: Vec<NetId> = l
            .spawn_pending
            .iter()
            .filter(|(_, seq)| l.reliable.is_acked(**seq))
            .map(|(id, _)| *id)
            .collect();
        for id in &acked {
            l.spawn_pending.remove(id);
        }
        if self.role == Role::Host {
            for id in acked {
                if self.owner(id) != Some(from) {
                    self.queue_entries(now, from, id, Refresh::Keyframe);
                }
            }
            self.advance_deliveries(now);
        }
    }

    /// The peer's state ack: the entries of the datagrams it covers become delta bases.
    fn on_state_ack(&mut self, from: PeerId, latest: u8, mask: u32) {
        let Some(l) = self.links.get_mut(&from) else {
            return;
        };
        for (id, part, number) in l.in_flight.on_ack(latest, mask) {
            l.send.on_acked(&(id, part), number);
        }
    }

    /// Applies one entry against its delta base (or as a keyframe), if it comes from the
    /// object's source with the current epoch tag.
    fn apply_entry(
        &mut self,
        now: Instant,
        from: PeerId,
        e: StateEntry,
        fresh: bool,
        touched: &mut BTreeSet<NetId>,
    ) -> Applied {
        let Some(o) = self.objects.get(e.id) else {
            return Applied::Dropped;
        };
        if o.info.owner == self.local {
            self.stats.dropped_non_owner += 1;
            return Applied::Dropped;
        }
        // the host hears an object's owner; a client hears its host (which relays), or, with
        // direct state, the owner itself
        let sender_ok = if self.role == Role::Host || self.cfg.state_route == StateRoute::Direct {
            from == o.info.owner
        } else {
            Some(from) == self.host
        };
        if !sender_ok {
            self.stats.dropped_non_owner += 1;
            return Applied::Dropped;
        }
        if e.epoch_tag != o.info.epoch.tag() {
            self.stats.dropped_stale_epoch += 1;
            return Applied::Dropped;
        }
        let Some(class) = self.cfg.class(o.info.class) else {
            return Applied::Dropped;
        };
        let pq = class.position_quantizer();
        let part = e.part();
        let Some(link) = self.links.get_mut(&from) else {
            return Applied::Dropped;
        };
        let rp = link.recv.part((e.id, part));
        let state = if e.key {
            match &e.body {
                PartBody::Transform {
                    pos: Some(PosEnc::Abs(p)),
                    rot: Some(r),
                } => Some(PartQ::Transform {
                    pos: pq.clamp(p.map(i64::from)),
                    rot: *r,
                }),
                PartBody::Chunk {
                    values: ChunkEnc::Abs(v),
                    ..
                } => Some(PartQ::Chunk(v.clone())),
                _ => None,
            }
        } else {
            match (&e.body, rp.base(e.base)) {
                (PartBody::Transform { pos, rot }, Some(PartQ::Transform { pos: bp, rot: br })) => {
                    let np = match pos {
                        Some(PosEnc::Delta(d)) => {
                            pq.clamp([0, 1, 2].map(|i| i64::from(bp[i]) + i64::from(d[i])))
                        }
                        Some(PosEnc::Abs(p)) => pq.clamp(p.map(i64::from)),
                        None => bp,
                    };
                    Some(PartQ::Transform {
                        pos: np,
                        rot: rot.unwrap_or(br),
                    })
                }
                (
                    PartBody::Chunk {
                        values: ChunkEnc::Delta(list),
                        ..
                    },
                    Some(PartQ::Chunk(mut v)),
                ) => {
                    let q = class.particle_quantizer();
                    for (i, d) in list {
                        if let Some(x) = v.get_mut(*i as usize) {
                            *x = q.clamp([0, 1, 2].map(|k| i64::from(x[k]) + i64::from(d[k])));
                        }
                    }
                    Some(PartQ::Chunk(v))
                }
                (_, None) => {
                    // the base is unknown (history reset): ask for a keyframe, rate-limited
                    self.stats.chain_breaks += 1;
                    let gap = link.rtt.keyframe_request_gap();
                    link.keyframes.want(e.id, now, gap);
                    return Applied::Dropped;
                }
                _ => None,
            }
        };
        let Some(state) = state else {
            return Applied::Dropped;
        };
        if !link
            .recv
            .part((e.id, part))
            .record(e.seq, state.clone(), fresh)
        {
            return Applied::Kept; // older than what we show (reordered); kept only as a base
        }
        let chunk_len = class.chunk_len();
        let Some(o) = self.objects.get_mut(e.id) else {
            return Applied::Dropped;
        };
        o.apply_part(part, state, chunk_len);
        if o.rest != e.rest {
            o.rest = e.rest;
            if e.rest {
                o.last_change = now;
            }
        }
        o.source = Some(from);
        touched.insert(e.id);
        Applied::Kept
    }

    /// An object's state changed from `from`'s datagram: buffer it for interpolation, and,
    /// as host, relay it to every other member (thesis Figure 5.2).
    fn after_update(&mut self, now: Instant, from: PeerId, id: NetId, sample_time: Instant) {
        let interp = self.interp;
        let Some(o) = self.objects.get(id) else {
            return;
        };
        let Some(class) = self.class(o.info.class) else {
            return;
        };
        let snap = o.snapshot(sample_time, class);
        if let Some(o) = self.objects.get_mut(id) {
            o.buffer.push(snap, &interp);
        }
        if self.role == Role::Host && self.cfg.state_route == StateRoute::Relay {
            let targets: Vec<PeerId> = self
                .members
                .keys()
                .copied()
                .filter(|p| *p != self.local && *p != from)
                .collect();
            for p in targets {
                if self.queue_entries(now, p, id, Refresh::Relay) {
                    self.last_relay_at = Some(now);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::super::testkit::{config, Wire};
    use super::*;
    use crate::ids::Term;
    use crate::wire::{PacketWriter, PROTOCOL_VERSION};

    #[test]
    fn another_protocol_version_is_counted_and_answered_with_a_reliable_refusal() {
        let mut host = Session::host(PeerId(1), config(), Instant::ZERO);
        let mut bytes = vec![PROTOCOL_VERSION + 1];
        bytes.extend_from_slice(&[0, 0, 0, 0]);
        host.handle_packet(Instant::ZERO, PeerId(5), &bytes);
        assert_eq!(host.stats().decode_errors, 1);
        let t = host.poll_transmit(Instant::ZERO).unwrap();
        assert!(t.reliable && t.to == PeerId(5));
        let r = crate::wire::decode_refusal(&t.payload).unwrap();
        assert!(
            r.reason.contains("protocol version mismatch"),
            "{}",
            r.reason
        );
        // garbage is only counted
        host.handle_packet(Instant::ZERO, PeerId(5), &[PROTOCOL_VERSION, 0xFF]);
        assert_eq!(host.stats().decode_errors, 2);
        assert!(host.poll_transmit(Instant::ZERO).is_none());
    }

    #[test]
    fn a_refusal_from_our_host_ends_a_joining_session_and_one_from_a_stranger_does_not() {
        let mut j = Session::join(PeerId(2), PeerId(1), config(), Instant::ZERO);
        let refusal = encode_refusal("full", Term(1));
        j.handle_packet(Instant::ZERO, PeerId(7), &refusal);
        assert!(j.poll_event().is_none(), "not from our contact");
        j.handle_packet(Instant::ZERO, PeerId(1), &refusal);
        assert_eq!(
            j.poll_event(),
            Some(Event::Refused {
                reason: "full".into()
            })
        );
        assert!(j.poll_timeout().is_none(), "done");
    }

    #[test]
    fn a_departed_peers_late_datagrams_and_an_older_terms_are_ignored() {
        let mut w = Wire::new();
        w.add(Session::host(PeerId(1), config(), w.now));
        w.add(Session::join(PeerId(2), PeerId(1), config(), w.now));
        w.settle();
        // a member's datagram of an older term is dropped and counted
        let old = PacketHeader {
            term: Term(0),
            seq: 200,
            time_ms: 0,
        };
        let mut stale = PacketWriter::new(
            &PacketHeader {
                term: Term(1),
                ..old
            },
            1200,
        );
        stale.ping(1);
        let (ok, _) = stale.finish();
        let now = w.now;
        w.get(1).term = Term(2);
        w.get(1).handle_packet(now, PeerId(2), &ok);
        assert_eq!(w.get(1).stats().dropped_old_term, 1);
        // after Leave, nothing from the peer is heard
        w.get(1).term = Term(1);
        let now = w.now;
        w.get(2).leave(now);
        w.settle();
        let down = w.get(1).stats().down.packets;
        w.get(1).handle_packet(now, PeerId(2), &ok);
        assert_eq!(w.get(1).stats().down.packets, down);
    }

    #[test]
    fn strangers_beyond_the_bound_cost_no_state() {
        let mut host = Session::host(PeerId(1), config(), Instant::ZERO);
        let mut w = PacketWriter::new(
            &PacketHeader {
                term: Term(0),
                seq: 0,
                time_ms: 0,
            },
            1200,
        );
        w.ping(1);
        let (bytes, _) = w.finish();
        for p in 0..(MAX_STRANGERS as u64 + 10) {
            host.handle_packet(Instant::ZERO, PeerId(1000 + p), &bytes);
        }
        assert_eq!(host.stats().dropped_strangers, 10);
        assert!(host.links.len() <= MAX_STRANGERS);
    }
}
