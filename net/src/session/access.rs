//! Who may enter: a room with a key admits only joiners that prove they hold it.
//!
//! The host answers a `Hello` that passed every other check with a `Challenge` (a nonce of
//! its own); the joiner answers with a `Proof`, HMAC-SHA256 under the room key over the
//! nonce, its own id and the host's id. The secret never crosses the wire; a proof is good
//! for one nonce, one joiner and one host only, so a captured proof replayed (by anyone, for
//! any id, to this or another host) fails. Every member holds the key, so a new host after a
//! migration admits by the same rule. A joiner without the key, or with another, is refused
//! with a reason; refusals are counted.
//!
//! Not covered: a weak secret can be guessed offline from a captured challenge and proof
//! (use a long random one); the joiner does not check that the host knows the key.

use std::collections::BTreeMap;

use ring::hmac;

use super::{Role, Session, MAX_STRANGERS};
use crate::ids::PeerId;
use crate::time::Instant;
use crate::wire::{Control, RoomToken};

/// A room's secret, as the session uses it (an HMAC-SHA256 key) and the seed its
/// challenges are drawn from. Its `Debug` shows no key material.
#[derive(Clone)]
pub struct RoomKey {
    key: hmac::Key,
    nonce_seed: u64,
    /// HMAC of a fixed text under the key: keys compare by it, never by the secret.
    fingerprint: [u8; 32],
    /// The room the key is for: join tokens name it (`None`: tokens are refused).
    room: Option<String>,
    /// Seconds since the Unix epoch at the session's time zero: a host checks token expiry
    /// on it (`None`: tokens are refused, having no clock to expire on).
    unix_at_zero: Option<u64>,
}

impl RoomKey {
    /// The key of `secret` (the same bytes on every peer of the room; use 16 or more random
    /// bytes). `nonce_seed` makes this peer's challenges its own: give every process a fresh
    /// random one (the session draws no randomness itself).
    pub fn new(secret: &[u8], nonce_seed: u64) -> Self {
        let key = hmac::Key::new(hmac::HMAC_SHA256, secret);
        let mut fingerprint = [0u8; 32];
        let tag = hmac::sign(&key, b"softsync-fingerprint-v1");
        fingerprint.copy_from_slice(tag.as_ref().get(..32).unwrap_or(&[0; 32]));
        RoomKey {
            key,
            nonce_seed,
            fingerprint,
            room: None,
            unix_at_zero: None,
        }
    }

    /// This key, for room `room` (join tokens are bound to it).
    pub fn for_room(mut self, room: &str) -> Self {
        self.room = Some(room.to_owned());
        self
    }

    /// This key, with the wall clock at the session's time zero (seconds since the Unix
    /// epoch; the I/O layer's), so a host can tell an expired join token.
    pub fn with_clock(mut self, unix_at_zero: u64) -> Self {
        self.unix_at_zero = Some(unix_at_zero);
        self
    }

    fn token_mac(&self, room: &str, expires_unix: u64, nonce: &[u8; 16]) -> [u8; 16] {
        let mut ctx = hmac::Context::with_key(&self.key);
        ctx.update(b"softsync-token-v1");
        ctx.update(&(room.len() as u64).to_le_bytes());
        ctx.update(room.as_bytes());
        ctx.update(&expires_unix.to_le_bytes());
        ctx.update(nonce);
        let mut out = [0u8; 16];
        out.copy_from_slice(ctx.sign().as_ref().get(..16).unwrap_or(&[0; 16]));
        out
    }

    /// A join token for this key's room (see [`for_room`](Self::for_room)) until
    /// `expires_unix`; `nonce` must be random (the I/O layer draws it). `None` without a room.
    pub fn issue_token(&self, expires_unix: u64, nonce: [u8; 16]) -> Option<RoomToken> {
        let room = self.room.clone()?;
        let mac = self.token_mac(&room, expires_unix, &nonce);
        Some(RoomToken {
            room,
            expires_unix,
            nonce,
            mac,
        })
    }

