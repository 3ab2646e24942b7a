//! Typed application messages: declare a serde type as a [`Message`], register it in the
//! room's [`MessageTypes`], send it with [`Session::send`] and read it back with
//! [`MessageTypes::decode`].
//!
//! The table of registered names is part of the room's configuration digest
//! ([`SessionConfig::digest`]): a peer built with other message types is refused at the
//! handshake, so a kind number means the same type on every peer of a room. A message of a
//! kind outside the table (a modified peer) is refused by the host and counted.
//!
//! ```
//! use serde::{Deserialize, Serialize};
//! use softsync_net::messages::{Message, MessageTypes};
//! use softsync_net::wire::{Delivery, MessageTarget};
//! use softsync_net::{Event, Instant, PeerId, Session, SessionConfig};
//!
//! #[derive(Serialize, Deserialize, Debug, PartialEq)]
//! struct RingBell {
//!     loudness: u8,
//! }
//! impl Message for RingBell {
//!     const NAME: &'static str = "ring_bell";
//! }
//!
//! let mut types = MessageTypes::new();
//! types.register::<RingBell>().unwrap();
//! let mut cfg = SessionConfig::default();
//! types.configure(&mut cfg);
//!
//! let now = Instant::ZERO;
//! let mut host = Session::host(PeerId(1), cfg.clone(), now);
//! let mut guest = Session::join(PeerId(2), PeerId(1), cfg, now);
//! for _ in 0..4 {
//!     while let Some(t) = guest.poll_transmit(now) { host.handle_packet(now, PeerId(2), &t.payload); }
//!     while let Some(t) = host.poll_transmit(now) { guest.handle_packet(now, PeerId(1), &t.payload); }
//! }
//! host.send(now, &types, MessageTarget::Everyone, Delivery::Reliable, &RingBell { loudness: 3 })
//!     .unwrap();
//! while let Some(t) = host.poll_transmit(now) { guest.handle_packet(now, PeerId(1), &t.payload); }
//! let rung = std::iter::from_fn(|| guest.poll_event()).find_map(|e| match e {
//!     Event::Message(m) => types.decode::<RingBell>(&m),
//!     _ => None,
//! });
//! assert_eq!(rung, Some(Ok(RingBell { loudness: 3 })));
//! ```

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::policy::SessionConfig;
use crate::session::Session;
use crate::time::Instant;
use crate::wire::{
    Delivery, MessageKind, MessageRefusal, MessageTarget, ReceivedMessage, MAX_MESSAGE_PAYLOAD,
};

/// An application message type: serde both ways, and a name unique in the room.
pub trait Message: Serialize + DeserializeOwned {
    /// The type's name in the room's message table (the same on every peer).
    const NAME: &'static str;
}

/// Why a message type could not be registered.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegisterError {
    /// Two types with one name.
    #[error("message type `{0}` is registered twice")]
    Duplicate(String),
    /// More types than a kind number holds.
    #[error("more than {} message types", u16::MAX)]
    TooMany,
}

/// The room's message types: names in registration order, a kind number each.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MessageTypes {
    names: Vec<String>,
    kinds: BTreeMap<String, MessageKind>,
}

fn codec() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_MESSAGE_PAYLOAD>()
}

impl MessageTypes {
    /// No types.
    pub fn new() -> Self {
        MessageTypes::default()
    }

    /// Register `M`; its kind is the next number. Register in the same order on every peer.
    pub fn register<M: Message>(&mut self) -> Result<MessageKind, RegisterError> {
        self.register_name(M::NAME)
    }

    /// Register a type by name only (an untyped message, or a tool that relays bytes).
    pub fn register_name(&mut self, name: &str) -> Result<MessageKind, RegisterError> {
        if self.kinds.contains_key(name) {
            return Err(RegisterError::Duplicate(name.to_string()));
        }
        let kind =
            MessageKind(u16::try_from(self.names.len()).map_err(|_| RegisterError::TooMany)?);
        self.names.push(name.to_string());
        self.kinds.insert(name.to_string(), kind);
        Ok(kind)
    }

    /// The table a room's configuration holds (what [`configure`](Self::configure) put
    /// there); `None` if it names a type twice.
    pub fn from_config(cfg: &SessionConfig) -> Option<Self> {
        let mut t = MessageTypes::new();
        for n in &cfg.messages.kinds {
            t.register_name(n).ok()?;
        }
        Some(t)
    }

