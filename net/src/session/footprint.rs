//! What a session holds, per remote peer and for the room, and the caps the code keeps it
//! under: a diagnostic for applications, and what `crate::fuzzing::play_session` asserts
//! after every step (issue 32, "a fuzzer that plays sessions").
//!
//! [`Session::footprint`] reads the session's fields and its parts' crate API, and is cheap.
//! A few parts keep their entries private to their module and have no length accessor (the
//! open challenges, the `NewHost`s kept for later, the asks in flight, the peers remembered
//! as dropped or departed, the keyframe requests); their entries are counted from the part's
//! `Debug` text, which is small unless the part is big. [`Session::leftovers`] looks for
//! state kept for objects the session no longer knows and for peers it keeps no link to:
//! state that nothing bounds but the lifetime of the session. It formats the delta state of
//! every link, so it is a check to run now and then, not a per-frame figure.
//!
//! Every cap below is derived from a constant of the code (named in its doc) or from the
//! session's configuration; [`Footprint::check`] compares a footprint with them.

use std::collections::{BTreeMap, BTreeSet};

use super::link::MAX_KEYFRAME_REQUESTS_PER_S;
use super::topology::MAX_TOPOLOGY_LOG;
use super::{Session, MAX_STRANGERS};
use crate::ids::{NetId, PeerId};
use crate::policy::{SessionConfig, SoftBodyMode};
use crate::reliable::MAX_QUEUED;
use crate::time::Instant;
use crate::wire::{ENTRY_SEQ_MOD, MAX_CONTROL_LEN, MAX_MEMBERS};

/// Control messages one link may hold unacknowledged: its reliable channel refuses more
/// (`reliable::MAX_QUEUED`).
pub const MAX_UNACKED_PER_PEER: usize = MAX_QUEUED;

/// Bytes of one queued control message or unreliable message section: `Control::encode`
/// refuses a control message longer than `wire::MAX_CONTROL_LEN`, and an application message
/// envelope is bounded by the same limit.
pub const MAX_MESSAGE_BYTES: usize = MAX_CONTROL_LEN;

/// Links to peers that are neither members nor our host: `MAX_STRANGERS` senders admitted at
/// once, plus the members a takeover found dead, whose links stay until they are forgotten
/// as silent strangers (at most a room of them, `wire::MAX_MEMBERS`).
pub const MAX_STRANGER_LINKS: usize = MAX_STRANGERS + MAX_MEMBERS;

/// Open challenges of a host with a room key: `access` evicts the oldest past
/// `MAX_STRANGERS`.
pub const MAX_OPEN_CHALLENGES: usize = MAX_STRANGERS;

/// Control messages kept after one sender's `NewHost` until it is adopted: mirrors
/// `MAX_DEFERRED_CONTROLS` in `session/migration.rs` (private there; past it the `NewHost`
/// is dropped).
pub const MAX_DEFERRED_PER_SENDER: usize = 4096;

/// Peers remembered as departed, or as dropped by the host: mirrors `MAX_REMEMBERED` in
/// `session/liveness.rs` (private there; the set is cleared when full).
pub const MAX_REMEMBERED_PEERS: usize = 256;

/// Peers a room lost that it still sends beacons to: mirrors `MAX_LOST` in
/// `session/heal.rs` (private there; the oldest go first).
pub const MAX_LOST_PEERS: usize = 64;

/// Entries in flight for one object part toward one peer: `SendParts::emit` keeps the last
/// `ENTRY_SEQ_MOD − 8` (24) unacknowledged ones, so a wire sequence names one of them.
pub const MAX_UNACKED_ENTRIES_PER_PART: usize = ENTRY_SEQ_MOD as usize - 8;

/// State entries waiting for one peer's next datagram, per object part: one from the send
/// tick, and one per keyframe request section the peer may make a second
/// (`link::MAX_KEYFRAME_REQUESTS_PER_S`).
pub const MAX_PENDING_PER_PART: usize = 1 + MAX_KEYFRAME_REQUESTS_PER_S as usize;

