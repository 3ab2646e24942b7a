//! What this peer keeps per remote peer (`Link`): the reliable control channel, datagram
//! sequences (loss, and which datagram is the newest), the sender's clock (interpolation
//! timing), acknowledgements of state datagrams both ways, the RTT estimate, keyframe
//! requests, and what is queued to go out.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use super::delta::{DeltaBases, EntryRef, SendParts};
use crate::ids::NetId;
use crate::reliable::ReliableChannel;
use crate::stats::LinkStats;
use crate::time::Instant;
use crate::wire::{StateEntry, MAX_KEYFRAME_REQUEST};

/// A datagram this many or more datagrams older than the newest one received from its
/// sender is too late for its state entries to be used (their 5-bit sequences may alias).
const MAX_STATE_LATENESS: u8 = 16;

/// A datagram that looks 128 or more behind the newest is taken as the newest when nothing
/// advanced the datagram sequence for this long (many datagrams were lost, not one delayed).
const IN_SEQ_RESYNC_AFTER: Duration = Duration::from_millis(250);

/// How a received datagram stands against the ones received before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Arrival {
    /// The newest datagram from the peer so far: its entries are newer than any received
    /// before (entry sequences alone cannot tell after a gap of 16 or more).
    pub fresh: bool,
    /// So far behind the newest that its state entries could alias newer ones: neither
    /// applied nor acknowledged (the sender repeats what is unacknowledged).
    pub too_late: bool,
}

/// Datagram sequence numbers of one link: ours going out, and the newest that came in.
#[derive(Clone, Debug, Default)]
pub(crate) struct DatagramSeq {
    out: u8,
    newest_in: Option<u8>,
    /// When `newest_in` last advanced.
    newest_in_at: Option<Instant>,
}

impl DatagramSeq {
    /// The sequence of our next datagram.
    pub fn next_out(&self) -> u8 {
        self.out
    }

    /// Our datagram went out.
    pub fn sent(&mut self) {
        self.out = self.out.wrapping_add(1);
    }

    /// A datagram with sequence `seq` arrived at `now`: count gaps as losses in `stats`.
    pub fn on_receive(&mut self, now: Instant, seq: u8, stats: &mut LinkStats) -> Arrival {
        let mut fresh = true;
        match self.newest_in {
            Some(prev) => {
                let gap = seq.wrapping_sub(prev);
                // 8-bit sequences: after 128 or more lost datagrams every new one looks late;
                // once nothing has advanced the sequence for a while, take it as the newest
                let stuck = self
                    .newest_in_at
                    .is_some_and(|t| now >= t + IN_SEQ_RESYNC_AFTER);
                if (1..128).contains(&gap) {
                    stats.expected += u64::from(gap);
                    stats.lost += u64::from(gap - 1);
                    self.newest_in = Some(seq);
                    self.newest_in_at = Some(now);
                } else if gap >= 128 && stuck {
                    stats.expected += 1;
                    self.newest_in = Some(seq);
                    self.newest_in_at = Some(now);
                } else {
                    fresh = false;
                    if gap >= 128 && stats.lost > 0 {
                        stats.lost -= 1; // a late (reordered) datagram
                    }
                }
            }
            None => {
                stats.expected += 1;
                self.newest_in = Some(seq);
                self.newest_in_at = Some(now);
            }
        }
        let too_late = self
            .newest_in
            .is_some_and(|newest| (MAX_STATE_LATENESS..128).contains(&newest.wrapping_sub(seq)));
        Arrival { fresh, too_late }
    }
}

/// The sender's clock as seen through one link: its 16-bit millisecond stamps unwrapped,
/// mapped to ours through the smallest offset seen (the least delayed datagram), and the
/// jitter above that offset.
#[derive(Clone, Debug, Default)]
pub(crate) struct LinkClock {
    last_full_ms: Option<i64>,
    last_ms: u16,
    min_offset_us: Option<i64>,
    jitter_us: f64,
}

