//! The uplink budget (issue 18): a token bucket per link, and a priority accumulator per link
//! and object in the style of Glenn Fiedler's state synchronization.
//!
//! With [`SessionConfig::uplink_bytes_per_s`](crate::SessionConfig::uplink_bytes_per_s) set,
//! each link may send `cap / links` bytes a second (datagram payloads plus the estimated
//! transport overhead, [`TRANSPORT_OVERHEAD_BYTES`]): a bucket holding a twentieth of a second's
//! share, refilled at 95 % of the share, so no 1 s window carries more than the cap
//! (acks, pings and control messages always go, a bucket in debt waits; state waits while
//! the bucket is empty). Every send tick
//! adds to an object's accumulator its weight toward that link:
//!
//! `class priority × (held 8 | just released or thrown 4 | moving 2 | at rest 1) × interest`
//!
//! where interest is `1 / (1 + d)` for an object `d` metres from the point the link's peer
//! looks at ([`Session::set_interest`](crate::Session::set_interest)), 1 when unknown. Each
//! datagram takes the pending entries of objects that waited [`MAX_WAIT`] first (nothing
//! starves), then those of held objects (someone's hand is on them), then the highest
//! accumulators; an object whose entries all went starts again from zero. Among the rest, an
//! object that waits keeps accumulating, so it overtakes a just-sent one of `k` times its
//! weight after `k` ticks.

use std::collections::BTreeMap;
use std::time::Duration;

use glam::Vec3;

use super::delta::EntryRef;
use super::link::Link;
use super::registry::{Object, Registry};
use super::send::{plan_entries, LinkView, Refresh};
use crate::ids::NetId;
use crate::policy::ClassConfig;
use crate::stats::TRANSPORT_OVERHEAD_BYTES;
use crate::time::Instant;
use crate::wire::{EntryLayout, PacketWriter, Pushed, StateBlockWriter, StateEntry};

/// How much of a second of budget the bucket holds (state waits at most this long for a
/// datagram's worth).
const BUCKET_SECONDS: f64 = 0.05;

/// How long a released (or thrown) object keeps its boost.
pub(crate) const RELEASE_BOOST: Duration = Duration::from_secs(1);

/// A link's share of the uplink, as a token bucket of bytes.
#[derive(Debug, Default)]
pub(crate) struct Bucket {
    tokens: f64,
    last: Option<Instant>,
}

impl Bucket {
    /// Refill at `rate` bytes a second up to a twentieth of a second's worth (a new bucket
    /// starts full) and say whether state may go now: once the bucket holds a full datagram
    /// of `mtu` (or is full, when it holds less), so that state goes in few, well-filled
    /// datagrams rather than many that are mostly headers.
    pub fn refill(&mut self, now: Instant, rate: f64, mtu: usize) -> bool {
        // a bucket of a twentieth of a second refilled at 95 % of the rate: no 1 s window
        // holds more than the rate
        let cap = (rate * BUCKET_SECONDS).max(1.0);
        let fill = rate * (1.0 - BUCKET_SECONDS);
        self.tokens = match self.last {
            None => cap,
            Some(t) => (self.tokens + now.saturating_since(t).as_secs_f64() * fill).min(cap),
        };
        self.last = Some(now);
        self.tokens >= cap.min((mtu + TRANSPORT_OVERHEAD_BYTES) as f64)
    }

    /// Bytes state entries may take in a datagram that already holds `so_far` bytes.
    pub fn room_for_state(&self, so_far: usize) -> usize {
        (self.tokens - (so_far + TRANSPORT_OVERHEAD_BYTES) as f64).max(0.0) as usize
    }

    /// A datagram of `payload` bytes went (it may leave the bucket in debt: control always
    /// goes).
    pub fn spend(&mut self, payload: usize) {
        self.tokens -= (payload + TRANSPORT_OVERHEAD_BYTES) as f64;
    }
}

/// An object waiting this long goes before anything else (held objects included): the bound
/// on starvation.
pub(crate) const MAX_WAIT: Duration = Duration::from_secs(1);

/// A link's priority accumulators.
#[derive(Debug, Default)]
pub(crate) struct Priorities {
    acc: BTreeMap<NetId, f32>,
    /// Since when each object has had something waiting.
    since: BTreeMap<NetId, Instant>,
}

impl Priorities {
    /// Object `id` had something to send at a tick of `interval`, weighing `weight`.
    pub fn accumulate(&mut self, id: NetId, weight: f32, interval: Duration, now: Instant) {
        *self.acc.entry(id).or_default() += weight * interval.as_secs_f32();
        self.since.entry(id).or_insert(now);
    }

    /// Whether `id` has waited [`MAX_WAIT`] or longer.
    pub fn overdue(&self, id: NetId, now: Instant) -> bool {
        self.since
            .get(&id)
            .is_some_and(|t| now.saturating_since(*t) >= MAX_WAIT)
    }

    /// Its accumulated priority.
    pub fn of(&self, id: NetId) -> f32 {
        self.acc.get(&id).copied().unwrap_or(0.0)
    }