/// What a session holds for one remote peer.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PeerFootprint {
    /// A member of the room, or our host.
    pub member: bool,
    /// We keep link state for it.
    pub link: bool,
    /// Control messages queued to it and not acknowledged.
    pub unacked: usize,
    /// Their encoded bytes.
    pub unacked_bytes: usize,
    /// Objects whose `Spawn` it has not acknowledged (no state flows before).
    pub spawn_pending: usize,
    /// Of those, objects we no longer know.
    pub spawn_pending_unknown: usize,
    /// State entries waiting for the next datagram to it.
    pub pending_entries: usize,
    /// Unreliable application messages waiting for the next datagram to it.
    pub unreliable: usize,
    /// Their bytes.
    pub unreliable_bytes: usize,
    /// Parts of objects we know with sending state (a delta chain) toward it.
    pub send_parts: usize,
    /// Entries of those parts sent and not acknowledged.
    pub send_unacked: usize,
    /// Objects waiting their turn under the uplink budget (one of an object gone since is
    /// dropped when the budget next lets state go to the peer).
    pub dirty: usize,
    /// Object ids we asked it keyframes of (remembered for the rate limit) or will ask.
    pub keyframe_ids: usize,
    /// Its statistics are kept (`Stats::links`).
    pub stats: bool,
}

/// What a session holds: per remote peer, and for the room.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Footprint {
    /// Every peer we keep link state or statistics for.
    pub peers: BTreeMap<PeerId, PeerFootprint>,
    /// Members of the room (us included).
    pub members: usize,
    /// Are we the host?
    pub host: bool,
    /// Links to peers that are neither members nor our host.
    pub strangers: usize,
    /// Objects we know.
    pub objects: usize,
    /// Their parts (transform, particle chunks): what per-part state is kept for.
    pub object_parts: usize,
    /// Topology log entries of all objects.
    pub topology_entries: usize,
    /// The longest topology log.
    pub longest_topology_log: usize,
    /// Retained application messages.
    pub retained_messages: usize,
    /// Message kinds of the room (a retained message is kept per kind and object).
    pub message_kinds: usize,
    /// Our reliable messages not delivered everywhere yet.
    pub outbox: usize,
    /// Our spawn requests the host has not answered.
    pub pending_spawns: usize,
    /// Events the application has not polled.
    pub events: usize,
    /// Datagrams written outside the links (refusals, beacons) not polled.
    pub raw_out: usize,
    /// Peers the room lost that we send beacons to.
    pub lost_peers: usize,
    /// Host: open challenges (a room with a key).
    pub open_challenges: usize,
    /// `NewHost`s kept for later (one per sender at most).
    pub waiting_new_hosts: usize,
    /// Control messages kept after them.
    pub deferred_controls: usize,
    /// Peers remembered as dropped by this host.
    pub dropped_peers: usize,
    /// Peers remembered as departed.
    pub departed_peers: usize,
}

/// State a session keeps for objects it no longer knows, or for peers it keeps no link to:
/// nothing bounds it but the session's lifetime (see [`Session::leftovers`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Leftovers {
    /// Per peer: object parts with sending state for objects we no longer know.
    pub send_parts: BTreeMap<PeerId, usize>,
    /// Per peer: object parts with receiving state (delta bases) for objects we no longer
    /// know.
    pub delta_parts: BTreeMap<PeerId, usize>,
    /// Per peer: keyframe requests remembered for objects we no longer know.
    pub keyframe_ids: BTreeMap<PeerId, usize>,
    /// Objects we no longer know with asks remembered (`OwnerMustAgree`).
    pub asks: usize,
    /// Peers with statistics and neither link state nor membership (a gone peer's).
    pub stats_without_link: Vec<PeerId>,
}

impl Leftovers {
    /// Nothing left over.
    pub fn is_empty(&self) -> bool {
        *self == Leftovers::default()
    }
}