impl LinkClock {
    /// A datagram stamped `time_ms` (sender clock) arrived at `now`: returns the time, in our
    /// clock, that its samples describe.
    pub fn observe(&mut self, now: Instant, time_ms: u16) -> Instant {
        let full = match self.last_full_ms {
            Some(last) => last + i64::from(time_ms.wrapping_sub(self.last_ms) as i16),
            None => i64::from(time_ms),
        };
        if self.last_full_ms.is_none_or(|l| full > l) {
            self.last_full_ms = Some(full);
            self.last_ms = time_ms;
        }
        let offset = now.as_micros() as i64 - full * 1000;
        // The minimum drifts up by 20 µs per datagram, so a clock that moved is followed.
        let min = match self.min_offset_us {
            Some(m) => (m + 20).min(offset),
            None => offset,
        };
        self.min_offset_us = Some(min);
        self.jitter_us = 0.9 * self.jitter_us + 0.1 * (offset - min) as f64;
        Instant::from_micros((full * 1000 + min).max(0) as u64)
    }

    /// Smoothed delay above the least delayed datagram (µs).
    pub fn jitter_us(&self) -> f64 {
        self.jitter_us
    }

    /// The sender's clock at our time `t`.
    pub fn to_sender_time(&self, t: Instant) -> Instant {
        let src = t.as_micros() as i64 - self.min_offset_us.unwrap_or(0);
        Instant::from_micros(src.max(0) as u64)
    }
}

/// Smoothed round-trip time from pings (SRTT, 1/8 gain) and what it sets.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct RttEstimator {
    srtt: Option<Duration>,
}

impl RttEstimator {
    /// A round trip was measured.
    pub fn on_sample(&mut self, rtt: Duration) {
        self.srtt = Some(match self.srtt {
            Some(s) => (s * 7 + rtt) / 8,
            None => rtt,
        });
    }

    /// The estimate, once measured.
    pub fn srtt(&self) -> Option<Duration> {
        self.srtt
    }

    /// Retransmission timeout of reliable messages: 1.25 · SRTT + 20 ms (200 ms unmeasured),
    /// at least `min_rto`.
    pub fn rto(&self, min_rto: Duration) -> Duration {
        let srtt = self.srtt.unwrap_or(Duration::from_millis(200));
        (srtt * 5 / 4 + Duration::from_millis(20)).max(min_rto)
    }

    /// How long an unacknowledged state entry waits before it is repeated.
    pub fn ack_wait(&self) -> Duration {
        self.srtt.unwrap_or(Duration::from_millis(200)) * 3 / 2 + Duration::from_millis(30)
    }

    /// Least time between two keyframe requests for one object.
    pub fn keyframe_request_gap(&self) -> Duration {
        self.srtt
            .unwrap_or(Duration::from_millis(100))
            .max(Duration::from_millis(50))
    }
}

/// Which of the peer's state datagrams arrived: the newest sequence and a bitmap of the 32
/// before it (bit i: newest − 1 − i), what our state ack says.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct StateAckWindow {
    received: Option<(u8, u32)>,
    /// We owe the peer a state ack.
    owed: bool,
}

impl StateAckWindow {
    /// A state datagram `seq` was read in full: note it, and owe an ack.
    pub fn record(&mut self, seq: u8) {
        self.received = Some(match self.received {
            None => (seq, 0),
            Some((latest, mask)) => {
                let d = seq.wrapping_sub(latest);
                if d == 0 {
                    (latest, mask)
                } else if d < 128 {
                    // newer: shift the history by d, the old newest becomes bit d − 1
                    let shifted = if d >= 32 {
                        0
                    } else {
                        (mask << d) | (1 << (d - 1))
                    };
                    let shifted = if d == 32 { 1 << 31 } else { shifted };
                    (seq, shifted)
                } else {
                    // older: set its bit if it is within the 32 before the newest
                    let back = latest.wrapping_sub(seq);
                    let bit = if (1..=32).contains(&back) {
                        1u32 << (back - 1)
                    } else {
                        0
                    };
                    (latest, mask | bit)
                }
            }
        });
        self.owed = true;
    }

    /// The ack to send, if one is owed (the debt is paid either way).
    pub fn take_owed(&mut self) -> Option<(u8, u32)> {
        if !self.owed {
            return None;
        }
        self.owed = false;
        self.received
    }

