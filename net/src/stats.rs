//! Traffic and quality statistics: cumulative counters the caller turns into rates.

use std::collections::BTreeMap;
use std::time::Duration;

use crate::ids::PeerId;

/// Counters of one direction.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Traffic {
    /// Datagram bytes (our header + sections; transport headers excluded).
    pub bytes: u64,
    /// Datagrams.
    pub packets: u64,
}

impl Traffic {
    /// (bytes/s, packets/s) between an `earlier` reading and this one, `dt` apart.
    pub fn rate_since(&self, earlier: &Traffic, dt: Duration) -> (f64, f64) {
        let s = dt.as_secs_f64().max(1e-9);
        (
            self.bytes.saturating_sub(earlier.bytes) as f64 / s,
            self.packets.saturating_sub(earlier.packets) as f64 / s,
        )
    }

    pub(crate) fn add(&mut self, bytes: usize) {
        self.bytes += bytes as u64;
        self.packets += 1;
    }
}

/// Per-peer link statistics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinkStats {
    /// Sent to the peer.
    pub up: Traffic,
    /// Received from the peer.
    pub down: Traffic,
    /// Smoothed round-trip time.
    pub rtt: Option<Duration>,
    /// Datagrams the peer sent that never arrived (from sequence gaps).
    pub lost: u64,
    /// Datagrams expected from the peer (received + lost).
    pub expected: u64,
}

impl LinkStats {
    /// Fraction of the peer's datagrams lost.
    pub fn loss(&self) -> f64 {
        if self.expected == 0 {
            0.0
        } else {
            self.lost as f64 / self.expected as f64
        }
    }
}

/// Session-wide statistics.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    /// Per remote peer.
    pub links: BTreeMap<PeerId, LinkStats>,
    /// State bytes sent per object class name (entry bits rounded up per datagram share).
    pub class_up_bytes: BTreeMap<String, f64>,
    /// State bytes received per object class name.
    pub class_down_bytes: BTreeMap<String, f64>,
    /// Total up traffic.
    pub up: Traffic,
    /// Total down traffic.
    pub down: Traffic,
    /// Sum of datagram sizes / mtu, for the average MTU fill.
    pub mtu_fill_sum: f64,
    /// Largest datagram sent.
    pub max_datagram: usize,
    /// State updates dropped: stale authority epoch.
    pub dropped_stale_epoch: u64,
    /// State updates dropped: sender does not own the object.
    pub dropped_non_owner: u64,
    /// Datagrams ignored: older room term.
    pub dropped_old_term: u64,
    /// Acks of reliable messages never sent on the link, ignored (a stale ack of an earlier
    /// session of the peer's, arriving after it joined again).
    pub implausible_acks: u64,
    /// Datagrams that failed to decode.
    pub decode_errors: u64,
    /// Beacons sent to peers the room lost (partition healing).
    pub beacons_sent: u64,
    /// Beacons heard from another room of ours (a partition healed).
    pub beacons_heard: u64,
    /// Beacons ignored: not from a peer the room lost, an implausible member count, or (in a
    /// room with a key) no valid tag.
    pub beacons_refused: u64,
    /// Beacons of strangers whose room loses to ours, answered with our beacon (they may
    /// have lost us without our ever knowing them; see `session::heal`).
    pub beacons_answered_strangers: u64,
    /// Requests of a member over its rate (`MAX_REQUESTS_PER_S` at the host, and keyframe
    /// requests over `MAX_KEYFRAME_REQUESTS_PER_S`), refused.
    pub requests_rate_limited: u64,
    /// Times this peer's room yielded to another after a partition (0 or 1 per session).
    pub merges: u64,
    /// Delta updates whose base was missing (a keyframe was requested).
    pub chain_breaks: u64,
    /// Entries too large for any datagram (never sent).
    pub oversize_dropped: u64,
    /// Datagrams dropped because too many unknown senders already have state.
    pub dropped_strangers: u64,
    /// Strangers forgotten to make room for a new one (`PeerBudget::stranger_evictable_after`).
    pub strangers_evicted: u64,
    /// Control messages or claims refused: out of place (e.g. a `Resync` outside the window
    /// after a migration), implausible (an epoch or id the sender cannot know) or over a
    /// per-peer limit.
    pub refused_controls: u64,
    /// Host: joiners refused for a wrong room key.
    pub refused_joins: u64,
    /// Control messages not sent because they could not be encoded (over their size limit).
    pub unencodable_controls: u64,
    /// Control messages not queued because the peer's reliable channel was full
    /// (`reliable::MAX_QUEUED` unacknowledged).
    pub controls_over_quota: u64,
    /// Host: members dropped for acknowledging too little (`PeerBudget::max_control_in_flight`).
    pub dropped_over_quota: u64,
    /// Host: peers kicked out and banned (`Session::kick`).
    pub kicked: u64,
    /// Datagrams from banned peers dropped (a host answers them with the reason, at most
    /// once per heartbeat).
    pub banned_dropped: u64,
    /// Host: repeated `Hello`s of members not answered with another `Welcome` (one was in
    /// flight, or sent less than `PeerBudget::rewelcome_every` ago).
    pub repeated_hellos_ignored: u64,
    /// Application messages.
    pub messages: MessageStats,
}