    /// Why `token` does not admit anyone at session time `now`, if it does not: signed by
    /// another key or for another room, or expired (checked in constant time for the MAC).
    pub fn check_token(&self, token: &RoomToken, now: Instant) -> Result<(), &'static str> {
        let Some(room) = &self.room else {
            return Err("this host takes no join tokens (its key names no room)");
        };
        let expected = self.token_mac(&token.room, token.expires_unix, &token.nonce);
        let same = expected
            .iter()
            .zip(&token.mac)
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0;
        if !same || token.room != *room {
            return Err("the join token is not this room's");
        }
        let Some(zero) = self.unix_at_zero else {
            return Err("this host has no clock to check join tokens on");
        };
        if zero.saturating_add(now.as_micros() / 1_000_000) >= token.expires_unix {
            return Err("the join token expired");
        }
        Ok(())
    }

    fn signal_mac(&self, room: &str, expires_unix: u64, nonce: &[u8; 16]) -> hmac::Tag {
        let mut ctx = hmac::Context::with_key(&self.key);
        ctx.update(b"softsync-signal-v2");
        ctx.update(&(room.len() as u64).to_le_bytes());
        ctx.update(room.as_bytes());
        ctx.update(&expires_unix.to_le_bytes());
        ctx.update(nonce);
        ctx.sign()
    }

    /// What a peer of room `room` shows the signaling server to be let in, made at
    /// `unix_now` with a fresh random `nonce` (the I/O layer draws it):
    /// `EXPIRES.NONCE.MAC` (decimal, then hex), the MAC HMAC-SHA256 under the key of
    /// `"softsync-signal-v2" ‖ room length (u64 LE) ‖ room ‖ expires (u64 LE) ‖ nonce`. It is
    /// good for [`SIGNAL_PROOF_LIFETIME_S`] and, at a server that remembers nonces, once: a
    /// captured URL is worth little (still, use `wss://`).
    pub fn signal_proof(&self, room: &str, unix_now: u64, nonce: [u8; 16]) -> String {
        let expires = unix_now.saturating_add(SIGNAL_PROOF_LIFETIME_S);
        let hex = |b: &[u8]| b.iter().map(|x| format!("{x:02x}")).collect::<String>();
        format!(
            "{expires}.{}.{}",
            hex(&nonce),
            hex(self.signal_mac(room, expires, &nonce).as_ref())
        )
    }

    /// The signaling server's check of a [`signal_proof`](Self::signal_proof) for room
    /// `room` at `unix_now`: its nonce and expiry if it is right and current (not expired,
    /// not made further ahead than its lifetime and a minute of clock skew), else why not.
    /// The server refuses a nonce it has seen before its expiry.
    pub fn check_signal_proof(
        &self,
        room: &str,
        proof: &str,
        unix_now: u64,
    ) -> Result<([u8; 16], u64), &'static str> {
        let bad = "the room key's proof is malformed";
        let mut parts = proof.split('.');
        let (Some(e), Some(n), Some(m), None) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            return Err(bad);
        };
        let expires: u64 = e.parse().map_err(|_| bad)?;
        let unhex = |h: &str, out: &mut [u8]| -> Result<(), &'static str> {
            if h.len() != 2 * out.len() || !h.is_ascii() {
                return Err(bad);
            }
            for (k, o) in out.iter_mut().enumerate() {
                *o = u8::from_str_radix(&h[2 * k..2 * k + 2], 16).map_err(|_| bad)?;
            }
            Ok(())
        };
        let mut nonce = [0u8; 16];
        let mut mac = [0u8; 32];
        unhex(n, &mut nonce)?;
        unhex(m, &mut mac)?;
        let mut msg = Vec::with_capacity(64 + room.len());
        msg.extend_from_slice(b"softsync-signal-v2");
        msg.extend_from_slice(&(room.len() as u64).to_le_bytes());
        msg.extend_from_slice(room.as_bytes());
        msg.extend_from_slice(&expires.to_le_bytes());
        msg.extend_from_slice(&nonce);
        if hmac::verify(&self.key, &msg, &mac).is_err() {
            return Err("wrong room key");
        }
        if expires <= unix_now {
            return Err("the room key's proof expired (check this machine's clock)");
        }
        if expires > unix_now + SIGNAL_PROOF_LIFETIME_S + 60 {
            return Err("the room key's proof is from the future (check this machine's clock)");
        }
        Ok((nonce, expires))
    }

    /// The signaling server's check of a connection to room `room` without a proof: a join
    /// token of this key for that room that has not expired at `unix_now`.
    pub fn admits_signal_token(&self, room: &str, token: &RoomToken, unix_now: u64) -> bool {
        token.room == room
            && token.expires_unix > unix_now
            && self.clone().for_room(room).token_is_ours(token)
    }

    /// Whether `token` is signed with this key for this key's room (its expiry aside).
    pub fn token_is_ours(&self, token: &RoomToken) -> bool {
        let Some(room) = &self.room else {
            return false;
        };
        let expected = self.token_mac(&token.room, token.expires_unix, &token.nonce);
        expected
            .iter()
            .zip(&token.mac)
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
            && token.room == *room
    }

    /// Seconds since the Unix epoch at session time `now`, if the key has a clock.
    pub(crate) fn unix_now(&self, now: Instant) -> Option<u64> {
        self.unix_at_zero
            .map(|z| z.saturating_add(now.as_micros() / 1_000_000))
    }

    /// The key of `secret`, its nonce seed drawn from the system's random source (`None` if
    /// there is none).
    pub fn with_random_seed(secret: &[u8]) -> Option<Self> {
        use ring::rand::SecureRandom;
        let mut seed = [0u8; 8];
        ring::rand::SystemRandom::new().fill(&mut seed).ok()?;
        Some(RoomKey::new(secret, u64::from_le_bytes(seed)))
    }

    /// The proof a peer without a session shows a member to be sent the room's scene
    /// (`crate::share`): HMAC-SHA256 of `"softsync-scene-v1" ‖ requester ‖ server` (ids as u64
    /// LE). Bound to both ids; it opens nothing but the scene of a room whose key it holds.
    pub fn scene_proof(&self, requester: PeerId, server: PeerId) -> [u8; 32] {
        let mut ctx = hmac::Context::with_key(&self.key);
        ctx.update(b"softsync-scene-v1");
        ctx.update(&requester.0.to_le_bytes());
        ctx.update(&server.0.to_le_bytes());
        let mut out = [0u8; 32];
        out.copy_from_slice(ctx.sign().as_ref());
        out
    }

    /// Whether `proof` is [`scene_proof`](Self::scene_proof)`(requester, server)` (constant
    /// time).
    pub fn verify_scene_proof(&self, requester: PeerId, server: PeerId, proof: &[u8]) -> bool {
        let mut msg = Vec::with_capacity(17 + 16);
        msg.extend_from_slice(b"softsync-scene-v1");
        msg.extend_from_slice(&requester.0.to_le_bytes());
        msg.extend_from_slice(&server.0.to_le_bytes());
        hmac::verify(&self.key, &msg, proof).is_ok()
    }

    /// The tag of a beacon (`session::heal`): HMAC-SHA256 of `"softsync-beacon-v1" ‖ digest
    /// ‖ host ‖ host join ‖ members ‖ term ‖ from ‖ to` (integers LE), first 16 bytes.
    pub(crate) fn beacon_tag(
        &self,
        s: &crate::wire::RoomSummary,
        term: crate::ids::Term,
        from: PeerId,
        to: PeerId,
    ) -> [u8; 16] {
        let mut ctx = hmac::Context::with_key(&self.key);
        ctx.update(b"softsync-beacon-v1");
        ctx.update(&s.digest.to_le_bytes());
        ctx.update(&s.host.0.to_le_bytes());
        ctx.update(&s.host_join.to_le_bytes());
        ctx.update(&s.members.to_le_bytes());
        ctx.update(&term.0.to_le_bytes());
        ctx.update(&from.0.to_le_bytes());
        ctx.update(&to.0.to_le_bytes());
        let mut out = [0u8; 16];
        out.copy_from_slice(ctx.sign().as_ref().get(..16).unwrap_or(&[0; 16]));
        out
    }

    fn proof(&self, nonce: &[u8; 16], joiner: PeerId, host: PeerId) -> hmac::Tag {
        let mut ctx = hmac::Context::with_key(&self.key);
        ctx.update(b"softsync-join-v1");
        ctx.update(nonce);
        ctx.update(&joiner.0.to_le_bytes());
        ctx.update(&host.0.to_le_bytes());
        ctx.sign()
    }

    fn verify(&self, nonce: &[u8; 16], joiner: PeerId, host: PeerId, mac: &[u8]) -> bool {
        let mut msg = Vec::with_capacity(16 + 16 + 16);
        msg.extend_from_slice(b"softsync-join-v1");
        msg.extend_from_slice(nonce);
        msg.extend_from_slice(&joiner.0.to_le_bytes());
        msg.extend_from_slice(&host.0.to_le_bytes());
        hmac::verify(&self.key, &msg, mac).is_ok()
    }

    fn nonce(&self, host: PeerId, joiner: PeerId, counter: u64, now: Instant) -> [u8; 16] {
        let mut ctx = hmac::Context::with_key(&self.key);
        ctx.update(b"softsync-nonce-v1");
        for v in [self.nonce_seed, host.0, joiner.0, counter, now.as_micros()] {
            ctx.update(&v.to_le_bytes());
        }
        let tag = ctx.sign();
        let mut n = [0u8; 16];
        n.copy_from_slice(tag.as_ref().get(..16).unwrap_or(&[0; 16]));
        n
    }
}