    /// Whether an ack is owed.
    pub fn is_owed(&self) -> bool {
        self.owed
    }

    /// Forget what arrived (the peer's sequences restart with a new host).
    pub fn reset(&mut self) {
        self.received = None;
    }
}

/// Whether a state ack (`latest`, `mask`) covers datagram `seq`.
pub(crate) fn ack_covers(latest: u8, mask: u32, seq: u8) -> bool {
    let back = latest.wrapping_sub(seq);
    back == 0 || ((1..=32).contains(&back) && mask & (1 << (back - 1)) != 0)
}

/// Our datagrams that carried state entries, until the peer acknowledges them.
#[derive(Clone, Debug, Default)]
pub(crate) struct StateInFlight {
    sent: VecDeque<(u8, Vec<EntryRef>)>,
}

impl StateInFlight {
    /// Datagram `seq` carried these entries.
    pub fn record(&mut self, seq: u8, carried: Vec<EntryRef>) {
        self.sent.push_back((seq, carried));
        // a state ack names 8-bit datagram sequences: forget datagrams old enough to alias
        self.sent.retain(|(ds, _)| seq.wrapping_sub(*ds) < 128);
        while self.sent.len() > 64 {
            self.sent.pop_front();
        }
    }

    /// The peer's state ack: the entries of every datagram it covers, in sending order.
    pub fn on_ack(&mut self, latest: u8, mask: u32) -> Vec<EntryRef> {
        let mut done = Vec::new();
        self.sent.retain(|(ds, entries)| {
            if ack_covers(latest, mask, *ds) {
                done.extend(entries.iter().copied());
                false
            } else {
                true
            }
        });
        done
    }

    /// Forget everything.
    pub fn clear(&mut self) {
        self.sent.clear();
    }
}

/// Requests a member may make of the host per second (grabs, releases, authority answers,
/// spawns, despawns, resync claims; topology events have their own rate per object,
/// `MAX_TOPOLOGY_RATE`): a person's two hands make a few; past this a request is refused and
/// counted (`Stats::requests_rate_limited`).
pub const MAX_REQUESTS_PER_S: u32 = 60;
/// `Hello`s a member may repeat a second (an honest joiner that missed its `Welcome` repeats
/// one every few hundred milliseconds); twice this for [`REQUEST_FLOOD_STRIKES`] seconds is a
/// flood, and the member is dropped.
pub const MAX_HELLOS_PER_S: u32 = 10;

/// Keyframe requests a member or our host may make of us per second (each names up to
/// [`MAX_KEYFRAME_REQUEST`] objects; a healthy link asks after a loss burst, a few a second).
pub const MAX_KEYFRAME_REQUESTS_PER_S: u32 = 30;

/// A member whose requests, keyframe requests or application messages went over twice their
/// rate this many seconds in a row is dropped (a flood, not a burst): `DropWhy::Flood`.
pub const REQUEST_FLOOD_STRIKES: u32 = 5;

/// A count per one-second window, to rate-limit what a peer asks of us; and how many
/// windows in a row it asked for twice its rate or more (a flood's strikes).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct RateWindow {
    /// Start, admitted, refused.
    window: Option<(Instant, u32, u32)>,
    strikes: u32,
}

impl RateWindow {
    /// Counts one at `now` against `per_s`; false if over it (counted as refused).
    pub fn admit(&mut self, now: Instant, per_s: u32) -> bool {
        match &mut self.window {
            Some((start, n, refused)) if now < *start + Duration::from_secs(1) => {
                if *n >= per_s {
                    *refused += 1;
                    return false;
                }
                *n += 1;
            }
            w => {
                // a window closed: was it a flood (twice the rate asked, or more)?
                if let Some((start, _, refused)) = *w {
                    let consecutive = now < start + Duration::from_secs(2);
                    self.strikes = match (refused >= per_s, consecutive) {
                        (true, true) => self.strikes + 1,
                        (true, false) => 1,
                        (false, _) => 0,
                    };
                }
                *w = Some((now, 1, 0));
            }
        }
        true
    }

