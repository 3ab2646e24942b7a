//! Application messages: the sender's outbox, the receiver's duplicate filter and retained
//! table, and the host's relay with its checks and delivery ledger.
//!
//! # Exactly once, also across a host migration
//!
//! A reliable message carries its origin's number (from 1, one per reliable message). The
//! origin keeps it in its outbox until the host says every target has it
//! ([`Control::MessagesDelivered`], sent once each target's link acknowledged the relayed
//! copy, or the target left), or refused it. When the host changes, the origin sends every
//! message still in its outbox to the new host (or, if it is the new host, relays them
//! itself), in order. Every path from an origin to a receiver keeps the origin's order (one
//! ordered channel to the host, one from the host), so a receiver delivers a message only if
//! its number is above the last it delivered from that origin: a resent message some target
//! already had is dropped there, and the targets that missed it get it. What is not
//! guaranteed: a message whose origin dies with the host before the host relayed it (nobody
//! is left who has it). Also not: that a target that changes across a migration (`Host`,
//! `OwnerOf`) is one peer; the new host resolves it again, and runs its filter again.
//!
//! # Retained state
//!
//! Retained messages (room-wide or per object) are state, kept by every member in the host's
//! relay order: the host relays a retained message to every member but itself, its origin
//! included, so every table applies the same sequence. A joiner, and after a migration every
//! member, gets the host's table as `Replay`s: a replay sets the state (told if it differs)
//! without moving the origin's number, so the origin's earlier messages resent to the new host
//! are still delivered; the live copy of a replayed message is recognised by the table.

use std::collections::{BTreeMap, VecDeque};

use super::{Event, Role, Session};
use crate::ids::{NetId, PeerId};
use crate::time::Instant;
use crate::wire::{
    encode_unreliable_message, AppMessage, Control, Delivery, MessageKind, MessageRefusal,
    MessageTarget, ReceivedMessage,
};

/// A token bucket: `rate` per second, at most `cap` at once.
#[derive(Debug, Default, Clone)]
struct TokenBucket {
    tokens: f32,
    at: Option<Instant>,
}

impl TokenBucket {
    /// Take one token if there is one.
    fn take(&mut self, now: Instant, rate: f32, cap: f32) -> bool {
        let tokens = match self.at {
            None => cap,
            Some(at) => {
                let dt = now.saturating_since(at).as_secs_f32();
                (self.tokens + dt * rate.max(0.0)).min(cap)
            }
        };
        self.at = Some(now);
        if tokens >= 1.0 {
            self.tokens = tokens - 1.0;
            true
        } else {
            self.tokens = tokens;
            false
        }
    }
}

/// A reliable message the host relayed and the targets' links still have to acknowledge.
#[derive(Debug)]
struct Relayed {
    seq: u32,
    /// When it was relayed (a target that never acknowledges is given up on).
    at: Instant,
    /// (target, reliable sequence of the relayed copy on its link).
    waiting: Vec<(PeerId, u16)>,
}

/// The host's check on a message before it relays it.
type FilterFn = dyn FnMut(&ReceivedMessage) -> Result<(), u16> + Send + Sync;

/// Everything the session keeps about application messages.
#[derive(Default)]
pub(crate) struct Messages {
    /// Our last reliable message number.
    last_seq: u32,
    /// Our reliable messages not yet delivered everywhere, in order.
    outbox: VecDeque<AppMessage>,
    /// Our sending rate of reliable messages.
    bucket: TokenBucket,
    /// Our sending rate of unreliable messages.
    unreliable_bucket: TokenBucket,
    /// Per origin: the highest reliable message number delivered to us.
    passed: BTreeMap<PeerId, u32>,
    /// The latest retained message of each kind (and object, for per-object state).
    retained: BTreeMap<(MessageKind, Option<NetId>), AppMessage>,
    /// Host: per origin, relayed reliable messages not yet acknowledged by every target.
    ledger: BTreeMap<PeerId, VecDeque<Relayed>>,
    /// Host: per origin and reliability (true: unreliable), its sending rate.
    buckets: BTreeMap<(PeerId, bool), TokenBucket>,
    filter: Option<Box<FilterFn>>,
}

impl std::fmt::Debug for Messages {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Messages")
            .field("last_seq", &self.last_seq)
            .field("outbox", &self.outbox.len())
            .field("passed", &self.passed)
            .field("retained", &self.retained.len())
            .field("ledger", &self.ledger.len())
            .field("filter", &self.filter.is_some())
            .finish()
    }
}