impl std::fmt::Debug for RoomKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RoomKey(..)")
    }
}

impl PartialEq for RoomKey {
    /// The same secret (by fingerprint; the nonce seeds may differ).
    fn eq(&self, other: &Self) -> bool {
        self.fingerprint == other.fingerprint
    }
}

/// The host's open challenges (nonce, and when it was issued), and the join tokens used (by
/// whom, until when): every member keeps the latter, so a new host knows them.
#[derive(Debug, Default)]
pub(crate) struct Challenges {
    pub(super) open: BTreeMap<PeerId, ([u8; 16], Instant)>,
    issued: u64,
    pub(super) tokens_used: BTreeMap<[u8; 16], (PeerId, u64)>,
}

/// Seconds a signaling proof ([`RoomKey::signal_proof`]) is good for.
pub const SIGNAL_PROOF_LIFETIME_S: u64 = 300;

/// Most used join tokens a session remembers. Expired ones are forgotten; a host that
/// remembers this many unexpired ones takes no new token (it never forgets a valid one, which
/// would let it be used twice); a member told of more by its host forgets the soonest to expire.
pub const MAX_TOKENS_USED: usize = 4096;

impl Session {
    /// Host: a joiner passed the other checks. Without a room key it is admitted; with one
    /// it is challenged (the same nonce again for a repeated `Hello`). False if admitted.
    pub(super) fn challenge(&mut self, now: Instant, from: PeerId) -> bool {
        let Some(key) = self.cfg.room_key.clone() else {
            if self.cfg.room_token.is_some() {
                // we got in with a token and hold no key: we cannot check anyone's, and a
                // room with a key must not open up because its host changed
                self.stats.refused_joins += 1;
                let reason = "this room's host joined with a token and holds no key: it \
                              cannot admit anyone until a peer with the key hosts"
                    .to_string();
                self.send_control(now, from, &Control::refused(reason));
                return true;
            }
            return false;
        };
        let nonce = match self.challenges.open.get(&from) {
            Some((n, _)) => *n,
            None => {
                if self.challenges.open.len() >= MAX_STRANGERS {
                    // bounded: the oldest challenge goes (its joiner is told if it answers)
                    let oldest = self
                        .challenges
                        .open
                        .iter()
                        .min_by_key(|(_, (_, at))| *at)
                        .map(|(p, _)| *p);
                    if let Some(p) = oldest {
                        self.challenges.open.remove(&p);
                    }
                }
                self.challenges.issued += 1;
                let n = key.nonce(self.local, from, self.challenges.issued, now);
                self.challenges.open.insert(from, (n, now));
                n
            }
        };
        self.send_control(now, from, &Control::Challenge { nonce });
        true
    }

