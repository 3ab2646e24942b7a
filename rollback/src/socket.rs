//! Rollback datagrams on the room's transport, beside the session's and the scene share's:
//! ggrs's messages (its own UDP socket is not used) and the snapshot a joiner pulls.
//!
//! # Wire
//! Every datagram starts with [`ROLLBACK_MARKER`] (never a session datagram's first byte: that
//! is the protocol version or 0; nor a share datagram's), then a kind byte and the epoch (u32,
//! little endian) it belongs to:
//! - `1` ggrs: a `ggrs::Message`, bincode (standard, at most [`MAX_GGRS_BYTES`]);
//! - `2` snapshot: a share datagram ([`softsync_net::share`]) for the epoch's snapshot.
//!
//! Decoding never panics: a short, unknown or over-long datagram is an error.

use std::cell::RefCell;
use std::rc::Rc;

use ggrs::{Message, NonBlockingSocket};
use softsync_net::{PeerId, Transmit};

/// First byte of every rollback datagram.
pub const ROLLBACK_MARKER: u8 = softsync_net::door::ROLLBACK;
/// Largest ggrs message we decode (its input messages carry a few frames of a few players).
pub const MAX_GGRS_BYTES: usize = 4096;

const KIND_GGRS: u8 = 1;
const KIND_SNAPSHOT: u8 = 2;

/// A decoded rollback datagram.
#[derive(Debug)]
pub enum Datagram<'a> {
    /// A ggrs message of `epoch`.
    Ggrs {
        /// The epoch (ggrs session) it belongs to.
        epoch: u32,
        /// The message.
        msg: Message,
    },
    /// A share datagram about `epoch`'s snapshot.
    Snapshot {
        /// The epoch.
        epoch: u32,
        /// The share datagram inside.
        share: &'a [u8],
    },
}

/// Why a rollback datagram was dropped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Not one of ours (the first byte is not [`ROLLBACK_MARKER`]) or cut short.
    #[error("not a rollback datagram, or shorter than its header")]
    Short,
    /// An unknown kind byte.
    #[error("unknown rollback datagram kind {0}")]
    Kind(u8),
    /// The ggrs message does not decode.
    #[error("bad ggrs message: {0}")]
    Ggrs(String),
}

/// Whether a datagram is a rollback one.
pub fn is_rollback(datagram: &[u8]) -> bool {
    datagram.first() == Some(&ROLLBACK_MARKER)
}

fn bincode_cfg() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_GGRS_BYTES>()
}

fn header(kind: u8, epoch: u32) -> Vec<u8> {
    let mut out = Vec::with_capacity(64);
    out.push(ROLLBACK_MARKER);
    out.push(kind);
    out.extend_from_slice(&epoch.to_le_bytes());
    out
}

/// Encode a ggrs message of `epoch`.
pub fn encode_ggrs(epoch: u32, msg: &Message) -> Vec<u8> {
    let mut out = header(KIND_GGRS, epoch);
    // A ggrs message always encodes (plain data); an error would only be a full buffer.
    if let Ok(bytes) = bincode::serde::encode_to_vec(msg, bincode_cfg()) {
        out.extend_from_slice(&bytes);
    }
    out
}

/// Wrap a share datagram about `epoch`'s snapshot.
pub fn encode_snapshot(epoch: u32, share: &[u8]) -> Vec<u8> {
    let mut out = header(KIND_SNAPSHOT, epoch);
    out.extend_from_slice(share);
    out
}

/// Decode a rollback datagram.
pub fn decode(datagram: &[u8]) -> Result<Datagram<'_>, DecodeError> {
    if datagram.len() < 6 || datagram[0] != ROLLBACK_MARKER {
        return Err(DecodeError::Short);
    }
    let epoch = u32::from_le_bytes([datagram[2], datagram[3], datagram[4], datagram[5]]);
    let body = &datagram[6..];
    match datagram[1] {
        KIND_GGRS => {
            if body.len() > MAX_GGRS_BYTES {
                return Err(DecodeError::Ggrs("over-long".into()));
            }
            let (msg, used) = bincode::serde::decode_from_slice::<Message, _>(body, bincode_cfg())
                .map_err(|e| DecodeError::Ggrs(e.to_string()))?;
            if used != body.len() {
                return Err(DecodeError::Ggrs("trailing bytes".into()));
            }
            Ok(Datagram::Ggrs { epoch, msg })
        }
        KIND_SNAPSHOT => Ok(Datagram::Snapshot { epoch, share: body }),
        k => Err(DecodeError::Kind(k)),
    }
}

/// What ggrs's socket and the room share: ggrs's sends to go out, received messages to give.
#[derive(Debug, Default)]
pub struct Queues {
    /// The epoch this socket's ggrs session is.
    pub epoch: u32,
    /// Datagrams ggrs sent, for the room to hand to the transport.
    pub outbox: Vec<Transmit>,
    /// Messages received for this epoch, for ggrs.
    pub inbox: Vec<(PeerId, Message)>,
    /// Bytes ggrs sent (for the bench's bytes per second).
    pub bytes_sent: u64,
}

/// ggrs's socket: [`Queues`] the room fills and drains.
#[derive(Clone, Debug)]
pub struct GgrsSocket(pub Rc<RefCell<Queues>>);

impl NonBlockingSocket<PeerId> for GgrsSocket {
    fn send_to(&mut self, msg: &Message, addr: &PeerId) {
        let mut q = self.0.borrow_mut();
        let payload = encode_ggrs(q.epoch, msg);
        q.bytes_sent += payload.len() as u64;
        q.outbox.push(Transmit {
            to: *addr,
            payload,
            reliable: false,
        });
    }

    fn receive_all_messages(&mut self) -> Vec<(PeerId, Message)> {
        std::mem::take(&mut self.0.borrow_mut().inbox)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hostile_datagrams_are_errors_and_never_panic() {
        assert_eq!(decode(&[]).err(), Some(DecodeError::Short));
        assert_eq!(
            decode(&[ROLLBACK_MARKER, 1, 0]).err(),
            Some(DecodeError::Short)
        );
        assert_eq!(
            decode(&[ROLLBACK_MARKER, 9, 0, 0, 0, 0]).err(),
            Some(DecodeError::Kind(9))
        );
        // A hostile length inside the ggrs message: bincode's limit refuses it.
        let mut d = vec![ROLLBACK_MARKER, 1, 0, 0, 0, 0];
        d.extend_from_slice(&[0x03, 0xFC, 0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0xFF]);
        assert!(matches!(decode(&d), Err(DecodeError::Ggrs(_))));
        // Every prefix and every single-byte corruption of a real datagram: no panic.
        let mut r = 0x1234_5678u32;
        for len in 0..64 {
            let mut d = vec![ROLLBACK_MARKER, 1, 7, 0, 0, 0];
            for _ in 0..len {
                r = r.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                d.push((r >> 24) as u8);
            }
            let _ = decode(&d);
        }
    }
}
