//! The crate's error type.

use crate::ids::{NetId, PeerId};

/// Everything that can go wrong in `softsync-net`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NetError {
    /// A datagram could not be decoded.
    #[error("decode error at byte {offset}: {what}")]
    Decode {
        /// Byte offset in the datagram.
        offset: usize,
        /// What was wrong.
        what: &'static str,
    },
    /// The remote speaks another protocol version.
    #[error("protocol version mismatch: ours {ours}, theirs {theirs}")]
    VersionMismatch {
        /// Our version.
        ours: u8,
        /// Their version.
        theirs: u8,
    },
    /// The object is unknown.
    #[error("unknown object {0:?}")]
    UnknownObject(NetId),
    /// The local peer does not own the object.
    #[error("object {0:?} is owned by {1:?}, not by us")]
    NotOwner(NetId, PeerId),
    /// The state does not fit the object's class.
    #[error("invalid state for object: {0}")]
    InvalidState(&'static str),
    /// The session is not (yet) part of a room.
    #[error("not connected to a room")]
    NotConnected,
    /// The class id is not configured.
    #[error("unknown class {0}")]
    UnknownClass(u16),
    /// The room's object id space is used up.
    #[error("no object ids left in this room")]
    IdsExhausted,
    /// A state entry of particles laid out for another resolution of the object than ours
    /// (sent before or after a resolution change we have not seen yet): it cannot be parsed,
    /// so the rest of its block is skipped.
    #[error("state of object {0:?} laid out for another resolution")]
    OtherLayout(NetId),
    /// A room cannot be reopened this way ([`crate::Session::restore_object`]).
    #[error("cannot restore the room: {0}")]
    Restore(&'static str),
    /// A message could not be encoded (too large for its limit): it is not sent.
    #[error("cannot encode {what}")]
    Encode {
        /// What, and why.
        what: String,
    },
}

/// Shorthand for a decode error.
pub(crate) fn decode_err(offset: usize, what: &'static str) -> NetError {
    NetError::Decode { offset, what }
}