impl Messages {
    /// An origin is gone (or came back with a fresh session): forget its numbers and what
    /// the host kept for it.
    fn forget(&mut self, p: PeerId) {
        self.passed.remove(&p);
        self.ledger.remove(&p);
        self.buckets.remove(&(p, false));
        self.buckets.remove(&(p, true));
    }
}

impl Session {
    /// Send an application message of type `kind` (an index into the room's message table,
    /// [`crate::policy::MessageConfig::kinds`]; the typed way is [`Session::send`]).
    /// Returns the message's number (0 for an unreliable one): [`Event::MessageDelivered`]
    /// or [`Event::MessageRefused`] later name it.
    ///
    /// A reliable message sent while still joining waits for the welcome. Every refusal is
    /// counted in [`crate::stats::MessageStats::refused`].
    pub fn send_message(
        &mut self,
        now: Instant,
        kind: MessageKind,
        to: MessageTarget,
        delivery: Delivery,
        payload: Vec<u8>,
    ) -> Result<u32, MessageRefusal> {
        let r = self.try_send_message(now, kind, to, delivery, payload);
        if let Err(e) = r {
            *self.stats.messages.refused.entry(e).or_default() += 1;
        }
        r
    }

    fn try_send_message(
        &mut self,
        now: Instant,
        kind: MessageKind,
        to: MessageTarget,
        delivery: Delivery,
        payload: Vec<u8>,
    ) -> Result<u32, MessageRefusal> {
        let cfg = &self.cfg.messages;
        let usable = match self.role {
            Role::Host | Role::Client => true,
            Role::Joining => delivery.is_reliable(),
            Role::Refused => false,
        };
        if !usable {
            return Err(MessageRefusal::NotConnected);
        }
        if usize::from(kind.0) >= cfg.kinds.len() {
            return Err(MessageRefusal::UnknownKind);
        }
        if payload.len() > self.cfg.max_message_payload() {
            return Err(MessageRefusal::TooLarge);
        }
        if delivery.is_retained() && to != MessageTarget::Everyone {
            return Err(MessageRefusal::BadDelivery);
        }
        if to == MessageTarget::Peer(self.local)
            || (to == MessageTarget::Host && self.role == Role::Host)
        {
            return Err(MessageRefusal::NoSuchTarget);
        }
        if let Delivery::ObjectState(id) = delivery {
            if self.objects.get(id).is_none() {
                return Err(MessageRefusal::NoSuchTarget);
            }
        }
        if delivery.is_reliable() && self.messages.outbox.len() >= cfg.max_outbox {
            return Err(MessageRefusal::QueueFull);
        }
        let taken = if delivery.is_reliable() {
            let (rate, cap) = (cfg.rate_per_s, cfg.burst as f32);
            self.messages.bucket.take(now, rate, cap)
        } else {
            let (rate, cap) = (cfg.unreliable_rate_per_s, cfg.unreliable_burst as f32);
            self.messages.unreliable_bucket.take(now, rate, cap)
        };
        if !taken {
            return Err(MessageRefusal::RateLimited);
        }
        let seq = if delivery.is_reliable() {
            self.messages.last_seq = self.messages.last_seq.wrapping_add(1).max(1);
            self.messages.last_seq
        } else {
            0
        };
        let msg = AppMessage {
            origin: self.local,
            seq,
            kind,
            to,
            delivery,
            payload,
        };
        self.stats.messages.sent += 1;
        if delivery.is_reliable() {
            self.messages.outbox.push_back(msg.clone());
        }
        match self.role {
            Role::Host => {
                let me = self.local;
                self.host_relay(now, me, msg);
            }
            Role::Client => {
                if let Some(host) = self.host {
                    if delivery.is_reliable() {
                        self.send_control(now, host, &Control::Message(msg));
                    } else {
                        self.queue_unreliable(host, &msg);
                    }
                }
            }
            // kept in the outbox: sent when welcomed
            Role::Joining | Role::Refused => {}
        }
        Ok(seq)
    }

    /// Install the host's check on every message it relays: `Err(code)` refuses the
    /// message (its sender hears [`MessageRefusal::Filtered`] with the code). Only the host
    /// calls it, but any peer may become the host: install it on every peer.
    pub fn set_message_filter(
        &mut self,
        filter: impl FnMut(&ReceivedMessage) -> Result<(), u16> + Send + Sync + 'static,
    ) {
        self.messages.filter = Some(Box::new(filter));
    }

    /// Our reliable messages not yet delivered to every target.
    pub fn messages_in_flight(&self) -> usize {
        self.messages.outbox.len()
    }

