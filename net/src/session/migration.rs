//! Host migration: when the host goes silent, the surviving member that joined earliest
//! takes over ([`heir`]; deterministic, no vote), bumps the term, adopts its replica, takes
//! the objects of the dead, and tells the others (`NewHost` + snapshot); members follow a
//! `NewHost` only from the heir they expect, and tell the new host what they own (`Resync`),
//! which it believes within a window and within what a claimant can know.

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use super::spawn::spawn_request;
use super::{Event, Role, Session, LOST_ID_WINDOW, MAX_TERM_JUMP};
use crate::ids::{NetId, PeerId, Term};
use crate::time::Instant;
use crate::wire::{Control, SpawnInfo};

/// Control messages kept after a `NewHost` not adopted yet (more drop the `NewHost`).
const MAX_DEFERRED_CONTROLS: usize = 4096;

/// The member that takes over from `host`: the earliest joiner among the others that are
/// alive.
pub(crate) fn heir(
    members: &BTreeMap<PeerId, u32>,
    host: PeerId,
    alive: impl Fn(PeerId) -> bool,
) -> Option<PeerId> {
    members
        .iter()
        .filter(|(p, _)| **p != host && alive(**p))
        .min_by_key(|(_, seq)| **seq)
        .map(|(p, _)| *p)
}

/// A `NewHost` kept for later, with the control messages its sender sent after it (the
/// snapshot, ownership changes), replayed once it is adopted.
#[derive(Debug)]
struct PendingNewHost {
    at: Instant,
    term: Term,
    members: Vec<(PeerId, u32)>,
    later: Vec<Control>,
}

/// What [`Succession::defer`] did with a control message.
#[derive(Debug)]
pub(crate) enum Deferred {
    /// Its sender has no `NewHost` waiting (or it is one): handle it now.
    NotPending(Control),
    /// Kept for after the sender's `NewHost`.
    Kept,
    /// Too many kept: the sender's `NewHost` is dropped.
    Overflow,
}

/// Migration state: `NewHost` messages not acceptable yet, and, after we took over, until
/// when members' claims are believed.
#[derive(Debug, Default)]
pub(crate) struct Succession {
    pending: BTreeMap<PeerId, PendingNewHost>,
    resync_until: Option<Instant>,
    /// After we followed a new host: the replicas (not ours) its snapshot has not named yet.
    unconfirmed: BTreeSet<NetId>,
}

impl Succession {
    /// Keep `c` for later if its sender has a `NewHost` waiting.
    pub fn defer(&mut self, from: PeerId, c: Control) -> Deferred {
        if matches!(c, Control::NewHost { .. }) {
            return Deferred::NotPending(c);
        }
        let Some(p) = self.pending.get_mut(&from) else {
            return Deferred::NotPending(c);
        };
        if p.later.len() < MAX_DEFERRED_CONTROLS {
            p.later.push(c);
            Deferred::Kept
        } else {
            self.pending.remove(&from);
            Deferred::Overflow
        }
    }

    /// Keep (or replace) `from`'s `NewHost`, with what was kept after its earlier one.
    fn keep(&mut self, from: PeerId, now: Instant, term: Term, members: Vec<(PeerId, u32)>) {
        let later = self.take_later(from);
        self.pending.insert(
            from,
            PendingNewHost {
                at: now,
                term,
                members,
                later,
            },
        );
    }

    /// Drop `from`'s waiting `NewHost`; what was kept after it.
    fn take_later(&mut self, from: PeerId) -> Vec<Control> {
        self.pending
            .remove(&from)
            .map(|p| p.later)
            .unwrap_or_default()
    }

    /// Forget `NewHost`s older than `keep_for`; then the first for a term at least `term`
    /// (ours: a rival's takeover of our host's room) whose sender `acceptable` says may take
    /// over.
    fn ready(
        &mut self,
        now: Instant,
        keep_for: Duration,
        term: Term,
        acceptable: impl Fn(PeerId) -> bool,
    ) -> Option<(PeerId, PendingNewHost)> {
        self.pending.retain(|_, p| now < p.at + keep_for);
        let from = self
            .pending
            .iter()
            .find(|(p, n)| n.term >= term && acceptable(**p))
            .map(|(p, _)| *p)?;
        self.pending.remove(&from).map(|p| (from, p))
    }