    /// Joiner: our contact challenges us.
    pub(super) fn on_challenge(&mut self, now: Instant, from: PeerId, nonce: [u8; 16]) {
        match (self.cfg.room_key.clone(), self.cfg.room_token.clone()) {
            (Some(key), _) => {
                let tag = key.proof(&nonce, self.local, from);
                let mut mac = [0u8; 32];
                mac.copy_from_slice(tag.as_ref().get(..32).unwrap_or(&[0; 32]));
                self.send_control(now, from, &Control::Proof { mac });
            }
            (None, Some(token)) => {
                self.send_control(now, from, &Control::TokenProof { token });
            }
            (None, None) => self.on_refused(
                "the room needs a key and this peer has none (--room-key-file, or \
                 SOFTSYNC_ROOM_KEY, or a join token: --room-token)"
                    .into(),
            ),
        }
    }

    /// Host: a joiner shows a join token. Admitted if it is this room's, unexpired, and not
    /// used by another peer; refused with the reason otherwise.
    pub(super) fn on_token_proof(&mut self, now: Instant, from: PeerId, token: RoomToken) {
        if self.cfg.room_key.is_none() {
            self.stats.refused_controls += 1;
            return;
        }
        if self.members.contains_key(&from) {
            return;
        }
        if self.challenges.open.remove(&from).is_none() {
            self.stats.refused_controls += 1;
            let reason = "no open challenge for this peer (it expired): join again".to_string();
            self.send_control(now, from, &Control::refused(reason));
            return;
        }
        let verdict = self.token_admits(&token, from, now).and_then(|()| {
            // bounded, and a valid token is never forgotten: when the room remembers as many
            // unexpired tokens as it can, it takes no new one
            let used = &self.challenges.tokens_used;
            if !used.contains_key(&token.nonce) && self.tokens_used_live(now) >= MAX_TOKENS_USED {
                return Err(
                    "the room has taken as many join tokens as it remembers: ask for the key",
                );
            }
            Ok(())
        });
        if let Err(why) = verdict {
            self.stats.refused_joins += 1;
            self.send_control(now, from, &Control::refused(why));
            return;
        }
        self.admit(now, from);
        if self.members.contains_key(&from) {
            let used = Control::TokenUsed {
                nonce: token.nonce,
                peer: from,
                expires_unix: token.expires_unix,
            };
            self.note_token_used(now, token.nonce, from, token.expires_unix);
            self.broadcast(now, &used, None);
        }
    }

