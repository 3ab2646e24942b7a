//! Per-(link, object, part) delta state, both ways (the Quake 3 / Fiedler snapshot-delta
//! scheme, per part rather than per world).
//!
//! Sending ([`SendParts`]): every entry gets a number that never wraps (5 bits of it on the
//! wire); the newest acknowledged entry and the state the peer holds after it is the base of
//! the next delta. Receiving ([`DeltaBases`]): the state after each of the last 32 entries, by
//! wire sequence, so a delta naming its base can be applied, and one whose base is gone is
//! told apart.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::ids::NetId;
use crate::quant::QuatQ;
use crate::time::Instant;
use crate::wire::ENTRY_SEQ_MOD;

/// A part's state on the quantization grid: the transform (part 0) or a particle chunk.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum PartQ {
    /// Center position and rotation.
    Transform {
        /// Position on the class grid.
        pos: [u32; 3],
        /// Smallest-three rotation.
        rot: QuatQ,
    },
    /// Particle offsets of one chunk on the particle grid.
    Chunk(Vec<[u32; 3]>),
}

/// (object, part): 0 is the transform, k ≥ 1 particle chunk k − 1.
pub(crate) type PartKey = (NetId, u32);

/// (object, part, entry number) of an entry carried by a datagram.
pub(crate) type EntryRef = (NetId, u32, u64);

/// Wire sequence of an entry number.
pub(crate) fn wire_seq(n: u64) -> u8 {
    (n % u64::from(ENTRY_SEQ_MOD)) as u8
}

/// Seq `a` is newer than `b` in wrapping entry-sequence order.
pub(crate) fn seq_newer(a: u8, b: u8) -> bool {
    let d = a.wrapping_sub(b) % ENTRY_SEQ_MOD;
    (1..ENTRY_SEQ_MOD / 2).contains(&d)
}

/// Sending side of one part on one link.
#[derive(Clone, Debug)]
pub(crate) struct SendPart {
    /// Last entry number used (never wraps; the wire carries it mod [`ENTRY_SEQ_MOD`]).
    pub seq: u64,
    /// Newest acknowledged entry (number) and the state the peer holds after it.
    pub acked: Option<(u64, PartQ)>,
    /// Sent, not yet acknowledged: (entry number, state after it, send time).
    pub unacked: VecDeque<(u64, PartQ, Instant)>,
    /// When the last keyframe of this part went out.
    pub last_key_at: Instant,
    /// When each field was last sent (transform: position, rotation; chunk: per particle).
    pub sent_at: Vec<Instant>,
}

impl SendPart {
    /// The newest acknowledged state as a delta base (its wire sequence), unless too old for
    /// the peer's history ring.
    pub fn base(&self) -> Option<(u8, PartQ)> {
        let (n, st) = self.acked.as_ref()?;
        let age = self.seq.saturating_sub(*n);
        (age < u64::from(ENTRY_SEQ_MOD - 8)).then(|| (wire_seq(*n), st.clone()))
    }
}

/// One entry about to go out: what the peer will hold once it applies it.
#[derive(Clone, Debug)]
pub(crate) struct Emission<'a> {
    /// The state after the entry.
    pub after: PartQ,
    /// A keyframe (absolute values).
    pub key: bool,
    /// Repeat even if the same state is in flight and not overdue.
    pub force: bool,
    /// Fields the entry carries (their send times are refreshed).
    pub fields: &'a [usize],
    /// Fields the part has.
    pub field_count: usize,
}

/// The sending side of every part on one link.
#[derive(Clone, Debug, Default)]
pub(crate) struct SendParts {
    parts: BTreeMap<PartKey, SendPart>,
}

impl SendParts {
    /// The part's state, if it ever sent.
    pub fn get(&self, key: &PartKey) -> Option<&SendPart> {
        self.parts.get(key)
    }

    /// Book-keep one outgoing entry of a part: a new entry number, the state the peer will
    /// hold once it applies it, per-field send times. Returns the wire sequence, or `None`
    /// (send nothing) when the same state is already in flight and its acknowledgement is
    /// not overdue (`ack_wait`).
    pub fn emit(
        &mut self,
        key: PartKey,
        e: Emission<'_>,
        now: Instant,
        ack_wait: Duration,
    ) -> Option<u8> {
        let sp = self.parts.entry(key).or_insert_with(|| SendPart {
            seq: u64::from(ENTRY_SEQ_MOD) - 1,
            acked: None,
            unacked: VecDeque::new(),
            last_key_at: now,
            sent_at: vec![now; e.field_count],
        });
        if !e.force {
            if let Some((_, st, at)) = sp.unacked.back() {
                if *st == e.after && now < *at + ack_wait {
                    return None;
                }
            }
        }
        sp.seq = sp.seq.wrapping_add(1);
        sp.unacked.push_back((sp.seq, e.after, now));
        while sp.unacked.len() > usize::from(ENTRY_SEQ_MOD) - 8 {
            sp.unacked.pop_front();
        }
        if e.key {
            sp.last_key_at = now;
        }
        sp.sent_at.resize(e.field_count, now);
        for f in e.fields {
            if let Some(t) = sp.sent_at.get_mut(*f) {
                *t = now;
            }
        }
        Some(wire_seq(sp.seq))
    }