    /// Note that a new host's snapshot named `id`; whether it was waiting to be named.
    pub fn confirm(&mut self, id: NetId) -> bool {
        self.unconfirmed.remove(&id)
    }

    /// The replicas the new host's snapshot did not name, once it is whole (emptied).
    pub fn unconfirmed(&mut self) -> Vec<NetId> {
        std::mem::take(&mut self.unconfirmed).into_iter().collect()
    }

    /// Believe members' claims until `until` (we just took over).
    fn open_resync(&mut self, until: Instant) {
        self.resync_until = Some(until);
    }

    /// Are claims believed at `now`?
    pub fn resync_open(&self, now: Instant) -> bool {
        self.resync_until.is_some_and(|t| now < t)
    }
}

impl Session {
    /// Our host is silent and we are its heir: take over. The term goes up; members found
    /// dead go; ids the old host may have used unseen are reserved for claims; the objects of
    /// peers no longer members become ours (epochs bumped into our term); every member gets
    /// `NewHost` and a snapshot; our own unanswered spawn requests are served.
    pub(super) fn become_host(&mut self, now: Instant, old_host: PeerId) {
        let Some(next_term) = self.term.0.checked_add(1) else {
            return; // the term space is used up: nobody can take over
        };
        self.term = Term(next_term);
        self.role = Role::Host;
        self.host = Some(self.local);
        self.clock.host();
        let term = self.term;
        let dead: Vec<PeerId> = self
            .members
            .keys()
            .copied()
            .filter(|p| *p == old_host || !self.alive(*p, now))
            .collect();
        self.heal_remember_members();
        for p in &dead {
            self.members.remove(p);
            self.forget_message_origin(*p);
            if let Some(l) = self.links.get_mut(p) {
                l.pending.clear();
            }
        }
        self.next_join_seq = self
            .members
            .values()
            .max()
            .map_or(1, |m| m.saturating_add(1));
        self.objects.reserve_lost_ids(LOST_ID_WINDOW);
        self.succession.open_resync(now + self.cfg.peer_timeout * 2);
        self.succession.unconfirmed.clear();
        // a host follows no `NewHost`: what was kept for one goes
        self.succession.pending.clear();
        // peers told of an older term while we were a client may have joined since: as
        // host we judge them afresh
        self.dropped.clear();
        let me = self.local;
        let mut changed = Vec::new();
        for o in self.objects.iter_mut() {
            if !self.members.contains_key(&o.info.owner) {
                o.info.owner = me;
                o.info.epoch = o.info.epoch.bumped(term);
                o.info.held = false;
                changed.push((o.info.id, o.info.epoch));
            }
        }
        for (id, epoch) in changed {
            self.adopt_replica(id);
            self.events.push_back(Event::AuthorityChanged {
                id,
                owner: me,
                epoch,
            });
        }
        let members: Vec<(PeerId, u32)> = self.members.iter().map(|(p, s)| (*p, *s)).collect();
        let others: Vec<PeerId> = self.members.keys().copied().filter(|p| *p != me).collect();
        for p in others {
            if let Some(l) = self.links.get_mut(&p) {
                l.send.clear();
                l.spawn_pending.clear();
            }
            self.send_control(
                now,
                p,
                &Control::NewHost {
                    term,
                    host: me,
                    members: members.clone(),
                },
            );
            self.send_snapshot(now, p);
        }
        self.events.push_back(Event::HostChanged { host: me, term });
        // our messages the old host had not delivered everywhere: we relay them now, then
        // the room's retained state as we know it (which includes them)
        self.resend_outbox(now);
        let others: Vec<PeerId> = self.members.keys().copied().filter(|p| *p != me).collect();
        for p in others {
            self.send_retained(now, p);
        }
        // our own spawn requests the old host never answered: we create them now
        for (request, class, st) in self.spawns.take_all() {
            let _ = self.host_spawn_own(now, class, &st, request);
        }
        for p in dead {
            if p != me {
                self.events.push_back(Event::PeerLeft(p));
            }
        }
    }

