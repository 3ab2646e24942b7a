//! Keeping a prankster out: the host kicks a member and bans its id, and the join token it
//! came in with, for the room's life.
//!
//! [`Session::kick`] drops the member at once (its objects go to others as when it leaves),
//! tells it why, and sends every member a `Banned` control; a joiner is sent the list after
//! its snapshot, so whoever hosts after a migration keeps the ban. A banned id's datagrams
//! are answered by the host with the reason (at most once per heartbeat) and otherwise
//! dropped by everyone; a banned token admits nobody and opens nothing (the scene share asks
//! [`Session::token_admits`]). Bans are local policy, not part of the room's digest; at most
//! [`MAX_BANNED`] are kept (the oldest goes first).

use std::collections::{BTreeMap, VecDeque};

use super::liveness::DropWhy;
use super::{Event, Role, Session};
use crate::ids::PeerId;
use crate::time::Instant;
use crate::wire::Control;

/// Most bans a session keeps (ids; their tokens with them).
pub const MAX_BANNED: usize = 1024;
/// Longest reason a ban carries (bytes; longer ones are cut on a character boundary).
pub const MAX_BAN_REASON: usize = 120;

/// Why a kick was not done.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KickError {
    /// Only the room's host kicks (a member asks it, e.g. with an application message).
    #[error("only the room's host can kick a peer")]
    NotHost,
    /// A peer does not kick itself (leave instead).
    #[error("a peer cannot kick itself: leave instead")]
    Myself,
}

/// The room's bans: ids with their reasons, and the join tokens they came in with.
#[derive(Debug, Default)]
pub(crate) struct Bans {
    peers: BTreeMap<PeerId, String>,
    order: VecDeque<PeerId>,
    tokens: BTreeMap<[u8; 16], PeerId>,
}

impl Bans {
    fn insert(&mut self, peer: PeerId, token: Option<[u8; 16]>, reason: String) {
        if !self.peers.contains_key(&peer) {
            if self.order.len() >= MAX_BANNED {
                if let Some(old) = self.order.pop_front() {
                    self.peers.remove(&old);
                    self.tokens.retain(|_, p| *p != old);
                }
            }
            self.order.push_back(peer);
        }
        self.peers.insert(peer, reason);
        if let Some(t) = token {
            self.tokens.insert(t, peer);
        }
    }

    /// Whether `p` is banned.
    pub fn contains(&self, p: PeerId) -> bool {
        self.peers.contains_key(&p)
    }

    /// Why `p` is banned.
    pub fn reason(&self, p: PeerId) -> Option<&str> {
        self.peers.get(&p).map(String::as_str)
    }

    /// Whether the token of this nonce belongs to a banned peer.
    pub fn token_banned(&self, nonce: &[u8; 16]) -> bool {
        self.tokens.contains_key(nonce)
    }
}

fn cut(reason: &str) -> String {
    let mut end = reason.len().min(MAX_BAN_REASON);
    while !reason.is_char_boundary(end) {
        end -= 1;
    }
    reason[..end].to_owned()
}

impl Session {
    /// Host: kick `peer` out of the room and ban it for the room's life (its id, and the join
    /// token it came in with), telling it `reason`; every member is told, so a new host
    /// after a migration keeps it out. A peer that is not (or no longer) a member is banned
    /// all the same. Bans are this room's policy, not part of its configuration digest.
    pub fn kick(&mut self, now: Instant, peer: PeerId, reason: &str) -> Result<(), KickError> {
        if self.role != Role::Host {
            return Err(KickError::NotHost);
        }
        if peer == self.local {
            return Err(KickError::Myself);
        }
        let reason = cut(reason);
        let token = self
            .challenges
            .tokens_used
            .iter()
            .find(|(_, (p, _))| *p == peer)
            .map(|(n, _)| *n);
        self.bans.insert(peer, token, reason.clone());
        self.stats.kicked += 1;
        let banned = Control::Banned {
            peer,
            token,
            reason,
        };
        self.broadcast(now, &banned, Some(peer));
        self.challenges.open.remove(&peer);
        self.dropped.insert(peer, DropWhy::Banned);
        if self.members.contains_key(&peer) {
            self.host_peer_left(now, peer);
        }
        self.tell_banned(now, peer);
        self.events.push_back(Event::Kicked(peer));
        Ok(())
    }

    /// Whether `peer` is banned from this room.
    pub fn is_banned(&self, peer: PeerId) -> bool {
        self.bans.contains(peer)
    }

    /// The banned peers, with why (oldest ban first).
    pub fn banned(&self) -> Vec<(PeerId, String)> {
        self.bans
            .order
            .iter()
            .filter_map(|p| Some((*p, self.bans.peers.get(p)?.clone())))
            .collect()
    }

    /// Why the banned peer `p` is out (for its drop notice).
    pub(super) fn ban_reason(&self, p: PeerId) -> Option<&str> {
        self.bans.reason(p)
    }

    /// Whether the join token of this nonce came in with a banned peer.
    pub(super) fn token_banned(&self, nonce: &[u8; 16]) -> bool {
        self.bans.token_banned(nonce)
    }

    /// A datagram from a banned peer: the host tells it why (at most once per heartbeat);
    /// everyone drops it. True if `from` is banned.
    pub(super) fn refuse_if_banned(&mut self, now: Instant, from: PeerId) -> bool {
        if !self.bans.contains(from) {
            return false;
        }
        self.stats.banned_dropped += 1;
        if self.role == Role::Host {
            if !self.dropped.contains(from) {
                self.dropped.insert(from, DropWhy::Banned);
            }
            self.tell_banned(now, from);
        }
        true
    }

    /// Host: tell banned `to` why, in a plain refusal (no host to join again: a joining
    /// session takes it too), at most once per heartbeat interval.
    fn tell_banned(&mut self, now: Instant, to: PeerId) {
        if self
            .dropped
            .due_notice(to, now, self.cfg.heartbeat_interval)
            .is_none()
        {
            return;
        }
        let reason = format!(
            "kicked out of the room and banned by its host: {}",
            self.ban_reason(to).unwrap_or("no reason given")
        );
        self.raw_out.push_back(crate::transport::Transmit {
            to,
            payload: crate::wire::encode_refusal(&reason, self.term),
            reliable: true,
        });
    }

    /// Our host banned `peer` (or told a joiner of an earlier ban).
    pub(super) fn on_banned(&mut self, peer: PeerId, token: Option<[u8; 16]>, reason: String) {
        if peer == self.local {
            return;
        }
        self.bans.insert(peer, token, cut(&reason));
    }

    /// Host: the bans, to a new member (after its snapshot).
    pub(super) fn send_bans(&mut self, now: Instant, to: PeerId) {
        let all: Vec<Control> = self
            .bans
            .order
            .iter()
            .filter_map(|p| {
                let reason = self.bans.peers.get(p)?.clone();
                let token = self
                    .bans
                    .tokens
                    .iter()
                    .find(|(_, q)| *q == p)
                    .map(|(n, _)| *n);
                Some(Control::Banned {
                    peer: *p,
                    token,
                    reason,
                })
            })
            .collect();
        for c in all {
            self.send_control(now, to, &c);
        }
    }
}
