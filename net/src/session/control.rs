//! Control messages: sending them on a link's reliable channel, routing received ones to the
//! part of the session that handles them, and the host as a client of itself — a local
//! request ([`Session::ask_host`]) goes the same way as a member's, the host just hands it
//! to itself instead of sending it.

use super::migration::Deferred;
use super::{Role, Session};
use crate::error::NetError;
use crate::ids::PeerId;
use crate::time::Instant;
use crate::wire::Control;

impl Session {
    /// Queue `msg` to `to` on the reliable channel; returns its reliable sequence, or `None`
    /// when nothing was queued: it cannot be encoded (over its size limit: counted in
    /// `Stats::unencodable_controls` — an empty message would reach the peer as a malformed
    /// one), or the peer's channel is full (it acknowledges nothing: counted in
    /// `Stats::controls_over_quota`; the host drops such a member at its next liveness check).
    pub(super) fn send_control(&mut self, now: Instant, to: PeerId, msg: &Control) -> Option<u16> {
        let Ok(bytes) = msg.encode() else {
            self.stats.unencodable_controls += 1;
            return None;
        };
        let seq = self.links.entry(to).or_default().reliable.push(now, bytes);
        if seq.is_none() {
            self.stats.controls_over_quota += 1;
        }
        seq
    }

    /// Queue `msg` to every member but us and `except`. A `Spawn` is remembered per link
    /// until acknowledged: no state flows for the object before.
    pub(super) fn broadcast(&mut self, now: Instant, msg: &Control, except: Option<PeerId>) {
        let peers: Vec<PeerId> = self
            .members
            .keys()
            .copied()
            .filter(|p| *p != self.local && Some(*p) != except)
            .collect();
        for p in peers {
            let seq = self.send_control(now, p, msg);
            if let (Control::Spawn(info), Some(seq)) = (msg, seq) {
                if let Some(l) = self.links.get_mut(&p) {
                    l.spawn_pending.insert(info.id, seq);
                }
            }
        }
    }

    /// A request to the host (spawn, despawn, authority): a client sends it; the host, a
    /// client of itself, handles it at once as if a member had sent it.
    pub(super) fn ask_host(&mut self, now: Instant, msg: Control) -> Result<(), NetError> {
        match self.role {
            Role::Host => {
                let me = self.local;
                self.on_request(now, me, msg);
                Ok(())
            }
            Role::Client => {
                let host = self.host.ok_or(NetError::NotConnected)?;
                self.send_control(now, host, &msg);
                Ok(())
            }
            Role::Joining | Role::Refused => Err(NetError::NotConnected),
        }
    }

    /// Is `p` a member other than us, and are we the host (the only peer that serves
    /// requests)?
    pub(super) fn is_member_client(&self, p: PeerId) -> bool {
        self.role == Role::Host && p != self.local && self.members.contains_key(&p)
    }

    /// A control message that arrived from `from`. After a `NewHost` we have not adopted yet,
    /// its sender's later messages (the snapshot, ownership changes) wait for it.
    /// Only a client follows a `NewHost`, so only a client defers; a `Hello` is a joining
    /// session's, never part of what follows a `NewHost` (the fuzzer found a host that kept a
    /// rejoining peer's `Hello`s behind that peer's old `NewHost` for good).
    pub(super) fn deliver_control(&mut self, now: Instant, from: PeerId, c: Control) {
        let c = if self.role == Role::Client && !matches!(c, Control::Hello { .. }) {
            match self.succession.defer(from, c) {
                Deferred::NotPending(c) => c,
                Deferred::Kept => return,
                Deferred::Overflow => {
                    self.stats.refused_controls += 1;
                    return;
                }
            }
        } else {
            c
        };
        self.handle_control(now, from, c);
    }

