//! Partitions heal into one room.
//!
//! A partition leaves two rooms of one room's peers, each with a host (the side without the
//! old host elected one). Neither speaks to the other again on its own: each dropped the
//! other's peers. So every member remembers the peers its room **lost** — gone from the
//! member list without a `Leave` — and, for [`SessionConfig::heal_window`], sends each of them
//! a beacon once per peer timeout: a datagram with its room's [`RoomSummary`] (config digest,
//! host, the host's join order, member count). When the partition ends, beacons arrive; a
//! peer that hears one of the same room (same digest) with another host compares the two
//! with [`RoomSummary::beats`], which every peer computes alike:
//!
//! - its room wins: it answers with its own beacon (at most once per peer timeout per
//!   sender), so the other side learns it loses even if it lost none of our peers;
//! - its room loses: it **yields**: a host first tells each member to join the winner (a
//!   refusal naming the winning host, sent twice), then it — host or member — emits
//!   [`Event::Dropped`] naming the winning host, and the application joins that host with a
//!   fresh session (as after any drop: the winner's snapshot rebuilds its world).
//!
//! A beacon counts only from a peer our room lost, claiming at most `max_members` members
//! (`SessionConfig`): a member or a stranger that makes one up takes nothing, key or not. (A
//! peer that joined the other side during the partition, and so lost none of ours, learns it
//! loses from its host, which did.) A stranger whose room loses to ours is still answered
//! with our beacon (at most [`MAX_STRANGER_ANSWERS_PER_S`] a second): it may have lost us
//! while we never knew it — it joined just before the old host fell, and our side missed its
//! arrival — and, told, it yields; a stranger's beacon never makes us yield.
//!
//! A peer just woken from a stall of its own ignores beacons: its member list still counts the
//! peers that went on without it, and the stall path (a refusal of the newer term) brings it
//! back instead.
//!
//! What the winning room had is kept whole: its registry never changes, and the objects the
//! yielding peers owned there went back to its host when it timed them out. What the yielding
//! room did apart — objects it spawned, changes to objects it owned — is dropped (the peer
//! layer counts what it owned: `Counters::discarded_objects`). No object has two owners: the
//! yielding side keeps no replica.

use std::collections::{BTreeMap, BTreeSet};

use super::{Event, Role, Session, Transmit};
use crate::ids::PeerId;
use crate::time::Instant;
use crate::wire::{encode_beacon, encode_refusal_to, PacketHeader, RoomSummary};

/// What a session remembers to heal a partition.
#[derive(Debug, Default)]
pub(crate) struct Heal {
    /// The room's members (and host) at the last check.
    seen: BTreeSet<PeerId>,
    /// Peers the room lost (not departed), and when.
    lost: BTreeMap<PeerId, Instant>,
    /// When beacons next go out.
    next_beacon: Option<Instant>,
    /// When we last answered each foreign beacon's sender.
    answered: BTreeMap<PeerId, Instant>,
    /// Strangers' beacons answered in the current second: (second, count).
    stranger_answers: (u64, u32),
}

/// Strangers' beacons answered per second, at most (see `on_beacon`).
pub const MAX_STRANGER_ANSWERS_PER_S: u32 = 4;

/// Most lost peers remembered (a room's worth; the oldest go first).
const MAX_LOST: usize = 64;

impl Session {
    /// Our room's summary; `None` unless we are in a room.
    pub fn room_summary(&self) -> Option<RoomSummary> {
        if !matches!(self.role, Role::Host | Role::Client) {
            return None;
        }
        let host = self.host?;
        Some(RoomSummary {
            digest: self.cfg.digest(),
            host,
            host_join: self.members.get(&host).copied().unwrap_or(u32::MAX),
            members: self.members.len() as u32,
            tag: None,
        })
    }

    /// Note the members (and host) as seen before some leave the member list: a peer that
    /// joined and went between two heal timers is still noted as lost at the next (the
    /// fuzzer's known issue 3: a host that left just as a peer joined split the room for
    /// good, neither side noting the other).
    pub(super) fn heal_remember_members(&mut self) {
        if !matches!(self.role, Role::Host | Role::Client) {
            return;
        }
        self.heal.seen.extend(self.members.keys().copied());
        self.heal.seen.extend(self.host);
    }

    /// Peers our room lost that we still send beacons to.
    pub fn lost_peers(&self) -> Vec<PeerId> {
        self.heal.lost.keys().copied().collect()
    }

    /// Timer: note peers the room lost since the last check, send beacons when due.
    pub(super) fn heal_tick(&mut self, now: Instant) {
        if !matches!(self.role, Role::Host | Role::Client) {
            return;
        }
        let mut now_in: BTreeSet<PeerId> = self.members.keys().copied().collect();
        now_in.extend(self.host);
        for p in self.heal.seen.difference(&now_in) {
            if *p != self.local && !self.departed.contains(*p) {
                self.heal.lost.insert(*p, now);
            }
        }
        for p in &now_in {
            self.heal.lost.remove(p);
        }
        self.heal.seen = now_in;
        let window = self.cfg.heal_window;
        self.heal
            .lost
            .retain(|_, at| now.saturating_since(*at) < window);
        while self.heal.lost.len() > MAX_LOST {
            let oldest = self
                .heal
                .lost
                .iter()
                .min_by_key(|(_, t)| **t)
                .map(|(p, _)| *p);
            match oldest {
                Some(p) => self.heal.lost.remove(&p),
                None => break,
            };
        }
        if self.heal.lost.is_empty() {
            self.heal.next_beacon = None;
            return;
        }
        let due = *self.heal.next_beacon.get_or_insert(now);
        if now < due {
            return;
        }
        self.heal.next_beacon = Some(now + self.cfg.peer_timeout);
        let targets: Vec<PeerId> = self.heal.lost.keys().copied().collect();
        for to in targets {
            self.send_beacon(now, to);
        }
    }