    /// The entry number of the unacknowledged entry of `key` sent with wire sequence `seq`
    /// (unique: at most 24 are kept).
    pub fn number_of(&self, key: &PartKey, seq: u8) -> Option<u64> {
        self.parts.get(key).and_then(|sp| {
            sp.unacked
                .iter()
                .rev()
                .find(|(n, _, _)| wire_seq(*n) == seq)
                .map(|x| x.0)
        })
    }

    /// The peer acknowledged entry `number` of `key`: it becomes the delta base (if newer than
    /// the current one), and older unacknowledged entries are forgotten.
    pub fn on_acked(&mut self, key: &PartKey, number: u64) {
        let Some(sp) = self.parts.get_mut(key) else {
            return;
        };
        let Some((q, st, _)) = sp.unacked.iter().find(|(q, _, _)| *q == number).cloned() else {
            return;
        };
        if sp.acked.as_ref().is_none_or(|(a, _)| q > *a) {
            sp.acked = Some((q, st));
            sp.unacked.retain(|(x, _, _)| *x > q);
        }
    }

    /// Forget the parts of object `id` (its chains restart with keyframes).
    pub fn forget_object(&mut self, id: NetId) {
        self.parts.retain(|(o, _), _| *o != id);
    }

    /// Forget everything.
    pub fn clear(&mut self) {
        self.parts.clear();
    }
}

/// The receiving side of one part: the state after each recently received entry.
#[derive(Clone, Debug)]
pub(crate) struct RecvPart {
    /// State after each recently received entry, by sequence (delta bases).
    ring: Vec<Option<(u8, PartQ)>>,
    /// Sequence of the entry whose state is shown.
    latest: Option<u8>,
}

fn slot(s: u8) -> usize {
    usize::from(s % ENTRY_SEQ_MOD)
}

impl RecvPart {
    fn new() -> Self {
        RecvPart {
            ring: vec![None; usize::from(ENTRY_SEQ_MOD)],
            latest: None,
        }
    }

    /// The state after entry `seq`, if the ring still holds it.
    pub fn base(&self, seq: u8) -> Option<PartQ> {
        self.ring
            .get(slot(seq))
            .and_then(|x| x.as_ref())
            .filter(|(s, _)| *s == seq)
            .map(|(_, st)| st.clone())
    }

    /// Keep the state after entry `seq` as a base; true if it is also the one to show (from
    /// the newest datagram of the peer, `fresh`, or newer than what is shown).
    pub fn record(&mut self, seq: u8, state: PartQ, fresh: bool) -> bool {
        if let Some(x) = self.ring.get_mut(slot(seq)) {
            *x = Some((seq, state));
        }
        if !fresh && self.latest.is_some_and(|l| !seq_newer(seq, l)) {
            return false; // older than what we show (reordered); kept only as a base
        }
        self.latest = Some(seq);
        true
    }
}

/// The receiving side of every part on one link.
#[derive(Clone, Debug, Default)]
pub(crate) struct DeltaBases {
    parts: BTreeMap<PartKey, RecvPart>,
}

impl DeltaBases {
    /// The part's ring, made on first use.
    pub fn part(&mut self, key: PartKey) -> &mut RecvPart {
        self.parts.entry(key).or_insert_with(RecvPart::new)
    }

    /// An entry we decoded but did not apply. Its datagram is still acknowledged, so the
    /// sender takes the entry as a delta base: forget whatever the ring holds in its slot (a
    /// state 32 entries older), so that a delta naming it breaks the chain and asks for a
    /// keyframe instead of silently applying to the wrong base.
    pub fn forget_entry(&mut self, key: &PartKey, seq: u8) {
        if let Some(rp) = self.parts.get_mut(key) {
            if let Some(x) = rp.ring.get_mut(slot(seq)) {
                *x = None;
            }
        }
    }

    /// Forget the parts of object `id`.
    pub fn forget_object(&mut self, id: NetId) {
        self.parts.retain(|(o, _), _| *o != id);
    }