    /// Route a control message from `from` to its handler, if it is in place: joining
    /// messages while joining, room news from our host, requests at the host from members.
    pub(super) fn handle_control(&mut self, now: Instant, from: PeerId, msg: Control) {
        let from_host = Some(from) == self.host && self.role != Role::Host;
        match msg {
            // ---- joining and membership (join.rs)
            Control::Hello {
                protocol,
                config_digest,
            } => self.on_hello(now, from, protocol, config_digest),
            Control::Welcome {
                term,
                host,
                join_seq: _,
                members,
            } if self.role == Role::Joining && from == host && Some(from) == self.host => {
                self.on_welcome(now, term, host, members);
            }
            // only the peer we asked may refuse or redirect us
            Control::Refused { reason }
                if self.role == Role::Joining && Some(from) == self.host =>
            {
                self.on_refused(reason);
            }
            Control::Challenge { nonce }
                if self.role == Role::Joining && Some(from) == self.host =>
            {
                self.on_challenge(now, from, nonce);
            }
            Control::Proof { mac } if self.role == Role::Host => self.on_proof(now, from, mac),
            Control::TokenProof { token } if self.role == Role::Host => {
                self.on_token_proof(now, from, token);
            }
            Control::TokenUsed {
                nonce,
                peer,
                expires_unix,
            } if from_host => self.note_token_used(now, nonce, peer, expires_unix),
            Control::Banned {
                peer,
                token,
                reason,
            } if from_host => self.on_banned(peer, token, reason),
            Control::Redirect { host }
                if self.role == Role::Joining && from != host && Some(from) == self.host =>
            {
                self.join_via(now, host);
            }
            Control::PeerJoined { peer, join_seq } if from_host => {
                self.on_peer_joined(peer, join_seq);
            }
            Control::Leave
                if from != self.local
                    && (self.members.contains_key(&from) || Some(from) == self.host) =>
            {
                self.on_leave(now, from);
            }
            Control::PeerLeft { peer } if from_host => self.on_peer_left(peer),
            // ---- objects and owners, from our host (spawn.rs, authority.rs)
            Control::Spawn(info) if from_host => self.on_spawn_from_host(now, info),
            Control::Despawn { id } if from_host => self.on_despawn_from_host(id),
            Control::SnapshotEnd if from_host => self.on_snapshot_end(),
            Control::OwnerChanged {
                id,
                owner,
                epoch,
                held,
            } if from_host => self.set_owner(id, owner, epoch, held),
            Control::AuthorityDenied { id, reason } if from_host => {
                self.on_denied(id, reason);
            }
            Control::AuthorityAsk { id, by } if from_host => self.on_asked(id, by),
            Control::Topology { id, seq, event } if from_host => {
                self.on_topology_from_host(id, seq, event);
            }
            // ---- migration (migration.rs)
            Control::NewHost {
                term,
                host,
                members,
            } if host == from && self.role == Role::Client => {
                self.on_new_host(now, from, term, members);
            }
            // ---- application messages (messages.rs)
            Control::Message(m) if self.is_member_client(from) => self.host_relay(now, from, m),
            Control::Message(m) if from_host => self.deliver_message(m),
            Control::Replay(m) if from_host => self.deliver_replay(m),
            Control::MessagesDelivered { up_to } if from_host => self.on_messages_delivered(up_to),
            Control::MessageRefused { seq, reason } if from_host => {
                self.on_message_refused(seq, reason);
            }
            // ---- requests at the host
            msg @ (Control::SpawnRequest { .. }
            | Control::DespawnRequest { .. }
            | Control::AuthorityRequest { .. }
            | Control::AuthorityAnswer { .. }
            | Control::AuthorityRelease { .. }
            | Control::TopologyRequest { .. }
            | Control::Resync { .. })
                if self.is_member_client(from) =>
            {
                // a member's requests are rate-limited (the host's own are not; topology
                // requests have their own, per object: a fast scalpel makes 200 a second)
                let topology = matches!(msg, Control::TopologyRequest { .. });
                let admitted = from == self.local
                    || topology
                    || self
                        .links
                        .get_mut(&from)
                        .is_none_or(|l| l.requests.admit(now, super::link::MAX_REQUESTS_PER_S));
                if admitted {
                    self.on_request(now, from, msg);
                } else {
                    self.stats.requests_rate_limited += 1;
                    self.drop_if_flooding(now, from);
                }
            }
            _ => {}
        }
    }

