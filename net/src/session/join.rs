//! Joining and leaving: a joiner says `Hello` (protocol version and class-table digest) to
//! its contact; the host answers `Welcome` and a snapshot, or a clear refusal; a member that
//! is not the host answers `Redirect` to the host. Members hear of each other through the
//! host (`PeerJoined`, `PeerLeft`); a member leaving on purpose says `Leave`.

use super::{Event, Role, Session};
use crate::ids::{PeerId, Term};
use crate::time::Instant;
use crate::wire::{Control, PROTOCOL_VERSION};

/// Re-welcomes a member may have at once (then one per `PeerBudget::rewelcome_every`).
const REWELCOME_BURST: f32 = 3.0;

impl Session {
    /// Say `Hello` to `contact`.
    pub(super) fn say_hello(&mut self, now: Instant, contact: PeerId) {
        let hello = Control::Hello {
            protocol: PROTOCOL_VERSION,
            config_digest: self.cfg.digest(),
        };
        self.send_control(now, contact, &hello);
    }

    /// A joiner whose contact has not answered (another joiner knows no host yet) asks
    /// `contact` instead, with this same session: its sequences with the peers it asked
    /// before stay in step (a fresh session would restart them, and a peer that saw the first
    /// `Hello` would later take this peer's first reliable message for a duplicate). False,
    /// and nothing sent, unless the session is still joining.
    pub fn join_via(&mut self, now: Instant, contact: PeerId) -> bool {
        if self.role != Role::Joining || contact == self.local {
            return false;
        }
        self.host = Some(contact);
        self.clock.follow();
        self.say_hello(now, contact);
        true
    }

    /// Leave the room: tell every member (and the host) that we are gone, so that they act
    /// at once instead of after `peer_timeout`. Send what `poll_transmit` gives afterwards;
    /// the session is not meant to be used after that.
    pub fn leave(&mut self, now: Instant) {
        for p in self.others() {
            self.send_control(now, p, &Control::Leave);
        }
    }

    /// `Hello` from `from`: the host welcomes it (or refuses: another protocol or class
    /// table, a full room); a member redirects it to the host; a joiner cannot answer.
    pub(super) fn on_hello(&mut self, now: Instant, from: PeerId, protocol: u8, digest: u64) {
        if self.role != Role::Host {
            if let Some(host) = self.host {
                if self.is_connected() {
                    self.send_control(now, from, &Control::Redirect { host });
                }
            }
            return;
        }
        if let Some(&join_seq) = self.members.get(&from) {
            // A member says Hello again: it never took our Welcome (it had turned to another
            // contact when the Welcome came, and a joiner takes a Welcome only from the peer
            // it asks now), and it will not stop asking. Welcome it again (the reliable
            // layer will not resend what it acked). Found by the churn soak: a peer stopped
            // past the timeout rejoined, asked a member, and waited for ever.
            // Bounded, since each costs a snapshot: never while a Welcome to it is in flight
            // (that one arrives by itself), and a burst of `REWELCOME_BURST` at most, then
            // one per `rewelcome_every`.
            // More than `MAX_HELLOS_PER_S` a second is ignored at once; twice that for
            // `REQUEST_FLOOD_STRIKES` seconds is a flood, and the member is dropped.
            let admitted = self
                .links
                .get_mut(&from)
                .is_some_and(|l| l.hello_asks.admit(now, super::link::MAX_HELLOS_PER_S));
            if !admitted {
                self.stats.repeated_hellos_ignored += 1;
                self.drop_if_flooding(now, from);
                return;
            }
            if protocol == PROTOCOL_VERSION && digest == self.cfg.digest() {
                let every = self.cfg.peer_budget.rewelcome_every.as_secs_f32().max(1e-3);
                let allowed = self.links.get_mut(&from).is_some_and(|l| {
                    if l.welcomed.is_some_and(|seq| !l.reliable.is_acked(seq)) {
                        return false;
                    }
                    let (debt, at) = l.rewelcome_debt;
                    let paid = at.map_or(0.0, |t| now.saturating_since(t).as_secs_f32() / every);
                    let debt = (debt - paid).max(0.0);
                    if debt + 1.0 > REWELCOME_BURST {
                        l.rewelcome_debt = (debt, Some(now));
                        return false;
                    }
                    l.rewelcome_debt = (debt + 1.0, Some(now));
                    true
                });
                if allowed {
                    self.welcome(now, from, join_seq);
                } else {
                    self.stats.repeated_hellos_ignored += 1;
                }
            }
            return;
        }
        let refusal = if protocol != PROTOCOL_VERSION {
            Some(format!(
                "protocol version mismatch: host speaks {PROTOCOL_VERSION}, you speak {protocol}"
            ))
        } else if digest != self.cfg.digest() {
            Some(format!(
                "room configuration differs from the host's (another scene, other replication \
                 settings, or other message types; the host's message types: {})",
                self.cfg.messages.kinds.join(", ")
            ))
        } else if self.members.len() >= self.cfg.max_members {
            Some(format!(
                "the room is full ({} members)",
                self.cfg.max_members
            ))
        } else {
            None
        };
        if let Some(reason) = refusal {
            self.send_control(now, from, &Control::refused(reason));
            return;
        }
        if self.challenge(now, from) {
            return; // a room with a key: admitted once it proves it holds the key
        }
        self.admit(now, from);
    }

