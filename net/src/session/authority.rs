//! Who owns what (thesis 5.1, limitation 6.3): every object has exactly one owner; authority
//! moves on request, granted or denied by the host by policy ([`decide_request`]), comes
//! back on release and when the owner leaves; each grant bumps the object's epoch. After a
//! migration, members' claims are judged by what a claimant can know ([`judge_claim`]).

use std::collections::{BTreeMap, BTreeSet};

use super::{Event, Role, Session};
use crate::error::NetError;
use crate::ids::{AuthorityEpoch, NetId, PeerId};
use crate::policy::AuthorityPolicy;
use crate::time::Instant;
use crate::wire::{Control, DenyReason, SpawnInfo};

/// Asks in flight under [`AuthorityPolicy::OwnerMustAgree`]: who asked for which object.
#[derive(Debug, Default)]
pub(crate) struct PendingAsks {
    asks: BTreeMap<NetId, BTreeSet<PeerId>>,
}

impl PendingAsks {
    /// `by` asks for `id`; false if it already had.
    fn ask(&mut self, id: NetId, by: PeerId) -> bool {
        self.asks.entry(id).or_default().insert(by)
    }

    /// The owner answered `by`'s ask for `id`; false if there was none.
    fn answer(&mut self, id: NetId, by: PeerId) -> bool {
        let answered = self.asks.get_mut(&id).is_some_and(|s| s.remove(&by));
        if self.asks.get(&id).is_some_and(BTreeSet::is_empty) {
            self.asks.remove(&id);
        }
        answered
    }

    /// `id` was granted or despawned: its other asks are moot.
    pub(super) fn clear(&mut self, id: NetId) {
        self.asks.remove(&id);
    }

    /// `p` left: its asks go.
    fn forget_peer(&mut self, p: PeerId) {
        for asks in self.asks.values_mut() {
            asks.remove(&p);
        }
        self.asks.retain(|_, a| !a.is_empty());
    }
}

/// The host's answer to an authority request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Decision {
    /// Grant it (the requester holds it).
    Grant,
    /// Refuse, saying why.
    Deny(DenyReason),
    /// Ask the owner, which must agree.
    AskOwner(PeerId),
}

/// The host's rule for `from` asking for an object `owner` owns (`held`: someone holds it).
pub(crate) fn decide_request(
    from: PeerId,
    owner: PeerId,
    held: bool,
    policy: AuthorityPolicy,
) -> Decision {
    if owner == from {
        return Decision::Grant;
    }
    match policy {
        AuthorityPolicy::Locked => Decision::Deny(DenyReason::Locked),
        AuthorityPolicy::Free if held => Decision::Deny(DenyReason::Held(owner)),
        AuthorityPolicy::OwnerMustAgree if held => Decision::AskOwner(owner),
        _ => Decision::Grant,
    }
}

/// What the object's record says, for judging a claim.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Record {
    pub owner: PeerId,
    pub epoch: AuthorityEpoch,
    pub policy: AuthorityPolicy,
    /// Someone holds it, as far as the record says.
    pub held: bool,
    /// The claim names the same object (class and particle count agree).
    pub same_object: bool,
}

/// The new host's verdict on a member's claim to own a known object.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ClaimVerdict {
    /// Our record is as new or newer: nothing to change (the claimant may need telling).
    Stale,
    /// The claimant heard of a grant we missed: it is the owner.
    Believe,
    /// Implausible: an epoch or object the claimant cannot know.
    Refuse,
}

/// A claim of `claim_epoch` on an object recorded as `rec`: believed only if it is at most
/// one grant ahead of our record (the first of a later term, or the next one) and it is a
/// grant the host would have made on that record ([`decide_request`]): never of an object
/// locked to someone else, nor of one the record says someone holds (a `Free` one is denied,
/// an `OwnerMustAgree` one needs its owner's word, which a claim does not carry). A claim
/// may not do what a request may not: a member that invents the next grant of a held body
/// during a migration's claim window is refused. (The price: a grant of a held
/// `OwnerMustAgree` body that the old host made and the new one missed is undone — its
/// owner gets it back.)
pub(crate) fn judge_claim(from: PeerId, claim_epoch: AuthorityEpoch, rec: Record) -> ClaimVerdict {
    if claim_epoch <= rec.epoch && rec.same_object {
        return ClaimVerdict::Stale;
    }
    let next = if claim_epoch.term == rec.epoch.term {
        claim_epoch.grant <= rec.epoch.grant.saturating_add(1)
    } else {
        claim_epoch.grant == 0
    };
    let grantable = rec.owner == from
        || decide_request(from, rec.owner, rec.held, rec.policy) == Decision::Grant;
    let plausible = rec.same_object && next && grantable;
    if plausible {
        ClaimVerdict::Believe
    } else {
        ClaimVerdict::Refuse
    }
}

