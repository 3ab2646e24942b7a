//! Bit-level and byte-level primitives of the codec: a bit writer/reader, LEB128 varints,
//! zigzag and Exp-Golomb codes. Readers never panic and never allocate from wire lengths.

use crate::error::{decode_err, NetError};

/// Appends bits (LSB first) to a byte vector.
#[derive(Default, Debug, Clone)]
pub struct BitWriter {
    bytes: Vec<u8>,
    bit_len: usize,
}

impl BitWriter {
    /// An empty writer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of bits written.
    pub fn bit_len(&self) -> usize {
        self.bit_len
    }

    /// Write the low `n` bits of `v` (n ≤ 32).
    pub fn write(&mut self, v: u32, n: u32) {
        for i in 0..n {
            let bit = (v >> i) & 1;
            let byte = self.bit_len / 8;
            if byte == self.bytes.len() {
                self.bytes.push(0);
            }
            if let Some(b) = self.bytes.get_mut(byte) {
                *b |= (bit as u8) << (self.bit_len % 8);
            }
            self.bit_len += 1;
        }
    }

    /// Write one flag bit.
    pub fn write_bool(&mut self, b: bool) {
        self.write(u32::from(b), 1);
    }

    /// Exp-Golomb (order 0) code of `v`: small values take few bits.
    pub fn write_exp_golomb(&mut self, v: u32) {
        let x = u64::from(v) + 1;
        let n = 63 - x.leading_zeros(); // floor(log2 x)
        self.write(0, n);
        // write x in n+1 bits, MSB first so the leading 1 ends the zero run
        for i in (0..=n).rev() {
            self.write(((x >> i) & 1) as u32, 1);
        }
    }

    /// A signed value as zigzag + Exp-Golomb.
    pub fn write_signed_exp_golomb(&mut self, v: i32) {
        self.write_exp_golomb(zigzag(v));
    }

    /// Append another writer's bits.
    pub fn append(&mut self, other: &BitWriter) {
        let mut r = BitReader::new(&other.bytes);
        let mut left = other.bit_len;
        while left > 0 {
            let n = left.min(32) as u32;
            let v = r.read(n).unwrap_or(0);
            self.write(v, n);
            left -= n as usize;
        }
    }

    /// The bytes (last byte zero-padded).
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }

    /// Bytes written so far, rounded up.
    pub fn byte_len(&self) -> usize {
        self.bit_len.div_ceil(8)
    }
}

/// Reads bits (LSB first) from a byte slice.
#[derive(Debug, Clone)]
pub struct BitReader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> BitReader<'a> {
    /// A reader over `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        BitReader { bytes, pos: 0 }
    }

    /// Bits read so far.
    pub fn bits_read(&self) -> usize {
        self.pos
    }

    /// Bits left.
    pub fn remaining(&self) -> usize {
        (self.bytes.len() * 8).saturating_sub(self.pos)
    }

    /// Read `n` bits (n ≤ 32).
    pub fn read(&mut self, n: u32) -> Result<u32, NetError> {
        if n > 32 || self.remaining() < n as usize {
            return Err(decode_err(self.pos / 8, "bit stream truncated"));
        }
        let mut v: u32 = 0;
        for i in 0..n {
            let byte = self.bytes.get(self.pos / 8).copied().unwrap_or(0);
            let bit = (byte >> (self.pos % 8)) & 1;
            v |= u32::from(bit) << i;
            self.pos += 1;
        }
        Ok(v)
    }

    /// Read one flag bit.
    pub fn read_bool(&mut self) -> Result<bool, NetError> {
        Ok(self.read(1)? == 1)
    }

    /// Read an Exp-Golomb code (values up to u32::MAX).
    pub fn read_exp_golomb(&mut self) -> Result<u32, NetError> {
        let mut zeros = 0u32;
        while !self.read_bool()? {
            zeros += 1;
            if zeros > 32 {
                return Err(decode_err(self.pos / 8, "exp-golomb code too long"));
            }
        }
        let mut x: u64 = 1;
        for _ in 0..zeros {
            x = (x << 1) | u64::from(self.read(1)?);
        }
        u32::try_from(x - 1).map_err(|_| decode_err(self.pos / 8, "exp-golomb overflow"))
    }

    /// Read a zigzag + Exp-Golomb signed value.
    pub fn read_signed_exp_golomb(&mut self) -> Result<i32, NetError> {
        Ok(unzigzag(self.read_exp_golomb()?))
    }
}