    /// Forget everything.
    pub fn clear(&mut self) {
        self.parts.clear();
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn chunk(v: u32) -> PartQ {
        PartQ::Chunk(vec![[v, v, v]])
    }

    fn emit(parts: &mut SendParts, v: u32, now: Instant, force: bool) -> Option<u8> {
        parts.emit(
            (NetId(1), 1),
            Emission {
                after: chunk(v),
                key: false,
                force,
                fields: &[0],
                field_count: 1,
            },
            now,
            Duration::from_millis(100),
        )
    }

    #[test]
    fn entry_numbers_start_at_zero_on_the_wire_and_never_wrap() {
        let mut parts = SendParts::default();
        let now = Instant::from_millis(10);
        let seqs: Vec<u8> = (0..40)
            .map(|v| emit(&mut parts, v, now, false).unwrap())
            .collect();
        assert_eq!(seqs[0], 0);
        assert_eq!(seqs[31], 31);
        assert_eq!(seqs[32], 0, "5 bits on the wire");
        let sp = parts.get(&(NetId(1), 1)).unwrap();
        assert_eq!(sp.seq, 31 + 40, "the number itself goes on");
        assert_eq!(sp.unacked.len(), 24, "at most 24 in flight are kept");
    }

    #[test]
    fn the_same_state_in_flight_is_repeated_only_once_its_ack_is_overdue_or_forced() {
        let mut parts = SendParts::default();
        let t0 = Instant::from_millis(0);
        assert!(emit(&mut parts, 5, t0, false).is_some());
        assert!(emit(&mut parts, 5, t0 + Duration::from_millis(50), false).is_none());
        assert!(emit(&mut parts, 5, t0 + Duration::from_millis(50), true).is_some());
        assert!(emit(&mut parts, 5, t0 + Duration::from_millis(200), false).is_some());
        assert!(emit(&mut parts, 6, t0 + Duration::from_millis(201), false).is_some());
    }

    #[test]
    fn an_ack_makes_the_newest_acknowledged_state_the_base_and_older_ones_do_not_go_back() {
        let mut parts = SendParts::default();
        let now = Instant::from_millis(0);
        let key = (NetId(1), 1);
        let s0 = emit(&mut parts, 10, now, false).unwrap();
        let s1 = emit(&mut parts, 11, now, false).unwrap();
        let n0 = parts.number_of(&key, s0).unwrap();
        let n1 = parts.number_of(&key, s1).unwrap();
        assert!(parts.get(&key).unwrap().base().is_none());
        parts.on_acked(&key, n1);
        assert_eq!(parts.get(&key).unwrap().base(), Some((s1, chunk(11))));
        assert!(parts.get(&key).unwrap().unacked.is_empty());
        parts.on_acked(&key, n0); // late ack of an older entry: already forgotten
        assert_eq!(parts.get(&key).unwrap().base(), Some((s1, chunk(11))));
    }

    #[test]
    fn a_base_too_old_for_the_peers_ring_is_not_used() {
        let mut parts = SendParts::default();
        let now = Instant::from_millis(0);
        let key = (NetId(1), 1);
        let s = emit(&mut parts, 0, now, false).unwrap();
        parts.on_acked(&key, parts.number_of(&key, s).unwrap());
        for v in 1..24 {
            emit(&mut parts, v, now, false);
        }
        assert!(
            parts.get(&key).unwrap().base().is_some(),
            "23 entries later"
        );
        emit(&mut parts, 24, now, false);
        assert!(
            parts.get(&key).unwrap().base().is_none(),
            "24 entries later"
        );
    }

    #[test]
    fn received_states_are_bases_by_sequence_and_only_newer_ones_are_shown() {
        let mut bases = DeltaBases::default();
        let key = (NetId(2), 0);
        assert!(bases.part(key).record(3, chunk(3), false));
        assert!(bases.part(key).record(5, chunk(5), false));
        assert!(
            !bases.part(key).record(4, chunk(4), false),
            "reordered: kept as a base only"
        );
        assert_eq!(bases.part(key).base(4), Some(chunk(4)));
        assert!(
            bases.part(key).record(2, chunk(2), true),
            "the newest datagram's entry is shown even if its sequence looks older"
        );
        // 32 entries later, sequence 3 comes round again: its slot holds the newer state
        bases.part(key).record(3, chunk(35), true);
        assert_eq!(bases.part(key).base(3), Some(chunk(35)));
        bases.forget_entry(&key, 3);
        assert_eq!(bases.part(key).base(3), None);
        assert!(seq_newer(1, 31) && !seq_newer(31, 1) && !seq_newer(7, 7));
    }
}