    /// Windows in a row that asked for twice the rate or more.
    pub fn strikes(&self) -> u32 {
        self.strikes
    }
}

/// Objects whose keyframes we ask the peer for (a delta's base was missing), rate-limited.
#[derive(Clone, Debug, Default)]
pub(crate) struct KeyframeRequests {
    due: BTreeSet<NetId>,
    asked_at: BTreeMap<NetId, Instant>,
}

impl KeyframeRequests {
    /// Ask for `id` unless we did less than `gap` ago.
    pub fn want(&mut self, id: NetId, now: Instant, gap: Duration) {
        if self.asked_at.get(&id).is_none_or(|t| now >= *t + gap) {
            self.asked_at.insert(id, now);
            self.due.insert(id);
        }
    }

    /// The next request's ids (at most [`MAX_KEYFRAME_REQUEST`]).
    pub fn due(&self) -> Vec<NetId> {
        self.due
            .iter()
            .copied()
            .take(MAX_KEYFRAME_REQUEST)
            .collect()
    }

    /// These went out.
    pub fn sent(&mut self, ids: &[NetId]) {
        for id in ids {
            self.due.remove(id);
        }
    }

    /// Anything to ask.
    pub fn any_due(&self) -> bool {
        !self.due.is_empty()
    }

    /// `id` is gone: nothing to ask of it, nothing to remember.
    pub fn forget(&mut self, id: NetId) {
        self.due.remove(&id);
        self.asked_at.remove(&id);
    }
}

/// Everything this peer keeps about one remote peer.
#[derive(Debug, Default)]
pub(crate) struct Link {
    /// Control messages, both ways.
    pub reliable: ReliableChannel,
    /// When we last sent it anything.
    pub last_sent: Option<Instant>,
    /// When we last pinged it.
    pub last_ping: Option<Instant>,
    /// When we last heard from it (liveness).
    pub last_heard: Option<Instant>,
    /// When we first heard from it (a stranger's age).
    pub first_heard: Option<Instant>,
    /// The gaps between datagrams from it (the adaptive failure detector).
    pub gaps: ArrivalGaps,
    /// Datagram sequences.
    pub seq: DatagramSeq,
    /// Its clock.
    pub clock: LinkClock,
    /// Round-trip time.
    pub rtt: RttEstimator,
    /// Its state datagrams that arrived (what we acknowledge).
    pub state_acks: StateAckWindow,
    /// Our state datagrams not acknowledged yet.
    pub in_flight: StateInFlight,
    /// Sending side of every object part toward it.
    pub send: SendParts,
    /// Receiving side (delta bases) of every object part from it.
    pub recv: DeltaBases,
    /// Objects whose `Spawn` it has not acknowledged yet (reliable sequence of the `Spawn`):
    /// no state flows for them before.
    pub spawn_pending: BTreeMap<NetId, u16>,
    /// State entries waiting for the next datagram.
    pub pending: Vec<StateEntry>,
    /// Time the owner's pending entries describe (the datagram is stamped with it).
    pub pending_sample: Option<Instant>,
    /// Keyframes to ask it for.
    pub keyframes: KeyframeRequests,
    /// What the peer asked of us this second: requests at the host, keyframe requests,
    /// application messages (all kinds together, against their rates' sum).
    pub requests: RateWindow,
    pub keyframe_asks: RateWindow,
    pub message_asks: RateWindow,
    /// `Hello`s it repeated this second, as a member.
    pub hello_asks: RateWindow,
    /// A ping of its to answer (its time, and when it came).
    pub pong_due: Option<(u32, Instant)>,
    /// A ping of ours to send.
    pub ping_due: bool,
    /// Unreliable application messages for the next datagram (encoded sections).
    pub unreliable: std::collections::VecDeque<Vec<u8>>,
    /// Its share of our uplink budget, if there is one (`session::budget`).
    pub bucket: super::budget::Bucket,
    /// Its objects' priority accumulators under a budget.
    pub priorities: super::budget::Priorities,
    /// Where its peer looks (its head), for the budget's interest.
    pub interest: Option<glam::Vec3>,
    /// Host: the reliable sequence of the last `Welcome` we sent it (a repeated `Hello` is
    /// answered again only once that one is acknowledged).
    pub welcomed: Option<u16>,
    /// Host: re-welcomes it got beyond its allowance, decaying one per
    /// `PeerBudget::rewelcome_every`, and when that was last updated.
    pub rewelcome_debt: (f32, Option<Instant>),
    /// Under a budget: objects with something to send, planned when a datagram takes them.
    pub dirty: BTreeMap<NetId, super::send::Refresh>,
}