/// Zigzag-map a signed value to unsigned.
pub fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

/// Inverse of [`zigzag`].
pub fn unzigzag(v: u32) -> i32 {
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

/// Append a LEB128 varint.
pub fn write_varint(out: &mut Vec<u8>, mut v: u64) {
    loop {
        let b = (v & 0x7F) as u8;
        v >>= 7;
        if v == 0 {
            out.push(b);
            return;
        }
        out.push(b | 0x80);
    }
}

/// A byte cursor over a datagram.
#[derive(Debug, Clone)]
pub struct ByteReader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> ByteReader<'a> {
    /// A cursor at the start of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        ByteReader { bytes, pos: 0 }
    }

    /// Current offset.
    pub fn pos(&self) -> usize {
        self.pos
    }

    /// True when everything has been read.
    pub fn is_empty(&self) -> bool {
        self.pos >= self.bytes.len()
    }

    /// Read one byte.
    pub fn u8(&mut self) -> Result<u8, NetError> {
        let b = self
            .bytes
            .get(self.pos)
            .copied()
            .ok_or(decode_err(self.pos, "unexpected end of datagram"))?;
        self.pos += 1;
        Ok(b)
    }

    /// Read a little-endian u16.
    pub fn u16(&mut self) -> Result<u16, NetError> {
        let lo = self.u8()?;
        let hi = self.u8()?;
        Ok(u16::from_le_bytes([lo, hi]))
    }

    /// Read a LEB128 varint of at most 10 bytes.
    pub fn varint(&mut self) -> Result<u64, NetError> {
        let start = self.pos;
        let mut v: u64 = 0;
        for i in 0..10 {
            let b = self.u8()?;
            let part = u64::from(b & 0x7F);
            if i == 9 && part > 1 {
                return Err(decode_err(start, "varint overflow"));
            }
            v |= part << (7 * i);
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(decode_err(start, "varint too long"))
    }

    /// Read a varint that must fit in u32.
    pub fn varint_u32(&mut self) -> Result<u32, NetError> {
        let at = self.pos;
        u32::try_from(self.varint()?).map_err(|_| decode_err(at, "varint exceeds u32"))
    }

    /// Borrow the next `n` bytes (n checked against what is left, never allocated).
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], NetError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or(decode_err(self.pos, "length exceeds datagram"))?;
        let s = self
            .bytes
            .get(self.pos..end)
            .ok_or(decode_err(self.pos, "length exceeds datagram"))?;
        self.pos = end;
        Ok(s)
    }
}

/// Encoded length of a varint.
pub fn varint_len(v: u64) -> usize {
    let bits = 64 - v.leading_zeros() as usize;
    bits.div_ceil(7).max(1)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn exp_golomb_round_trip() {
        let mut w = BitWriter::new();
        let vals = [0u32, 1, 2, 3, 7, 8, 1000, u32::MAX];
        for v in vals {
            w.write_exp_golomb(v);
        }
        w.write_signed_exp_golomb(-5);
        let bytes = w.into_bytes();
        let mut r = BitReader::new(&bytes);
        for v in vals {
            assert_eq!(r.read_exp_golomb().unwrap(), v);
        }
        assert_eq!(r.read_signed_exp_golomb().unwrap(), -5);
    }

    #[test]
    fn varint_round_trip() {
        for v in [0u64, 127, 128, 300, u64::MAX] {
            let mut b = Vec::new();
            write_varint(&mut b, v);
            assert_eq!(b.len(), varint_len(v));
            assert_eq!(ByteReader::new(&b).varint().unwrap(), v);
        }
    }
}