    /// Everything pending for `id` went: it starts again.
    pub fn sent(&mut self, id: NetId) {
        self.acc.remove(&id);
        self.since.remove(&id);
    }

    /// Forget everything (the replication toward the peer restarts).
    pub fn clear(&mut self) {
        self.acc.clear();
        self.since.clear();
    }
}

/// Object `o`'s weight toward a link whose peer looks at `interest`.
pub(crate) fn weight(o: &Object, class: &ClassConfig, now: Instant, interest: Option<Vec3>) -> f32 {
    let p = class.send.priority;
    let base = if p.is_finite() {
        p.clamp(0.01, 100.0)
    } else {
        1.0
    };
    let state = if o.info.held {
        8.0
    } else if o.boost_until.is_some_and(|t| now < t) {
        4.0
    } else if !o.rest {
        2.0
    } else {
        1.0
    };
    let near = interest.map_or(1.0, |at| {
        let pos = class.position_quantizer().dequantize(o.pos);
        let d = pos.distance(at);
        if d.is_finite() {
            1.0 / (1.0 + d)
        } else {
            1.0
        }
    });
    base * state * near
}

/// What [`fill_state`] put in a datagram.
#[derive(Debug, Default)]
pub(crate) struct Filled {
    /// The state section: entry count and bytes (none if empty).
    pub block: Option<(usize, Vec<u8>)>,
    /// The entries it carries, for acknowledgements.
    pub carried: Vec<EntryRef>,
    /// Bits per class, for the stats.
    pub class_bits: BTreeMap<u16, usize>,
    /// Entries too big for any datagram, dropped.
    pub oversize: u64,
    /// The newest owner sample among them (the datagram is stamped with it).
    pub sampled: Option<Instant>,
}

/// Bytes of a typical rigid state entry, for deciding whether a bucket holds the held
/// objects' entries.
pub(crate) const ENTRY_ESTIMATE: usize = 16;

/// The layout of object `o`'s entries (and its class's index).
pub(crate) fn layout_of<'a>(
    o: &Object,
    classes: &'a [ClassConfig],
) -> Option<(u16, EntryLayout<'a>)> {
    let class = classes.get(usize::from(o.info.class.0))?;
    Some((
        o.info.class.0,
        EntryLayout {
            class,
            particles: o.info.particles,
            generation: o.topology.generation(),
        },
    ))
}

/// Push `e` into `block`; false when it must wait for the next datagram. Entries too big for
/// any datagram are counted and dropped.
fn push_entry(
    block: &mut StateBlockWriter,
    e: &StateEntry,
    objects: &Registry,
    classes: &[ClassConfig],
    link: &Link,
    limited: bool,
    out: &mut Filled,
) -> bool {
    let Some((class_id, layout)) = objects.get(e.id).and_then(|o| layout_of(o, classes)) else {
        return true; // the object is gone: nothing to send
    };
    match block.push(e, &layout) {
        // too big for what the budget leaves, not for a datagram: it waits
        Pushed::Oversize if limited => false,
        Pushed::Oversize => {
            out.oversize += 1;
            true
        }
        Pushed::Full => false,
        Pushed::Written(bits) => {
            *out.class_bits.entry(class_id).or_default() += bits;
            let part = e.part();
            if let Some(n) = link.send.number_of(&(e.id, part), e.seq) {
                out.carried.push((e.id, part, n));
            }
            true
        }
    }
}