impl Footprint {
    /// Every figure within its cap (see the constants of this module), or the first one that
    /// is not, said in words. `cfg` is the session's configuration.
    pub fn check(&self, cfg: &SessionConfig) -> Result<(), String> {
        let fail = |what: String| Err(what);
        let member_cap = if self.host {
            cfg.max_members
        } else {
            MAX_MEMBERS
        };
        if self.members > member_cap {
            return fail(format!("{} members, cap {member_cap}", self.members));
        }
        if self.strangers > MAX_STRANGER_LINKS {
            return fail(format!(
                "{} stranger links, cap {MAX_STRANGER_LINKS}",
                self.strangers
            ));
        }
        if self.longest_topology_log > MAX_TOPOLOGY_LOG {
            return fail(format!(
                "a topology log of {} entries, cap {MAX_TOPOLOGY_LOG}",
                self.longest_topology_log
            ));
        }
        let retained_cap = self.message_kinds * (self.objects + 1);
        if self.retained_messages > retained_cap {
            return fail(format!(
                "{} retained messages, cap {retained_cap} (kinds × (objects + 1))",
                self.retained_messages
            ));
        }
        if self.outbox > cfg.messages.max_outbox {
            return fail(format!(
                "{} messages in the outbox, cap {}",
                self.outbox, cfg.messages.max_outbox
            ));
        }
        if self.lost_peers > MAX_LOST_PEERS {
            return fail(format!(
                "{} lost peers, cap {MAX_LOST_PEERS}",
                self.lost_peers
            ));
        }
        if self.open_challenges > MAX_OPEN_CHALLENGES {
            return fail(format!(
                "{} open challenges, cap {MAX_OPEN_CHALLENGES}",
                self.open_challenges
            ));
        }
        // one NewHost kept per sender, and senders are members
        if self.waiting_new_hosts > MAX_MEMBERS {
            return fail(format!(
                "{} NewHosts waiting, cap {MAX_MEMBERS}",
                self.waiting_new_hosts
            ));
        }
        let deferred_cap = self.waiting_new_hosts * MAX_DEFERRED_PER_SENDER;
        if self.deferred_controls > deferred_cap {
            return fail(format!(
                "{} deferred controls, cap {deferred_cap}",
                self.deferred_controls
            ));
        }
        if self.dropped_peers > MAX_REMEMBERED_PEERS || self.departed_peers > MAX_REMEMBERED_PEERS {
            return fail(format!(
                "{} dropped and {} departed peers remembered, cap {MAX_REMEMBERED_PEERS}",
                self.dropped_peers, self.departed_peers
            ));
        }
        for (p, f) in &self.peers {
            f.check(self, cfg)
                .map_err(|e| format!("peer {}: {e}", p.0))?;
        }
        Ok(())
    }
}

impl PeerFootprint {
    fn check(&self, room: &Footprint, cfg: &SessionConfig) -> Result<(), String> {
        let fail = |what: String| Err(what);
        if self.unacked > MAX_UNACKED_PER_PEER {
            return fail(format!(
                "{} unacknowledged controls, cap {MAX_UNACKED_PER_PEER}",
                self.unacked
            ));
        }
        if self.unacked_bytes > self.unacked * MAX_MESSAGE_BYTES {
            return fail(format!(
                "{} bytes in {} unacknowledged controls, cap {MAX_MESSAGE_BYTES} each",
                self.unacked_bytes, self.unacked
            ));
        }
        if self.spawn_pending > room.objects + self.spawn_pending_unknown
            || self.spawn_pending_unknown > 0
        {
            return fail(format!(
                "{} spawns unacknowledged, {} of objects we no longer know",
                self.spawn_pending, self.spawn_pending_unknown
            ));
        }
        let pending_cap = room.object_parts * MAX_PENDING_PER_PART;
        if self.pending_entries > pending_cap {
            return fail(format!(
                "{} state entries pending, cap {pending_cap} ({} parts × {MAX_PENDING_PER_PART})",
                self.pending_entries, room.object_parts
            ));
        }
        let unreliable_cap = cfg.messages.max_unreliable_queue;
        if self.unreliable > unreliable_cap
            || self.unreliable_bytes > self.unreliable * MAX_MESSAGE_BYTES
        {
            return fail(format!(
                "{} unreliable messages ({} bytes) queued, cap {unreliable_cap} of \
                 {MAX_MESSAGE_BYTES} bytes",
                self.unreliable, self.unreliable_bytes
            ));
        }
        let unacked_cap = self.send_parts * MAX_UNACKED_ENTRIES_PER_PART;
        if self.send_unacked > unacked_cap {
            return fail(format!(
                "{} state entries unacknowledged, cap {unacked_cap}",
                self.send_unacked
            ));
        }
        // a member's statistics may come before its link (a datagram of a member we have
        // not spoken to); a stranger's or a gone peer's may not
        if self.stats && !self.link && !self.member {
            return fail("statistics kept without link state or membership".into());
        }
        Ok(())
    }
}