    /// The numbers of our reliable messages not yet delivered everywhere (what is lost if
    /// this session is replaced, e.g. by a fresh one after the room went on without us).
    pub fn undelivered_messages(&self) -> Vec<u32> {
        self.messages.outbox.iter().map(|m| m.seq).collect()
    }

    /// Move the message filter of `old` (a session this one replaces) to this one.
    pub fn take_message_filter_from(&mut self, old: &mut Session) {
        if let Some(f) = old.messages.filter.take() {
            self.messages.filter = Some(f);
        }
    }

    /// The retained messages of the room, one per kind and one per kind and object (what a
    /// late joiner receives).
    pub fn retained_messages(&self) -> impl Iterator<Item = ReceivedMessage> + '_ {
        self.messages
            .retained
            .values()
            .map(|m| ReceivedMessage::from(m.clone()))
    }

    /// The retained messages as the wire has them, to keep the room's state between sessions
    /// ([`Session::restore_retained`] takes them back).
    pub fn retained_for_keeping(&self) -> Vec<AppMessage> {
        self.messages.retained.values().cloned().collect()
    }

    /// An unreliable message for the next datagram to `to` (dropped, and counted, if its
    /// queue is full).
    fn queue_unreliable(&mut self, to: PeerId, msg: &AppMessage) {
        let max = self.cfg.messages.max_unreliable_queue;
        let l = self.links.entry(to).or_default();
        if l.unreliable.len() >= max {
            self.stats.messages.unreliable_dropped += 1;
        } else {
            l.unreliable.push_back(encode_unreliable_message(msg));
        }
    }

    /// Host: the checks on `msg` from `from`, and its targets if it passes.
    fn host_check(
        &mut self,
        now: Instant,
        from: PeerId,
        msg: &AppMessage,
    ) -> Result<Vec<PeerId>, MessageRefusal> {
        if from != self.local {
            // every message of a member counts toward a flood, well-formed or not (twice its
            // rates, seconds in a row: dropped by the caller, `drop_if_flooding`)
            let flood_rate = self.message_flood_rate();
            if let Some(l) = self.links.get_mut(&from) {
                if !l.message_asks.admit(now, flood_rate) {
                    return Err(MessageRefusal::RateLimited);
                }
            }
        }
        let cfg = &self.cfg.messages;
        if msg.origin != from || !msg.valid() {
            return Err(MessageRefusal::Malformed);
        }
        if usize::from(msg.kind.0) >= cfg.kinds.len() {
            return Err(MessageRefusal::UnknownKind);
        }
        if msg.payload.len() > self.cfg.max_message_payload() {
            return Err(MessageRefusal::TooLarge);
        }
        if from != self.local {
            // room above the burst for a whole outbox: what a joiner queued before its
            // welcome, or a member resends to a new host, arrives at once
            let unreliable = !msg.delivery.is_reliable();
            let (rate, cap) = if unreliable {
                (cfg.unreliable_rate_per_s, cfg.unreliable_burst as f32)
            } else {
                (cfg.rate_per_s, cfg.burst as f32 + cfg.max_outbox as f32)
            };
            if !self
                .messages
                .buckets
                .entry((from, unreliable))
                .or_default()
                .take(now, rate, cap)
            {
                return Err(MessageRefusal::RateLimited);
            }
            let waiting = self.messages.ledger.get(&from).map_or(0, VecDeque::len);
            if msg.delivery.is_reliable() && waiting >= cfg.max_outbox.saturating_mul(2) {
                return Err(MessageRefusal::QueueFull);
            }
        }
        if let Delivery::ObjectState(id) = msg.delivery {
            if self.objects.get(id).is_none() {
                return Err(MessageRefusal::NoSuchTarget);
            }
        }
        let me = self.local;
        let targets: Vec<PeerId> = match msg.to {
            // a retained message also goes back to its origin: every member's table then
            // follows the relay order
            MessageTarget::Everyone if msg.delivery.is_retained() => {
                self.members.keys().copied().filter(|p| *p != me).collect()
            }
            MessageTarget::Everyone => self
                .members
                .keys()
                .copied()
                .filter(|p| *p != from)
                .collect(),
            MessageTarget::Peer(p) if p != from && self.members.contains_key(&p) => vec![p],
            MessageTarget::Peer(_) => return Err(MessageRefusal::NoSuchTarget),
            MessageTarget::OwnerOf(id) => match self.objects.owner(id) {
                None => return Err(MessageRefusal::NoSuchTarget),
                Some(o) if o == from => Vec::new(),
                Some(o) => vec![o],
            },
            MessageTarget::Host if from == self.local => return Err(MessageRefusal::NoSuchTarget),
            MessageTarget::Host => vec![self.local],
        };
        if let Some(filter) = self.messages.filter.as_mut() {
            filter(&ReceivedMessage::from(msg.clone())).map_err(MessageRefusal::Filtered)?;
        }
        Ok(targets)
    }

    /// Host: relay `msg` from `from` (a member, or ourselves) to its targets, or refuse it.
    pub(super) fn host_relay(&mut self, now: Instant, from: PeerId, msg: AppMessage) {
        let targets = match self.host_check(now, from, &msg) {
            Ok(t) => t,
            Err(reason) => {
                if from != self.local {
                    *self.stats.messages.refused.entry(reason).or_default() += 1;
                    if reason == MessageRefusal::RateLimited {
                        self.drop_if_flooding(now, from);
                        if !self.members.contains_key(&from) {
                            return; // dropped: told why, nothing more to answer
                        }
                    }
                }
                if msg.delivery.is_reliable() {
                    if from == self.local {
                        self.on_message_refused(msg.seq, reason);
                    } else {
                        let refusal = Control::MessageRefused {
                            seq: msg.seq,
                            reason,
                        };
                        self.send_control(now, from, &refusal);
                    }
                }
                return;
            }
        };
        // the host's own table takes a retained message in relay order; another's is news
        // to the host as to every member (a retained message's targets exclude the host)
        if let Some(key) = msg.retain_key() {
            if from == self.local {
                self.messages.retained.insert(key, msg.clone());
            } else {
                self.deliver_message(msg.clone());
            }
        }
        let mut waiting = Vec::new();
        for t in targets {
            if t == self.local {
                self.deliver_message(msg.clone());
            } else if msg.delivery.is_reliable() {
                if let Some(seq) = self.send_control(now, t, &Control::Message(msg.clone())) {
                    waiting.push((t, seq));
                }
                self.stats.messages.relayed += 1;
            } else {
                self.queue_unreliable(t, &msg);
                self.stats.messages.relayed += 1;
            }
        }
        if msg.delivery.is_reliable() {
            self.messages
                .ledger
                .entry(from)
                .or_default()
                .push_back(Relayed {
                    seq: msg.seq,
                    waiting,
                    at: now,
                });
            self.advance_deliveries(now);
        }
    }

    /// Host: tell each origin how far its messages have reached every target.
    pub(super) fn advance_deliveries(&mut self, now: Instant) {
        if self.role != Role::Host {
            return;
        }
        let mut done: Vec<(PeerId, u32)> = Vec::new();
        let give_up = self.cfg.peer_timeout * 4;
        for (origin, queue) in self.messages.ledger.iter_mut() {
            let mut up_to = None;
            while let Some(front) = queue.front() {
                let complete = front.waiting.iter().all(|(p, seq)| {
                    !self.members.contains_key(p)
                        || self.links.get(p).is_none_or(|l| l.reliable.is_acked(*seq))
                });
                let stale = now.saturating_since(front.at) > give_up;
                if stale && !complete {
                    // a member that stays but never acknowledges must not hold up the room
                    self.stats.messages.unacknowledged += 1;
                }
                if !complete && !stale {
                    break;
                }
                up_to = Some(front.seq);
                queue.pop_front();
            }
            if let Some(u) = up_to {
                done.push((*origin, u));
            }
        }
        self.messages.ledger.retain(|_, q| !q.is_empty());
        for (origin, up_to) in done {
            if origin == self.local {
                self.on_messages_delivered(up_to);
            } else if self.members.contains_key(&origin) {
                self.send_control(now, origin, &Control::MessagesDelivered { up_to });
            }
        }
    }

    /// A message for us (relayed by our host, or one the host is a target of): delivered
    /// unless we had it already.
    pub(super) fn deliver_message(&mut self, msg: AppMessage) {
        if !self.known_kind(&msg) {
            return;
        }
        if msg.origin == self.local {
            // our own retained message back from the host: the table follows the relay order
            if let Some(key) = msg.retain_key() {
                self.messages.retained.insert(key, msg);
            }
            return;
        }
        if msg.delivery.is_reliable() {
            let passed = self.messages.passed.get(&msg.origin).copied();
            if passed.is_some_and(|p| msg.seq <= p) {
                // a resend after a migration: had it. A retained one still sets the state in
                // the relay order (told again only if the state was another meanwhile).
                self.stats.messages.duplicates += 1;
                self.adopt_retained(msg);
                return;
            }
            self.messages.passed.insert(msg.origin, msg.seq);
            if msg.retain_key().is_some() {
                self.adopt_retained(msg);
                return;
            }
        }
        self.stats.messages.received += 1;
        self.events.push_back(Event::Message(msg.into()));
    }

    /// A retained message from a new host's snapshot: it sets the state without moving the
    /// origin's number (its live messages before it may still come, resent).
    pub(super) fn deliver_replay(&mut self, msg: AppMessage) {
        if !self.known_kind(&msg) || msg.retain_key().is_none() {
            return;
        }
        if msg.origin == self.local {
            if let Some(key) = msg.retain_key() {
                self.messages.retained.insert(key, msg);
            }
            return;
        }
        self.adopt_retained(msg);
    }

    /// The room's state for a retained message's key is `msg`: stored, and told unless it
    /// was already that.
    fn adopt_retained(&mut self, msg: AppMessage) {
        let Some(key) = msg.retain_key() else {
            return;
        };
        let same = self
            .messages
            .retained
            .get(&key)
            .is_some_and(|r| r.origin == msg.origin && r.seq == msg.seq);
        if same {
            return;
        }
        self.messages.retained.insert(key, msg.clone());
        self.stats.messages.received += 1;
        self.events.push_back(Event::Message(msg.into()));
    }

    /// A kind in the room's table (one beyond it is counted and dropped).
    fn known_kind(&mut self, msg: &AppMessage) -> bool {
        if usize::from(msg.kind.0) < self.cfg.messages.kinds.len() {
            return true;
        }
        *self
            .stats
            .messages
            .refused
            .entry(MessageRefusal::UnknownKind)
            .or_default() += 1;
        false
    }

    /// Our host: our messages up to `up_to` reached every target.
    pub(super) fn on_messages_delivered(&mut self, up_to: u32) {
        while let Some(front) = self.messages.outbox.front() {
            if front.seq > up_to {
                break;
            }
            let seq = front.seq;
            self.messages.outbox.pop_front();
            self.stats.messages.delivered += 1;
            self.events.push_back(Event::MessageDelivered { seq });
        }
    }

    /// Our host refused our message `seq`.
    pub(super) fn on_message_refused(&mut self, seq: u32, reason: MessageRefusal) {
        let Some(i) = self.messages.outbox.iter().position(|m| m.seq == seq) else {
            return;
        };
        if self.messages.outbox.remove(i).is_none() {
            return;
        }
        *self.stats.messages.refused.entry(reason).or_default() += 1;
        self.events.push_back(Event::MessageRefused { seq, reason });
    }

    /// We have a new host (welcomed, or a migration): every message of ours not yet
    /// delivered everywhere goes to it, in order; if we are the new host, we relay them.
    pub(super) fn resend_outbox(&mut self, now: Instant) {
        let pending: Vec<AppMessage> = self.messages.outbox.iter().cloned().collect();
        match self.role {
            Role::Host => {
                let me = self.local;
                for m in pending {
                    self.host_relay(now, me, m);
                }
            }
            Role::Client => {
                if let Some(host) = self.host {
                    for m in pending {
                        self.send_control(now, host, &Control::Message(m));
                    }
                }
            }
            Role::Joining | Role::Refused => {}
        }
    }

    /// The retained messages, for a joiner's (or after a migration, a member's) snapshot, as
    /// replays (they set the state; they do not count as the origin's live messages).
    pub(super) fn send_retained(&mut self, now: Instant, to: PeerId) {
        let mut all: Vec<AppMessage> = self.messages.retained.values().cloned().collect();
        all.sort_by_key(|m| (m.origin, m.seq));
        for m in all {
            self.send_control(now, to, &Control::Replay(m));
        }
    }

    /// The latest per-object state message of each kind about `id`.
    pub fn object_messages(&self, id: NetId) -> impl Iterator<Item = ReceivedMessage> + '_ {
        self.messages
            .retained
            .iter()
            .filter(move |((_, o), _)| *o == Some(id))
            .map(|(_, m)| ReceivedMessage::from(m.clone()))
    }

    /// An object is gone: its per-object state goes with it.
    pub(super) fn forget_object_messages(&mut self, id: NetId) {
        self.messages.retained.retain(|(_, o), _| *o != Some(id));
    }

    /// A peer left or joined afresh: forget its message numbers.
    pub(super) fn forget_message_origin(&mut self, p: PeerId) {
        self.messages.forget(p);
    }
}

#[cfg(test)]
mod tests;