impl Link {
    /// Anything to send now (`state`: whether pending state may go, the budget allowing).
    pub fn has_work(&self, now: Instant, state: bool) -> bool {
        self.reliable.ack_pending
            || self.pong_due.is_some()
            || self.ping_due
            || self.keyframes.any_due()
            || (state && !(self.pending.is_empty() && self.dirty.is_empty()))
            || self.state_acks.is_owed()
            || self.reliable.has_due(now)
            || !self.unreliable.is_empty()
    }

    /// Forget the replication state toward and from the peer (a new host: every chain
    /// restarts with keyframes).
    pub fn reset_replication(&mut self) {
        self.send.clear();
        self.recv.clear();
        self.pending.clear();
        self.dirty.clear();
        self.priorities.clear();
        self.in_flight.clear();
        self.state_acks.reset();
        self.spawn_pending.clear();
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn sequence_gaps_count_as_losses_and_a_late_datagram_gives_one_back() {
        let mut seq = DatagramSeq::default();
        let mut st = LinkStats::default();
        let t = Instant::from_millis(1);
        assert_eq!(
            seq.on_receive(t, 10, &mut st),
            Arrival {
                fresh: true,
                too_late: false
            }
        );
        assert!(seq.on_receive(t, 13, &mut st).fresh);
        assert_eq!((st.expected, st.lost), (4, 2));
        let late = seq.on_receive(t, 12, &mut st);
        assert!(!late.fresh && !late.too_late);
        assert_eq!(st.lost, 1, "12 arrived after all");
        assert!(!seq.on_receive(t, 13, &mut st).fresh, "a duplicate");
        assert_eq!(st.lost, 1);
    }

    #[test]
    fn a_datagram_16_or_more_behind_is_too_late_for_its_state() {
        let mut seq = DatagramSeq::default();
        let mut st = LinkStats::default();
        let t = Instant::from_millis(1);
        seq.on_receive(t, 100, &mut st);
        assert!(!seq.on_receive(t, 85, &mut st).too_late);
        assert!(seq.on_receive(t, 84, &mut st).too_late);
    }

    #[test]
    fn after_a_long_outage_a_datagram_that_looks_old_is_taken_as_the_newest() {
        let mut seq = DatagramSeq::default();
        let mut st = LinkStats::default();
        let t0 = Instant::from_millis(0);
        seq.on_receive(t0, 10, &mut st);
        // 200 datagrams lost: 210 % 256 = 210, 200 ahead looks 56 behind
        let looks_old = 10u8.wrapping_sub(56);
        assert!(
            !seq.on_receive(t0 + Duration::from_millis(100), looks_old, &mut st)
                .fresh
        );
        let a = seq.on_receive(t0 + Duration::from_millis(300), looks_old, &mut st);
        assert!(a.fresh, "nothing advanced for 250 ms");
        assert!(
            seq.on_receive(
                t0 + Duration::from_millis(301),
                looks_old.wrapping_add(1),
                &mut st
            )
            .fresh
        );
    }

    #[test]
    fn the_ack_bitmap_shifts_with_newer_datagrams_and_fills_in_older_ones() {
        let mut w = StateAckWindow::default();
        assert_eq!(w.take_owed(), None);
        w.record(5);
        assert_eq!(w.take_owed(), Some((5, 0)));
        assert_eq!(w.take_owed(), None, "paid");
        w.record(7); // 6 missing
        assert_eq!(w.take_owed(), Some((7, 0b10)));
        w.record(6); // late
        assert_eq!(w.take_owed(), Some((7, 0b11)));
        w.record(7 + 32); // the old newest falls to bit 31
        assert_eq!(w.take_owed(), Some((39, 1 << 31)));
        w.record(39 + 40); // far ahead: history cleared
        assert_eq!(w.take_owed(), Some((79, 0)));
        w.record(79 - 40); // too old to say
        assert_eq!(w.take_owed(), Some((79, 0)));
        for (seq, covered) in [(79, true), (78, false), (47, false)] {
            assert_eq!(ack_covers(79, 0, seq), covered);
        }
        assert!(ack_covers(79, 1 << 31, 47));
    }

    #[test]
    fn acked_datagrams_hand_back_their_entries_and_old_ones_are_forgotten() {
        let mut f = StateInFlight::default();
        f.record(1, vec![(NetId(1), 0, 10)]);
        f.record(2, vec![(NetId(2), 0, 11)]);
        f.record(3, vec![(NetId(1), 1, 12)]);
        assert_eq!(
            f.on_ack(3, 0b10),
            vec![(NetId(1), 0, 10), (NetId(1), 1, 12)]
        );
        assert_eq!(f.on_ack(3, 0b11), vec![(NetId(2), 0, 11)]);
        assert!(f.on_ack(3, u32::MAX).is_empty());
        for s in 0..70u8 {
            f.record(s, vec![(NetId(9), 0, u64::from(s))]);
        }
        assert_eq!(
            f.on_ack(69, u32::MAX).len(),
            33,
            "64 kept, 33 of them covered"
        );
    }

    #[test]
    fn the_clock_maps_sender_stamps_through_the_least_delayed_datagram() {
        let mut c = LinkClock::default();
        // sender stamps 1000 ms, arrives at our 5.030 s: offset 4.030 s
        let s = c.observe(Instant::from_micros(5_030_000), 1000);
        assert_eq!(s, Instant::from_micros(5_030_000));
        // next one 20 ms later by its clock, 10 ms less delayed
        let s = c.observe(Instant::from_micros(5_040_000), 1020);
        assert_eq!(s, Instant::from_micros(5_040_000));
        // a delayed one maps to when it was sent (+20 µs drift of the minimum)
        let s = c.observe(Instant::from_micros(5_100_000), 1040);
        assert_eq!(s, Instant::from_micros(5_060_020));
        assert!(c.jitter_us() > 0.0);
        assert_eq!(
            c.to_sender_time(Instant::from_micros(5_060_020)),
            Instant::from_millis(1040)
        );
        // the 16-bit stamp wraps
        let mut c = LinkClock::default();
        c.observe(Instant::from_millis(100), u16::MAX);
        let s = c.observe(Instant::from_millis(101), 0);
        assert_eq!(s, Instant::from_millis(101));
    }

    #[test]
    fn rto_follows_the_smoothed_rtt_with_a_floor() {
        let mut r = RttEstimator::default();
        let min = Duration::from_millis(60);
        assert_eq!(r.rto(min), Duration::from_millis(270));
        r.on_sample(Duration::from_millis(80));
        assert_eq!(r.srtt(), Some(Duration::from_millis(80)));
        r.on_sample(Duration::from_millis(160));
        assert_eq!(r.srtt(), Some(Duration::from_millis(90)));
        assert_eq!(r.rto(min), Duration::from_micros(132_500));
        r.on_sample(Duration::ZERO);
        for _ in 0..40 {
            r.on_sample(Duration::ZERO);
        }
        assert_eq!(r.rto(min), min);
    }

    #[test]
    fn keyframe_requests_are_rate_limited_per_object() {
        let mut k = KeyframeRequests::default();
        let t = Instant::from_millis(0);
        let gap = Duration::from_millis(50);
        k.want(NetId(1), t, gap);
        k.want(NetId(2), t, gap);
        assert_eq!(k.due(), vec![NetId(1), NetId(2)]);
        k.sent(&[NetId(1), NetId(2)]);
        k.want(NetId(1), t + Duration::from_millis(10), gap);
        assert!(!k.any_due(), "asked 10 ms ago");
        k.want(NetId(1), t + gap, gap);
        assert_eq!(k.due(), vec![NetId(1)]);
    }
}

/// The last [`ArrivalGaps::WINDOW`] gaps between datagrams from a peer, for the adaptive
/// failure detector ([`crate::policy::FailureDetector::Adaptive`]).
#[derive(Debug, Default, Clone)]
pub(crate) struct ArrivalGaps {
    gaps_ms: std::collections::VecDeque<f32>,
    /// The last [`timeout`](Self::timeout) asked and its answer, until a gap is recorded:
    /// `poll_timeout` asks for every member at every pump (it was 8 % of an idle viewer's CPU
    /// in a room of 16).
    memo: std::cell::Cell<Option<(TimeoutKey, Duration)>>,
}

/// The arguments of one [`ArrivalGaps::timeout`].
type TimeoutKey = (Duration, u32, u32, Duration, Duration);

impl ArrivalGaps {
    /// Gaps kept.
    pub const WINDOW: usize = 64;
    /// Gaps needed before the statistics are used.
    pub const MIN_SAMPLES: usize = 16;