    /// Whether `token` admits peer `who` at `now`: signed with the room's key for this room,
    /// unexpired, and not used by another peer (the host's check at a join; a member serving
    /// the scene asks the same before it sends anything of a keyed room). Why not, if not.
    pub fn token_admits(
        &self,
        token: &RoomToken,
        who: PeerId,
        now: Instant,
    ) -> Result<(), &'static str> {
        let Some(key) = self.cfg.room_key.as_ref() else {
            return Err("this peer holds no room key to check a join token");
        };
        key.check_token(token, now)?;
        if self.token_banned(&token.nonce) || self.is_banned(who) {
            return Err("banned from this room by its host");
        }
        match self.challenges.tokens_used.get(&token.nonce) {
            Some((p, _)) if *p != who => Err("the join token was used by another peer"),
            _ => Ok(()),
        }
    }

    /// Used tokens not yet expired at `now` (all of them without a clock).
    fn tokens_used_live(&self, now: Instant) -> usize {
        let t = self.cfg.room_key.as_ref().and_then(|k| k.unix_now(now));
        self.challenges
            .tokens_used
            .values()
            .filter(|(_, exp)| t.is_none_or(|t| *exp > t))
            .count()
    }

    /// A token was used (by us as host, or our host says so).
    pub(super) fn note_token_used(
        &mut self,
        now: Instant,
        nonce: [u8; 16],
        peer: PeerId,
        expires_unix: u64,
    ) {
        let used = &mut self.challenges.tokens_used;
        if let Some(t) = self.cfg.room_key.as_ref().and_then(|k| k.unix_now(now)) {
            used.retain(|_, (_, exp)| *exp > t);
        }
        while used.len() >= MAX_TOKENS_USED {
            let soonest = used.iter().min_by_key(|(_, (_, e))| *e).map(|(n, _)| *n);
            match soonest {
                Some(n) => used.remove(&n),
                None => break,
            };
        }
        used.insert(nonce, (peer, expires_unix));
    }

    /// Host: the used tokens, to a new member (after its snapshot).
    pub(super) fn send_tokens_used(&mut self, now: Instant, to: PeerId) {
        let all: Vec<Control> = self
            .challenges
            .tokens_used
            .iter()
            .map(|(nonce, (peer, expires_unix))| Control::TokenUsed {
                nonce: *nonce,
                peer: *peer,
                expires_unix: *expires_unix,
            })
            .collect();
        for c in all {
            self.send_control(now, to, &c);
        }
    }

    /// Host: a joiner's proof. Right: admitted; wrong: refused with a reason; no open
    /// challenge for it (never issued, or given up under a flood): refused, so the joiner
    /// does not wait forever, and counted.
    pub(super) fn on_proof(&mut self, now: Instant, from: PeerId, mac: [u8; 32]) {
        let Some(key) = self.cfg.room_key.clone() else {
            self.stats.refused_controls += 1;
            return;
        };
        if self.members.contains_key(&from) {
            return; // a member already (a proof repeated)
        }
        let Some((nonce, _)) = self.challenges.open.remove(&from) else {
            self.stats.refused_controls += 1;
            let reason = "no open challenge for this peer (it expired): join again".to_string();
            self.send_control(now, from, &Control::refused(reason));
            return;
        };
        if self.role == Role::Host && key.verify(&nonce, from, self.local, &mac) {
            self.admit(now, from);
        } else {
            self.stats.refused_joins += 1;
            let reason = "wrong room key".to_string();
            self.send_control(now, from, &Control::refused(reason));
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::super::testkit::{config, Wire};
    use super::super::Event;
    use super::*;

    fn keyed(secret: &[u8], seed: u64) -> crate::SessionConfig {
        let mut c = config();
        c.room_key = Some(RoomKey::new(secret, seed));
        c
    }

    fn refusal(w: &mut Wire, p: u64) -> Option<String> {
        w.events(p).into_iter().find_map(|e| match e {
            Event::Refused { reason } => Some(reason),
            _ => None,
        })
    }

    #[test]
    fn only_a_joiner_with_the_key_gets_in() {
        let mut w = Wire::new();
        w.add(Session::host(
            PeerId(1),
            keyed(b"open sesame, 16+", 1),
            w.now,
        ));
        w.add(Session::join(
            PeerId(2),
            PeerId(1),
            keyed(b"open sesame, 16+", 2),
            w.now,
        ));
        w.add(Session::join(PeerId(3), PeerId(1), config(), w.now));
        w.add(Session::join(
            PeerId(4),
            PeerId(1),
            keyed(b"guess", 4),
            w.now,
        ));
        w.settle();
        assert!(w.get(2).is_connected());
        let none = refusal(&mut w, 3).unwrap();
        assert!(none.contains("needs a key"), "{none}");
        assert_eq!(refusal(&mut w, 4).as_deref(), Some("wrong room key"));
        assert_eq!(w.get(1).members().len(), 2);
        assert_eq!(w.get(1).stats().refused_joins, 1);
        // the key is never in the configuration's debug text
        assert!(!format!("{:?}", keyed(b"open sesame, 16+", 1)).contains("sesame"));
    }

    #[test]
    fn a_captured_proof_is_worthless_to_another_peer_or_a_later_join() {
        let secret = b"open sesame, 16+";
        let mut w = Wire::new();
        w.add(Session::host(PeerId(1), keyed(secret, 1), w.now));
        w.add(Session::join(PeerId(5), PeerId(1), config(), w.now));
        w.settle();
        // peer 5 (no key) was challenged; an eavesdropper computes nothing from it, and a
        // proof made for peer 2's nonce, or for another host, does not open the door for 5
        let key = RoomKey::new(secret, 9);
        let other_nonce = [7u8; 16];
        let tag = key.proof(&other_nonce, PeerId(2), PeerId(1));
        let mut mac = [0u8; 32];
        mac.copy_from_slice(tag.as_ref());
        let mut s = Session::join(PeerId(6), PeerId(1), config(), w.now);
        s.send_raw_control(w.now, PeerId(1), &Control::Proof { mac });
        w.add(s);
        w.settle();
        assert_eq!(w.get(1).members().len(), 1, "nobody got in");
        // 6 has an open challenge now (its Hello), but the replayed proof does not match it
        let mut s = Session::join(PeerId(7), PeerId(1), config(), w.now);
        s.send_raw_control(w.now, PeerId(1), &Control::Proof { mac });
        w.add(s);
        w.settle();
        assert_eq!(w.get(1).members().len(), 1);
    }
}

#[cfg(test)]
mod joining_guards {
    #![allow(clippy::unwrap_used)]
    use super::super::testkit::{config, Wire};
    use super::super::Event;
    use super::*;

    #[test]
    fn only_the_peer_a_joiner_asked_may_welcome_refuse_or_redirect_it() {
        let mut w = Wire::new();
        let mut cfg = config();
        cfg.room_key = Some(RoomKey::new(b"a long random room secret", 1));
        w.add(Session::host(PeerId(1), cfg.clone(), w.now));
        w.add(Session::join(PeerId(2), PeerId(1), cfg, w.now));
        // a stranger tries to take the joiner over before the host answers
        let mut stranger = Session::host(PeerId(9), config(), w.now);
        let now = w.now;
        let welcome = Control::Welcome {
            term: crate::Term(1),
            host: PeerId(9),
            join_seq: 1,
            members: vec![(PeerId(9), 0), (PeerId(2), 1)],
        };
        stranger.send_raw_control(now, PeerId(2), &welcome);
        stranger.send_raw_control(
            now,
            PeerId(2),
            &Control::Refused {
                reason: "go away".into(),
            },
        );
        stranger.send_raw_control(now, PeerId(2), &Control::Redirect { host: PeerId(9) });
        w.add(stranger);
        w.settle();
        assert_eq!(w.get(2).host_id(), Some(PeerId(1)));
        assert!(w.get(2).is_connected(), "the real host admitted it");
        assert!(!w
            .events(2)
            .iter()
            .any(|e| matches!(e, Event::Refused { .. })));
    }

    #[test]
    fn a_proof_without_an_open_challenge_is_refused_so_nobody_waits_forever() {
        let mut w = Wire::new();
        let mut cfg = config();
        cfg.room_key = Some(RoomKey::new(b"a long random room secret", 1));
        w.add(Session::host(PeerId(1), cfg, w.now));
        let mut s = Session::host(PeerId(5), config(), w.now);
        s.send_raw_control(w.now, PeerId(1), &Control::Proof { mac: [0; 32] });
        w.add(s);
        w.settle();
        assert_eq!(w.get(1).stats().refused_controls, 1);
        assert_eq!(w.get(1).members().len(), 1);
        assert_eq!(
            RoomKey::new(b"same", 1),
            RoomKey::new(b"same", 2),
            "keys compare by secret"
        );
        assert_ne!(RoomKey::new(b"same", 1), RoomKey::new(b"other", 1));
    }
}

#[cfg(test)]
#[path = "access/tests.rs"]
mod tokens;