impl Session {
    /// What this session holds, per remote peer and for the room (see the module doc; the
    /// caps are checked by [`Footprint::check`]).
    pub fn footprint(&self) -> Footprint {
        let known: BTreeSet<NetId> = self.objects.ids().into_iter().collect();
        let parts = self.object_parts();
        let mut peers: BTreeMap<PeerId, PeerFootprint> = BTreeMap::new();
        for (p, l) in &self.links {
            // the bytes of the unacknowledged messages: walk a copy as if every one were due
            let mut unacked_bytes = 0usize;
            if l.reliable.in_flight() > 0 {
                let mut copy = l.reliable.clone();
                copy.take_due(
                    Instant::from_micros(u64::MAX),
                    std::time::Duration::ZERO,
                    |_, b| {
                        unacked_bytes += b.len();
                        true
                    },
                );
            }
            let mut send_parts = 0;
            let mut send_unacked = 0;
            for key in &parts {
                if let Some(sp) = l.send.get(key) {
                    send_parts += 1;
                    send_unacked += sp.unacked.len();
                }
            }
            let keyframes = format!("{:?}", l.keyframes);
            peers.insert(
                *p,
                PeerFootprint {
                    member: self.members.contains_key(p) || Some(*p) == self.host,
                    link: true,
                    unacked: l.reliable.in_flight(),
                    unacked_bytes,
                    spawn_pending: l.spawn_pending.len(),
                    spawn_pending_unknown: l
                        .spawn_pending
                        .keys()
                        .filter(|id| !known.contains(id))
                        .count(),
                    pending_entries: l.pending.len(),
                    unreliable: l.unreliable.len(),
                    unreliable_bytes: l.unreliable.iter().map(Vec::len).sum(),
                    send_parts,
                    send_unacked,
                    dirty: l.dirty.len(),
                    keyframe_ids: field_entries(&keyframes, "asked_at")
                        .first()
                        .map_or(0, Vec::len),
                    stats: false,
                },
            );
        }
        for p in self.stats.links.keys() {
            peers
                .entry(*p)
                .or_insert_with(|| PeerFootprint {
                    member: self.members.contains_key(p) || Some(*p) == self.host,
                    ..PeerFootprint::default()
                })
                .stats = true;
        }
        let succession = format!("{:?}", self.succession);
        let dropped = format!("{:?}", self.dropped);
        let departed = format!("{:?}", self.departed);
        let challenges = format!("{:?}", self.challenges);
        let count =
            |text: &str, field: &str| field_entries(text, field).first().map_or(0, Vec::len);
        let logs: Vec<usize> = self
            .objects
            .iter()
            .map(|o| o.topology.entries.len())
            .collect();
        Footprint {
            peers,
            members: self.members.len(),
            host: self.is_host(),
            strangers: self.stranger_count(),
            objects: known.len(),
            object_parts: parts.len(),
            topology_entries: logs.iter().sum(),
            longest_topology_log: logs.iter().copied().max().unwrap_or(0),
            retained_messages: self.retained_messages().count(),
            message_kinds: self.cfg.messages.kinds.len(),
            outbox: self.messages_in_flight(),
            pending_spawns: self.spawns.iter().count(),
            events: self.events.len(),
            raw_out: self.raw_out.len(),
            lost_peers: self.lost_peers().len(),
            open_challenges: count(&challenges, "open"),
            waiting_new_hosts: count(&succession, "pending"),
            deferred_controls: field_entries(&succession, "later")
                .iter()
                .map(Vec::len)
                .sum(),
            dropped_peers: count(&dropped, "peers"),
            departed_peers: count(&departed, "peers"),
        }
    }