    /// A datagram arrived `gap` after the one before it.
    pub fn record(&mut self, gap: Duration) {
        self.memo.set(None);
        if self.gaps_ms.len() == Self::WINDOW {
            self.gaps_ms.pop_front();
        }
        self.gaps_ms.push_back(gap.as_secs_f32() * 1e3);
    }

    /// Forget the history (a stall of ours, a rejoin).
    pub fn clear(&mut self) {
        self.memo.set(None);
        self.gaps_ms.clear();
    }

    /// The silence after which the peer is gone, from the gaps and the heartbeat interval
    /// `hb` (a live peer with the adaptive detector pings at most 1.25 `hb` apart): the share
    /// of gaps longer than 1.75 `hb` estimates the chance `q` that a heartbeat is lost (at
    /// least 1 %), so `k` lost in a row, `q^k`, is below 10^−phi for `k = ⌈phi / −log₁₀ q⌉`
    /// heartbeats; to those `k + ½` intervals come `deviations` standard deviations of the
    /// other gaps (jitter).
    /// Within `[min, max]`; `max` until there are enough gaps.
    pub fn timeout(
        &self,
        hb: Duration,
        phi: f32,
        deviations: f32,
        min: Duration,
        max: Duration,
    ) -> Duration {
        let key = (hb, phi.to_bits(), deviations.to_bits(), min, max);
        match self.memo.get() {
            Some((k, t)) if k == key => t,
            _ => {
                let t = self.compute_timeout(hb, phi, deviations, min, max);
                self.memo.set(Some((key, t)));
                t
            }
        }
    }