/// Application message counters.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MessageStats {
    /// Messages we sent (accepted by our own checks).
    pub sent: u64,
    /// Messages delivered to us.
    pub received: u64,
    /// Host: copies relayed to targets.
    pub relayed: u64,
    /// Our reliable messages that reached every target.
    pub delivered: u64,
    /// Reliable messages we had already (resent after a migration), dropped.
    pub duplicates: u64,
    /// Host: relayed reliable messages given up on for a target that stayed a member but did
    /// not acknowledge within four peer timeouts.
    pub unacknowledged: u64,
    /// Unreliable messages dropped: a full queue, or too big for a datagram.
    pub unreliable_dropped: u64,
    /// Refusals by reason: ours (at send, or told by the host) and, at the host, those it
    /// refused for members.
    pub refused: BTreeMap<crate::wire::MessageRefusal, u64>,
}

impl Stats {
    /// State bits sent per class (by index into `classes`).
    pub(crate) fn add_class_bits(
        &mut self,
        classes: &[crate::policy::ClassConfig],
        bits: BTreeMap<u16, usize>,
    ) {
        for (c, b) in bits {
            if let Some(cl) = classes.get(usize::from(c)) {
                *self.class_up_bytes.entry(cl.name.clone()).or_default() += b as f64 / 8.0;
            }
        }
    }

    pub(crate) fn on_send(&mut self, to: PeerId, bytes: usize, mtu: usize) {
        self.up.add(bytes);
        self.links.entry(to).or_default().up.add(bytes);
        self.mtu_fill_sum += bytes as f64 / mtu.max(1) as f64;
        self.max_datagram = self.max_datagram.max(bytes);
    }

    pub(crate) fn on_recv(&mut self, from: PeerId, bytes: usize) {
        self.down.add(bytes);
        self.links.entry(from).or_default().down.add(bytes);
    }

    /// Average datagram size as a fraction of the MTU.
    pub fn mtu_fill(&self) -> f64 {
        if self.up.packets == 0 {
            0.0
        } else {
            self.mtu_fill_sum / self.up.packets as f64
        }
    }
}

/// Estimated per-datagram overhead of the WebRTC data channel stack below us:
/// IPv4 20 + UDP 8 + DTLS 1.2 record header 13 (+ AEAD tag/nonce ~16… counted as 13 here,
/// see docs) + SCTP common header 12 + DATA chunk header 16 = 69 bytes.
pub const TRANSPORT_OVERHEAD_BYTES: usize = 20 + 8 + 13 + 12 + 16;