    /// State kept for objects this session no longer knows, or for peers it keeps no link
    /// to (see [`Leftovers`]). Formats every link's delta state: slow, for checks.
    pub fn leftovers(&self) -> Leftovers {
        let known: BTreeSet<NetId> = self.objects.ids().into_iter().collect();
        let unknown = |entries: &[&str]| {
            entries
                .iter()
                .filter_map(|e| first_net_id(e))
                .filter(|id| !known.contains(id))
                .count()
        };
        let mut out = Leftovers::default();
        let note = |map: &mut BTreeMap<PeerId, usize>, p: PeerId, n: usize| {
            if n > 0 {
                map.insert(p, n);
            }
        };
        for (p, l) in &self.links {
            let send = format!("{:?}", l.send);
            let recv = format!("{:?}", l.recv);
            let keyframes = format!("{:?}", l.keyframes);
            let first = |text: &str, field: &str| {
                field_entries(text, field)
                    .first()
                    .map_or(0, |e| unknown(e.as_slice()))
            };
            note(&mut out.send_parts, *p, first(&send, "parts"));
            note(&mut out.delta_parts, *p, first(&recv, "parts"));
            note(&mut out.keyframe_ids, *p, first(&keyframes, "asked_at"));
        }
        let asks = format!("{:?}", self.asks);
        out.asks = field_entries(&asks, "asks")
            .first()
            .map_or(0, |e| unknown(e.as_slice()));
        out.stats_without_link = self
            .stats
            .links
            .keys()
            .filter(|p| {
                !self.links.contains_key(p)
                    && !self.members.contains_key(p)
                    && Some(**p) != self.host
            })
            .copied()
            .collect();
        out
    }

    /// Every part of every known object: the transform, and the particle chunks of a soft
    /// body replicated with its particles.
    fn object_parts(&self) -> Vec<(NetId, u32)> {
        let mut parts = Vec::new();
        for o in self.objects.iter() {
            parts.push((o.info.id, 0));
            let Some(class) = self.cfg.class(o.info.class) else {
                continue;
            };
            if class.soft_body_mode == SoftBodyMode::Particles {
                let chunks = (o.info.particles as usize).div_ceil(class.chunk_len());
                parts.extend((1..=chunks as u32).map(|c| (o.info.id, c)));
            }
        }
        parts
    }
}

/// The top-level entries of every collection `field: {…}` or `field: […]` in derived `Debug`
/// text, outermost first (for the parts whose entries are private to their module).
fn field_entries<'a>(text: &'a str, field: &str) -> Vec<Vec<&'a str>> {
    let mut out = Vec::new();
    let pat = format!("{field}: ");
    let mut from = 0;
    while let Some(at) = text.get(from..).and_then(|t| t.find(&pat)) {
        let name_at = from + at;
        let start = name_at + pat.len();
        from = start;
        // a whole field name: after `{ ` or `, `
        let before = text.get(..name_at).unwrap_or_default();
        if !(before.ends_with("{ ") || before.ends_with(", ")) {
            continue;
        }
        if let Some(entries) = collection_entries(text.get(start..).unwrap_or_default()) {
            out.push(entries);
        }
    }
    out
}