impl Session {
    /// Ask for authority over an object (grab). The answer is an event.
    pub fn request_authority(&mut self, now: Instant, id: NetId) -> Result<(), NetError> {
        if !self.objects.contains(id) {
            return Err(NetError::UnknownObject(id));
        }
        self.ask_host(now, Control::AuthorityRequest { id })
    }

    /// Give authority back to the host (release).
    pub fn release_authority(&mut self, now: Instant, id: NetId) -> Result<(), NetError> {
        let owner = self.owner(id).ok_or(NetError::UnknownObject(id))?;
        if owner != self.local {
            return Err(NetError::NotOwner(id, owner));
        }
        self.ask_host(now, Control::AuthorityRelease { id })
    }

    /// Answer an [`Event::AuthorityAsked`].
    pub fn answer_authority(&mut self, now: Instant, id: NetId, by: PeerId, agree: bool) {
        // not in a room: there is nobody to answer
        let _ = self.ask_host(now, Control::AuthorityAnswer { id, by, agree });
    }

    /// Our host denied our request.
    pub(super) fn on_denied(&mut self, id: NetId, reason: DenyReason) {
        self.events.push_back(Event::AuthorityDenied { id, reason });
    }

    /// Our host asks whether `by` may have our object.
    pub(super) fn on_asked(&mut self, id: NetId, by: PeerId) {
        self.events.push_back(Event::AuthorityAsked { id, by });
    }

    /// Record a new owner (ignoring an older epoch). A client whose chains toward the host
    /// involved the object restarts them; the new owner takes over from its replica.
    pub(super) fn set_owner(
        &mut self,
        id: NetId,
        owner: PeerId,
        epoch: AuthorityEpoch,
        held: bool,
    ) {
        let local = self.local;
        let Some(o) = self.objects.get_mut(id) else {
            return;
        };
        if epoch < o.info.epoch {
            return;
        }
        let changed = o.info.owner != owner || o.info.epoch != epoch;
        let was_mine = o.info.owner == local;
        o.info.owner = owner;
        o.info.epoch = epoch;
        if o.info.held && !held {
            o.released = true;
        }
        o.info.held = held;
        if owner != local {
            o.published = None;
        }
        if changed && (was_mine || owner == local) && self.role != Role::Host {
            // a client's chains toward the host restart with keyframes (the host dropped its
            // side of them when it granted)
            for l in self.links.values_mut() {
                l.send.forget_object(id);
            }
        }
        if changed {
            if owner == local {
                self.adopt_replica(id);
            }
            self.events
                .push_back(Event::AuthorityChanged { id, owner, epoch });
        }
    }

    /// What we show of `id` becomes what we publish, unless we published already.
    pub(super) fn adopt_replica(&mut self, id: NetId) {
        let Some(class) = self
            .objects
            .get(id)
            .and_then(|o| self.cfg.class(o.info.class))
        else {
            return;
        };
        if let Some(o) = self.objects.get_mut(id) {
            o.adopt_replica(class);
        }
    }

    /// Host: give `id` to `to` in a new epoch of our term and tell everyone.
    pub(super) fn host_grant(&mut self, now: Instant, id: NetId, to: PeerId, held: bool) {
        let term = self.term;
        let Some(o) = self.objects.get(id) else {
            return;
        };
        let epoch = o.info.epoch.bumped(term);
        self.set_owner(id, to, epoch, held);
        // a new owner: asks of the old one are moot
        self.asks.clear(id);
        // the new owner sends keyframes on its own link; our relay chains restart
        for l in self.links.values_mut() {
            l.recv.forget_object(id);
        }
        self.broadcast(
            now,
            &Control::OwnerChanged {
                id,
                owner: to,
                epoch,
                held,
            },
            None,
        );
    }