    /// Put the table into a room's configuration (every peer must, before it hosts or joins).
    pub fn configure(&self, cfg: &mut SessionConfig) {
        cfg.messages.kinds = self.names.clone();
    }

    /// The names, in kind order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// `M`'s kind, if registered.
    pub fn kind<M: Message>(&self) -> Option<MessageKind> {
        self.kinds.get(M::NAME).copied()
    }

    /// The name of a kind.
    pub fn name(&self, kind: MessageKind) -> Option<&str> {
        self.names.get(usize::from(kind.0)).map(String::as_str)
    }

    /// `msg`'s kind and bytes.
    pub fn encode<M: Message>(&self, msg: &M) -> Result<(MessageKind, Vec<u8>), MessageRefusal> {
        let kind = self.kind::<M>().ok_or(MessageRefusal::UnknownKind)?;
        let bytes =
            bincode::serde::encode_to_vec(msg, codec()).map_err(|_| MessageRefusal::Malformed)?;
        if bytes.len() > MAX_MESSAGE_PAYLOAD {
            return Err(MessageRefusal::TooLarge);
        }
        Ok((kind, bytes))
    }

    /// `received` as an `M`: `None` if it is another type, `Some(Err(Malformed))` if its
    /// bytes are not an `M` (never a panic).
    pub fn decode<M: Message>(
        &self,
        received: &ReceivedMessage,
    ) -> Option<Result<M, MessageRefusal>> {
        if self.kind::<M>()? != received.kind {
            return None;
        }
        let decoded = bincode::serde::decode_from_slice::<M, _>(&received.payload, codec());
        Some(match decoded {
            Ok((m, used)) if used == received.payload.len() => Ok(m),
            _ => Err(MessageRefusal::Malformed),
        })
    }
}

impl Session {
    /// Send a typed message (see [`Session::send_message`]); `types` must be the table the
    /// room was configured with.
    pub fn send<M: Message>(
        &mut self,
        now: Instant,
        types: &MessageTypes,
        to: MessageTarget,
        delivery: Delivery,
        msg: &M,
    ) -> Result<u32, MessageRefusal> {
        let (kind, bytes) = types.encode(msg)?;
        self.send_message(now, kind, to, delivery, bytes)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use serde::Deserialize;

    #[derive(Serialize, Deserialize, Debug, PartialEq)]
    struct Valve {
        id: u32,
        opening: f32,
    }
    impl Message for Valve {
        const NAME: &'static str = "valve";
    }

    #[derive(Serialize, Deserialize, Debug, PartialEq)]
    struct Note(String);
    impl Message for Note {
        const NAME: &'static str = "note";
    }

    fn received(kind: MessageKind, payload: Vec<u8>) -> ReceivedMessage {
        ReceivedMessage {
            from: crate::PeerId(1),
            kind,
            to: MessageTarget::Everyone,
            delivery: Delivery::Reliable,
            payload,
        }
    }

    #[test]
    fn types_round_trip_and_another_type_or_bad_bytes_are_not_mistaken_for_one() {
        let mut t = MessageTypes::new();
        assert_eq!(t.register::<Valve>().unwrap(), MessageKind(0));
        assert_eq!(t.register::<Note>().unwrap(), MessageKind(1));
        assert_eq!(
            t.register::<Note>(),
            Err(RegisterError::Duplicate("note".into()))
        );
        let v = Valve {
            id: 3,
            opening: 0.5,
        };
        let (k, b) = t.encode(&v).unwrap();
        assert_eq!(t.decode::<Valve>(&received(k, b.clone())), Some(Ok(v)));
        assert_eq!(t.decode::<Note>(&received(k, b)), None);
        assert_eq!(
            t.decode::<Valve>(&received(k, vec![0xFF; 3])),
            Some(Err(MessageRefusal::Malformed))
        );
        let too_long = Note("x".repeat(MAX_MESSAGE_PAYLOAD + 1));
        assert_eq!(t.encode(&too_long), Err(MessageRefusal::TooLarge));
        let mut cfg = SessionConfig::default();
        let before = cfg.digest();
        t.configure(&mut cfg);
        assert_ne!(cfg.digest(), before, "the table is part of the digest");
        assert_eq!(t.name(MessageKind(1)), Some("note"));
    }
}
