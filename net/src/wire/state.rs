//! State entries: the bit-packed block of object parts (transforms and particle chunks),
//! written by [`StateBlockWriter`] and read by [`decode_state_block`].

use crate::bits::{BitReader, BitWriter};
use crate::error::{decode_err, NetError};
use crate::ids::NetId;
use crate::policy::ClassConfig;
use crate::quant::{read_quat, write_quat, QuatQ};

use super::{ENTRY_SEQ_BITS, ENTRY_SEQ_MOD};

/// Bits of the layout generation a particle chunk carries.
const LAYOUT_BITS: u32 = 2;
const LAYOUT_MASK: u8 = (1 << LAYOUT_BITS) - 1;

/// Position payload of a transform part.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PosEnc {
    /// Absolute grid value.
    Abs([u32; 3]),
    /// Grid delta from the link's last value.
    Delta([i32; 3]),
}

/// Particle payload of a chunk part.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ChunkEnc {
    /// All particles of the chunk, absolute.
    Abs(Vec<[u32; 3]>),
    /// Changed particles (index within chunk) with grid deltas.
    Delta(Vec<(u32, [i32; 3])>),
}

/// One part of an object's state.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PartBody {
    /// The center transform.
    Transform {
        /// Position, if sent.
        pos: Option<PosEnc>,
        /// Rotation, if sent.
        rot: Option<QuatQ>,
    },
    /// A range of particles.
    Chunk {
        /// Chunk index.
        chunk: u32,
        /// Payload.
        values: ChunkEnc,
    },
}

/// One state entry of a state block.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StateEntry {
    /// Object.
    pub id: NetId,
    /// Low bits of the authority epoch.
    pub epoch_tag: u8,
    /// Per-(link, object, part) entry sequence ([`ENTRY_SEQ_BITS`] bits).
    pub seq: u8,
    /// Keyframe: everything absolute.
    pub key: bool,
    /// Delta entries: the acknowledged entry this one is relative to.
    pub base: u8,
    /// The object is at rest (rest sync).
    pub rest: bool,
    /// Payload.
    pub body: PartBody,
}

/// What the decoder must know about an object to parse its entries (from local config).
#[derive(Clone, Copy, Debug)]
pub struct EntryLayout<'a> {
    /// The class.
    pub class: &'a ClassConfig,
    /// Particles of the object.
    pub particles: u32,
    /// The object's layout generation (resolution changes so far; the low 2 bits go with
    /// every particle chunk, so a chunk of another layout is recognised, not misparsed).
    pub generation: u8,
}

impl EntryLayout<'_> {
    fn chunk_len(&self, chunk: u32) -> Option<usize> {
        let per = self.class.chunk_len();
        let start = (chunk as usize).checked_mul(per)?;
        let n = self.particles as usize;
        if start >= n {
            return None;
        }
        Some((n - start).min(per))
    }
}

impl StateEntry {
    /// Part index: 0 = transform, k ≥ 1 = particle chunk k-1.
    pub fn part(&self) -> u32 {
        match &self.body {
            PartBody::Transform { .. } => 0,
            PartBody::Chunk { chunk, .. } => chunk + 1,
        }
    }