    /// Host: `from` is a member now: `Welcome`, the snapshot and the retained messages to
    /// it, `PeerJoined` to the others.
    pub(super) fn admit(&mut self, now: Instant, from: PeerId) {
        if self.members.contains_key(&from) {
            return;
        }
        if self.members.len() >= self.cfg.max_members {
            // it filled up while this joiner proved its key
            let reason = format!("the room is full ({} members)", self.cfg.max_members);
            self.send_control(now, from, &Control::refused(reason));
            return;
        }
        let join_seq = self.next_join_seq;
        self.next_join_seq = self.next_join_seq.saturating_add(1);
        self.members.insert(from, join_seq);
        self.forget_message_origin(from);
        self.welcome(now, from, join_seq);
        self.broadcast(
            now,
            &Control::PeerJoined {
                peer: from,
                join_seq,
            },
            Some(from),
        );
        self.events.push_back(Event::PeerJoined(from));
    }

    /// Host: `Welcome`, the snapshot, the retained messages and the used tokens to member
    /// `to`.
    fn welcome(&mut self, now: Instant, to: PeerId, join_seq: u32) {
        let members: Vec<(PeerId, u32)> = self.members.iter().map(|(p, s)| (*p, *s)).collect();
        let welcome = Control::Welcome {
            term: self.term,
            host: self.local,
            join_seq,
            members,
        };
        let seq = self.send_control(now, to, &welcome);
        if let Some(l) = self.links.get_mut(&to) {
            l.welcomed = seq;
        }
        self.send_snapshot(now, to);
        self.send_retained(now, to);
        self.send_tokens_used(now, to);
        self.send_bans(now, to);
    }

    /// The host welcomed us.
    pub(super) fn on_welcome(
        &mut self,
        now: Instant,
        term: Term,
        host: PeerId,
        members: Vec<(PeerId, u32)>,
    ) {
        self.role = Role::Client;
        self.term = term;
        if self.host != Some(host) {
            self.clock.follow();
        }
        self.host = Some(host);
        self.members = members.into_iter().collect();
        self.events.push_back(Event::Joined { host, term });
        // reliable messages sent while joining
        self.resend_outbox(now);
    }

    /// The host refused us while joining.
    pub(super) fn on_refused(&mut self, reason: String) {
        self.role = Role::Refused;
        self.events.push_back(Event::Refused { reason });
    }

    /// Our host says `peer` joined.
    pub(super) fn on_peer_joined(&mut self, peer: PeerId, join_seq: u32) {
        self.members.insert(peer, join_seq);
        self.forget_message_origin(peer);
        self.links.entry(peer).or_default();
        self.events.push_back(Event::PeerJoined(peer));
    }