    /// Host: `from` (a member or we) asks for `id`.
    pub(super) fn host_authority_request(&mut self, now: Instant, from: PeerId, id: NetId) {
        let Some(o) = self.objects.get(id) else {
            self.deny(now, from, id, DenyReason::Unknown);
            return;
        };
        match decide_request(from, o.info.owner, o.info.held, o.info.policy) {
            Decision::Grant => self.host_grant(now, id, from, true),
            Decision::Deny(reason) => self.deny(now, from, id, reason),
            Decision::AskOwner(owner) => {
                if self.asks.ask(id, from) {
                    if owner == self.local {
                        self.events
                            .push_back(Event::AuthorityAsked { id, by: from });
                    } else {
                        self.send_control(now, owner, &Control::AuthorityAsk { id, by: from });
                    }
                }
            }
        }
    }

    /// Host: the owner `from` answers `by`'s ask for `id`.
    pub(super) fn host_authority_answer(
        &mut self,
        now: Instant,
        from: PeerId,
        id: NetId,
        by: PeerId,
        agree: bool,
    ) {
        if self.owner(id) != Some(from) || !self.asks.answer(id, by) {
            return;
        }
        if agree && self.members.contains_key(&by) {
            self.asks.clear(id);
            self.host_grant(now, id, by, true);
        } else {
            self.deny(now, by, id, DenyReason::OwnerRefused);
        }
    }

    /// Host: tell `to` (a member or we) its request for `id` is denied.
    fn deny(&mut self, now: Instant, to: PeerId, id: NetId, reason: DenyReason) {
        if to == self.local {
            self.on_denied(id, reason);
        } else {
            self.send_control(now, to, &Control::AuthorityDenied { id, reason });
        }
    }

    /// Host: the owner `from` lets go of `id`: it comes back to us, not held.
    pub(super) fn host_release(&mut self, now: Instant, from: PeerId, id: NetId) {
        if self.owner(id) == Some(from) {
            let me = self.local;
            self.host_grant(now, id, me, false);
        }
    }

    /// Host: `p` left; its asks go.
    pub(super) fn forget_asks_of(&mut self, p: PeerId) {
        self.asks.forget_peer(p);
    }

    /// A member's claim after our takeover (`Resync`): what it owns according to its replica.
    ///
    /// Only what the claimant can know is believed: an epoch of an older term (every grant of
    /// our term is ours), at most one grant ahead of our record; an unknown object only
    /// with an id the old host may have spawned unseen by us ([`super::LOST_ID_WINDOW`]) and
    /// within the per-peer limits. An implausible claim on an object we know is answered by
    /// re-granting it to its recorded owner in our term, so every replica converges.
    pub(super) fn host_merge_claim(&mut self, now: Instant, from: PeerId, claim: SpawnInfo) {
        if claim.owner != from || claim.epoch.term >= self.term.0 {
            self.stats.refused_controls += 1;
            return;
        }
        let Some(class_policy) = self.class(claim.class).map(|c| c.authority) else {
            self.stats.refused_controls += 1;
            return;
        };
        let Some(o) = self.objects.get(claim.id) else {
            self.create_claimed(
                now,
                from,
                SpawnInfo {
                    policy: class_policy,
                    ..claim
                },
            );
            return;
        };
        let (owner, epoch, held) = (o.info.owner, o.info.epoch, o.info.held);
        let rec = Record {
            owner,
            epoch,
            policy: o.info.policy,
            held,
            same_object: o.info.class == claim.class && o.info.particles == claim.particles,
        };
        match judge_claim(from, claim.epoch, rec) {
            ClaimVerdict::Stale => {
                if owner != from {
                    // the claimant missed a later grant: tell it
                    self.tell_owner(now, from, claim.id, owner, epoch, held);
                }
            }
            ClaimVerdict::Believe => {
                self.set_owner(claim.id, from, claim.epoch, claim.held);
                for l in self.links.values_mut() {
                    l.recv.forget_object(claim.id);
                }
                self.broadcast(
                    now,
                    &Control::OwnerChanged {
                        id: claim.id,
                        owner: from,
                        epoch: claim.epoch,
                        held: claim.held,
                    },
                    None,
                );
            }
            ClaimVerdict::Refuse => {
                self.stats.refused_controls += 1;
                if epoch.term < self.term.0 {
                    // replicas may hold epochs newer than our record: a grant of our term
                    // beats them
                    self.host_grant(now, claim.id, owner, held);
                } else if owner != from {
                    self.tell_owner(now, from, claim.id, owner, epoch, held);
                }
            }
        }
    }