    /// Encode everything but the id (written by the block, delta-coded).
    pub fn encode_body(&self, layout: &EntryLayout, w: &mut BitWriter) {
        w.write(u32::from(self.epoch_tag & 0xF), 4);
        w.write_exp_golomb(self.part());
        if self.part() > 0 {
            w.write(u32::from(layout.generation & LAYOUT_MASK), LAYOUT_BITS);
        }
        w.write(u32::from(self.seq % ENTRY_SEQ_MOD), ENTRY_SEQ_BITS);
        w.write_bool(self.key);
        w.write_bool(self.rest);
        if !self.key {
            w.write(u32::from(self.base % ENTRY_SEQ_MOD), ENTRY_SEQ_BITS);
        }
        let pq = layout.class.position_quantizer();
        let bits = layout.class.rot_bits();
        match &self.body {
            PartBody::Transform { pos, rot } => {
                if !self.key {
                    w.write_bool(pos.is_some());
                    w.write_bool(rot.is_some());
                }
                match pos {
                    Some(PosEnc::Abs(q)) => pq.write(w, *q),
                    Some(PosEnc::Delta(d)) => {
                        let width = d.iter().map(|&x| signed_width(x)).max().unwrap_or(1);
                        w.write(width - 1, 5);
                        for x in d {
                            w.write((*x as u32) & mask_of(width), width);
                        }
                    }
                    None => {}
                }
                if let Some(r) = rot {
                    write_quat(w, *r, bits);
                }
            }
            PartBody::Chunk { values, .. } => {
                let q = layout.class.particle_quantizer();
                match values {
                    ChunkEnc::Abs(vals) => {
                        for v in vals {
                            q.write(w, *v);
                        }
                    }
                    ChunkEnc::Delta(list) => {
                        let n = layout.chunk_len(self.part() - 1).unwrap_or(0);
                        // index list or mask, whichever is smaller
                        let mask_bits = n;
                        let gap_bits: usize = gap_list_bits(list);
                        let use_mask = mask_bits <= gap_bits;
                        w.write_bool(use_mask);
                        if use_mask {
                            let mut k = 0;
                            for i in 0..n as u32 {
                                let set = list.get(k).is_some_and(|e| e.0 == i);
                                w.write_bool(set);
                                if set {
                                    k += 1;
                                }
                            }
                        } else {
                            w.write_exp_golomb(list.len() as u32);
                            let mut prev = 0u32;
                            for (i, (idx, _)) in list.iter().enumerate() {
                                let gap = if i == 0 { *idx } else { idx - prev - 1 };
                                w.write_exp_golomb(gap);
                                prev = *idx;
                            }
                        }
                        let width = list
                            .iter()
                            .flat_map(|(_, d)| d.iter())
                            .map(|&x| signed_width(x))
                            .max()
                            .unwrap_or(1);
                        w.write(width - 1, 5);
                        for (_, d) in list {
                            for x in d {
                                w.write((*x as u32) & mask_of(width), width);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Decode a body written by [`StateEntry::encode_body`].
    pub fn decode_body(
        id: NetId,
        layout: &EntryLayout,
        r: &mut BitReader,
    ) -> Result<StateEntry, NetError> {
        let epoch_tag = r.read(4)? as u8;
        let part = r.read_exp_golomb()?;
        if part > 0 && r.read(LAYOUT_BITS)? as u8 != layout.generation & LAYOUT_MASK {
            return Err(NetError::OtherLayout(id));
        }
        let seq = r.read(ENTRY_SEQ_BITS)? as u8;
        let key = r.read_bool()?;
        let rest = r.read_bool()?;
        let base = if key {
            0
        } else {
            r.read(ENTRY_SEQ_BITS)? as u8
        };
        let pq = layout.class.position_quantizer();
        let bits = layout.class.rot_bits();
        let body = if part == 0 {
            let (has_pos, has_rot) = if key {
                (true, true)
            } else {
                (r.read_bool()?, r.read_bool()?)
            };
            let pos = if !has_pos {
                None
            } else if key {
                Some(PosEnc::Abs(pq.read(r)?))
            } else {
                let width = r.read(5)? + 1;
                let mut d = [0i32; 3];
                for x in d.iter_mut() {
                    *x = sign_extend(r.read(width)?, width);
                }
                Some(PosEnc::Delta(d))
            };
            let rot = if has_rot {
                Some(read_quat(r, bits)?)
            } else {
                None
            };
            PartBody::Transform { pos, rot }
        } else {
            let chunk = part - 1;
            let n = layout
                .chunk_len(chunk)
                .ok_or(decode_err(0, "particle chunk out of range"))?;
            let q = layout.class.particle_quantizer();
            let values = if key {
                let mut vals = Vec::with_capacity(n);
                for _ in 0..n {
                    vals.push(q.read(r)?);
                }
                ChunkEnc::Abs(vals)
            } else {
                let use_mask = r.read_bool()?;
                let mut idx = Vec::new();
                if use_mask {
                    for i in 0..n as u32 {
                        if r.read_bool()? {
                            idx.push(i);
                        }
                    }
                } else {
                    let count = r.read_exp_golomb()? as usize;
                    if count > n {
                        return Err(decode_err(0, "more changed particles than the chunk has"));
                    }
                    let mut next = 0u32;
                    for _ in 0..count {
                        let gap = r.read_exp_golomb()?;
                        let i = next
                            .checked_add(gap)
                            .filter(|&i| (i as usize) < n)
                            .ok_or(decode_err(0, "particle index out of range"))?;
                        idx.push(i);
                        next = i + 1;
                    }
                }
                let width = r.read(5)? + 1;
                let mut list = Vec::with_capacity(idx.len());
                for i in idx {
                    let mut d = [0i32; 3];
                    for x in d.iter_mut() {
                        *x = sign_extend(r.read(width)?, width);
                    }
                    list.push((i, d));
                }
                ChunkEnc::Delta(list)
            };
            PartBody::Chunk { chunk, values }
        };
        Ok(StateEntry {
            id,
            epoch_tag,
            seq,
            key,
            base,
            rest,
            body,
        })
    }
}

fn mask_of(width: u32) -> u32 {
    if width >= 32 {
        u32::MAX
    } else {
        (1u32 << width) - 1
    }
}

fn signed_width(x: i32) -> u32 {
    let m = if x < 0 { !x } else { x };
    (33 - m.leading_zeros()).clamp(1, 26)
}

fn sign_extend(raw: u32, width: u32) -> i32 {
    let shift = 32 - width.clamp(1, 32);
    ((raw << shift) as i32) >> shift
}

fn eg_bits(v: u32) -> usize {
    let x = u64::from(v) + 1;
    (2 * (63 - x.leading_zeros()) + 1) as usize
}

fn gap_list_bits(list: &[(u32, [i32; 3])]) -> usize {
    let mut bits = eg_bits(list.len() as u32);
    let mut prev = 0u32;
    for (i, (idx, _)) in list.iter().enumerate() {
        let gap = if i == 0 {
            *idx
        } else {
            idx.saturating_sub(prev + 1)
        };
        bits += eg_bits(gap);
        prev = *idx;
    }
    bits
}

/// Encode the id prefix of an entry (delta from the previous id in the block).
pub fn write_entry_id(w: &mut BitWriter, prev: Option<NetId>, id: NetId) {
    let base = prev.map_or(0, |p| p.0);
    w.write_exp_golomb(id.0.wrapping_sub(base));
}

/// Bits an id prefix takes.
pub fn entry_id_bits(prev: Option<NetId>, id: NetId) -> usize {
    eg_bits(id.0.wrapping_sub(prev.map_or(0, |p| p.0)))
}

/// Decode a state block; stops early (keeping what was parsed) at an object it cannot lay out.
pub fn decode_state_block<'c>(
    count: u32,
    bits: &[u8],
    layout_of: impl Fn(NetId) -> Option<EntryLayout<'c>>,
) -> Result<(Vec<StateEntry>, bool), NetError> {
    let (entries, complete) = decode_state_block_sized(count, bits, layout_of)?;
    Ok((entries.into_iter().map(|(e, _)| e).collect(), complete))
}

/// A decoded entry with the bits its body took on the wire (the id prefix excluded).
pub type SizedEntry = (StateEntry, usize);

/// Decode a state block like [`decode_state_block`], with each entry's body size in bits (what
/// was read, for per-class statistics: nothing is encoded again to count it).
pub fn decode_state_block_sized<'c>(
    count: u32,
    bits: &[u8],
    layout_of: impl Fn(NetId) -> Option<EntryLayout<'c>>,
) -> Result<(Vec<SizedEntry>, bool), NetError> {
    let mut r = BitReader::new(bits);
    let mut out = Vec::new();
    let mut prev: Option<NetId> = None;
    for _ in 0..count {
        let d = r.read_exp_golomb()?;
        let id = NetId(prev.map_or(0, |p| p.0).wrapping_add(d));
        let Some(layout) = layout_of(id) else {
            return Ok((out, false));
        };
        let at = r.bits_read();
        let entry = match StateEntry::decode_body(id, &layout, &mut r) {
            Err(NetError::OtherLayout(_)) => return Ok((out, false)),
            e => e?,
        };
        out.push((entry, r.bits_read() - at));
        prev = Some(id);
    }
    Ok((out, true))
}

/// What [`StateBlockWriter::push`] did with an entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pushed {
    /// Written; it took this many bits (id prefix included).
    Written(usize),
    /// The block is full: the entry goes in a later datagram.
    Full,
    /// The entry alone is larger than an empty block may be: it can never be sent.
    Oversize,
}

/// Packs state entries into one block of at most `budget_bits`, ids delta-coded in order.
#[derive(Debug)]
pub struct StateBlockWriter {
    w: BitWriter,
    prev: Option<NetId>,
    count: usize,
    budget_bits: usize,
}

impl StateBlockWriter {
    /// An empty block that may grow to `budget_bits`.
    pub fn new(budget_bits: usize) -> Self {
        StateBlockWriter {
            w: BitWriter::new(),
            prev: None,
            count: 0,
            budget_bits,
        }
    }

    /// Append `e` if it fits (entries must come in ascending id order).
    pub fn push(&mut self, e: &StateEntry, layout: &EntryLayout) -> Pushed {
        let mut body = BitWriter::new();
        e.encode_body(layout, &mut body);
        let bits = entry_id_bits(self.prev, e.id) + body.bit_len();
        if self.w.bit_len() + bits > self.budget_bits {
            return if self.w.bit_len() == 0 {
                Pushed::Oversize
            } else {
                Pushed::Full
            };
        }
        write_entry_id(&mut self.w, self.prev, e.id);
        self.w.append(&body);
        self.count += 1;
        self.prev = Some(e.id);
        Pushed::Written(bits)
    }

    /// Nothing written yet.
    pub fn is_empty(&self) -> bool {
        self.w.bit_len() == 0
    }

    /// Entry count and the block's bytes.
    pub fn finish(self) -> (usize, Vec<u8>) {
        (self.count, self.w.into_bytes())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::policy::{SendPolicy, SoftBodyMode};

    #[test]
    fn chunk_delta_round_trip_mask_and_gaps() {
        let class = ClassConfig::soft_body("sb", SendPolicy::default(), SoftBodyMode::Particles);
        let layout = EntryLayout {
            class: &class,
            particles: 60,
            generation: 0,
        };
        for list in [
            vec![(3u32, [1i32, -2, 3])],
            (0..60)
                .map(|i| (i, [i as i32 - 30, 0, 1]))
                .collect::<Vec<_>>(),
        ] {
            let e = StateEntry {
                id: NetId(7),
                epoch_tag: 3,
                seq: 9,
                key: false,
                base: 30,
                rest: false,
                body: PartBody::Chunk {
                    chunk: 0,
                    values: ChunkEnc::Delta(list),
                },
            };
            let mut w = BitWriter::new();
            e.encode_body(&layout, &mut w);
            let bytes = w.into_bytes();
            let d =
                StateEntry::decode_body(NetId(7), &layout, &mut BitReader::new(&bytes)).unwrap();
            assert_eq!(d, e);
        }
    }

    fn transform_entry(id: u32, seq: u8) -> StateEntry {
        StateEntry {
            id: NetId(id),
            epoch_tag: 1,
            seq,
            key: true,
            base: 0,
            rest: false,
            body: PartBody::Transform {
                pos: Some(PosEnc::Abs([10, 20, 30])),
                rot: Some(crate::quant::quantize_quat(glam::Quat::IDENTITY, 11)),
            },
        }
    }

    #[test]
    fn a_block_reads_back_its_entries_with_the_bits_each_body_took() {
        let class = ClassConfig::rigid("r", SendPolicy::default());
        let layout = EntryLayout {
            class: &class,
            particles: 0,
            generation: 0,
        };
        let mut w = StateBlockWriter::new(10_000);
        let mut written = Vec::new();
        for (id, seq) in [(3, 1), (4, 2), (90, 3)] {
            let e = transform_entry(id, seq);
            let Pushed::Written(bits) = w.push(&e, &layout) else {
                panic!("did not fit");
            };
            let id_bits = entry_id_bits(
                written.last().map(|(e, _): &(StateEntry, usize)| e.id),
                e.id,
            );
            written.push((e, bits - id_bits));
        }
        let (count, bytes) = w.finish();
        let (read, complete) =
            decode_state_block_sized(count as u32, &bytes, |_| Some(layout)).unwrap();
        assert!(complete);
        assert_eq!(read, written);
    }

    #[test]
    fn a_full_block_refuses_more_and_an_entry_too_big_for_any_block_is_oversize() {
        let class = ClassConfig::rigid("r", SendPolicy::default());
        let layout = EntryLayout {
            class: &class,
            particles: 0,
            generation: 0,
        };
        let e = transform_entry(1, 0);
        let mut probe = StateBlockWriter::new(usize::MAX);
        let Pushed::Written(one) = probe.push(&e, &layout) else {
            panic!()
        };
        let mut w = StateBlockWriter::new(one + 5);
        assert_eq!(w.push(&e, &layout), Pushed::Written(one));
        assert_eq!(w.push(&transform_entry(2, 0), &layout), Pushed::Full);
        let mut tiny = StateBlockWriter::new(one - 1);
        assert_eq!(tiny.push(&e, &layout), Pushed::Oversize);
        assert!(tiny.is_empty());
    }
}