    /// The host serves a request of `from` (a member, or itself).
    fn on_request(&mut self, now: Instant, from: PeerId, msg: Control) {
        match msg {
            Control::SpawnRequest {
                request,
                class,
                particles,
                pos,
                rot,
            } => self.on_spawn_request(now, from, request, class, particles, pos, rot),
            // the host may despawn anything; a member what it owns
            Control::DespawnRequest { id }
                if from == self.local || self.owner(id) == Some(from) =>
            {
                self.host_despawn(now, id);
            }
            Control::AuthorityRequest { id } => self.host_authority_request(now, from, id),
            Control::AuthorityAnswer { id, by, agree } => {
                self.host_authority_answer(now, from, id, by, agree);
            }
            Control::AuthorityRelease { id } => self.host_release(now, from, id),
            Control::TopologyRequest {
                id,
                epoch,
                event,
                pieces,
            } => self.host_topology_request(now, from, id, epoch, event, pieces),
            // claims are answers to our NewHost: only shortly after we took over
            Control::Resync { claims } => {
                if self.succession.resync_open(now) {
                    for c in claims {
                        self.host_merge_claim(now, from, c);
                    }
                } else {
                    self.stats.refused_controls += 1;
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::super::testkit::{config, Wire};
    use super::super::{Event, ObjectState};
    use super::*;
    use crate::ids::ClassId;
    use glam::{Quat, Vec3};

    fn room() -> Wire {
        let mut w = Wire::new();
        w.add(Session::host(PeerId(1), config(), w.now));
        w.add(Session::join(PeerId(2), PeerId(1), config(), w.now));
        w.settle();
        w
    }

    #[test]
    fn the_host_is_a_client_of_itself_its_requests_take_the_members_path() {
        let mut w = room();
        let now = w.now;
        let st = ObjectState::rigid(Vec3::Y, Quat::IDENTITY);
        let (id, _) = w.get(2).spawn(now, ClassId(0), st).unwrap();
        assert_eq!(id.0, 0, "a member's spawn is a request");
        w.settle();
        let id = w.get(1).object_ids()[0];
        assert_eq!(w.get(1).owner(id), Some(PeerId(2)));
        // the member's object is held: the host's own request is denied like anyone's
        w.get(1).request_authority(now, id).unwrap();
        assert!(w
            .events(1)
            .iter()
            .any(|e| matches!(e, Event::AuthorityDenied { .. })));
        // released, the object comes back to the host; its own request is then granted
        w.get(2).release_authority(now, id).unwrap();
        w.settle();
        assert_eq!(w.get(1).owner(id), Some(PeerId(1)));
        w.get(1).request_authority(now, id).unwrap();
        w.settle();
        assert_eq!(w.get(2).owner(id), Some(PeerId(1)));
        // and the host may despawn any object, a member only its own
        assert!(matches!(
            w.get(2).despawn(now, id),
            Err(NetError::NotOwner(_, _))
        ));
        w.get(1).despawn(now, id).unwrap();
        w.settle();
        assert!(w.get(2).object_ids().is_empty());
    }

    #[test]
    fn a_joiner_cannot_ask_the_host_for_anything_yet() {
        let mut s = Session::join(PeerId(2), PeerId(1), config(), Instant::ZERO);
        let st = ObjectState::rigid(Vec3::Y, Quat::IDENTITY);
        assert_eq!(
            s.spawn(Instant::ZERO, ClassId(0), st),
            Err(NetError::NotConnected)
        );
        assert_eq!(
            s.ask_host(Instant::ZERO, Control::Leave),
            Err(NetError::NotConnected)
        );
    }

    #[test]
    fn requests_at_the_host_from_a_non_member_are_ignored() {
        let mut w = room();
        let now = w.now;
        w.add(Session::join(PeerId(9), PeerId(1), config(), now));
        // before it is a member (its Hello not delivered yet), a spawn request does nothing
        let req = Control::SpawnRequest {
            request: 0,
            class: ClassId(0),
            particles: 0,
            pos: [0.0, 1.0, 0.0],
            rot: [0.0, 0.0, 0.0, 1.0],
        };
        w.get(1).handle_control(now, PeerId(9), req);
        assert!(w.get(1).object_ids().is_empty());
    }
}