    /// Our host says `peer` left or timed out.
    pub(super) fn on_peer_left(&mut self, peer: PeerId) {
        self.heal_remember_members();
        self.members.remove(&peer);
        self.forget_message_origin(peer);
        // Its sequences die with its membership: should it join again, it does so with a
        // fresh session, and both ends start over.
        self.links.remove(&peer);
        self.stats.links.remove(&peer);
        self.events.push_back(Event::PeerLeft(peer));
    }

    /// A member (or our host) says it leaves: gone now, not after the timeout. The host
    /// drops the member (authority returns); if the host left, the earliest joiner takes
    /// over.
    pub(super) fn on_leave(&mut self, now: Instant, from: PeerId) {
        self.departed.insert(from);
        if let Some(l) = self.links.get_mut(&from) {
            l.last_heard = None;
        }
        self.check_liveness(now);
    }

    /// Host: member `p` is gone (timed out or left): drop it, tell the others, take its
    /// objects back.
    pub(super) fn host_peer_left(&mut self, now: Instant, p: PeerId) {
        self.heal_remember_members();
        self.members.remove(&p);
        self.links.remove(&p);
        // and its statistics (kept for every member ever dropped, the fuzzer found)
        self.stats.links.remove(&p);
        self.events.push_back(Event::PeerLeft(p));
        self.broadcast(now, &Control::PeerLeft { peer: p }, None);
        // authority returns to the host
        let me = self.local;
        for id in self.objects.owned_by(p) {
            self.host_grant(now, id, me, false);
        }
        self.forget_asks_of(p);
        self.forget_message_origin(p);
        self.advance_deliveries(now);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::super::testkit::{config, Wire};
    use super::*;

    /// Deliver everything `from` has for `to` (time `now`), after its due timers.
    fn deliver(now: Instant, from: &mut Session, to: &mut Session) {
        if from.poll_timeout().is_some_and(|t| t <= now) {
            from.handle_timeout(now);
        }
        while let Some(t) = from.poll_transmit(now) {
            if t.to == to.local_id() {
                to.handle_packet(now, from.local_id(), &t.payload);
            }
        }
    }

    #[test]
    fn a_stale_datagram_of_the_old_session_before_the_fresh_hello_is_harmless() {
        let mut now = Instant::ZERO;
        let mut host = Session::host(PeerId(1), config(), now);
        let mut old = Session::join(PeerId(2), PeerId(1), config(), now);
        let step = std::time::Duration::from_millis(20);
        for _ in 0..20 {
            deliver(now, &mut old, &mut host);
            deliver(now, &mut host, &mut old);
            now += step;
        }
        assert!(old.is_connected());
        // many reliable messages to the member: its acks name a high number
        for k in 0..40 {
            let st = crate::ObjectState::rigid(
                glam::Vec3::new(k as f32 * 0.01, 1.0, 0.0),
                glam::Quat::IDENTITY,
            );
            host.spawn(now, crate::ClassId(0), st).unwrap();
        }
        for _ in 0..40 {
            deliver(now, &mut host, &mut old);
            deliver(now, &mut old, &mut host);
            now += step;
        }
        // one more reliable message; the member stalls with its ack (of 41) still on its way
        let st = crate::ObjectState::rigid(glam::Vec3::ONE, glam::Quat::IDENTITY);
        host.spawn(now, crate::ClassId(0), st).unwrap();
        deliver(now, &mut host, &mut old);
        now += step;
        let stale: Vec<Vec<u8>> = std::iter::from_fn(|| old.poll_transmit(now))
            .filter(|t| t.to == PeerId(1))
            .map(|t| t.payload)
            .collect();
        assert!(!stale.is_empty());
        // the host runs on and drops it
        for _ in 0..75 {
            now += step;
            if host.poll_timeout().is_some_and(|t| t <= now) {
                host.handle_timeout(now);
            }
            while host.poll_transmit(now).is_some() {}
        }
        assert!(!host.members().contains_key(&PeerId(2)));
        // the old session's datagram arrives (answered with the drop notice), then the fresh
        // session's Hello: the order `Peer`'s REJOIN_QUIET keeps (arriving after the Hello, an
        // old datagram of the same term passes for the new member's, and its ack can name the
        // fresh Welcome's numbers: known, not fixed without a session number in the header)
        for d in &stale {
            host.handle_packet(now, PeerId(2), d);
        }
        let mut fresh = Session::join(PeerId(2), PeerId(1), config(), now);
        deliver(now, &mut fresh, &mut host);
        for _ in 0..100 {
            deliver(now, &mut host, &mut fresh);
            deliver(now, &mut fresh, &mut host);
            now += step;
        }
        assert!(fresh.is_connected(), "the rejoiner never took the Welcome");
        assert_eq!(host.members().len(), 2);
    }

    #[test]
    fn a_joiner_that_turned_away_before_the_welcome_came_is_welcomed_again() {
        let mut w = Wire::new();
        w.add(Session::host(PeerId(1), config(), w.now));
        w.add(Session::join(PeerId(3), PeerId(1), config(), w.now));
        w.settle();
        assert!(w.get(3).is_connected());
        w.add(Session::join(PeerId(2), PeerId(1), config(), w.now));
        let now = w.now;
        // the joiner's Hello reaches the host, which admits it ...
        while let Some(t) = w.get(2).poll_transmit(now) {
            if t.to == PeerId(1) {
                w.get(1).handle_packet(now, PeerId(2), &t.payload);
            }
        }
        assert!(w.get(1).members().contains_key(&PeerId(2)));
        // ... but before the Welcome arrives the joiner asks another member (its join
        // retry), and drops the host's Welcome: not from the peer it asks now
        assert!(w.get(2).join_via(now, PeerId(3)));
        w.settle();
        // the member redirects it to the host, whose second Welcome it takes
        assert!(w.get(2).is_connected(), "still joining");
        assert_eq!(w.get(2).host_id(), Some(PeerId(1)));
        assert!(w.get(2).members().contains_key(&PeerId(3)));
    }

    #[test]
    fn the_host_welcomes_a_joiner_and_a_member_redirects_the_next_one_to_the_host() {
        let mut w = Wire::new();
        w.add(Session::host(PeerId(1), config(), w.now));
        w.add(Session::join(PeerId(2), PeerId(1), config(), w.now));
        w.settle();
        assert!(w.events(2).contains(&Event::Joined {
            host: PeerId(1),
            term: Term(1)
        }));
        // the third asks the member, which answers Redirect; it follows to the host
        w.add(Session::join(PeerId(3), PeerId(2), config(), w.now));
        w.settle();
        assert!(w.get(3).is_connected());
        assert_eq!(w.get(3).host_id(), Some(PeerId(1)));
        assert_eq!(w.get(1).members().len(), 3);
        assert!(w.events(2).contains(&Event::PeerJoined(PeerId(3))));
    }

    #[test]
    fn another_class_table_or_a_full_room_is_refused_with_a_reason() {
        let mut w = Wire::new();
        let mut small = config();
        small.max_members = 2;
        w.add(Session::host(PeerId(1), small.clone(), w.now));
        let mut other = small.clone();
        other.classes.pop();
        w.add(Session::join(PeerId(2), PeerId(1), other, w.now));
        w.add(Session::join(PeerId(3), PeerId(1), small.clone(), w.now));
        w.settle();
        assert!(
            matches!(&w.events(2)[..], [Event::Refused { reason }] if reason.contains("configuration"))
        );
        w.add(Session::join(PeerId(4), PeerId(1), small, w.now));
        w.settle();
        assert!(matches!(&w.events(4)[..], [Event::Refused { reason }] if reason.contains("full")));
        assert!(!w.get(4).is_connected());
    }

    #[test]
    fn a_member_that_leaves_is_gone_for_everyone_at_once() {
        let mut w = Wire::new();
        w.add(Session::host(PeerId(1), config(), w.now));
        for p in [2, 3] {
            w.add(Session::join(PeerId(p), PeerId(1), config(), w.now));
            w.settle();
        }
        let now = w.now;
        w.get(3).leave(now);
        w.settle();
        assert!(!w.get(1).members().contains_key(&PeerId(3)));
        assert!(w.events(2).contains(&Event::PeerLeft(PeerId(3))));
    }
}