    /// A `NewHost` from `from`: adopted only from the peer that should take over (the
    /// lowest-join-order member we believe alive, our host aside), once our host is silent or
    /// about to be, and for a term at most [`MAX_TERM_JUMP`] ahead. One that is not
    /// acceptable yet is kept (per sender) and looked at again as time passes.
    pub(super) fn on_new_host(
        &mut self,
        now: Instant,
        from: PeerId,
        term: Term,
        members: Vec<(PeerId, u32)>,
    ) {
        // The same term as ours is a rival's: two members took over the same host's room, each
        // deaf to the other, and ours is dead too (only the heir we expect is followed, and
        // only once our host is silent).
        let ahead = term.0.saturating_sub(self.term.0);
        if term < self.term || ahead > MAX_TERM_JUMP || !self.members.contains_key(&from) {
            self.stats.refused_controls += 1;
            return;
        }
        if self.new_host_acceptable(now, from) {
            let later = self.succession.take_later(from);
            self.adopt_new_host(now, from, term, members);
            for c in later {
                self.handle_control(now, from, c);
            }
        } else {
            self.succession.keep(from, now, term, members);
        }
    }

    /// Is `from` the peer that takes over from our (silent) host?
    fn new_host_acceptable(&self, now: Instant, from: PeerId) -> bool {
        let Some(host) = self.host else {
            return false;
        };
        if from == host || self.role != Role::Client {
            return false;
        }
        // our host is silent, or will be within a heartbeat (timeouts differ a little)
        let host_failing = !self.alive(host, now + self.cfg.heartbeat_interval);
        host_failing && heir(&self.members, host, |p| self.alive(p, now)) == Some(from)
    }

    /// Looks again at `NewHost` messages kept for later; true if one was adopted.
    pub(super) fn retry_new_hosts(&mut self, now: Instant) -> bool {
        let keep_for = self.cfg.peer_timeout * 3;
        let term = self.term;
        // the check reads the session while the succession is borrowed: take it out
        let mut succession = std::mem::take(&mut self.succession);
        let ready = succession.ready(now, keep_for, term, |p| self.new_host_acceptable(now, p));
        self.succession = succession;
        let Some((from, p)) = ready else {
            return false;
        };
        self.adopt_new_host(now, from, p.term, p.members);
        for c in p.later {
            self.handle_control(now, from, c);
        }
        true
    }