/// Fill the state section of a datagram to `link` under the budget: first the entries a
/// previous datagram had no room for (they have their numbers: they must go), then objects
/// planned now, in order — waited too long, held, then by accumulated priority — until the
/// bucket's room is used. `held_only`: only held objects (the bucket holds them, not a full
/// datagram). An object is planned only when a datagram takes it, so no entry number is
/// spent on an entry that never goes: a part's number advances at most once per datagram,
/// which the receiver's lateness guard (a datagram 16 behind the newest is too late for state)
/// needs to keep 5-bit entry sequences from aliasing. (Planning at the send tick and dropping
/// unsent plans broke that: a datagram reordered behind 32 emissions put a stale state in a
/// base slot, and remotes showed objects metres away.)
pub(crate) fn fill_state(
    link: &mut Link,
    objects: &Registry,
    classes: &[ClassConfig],
    now: Instant,
    w: &PacketWriter,
    held_only: bool,
) -> Filled {
    let mut out = Filled::default();
    let full_bits = w.state_budget_bits();
    let bits = w.state_budget_bits_within(link.bucket.room_for_state(w.len()));
    let limited = bits < full_bits;
    let mut block = StateBlockWriter::new(bits);
    let mut room = true;
    // push `entries` in order; what does not fit waits in `link.pending`; false when full
    let mut push_all = |entries: Vec<StateEntry>, link: &mut Link, out: &mut Filled| {
        let mut left = entries.into_iter();
        let mut fit = true;
        for e in left.by_ref() {
            if !push_entry(&mut block, &e, objects, classes, link, limited, out) {
                link.pending.push(e);
                fit = false;
                break;
            }
        }
        link.pending.extend(left);
        fit
    };
    if !held_only {
        let carry = std::mem::take(&mut link.pending);
        room = push_all(carry, link, &mut out);
    }
    let held = |id: NetId| objects.get(id).is_some_and(|o| o.info.held);
    let mut order: Vec<(NetId, Refresh)> = link
        .dirty
        .iter()
        .filter(|(id, _)| !held_only || held(**id))
        .map(|(id, how)| (*id, *how))
        .collect();
    let pr = &link.priorities;
    let tier = |id: NetId| (pr.overdue(id, now), held(id));
    order.sort_by(|(a, _), (b, _)| {
        tier(*b)
            .cmp(&tier(*a))
            .then(pr.of(*b).total_cmp(&pr.of(*a)))
            .then(a.cmp(b))
    });
    for (id, how) in order {
        if !room {
            break;
        }
        if link.pending.iter().any(|e| e.id == id) {
            // its entries from the last datagram go first; planning again now would advance
            // a part's entry number twice in one datagram, and the receiver's lateness guard
            // (16 datagrams) relies on once per datagram to keep 5-bit sequences from aliasing
            continue;
        }
        link.dirty.remove(&id);
        let Some(o) = objects.get(id) else {
            link.priorities.sent(id);
            continue;
        };
        let Some(class) = classes.get(usize::from(o.info.class.0)) else {
            continue;
        };
        let view = LinkView {
            ack_wait: link.rtt.ack_wait(),
            parts: &mut link.send,
        };
        let owner = how == Refresh::Owner;
        let entries = plan_entries(o, class, view, now, owner, how == Refresh::Keyframe);
        if owner && !entries.is_empty() {
            out.sampled = Some(
                out.sampled
                    .map_or(o.published_at, |t| t.max(o.published_at)),
            );
        }
        room = push_all(entries, link, &mut out);
        if room {
            link.priorities.sent(id);
        }
    }
    if !block.is_empty() {
        out.block = Some(block.finish());
    }
    out
}

impl super::Session {
    /// Where the peer at the other end of a link looks (its head, say), so that under an
    /// uplink budget what is near it goes first; `None`: unknown (no preference).
    pub fn set_interest(&mut self, peer: crate::ids::PeerId, at: Option<Vec3>) {
        if let Some(l) = self.links.get_mut(&peer) {
            l.interest = at.filter(|p| p.is_finite());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bucket_refills_at_its_rate_up_to_a_twentieth_of_a_second_and_goes_into_debt() {
        let mut b = Bucket::default();
        let t0 = Instant::from_micros(1_000_000);
        // 20 kB/s: the bucket holds 1000 bytes and refills at 19 kB/s
        assert!(b.refill(t0, 20_000.0, 1200));
        assert_eq!(b.room_for_state(0), 1000 - TRANSPORT_OVERHEAD_BYTES);
        b.spend(1100 - TRANSPORT_OVERHEAD_BYTES);
        assert!(!b.refill(t0, 20_000.0, 1200));
        assert_eq!(b.room_for_state(0), 0);
        // state waits for a full bucket (it holds less than a datagram of 1200): 1000 bytes
        // at 19 kB/s take 53 ms
        assert!(!b.refill(t0 + Duration::from_millis(50), 20_000.0, 1200));
        assert!(b.refill(t0 + Duration::from_millis(60), 20_000.0, 1200));
        // never more than the bucket holds
        assert!(b.refill(t0 + Duration::from_secs(1), 20_000.0, 1200));
        assert_eq!(b.room_for_state(0), 1000 - TRANSPORT_OVERHEAD_BYTES);
        // a big bucket lets state go once it holds a datagram
        let mut big = Bucket::default();
        big.refill(t0, 100_000.0, 1200);
        big.spend(5_000);
        assert!(!big.refill(t0 + Duration::from_millis(10), 100_000.0, 1200));
        assert!(big.refill(t0 + Duration::from_millis(20), 100_000.0, 1200));
    }

    #[test]
    fn accumulators_grow_with_weight_and_time_and_nothing_starves() {
        let mut p = Priorities::default();
        let (held, resting) = (NetId(1), NetId(2));
        let tick = Duration::from_millis(50);
        // room for one object a tick: the held one goes first, the resting one still goes
        // within 8 ticks (the ratio of their weights)
        let mut resting_sent = None;
        for t in 0..20 {
            let now = Instant::from_micros(1_000_000 + t * 50_000);
            p.accumulate(held, 8.0, tick, now);
            p.accumulate(resting, 1.0, tick, now);
            assert!(!p.overdue(resting, now));
            let first = if p.of(resting) > p.of(held) {
                resting
            } else {
                held
            };
            if t == 0 {
                assert_eq!(first, held);
            }
            p.sent(first);
            if first == resting {
                resting_sent = Some(t);
                break;
            }
        }
        let t = resting_sent.expect("the resting object starved");
        assert!((7..=8).contains(&t), "sent at tick {t}");
    }
}