/// The top-level entries of the collection `text` starts with (`{…}` or `[…]`), or `None`
/// if it starts with none.
fn collection_entries(text: &str) -> Option<Vec<&str>> {
    let open = text.chars().next()?;
    if open != '{' && open != '[' {
        return None;
    }
    let mut entries = Vec::new();
    let mut depth = 0usize;
    let mut in_str = false;
    let mut escaped = false;
    let mut entry_start = 1;
    for (i, c) in text.char_indices() {
        if in_str {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, '\\') => escaped = true,
                (false, '"') => in_str = false,
                _ => {}
            }
            continue;
        }
        match c {
            '"' => in_str = true,
            '{' | '[' | '(' => depth += 1,
            '}' | ']' | ')' => {
                depth = depth.saturating_sub(1);
                if depth == 0 {
                    let last = text.get(entry_start..i).unwrap_or_default().trim();
                    if !last.is_empty() {
                        entries.push(last);
                    }
                    return Some(entries);
                }
            }
            ',' if depth == 1 => {
                entries.push(text.get(entry_start..i).unwrap_or_default().trim());
                entry_start = i + 1;
            }
            _ => {}
        }
    }
    Some(entries)
}

/// The first `NetId(n)` an entry's `Debug` text names (its key).
fn first_net_id(entry: &str) -> Option<NetId> {
    let rest = entry.get(entry.find("NetId(")? + "NetId(".len()..)?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    digits.parse().ok().map(NetId)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::super::testkit::{config, Wire};
    use super::*;
    use crate::session::RoomKey;
    use crate::wire::Control;

    #[test]
    fn debug_text_entries_are_counted_at_the_top_level_only() {
        let text = r#"X { open: {PeerId(5): ([1, 2], Instant(3)), PeerId(7): ([4], Instant(5))}, issued: 2, tokens_used: {} }"#;
        assert_eq!(field_entries(text, "open")[0].len(), 2);
        assert_eq!(field_entries(text, "tokens_used")[0].len(), 0);
        assert!(field_entries(text, "issued").is_empty(), "not a collection");
        let nested = r#"S { pending: {PeerId(2): P { later: [Leave, Refused { reason: "a, b]" }] }}, x_later: [1] }"#;
        assert_eq!(field_entries(nested, "pending")[0].len(), 1);
        assert_eq!(
            field_entries(nested, "later")[0].len(),
            2,
            "quoted text skipped"
        );
        assert_eq!(field_entries(nested, "later").len(), 1, "whole names only");
        assert_eq!(first_net_id("(NetId(42), 3): SendPart"), Some(NetId(42)));
    }

    #[test]
    fn the_parts_debug_text_still_has_the_fields_the_footprint_counts() {
        // a keyed host challenged by three strangers, one of them twice
        let mut w = Wire::new();
        let mut cfg = config();
        cfg.room_key = Some(RoomKey::new(b"a long random room secret", 1));
        w.add(Session::host(PeerId(1), cfg, w.now));
        for p in [5, 6, 7, 7] {
            let mut s = Session::join(PeerId(p), PeerId(1), config(), w.now);
            s.send_raw_control(w.now, PeerId(1), &Control::Leave);
            while let Some(t) = s.poll_transmit(w.now) {
                let now = w.now;
                w.get(1).handle_packet(now, PeerId(p), &t.payload);
            }
        }
        let f = w.get(1).footprint();
        assert_eq!(f.open_challenges, 3);
        assert_eq!(f.strangers, 3);
        assert!(
            f.peers[&PeerId(5)].unacked >= 1,
            "the challenge waits for an ack"
        );
        assert!(f.peers[&PeerId(5)].unacked_bytes > 16, "a nonce");
        f.check(w.get(1).config()).unwrap();
        // the other counted parts print the fields looked for
        let s = w.get(1);
        assert!(format!("{:?}", s.succession).contains("pending: {"));
        assert!(format!("{:?}", s.dropped).contains("peers: {"));
        assert!(format!("{:?}", s.departed).contains("peers: {"));
        assert!(format!("{:?}", s.asks).contains("asks: {"));
        let l = s.links.values().next().unwrap();
        assert!(format!("{:?}", l.keyframes).contains("asked_at: {"));
        assert!(format!("{:?}", l.send).contains("parts: {"));
        assert!(format!("{:?}", l.recv).contains("parts: {"));
        assert!(s.leftovers().is_empty());
    }
}