    /// Follow `host` of `term`: new members, links of peers gone dropped, every replication
    /// chain restarted; tell it what we own (`Resync`) and repeat our unanswered spawn
    /// requests to it (it answers one it already has with the existing object).
    fn adopt_new_host(
        &mut self,
        now: Instant,
        host: PeerId,
        term: Term,
        members: Vec<(PeerId, u32)>,
    ) {
        self.term = term;
        self.host = Some(host);
        self.clock.follow();
        self.role = Role::Client;
        self.heal_remember_members();
        self.members = members.into_iter().collect();
        self.succession.pending.clear();
        // Peers the new room does not have (the old host, members it found dead) lose their
        // link state: should one come back, it joins with a fresh session, and both ends
        // start their sequences over.
        let gone: Vec<PeerId> = self
            .links
            .keys()
            .copied()
            .filter(|p| !self.members.contains_key(p) && *p != host)
            .collect();
        for p in gone {
            self.links.remove(&p);
            self.stats.links.remove(&p);
            self.forget_message_origin(p);
        }
        for l in self.links.values_mut() {
            l.reset_replication();
        }
        // the replicas we may not claim wait for the new host's snapshot to name them: those we
        // do not own, and those a rival host of the new host's term granted us (claims are
        // of older terms only: every grant of its term is the new host's)
        let local = self.local;
        self.succession.unconfirmed = self
            .objects
            .iter()
            .filter(|o| !o.claimable(local, term))
            .map(|o| o.info.id)
            .collect();
        // tell the new host what we own, so an in-flight handoff is not lost
        let claims: Vec<SpawnInfo> = self
            .objects
            .iter()
            .filter(|o| o.claimable(local, term))
            .map(|o| o.info.clone())
            .collect();
        for chunk in claims.chunks(16) {
            self.send_control(
                now,
                host,
                &Control::Resync {
                    claims: chunk.to_vec(),
                },
            );
        }
        let requests: Vec<Control> = self
            .spawns
            .iter()
            .map(|(request, class, st)| spawn_request(request, class, &st))
            .collect();
        for msg in requests {
            self.send_control(now, host, &msg);
        }
        // our messages the old host had not delivered everywhere, in order
        self.resend_outbox(now);
        self.events.push_back(Event::HostChanged { host, term });
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn members(list: &[(u64, u32)]) -> BTreeMap<PeerId, u32> {
        list.iter().map(|(p, s)| (PeerId(*p), *s)).collect()
    }

    #[test]
    fn the_heir_is_the_earliest_live_joiner_other_than_the_host() {
        let m = members(&[(10, 0), (11, 3), (12, 1), (13, 2)]);
        assert_eq!(heir(&m, PeerId(10), |_| true), Some(PeerId(12)));
        assert_eq!(
            heir(&m, PeerId(10), |p| p != PeerId(12)),
            Some(PeerId(13)),
            "the earliest is dead too"
        );
        assert_eq!(heir(&m, PeerId(10), |_| false), None);
        assert_eq!(heir(&members(&[(10, 0)]), PeerId(10), |_| true), None);
    }

    #[test]
    fn controls_after_a_waiting_new_host_are_kept_for_it_and_bounded() {
        let mut s = Succession::default();
        let (a, b) = (PeerId(1), PeerId(2));
        assert!(matches!(
            s.defer(a, Control::Leave),
            Deferred::NotPending(_)
        ));
        s.keep(a, Instant::ZERO, Term(3), vec![]);
        assert!(matches!(s.defer(a, Control::Leave), Deferred::Kept));
        assert!(matches!(
            s.defer(b, Control::Leave),
            Deferred::NotPending(_)
        ));
        let nh = Control::NewHost {
            term: Term(4),
            host: a,
            members: vec![],
        };
        assert!(matches!(s.defer(a, nh), Deferred::NotPending(_)));
        // a newer NewHost from the same sender keeps what came after the first
        s.keep(a, Instant::ZERO, Term(4), vec![]);
        assert_eq!(s.take_later(a), vec![Control::Leave]);
        s.keep(a, Instant::ZERO, Term(4), vec![]);
        for _ in 0..MAX_DEFERRED_CONTROLS {
            assert!(matches!(s.defer(a, Control::Leave), Deferred::Kept));
        }
        assert!(matches!(s.defer(a, Control::Leave), Deferred::Overflow));
        assert!(s.pending.is_empty(), "the NewHost is dropped");
    }

    #[test]
    fn waiting_new_hosts_expire_and_only_a_term_as_new_as_ours_from_an_acceptable_peer_is_ready() {
        let mut s = Succession::default();
        let t0 = Instant::from_millis(1000);
        let keep = Duration::from_secs(3);
        s.keep(PeerId(1), t0, Term(2), vec![]);
        s.keep(PeerId(2), t0, Term(3), vec![]);
        assert!(s.ready(t0, keep, Term(4), |_| true).is_none(), "older");
        assert!(
            s.ready(t0, keep, Term(1), |_| false).is_none(),
            "not acceptable"
        );
        let (from, p) = s.ready(t0, keep, Term(1), |p| p == PeerId(2)).unwrap();
        assert_eq!((from, p.term), (PeerId(2), Term(3)));
        assert!(
            s.ready(t0 + keep, keep, Term(1), |_| true).is_none(),
            "expired"
        );
        assert!(s.pending.is_empty());
    }

    #[test]
    fn claims_are_believed_only_within_the_window_after_a_takeover() {
        let mut s = Succession::default();
        assert!(!s.resync_open(Instant::ZERO));
        s.open_resync(Instant::from_millis(2000));
        assert!(s.resync_open(Instant::from_millis(1999)));
        assert!(!s.resync_open(Instant::from_millis(2000)));
    }
}