    /// When the next beacons are due, if any.
    pub(super) fn heal_deadline(&self) -> Option<Instant> {
        self.heal.next_beacon
    }

    fn send_beacon(&mut self, now: Instant, to: PeerId) {
        let Some(mut summary) = self.room_summary() else {
            return;
        };
        if let Some(k) = &self.cfg.room_key {
            summary.tag = Some(k.beacon_tag(&summary, self.term, self.local, to));
        }
        let header = PacketHeader {
            term: self.term,
            seq: 0,
            time_ms: (now.as_micros() / 1000) as u16,
        };
        self.stats.beacons_sent += 1;
        self.raw_out.push_back(Transmit {
            to,
            payload: encode_beacon(&header, &summary),
            reliable: false,
        });
    }

    /// A beacon from `from`: the summary of its room.
    pub(super) fn on_beacon(
        &mut self,
        now: Instant,
        from: PeerId,
        term: crate::ids::Term,
        theirs: RoomSummary,
    ) {
        let Some(mine) = self.room_summary() else {
            return;
        };
        if theirs.digest != mine.digest || theirs.host == mine.host || from == self.local {
            return;
        }
        // Just woken from a stall of our own past the timeout: our member list is stale (it
        // still counts the peers that went on without us). The stall path settles it: the
        // room that went on tells us (a refusal of its newer term), and we rejoin it.
        if self.stalled_recently(now) {
            return;
        }
        // No room is bigger than a room may be (issue 32).
        if theirs.members < 1 || theirs.members as usize > self.cfg.max_members {
            self.stats.beacons_refused += 1;
            return;
        }
        if let Some(k) = &self.cfg.room_key {
            let untagged = RoomSummary {
                tag: None,
                ..theirs
            };
            let expected = k.beacon_tag(&untagged, term, from, self.local);
            // compared as HMAC tags are (ring verifies whole tags; this one is cut to 16
            // bytes, so compare without an early exit)
            let ok = theirs.tag.is_some_and(|t| {
                t.iter()
                    .zip(&expected)
                    .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                    == 0
            });
            if !ok {
                self.stats.beacons_refused += 1;
                return;
            }
        }
        // Only a peer our room lost speaks for the room it went on as (a partition's other
        // side: its members lost us as we lost them): a stranger's or a member's summary
        // never makes us yield (issue 32). But a stranger whose room loses to ours is told
        // so (our beacon, rate-limited): it may be a peer that lost us while we never knew
        // it — it joined as the old host fell, and our side missed its arrival — and the
        // two rooms would otherwise never merge. Telling costs one small datagram and
        // takes nothing from us.
        if !self.heal.lost.contains_key(&from) {
            let stranger = !self.members.contains_key(&from) && Some(from) != self.host;
            if stranger && !theirs.beats(&mine) && self.stranger_answer_allowed(now) {
                self.stats.beacons_answered_strangers += 1;
                self.answer_beacon(now, from);
            } else {
                self.stats.beacons_refused += 1;
            }
            return;
        }
        self.stats.beacons_heard += 1;
        if theirs.beats(&mine) {
            self.yield_to(theirs.host);
            return;
        }
        self.answer_beacon(now, from);
    }

    /// Send `from` our beacon, at most once per peer timeout.
    fn answer_beacon(&mut self, now: Instant, from: PeerId) {
        let due = self
            .heal
            .answered
            .get(&from)
            .is_none_or(|t| now.saturating_since(*t) >= self.cfg.peer_timeout);
        if due {
            if self.heal.answered.len() >= MAX_LOST {
                self.heal.answered.clear();
            }
            self.heal.answered.insert(from, now);
            self.send_beacon(now, from);
        }
    }

    /// Whether a stranger's beacon may be answered now: at most
    /// [`MAX_STRANGER_ANSWERS_PER_S`] a second in all (a flood of beacons from many ids gets
    /// no flood back).
    fn stranger_answer_allowed(&mut self, now: Instant) -> bool {
        let second = now.as_micros() / 1_000_000;
        let (at, n) = self.heal.stranger_answers;
        let n = if at == second { n } else { 0 };
        if n >= MAX_STRANGER_ANSWERS_PER_S {
            return false;
        }
        self.heal.stranger_answers = (second, n + 1);
        true
    }

    /// Our room loses to the room of `winner`: a host tells its members to join it; then we
    /// leave for it ([`Event::Dropped`]).
    fn yield_to(&mut self, winner: PeerId) {
        let reason = format!(
            "a partition healed: this room joins the room of host {} (the larger, or older, \
             of the two); what it did apart is dropped",
            winner.0
        );
        if self.role == Role::Host {
            let members: Vec<PeerId> = self
                .members
                .keys()
                .copied()
                .filter(|p| *p != self.local)
                .collect();
            for m in members {
                for _ in 0..2 {
                    self.raw_out.push_back(Transmit {
                        to: m,
                        payload: encode_refusal_to(&reason, self.term, Some(winner)),
                        reliable: true,
                    });
                }
            }
        }
        self.stats.merges += 1;
        self.role = Role::Refused;
        self.events.push_back(Event::Dropped {
            host: winner,
            reason,
        });
    }
}