    /// Tell `to` who owns `id`.
    fn tell_owner(
        &mut self,
        now: Instant,
        to: PeerId,
        id: NetId,
        owner: PeerId,
        epoch: AuthorityEpoch,
        held: bool,
    ) {
        let msg = Control::OwnerChanged {
            id,
            owner,
            epoch,
            held,
        };
        self.send_control(now, to, &msg);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    const A: PeerId = PeerId(1);
    const B: PeerId = PeerId(2);

    fn epoch(term: u32, grant: u32) -> AuthorityEpoch {
        AuthorityEpoch { term, grant }
    }

    #[test]
    fn requests_follow_the_policy_and_an_owner_always_gets_its_own_object() {
        use AuthorityPolicy::*;
        assert_eq!(decide_request(A, A, true, Locked), Decision::Grant);
        assert_eq!(
            decide_request(B, A, false, Locked),
            Decision::Deny(DenyReason::Locked)
        );
        assert_eq!(
            decide_request(B, A, true, Free),
            Decision::Deny(DenyReason::Held(A))
        );
        assert_eq!(decide_request(B, A, false, Free), Decision::Grant);
        assert_eq!(
            decide_request(B, A, true, OwnerMustAgree),
            Decision::AskOwner(A)
        );
        assert_eq!(decide_request(B, A, false, OwnerMustAgree), Decision::Grant);
    }

    #[test]
    fn asks_are_answered_once_and_a_departed_peer_asks_nothing() {
        let mut asks = PendingAsks::default();
        assert!(asks.ask(NetId(1), B));
        assert!(!asks.ask(NetId(1), B), "asked already");
        assert!(asks.answer(NetId(1), B));
        assert!(!asks.answer(NetId(1), B), "answered already");
        asks.ask(NetId(1), B);
        asks.forget_peer(B);
        assert!(!asks.answer(NetId(1), B));
    }

    fn rec(owner: PeerId, e: AuthorityEpoch, policy: AuthorityPolicy) -> Record {
        Record {
            owner,
            epoch: e,
            policy,
            held: false,
            same_object: true,
        }
    }

    #[test]
    fn a_claim_is_believed_only_one_grant_ahead_of_the_record() {
        let free = AuthorityPolicy::Free;
        let r = rec(A, epoch(2, 3), free);
        assert_eq!(judge_claim(B, epoch(2, 3), r), ClaimVerdict::Stale);
        assert_eq!(judge_claim(B, epoch(2, 4), r), ClaimVerdict::Believe);
        assert_eq!(judge_claim(B, epoch(2, 5), r), ClaimVerdict::Refuse);
        assert_eq!(judge_claim(B, epoch(3, 0), r), ClaimVerdict::Believe);
        assert_eq!(judge_claim(B, epoch(3, 1), r), ClaimVerdict::Refuse);
        let locked = rec(A, epoch(2, 3), AuthorityPolicy::Locked);
        assert_eq!(judge_claim(B, epoch(2, 4), locked), ClaimVerdict::Refuse);
        assert_eq!(judge_claim(A, epoch(2, 4), locked), ClaimVerdict::Believe);
        let other = Record {
            same_object: false,
            ..r
        };
        assert_eq!(
            judge_claim(B, epoch(2, 3), other),
            ClaimVerdict::Refuse,
            "another object under that id"
        );
    }

    /// Issue 32: a claim may not do what a request may not. A held body's next grant, claimed
    /// by someone other than its owner in the claim window, is refused (a `Free` body held is
    /// denied to a request; an `OwnerMustAgree` one needs its owner's word); its owner's own
    /// claim, and a claim on a body nobody holds, are believed as before.
    #[test]
    fn a_claim_cannot_take_a_held_body_or_skip_its_owners_word() {
        for policy in [AuthorityPolicy::Free, AuthorityPolicy::OwnerMustAgree] {
            let held = Record {
                held: true,
                ..rec(A, epoch(2, 3), policy)
            };
            assert_eq!(
                judge_claim(B, epoch(2, 4), held),
                ClaimVerdict::Refuse,
                "{policy:?}"
            );
            assert_eq!(
                judge_claim(B, epoch(3, 0), held),
                ClaimVerdict::Refuse,
                "{policy:?}"
            );
            assert_eq!(
                judge_claim(A, epoch(2, 4), held),
                ClaimVerdict::Believe,
                "{policy:?}"
            );
            let free = rec(A, epoch(2, 3), policy);
            assert_eq!(
                judge_claim(B, epoch(2, 4), free),
                ClaimVerdict::Believe,
                "{policy:?}"
            );
        }
    }
}