    fn compute_timeout(
        &self,
        hb: Duration,
        phi: f32,
        deviations: f32,
        min: Duration,
        max: Duration,
    ) -> Duration {
        let n = self.gaps_ms.len();
        if n < Self::MIN_SAMPLES {
            return max;
        }
        // A live peer pings at most 1.25 intervals apart (a round every half interval pings
        // a link quiet for three quarters of one); a gap past 1.75 means something was lost.
        let unit = hb.as_secs_f32() * 1e3;
        let long = self.gaps_ms.iter().filter(|g| **g > 1.75 * unit).count();
        let q = (long as f32 / n as f32).clamp(0.01, 0.9);
        let k = (-phi.max(0.5) / q.log10()).ceil().clamp(1.0, 40.0);
        let short: Vec<f32> = self
            .gaps_ms
            .iter()
            .copied()
            .filter(|g| *g <= 1.75 * unit)
            .collect();
        let sd = if short.len() >= 2 {
            let m = short.iter().sum::<f32>() / short.len() as f32;
            (short.iter().map(|g| (g - m).powi(2)).sum::<f32>() / (short.len() - 1) as f32).sqrt()
        } else {
            0.0
        };
        let t_ms = unit * (k + 0.5) + deviations * sd;
        if !t_ms.is_finite() {
            return max;
        }
        Duration::from_secs_f32((t_ms / 1e3).max(0.0)).clamp(min, max)
    }
}
