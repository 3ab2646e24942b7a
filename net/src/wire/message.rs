//! Application messages on the wire: the envelope ([`AppMessage`]) an application's own
//! message travels in, whom it goes to ([`MessageTarget`]), how ([`Delivery`]) and why one was
//! refused ([`MessageRefusal`]).
//!
//! Reliable and retained messages ride in a [`Control::Message`](super::Control::Message) on
//! the reliable channel; unreliable ones in a datagram's `MESSAGE` section. The session only
//! sees bytes and a kind number; the typed layer is [`crate::messages`].

use serde::{Deserialize, Serialize};

use crate::ids::{NetId, PeerId};

/// Largest application payload, bytes: an envelope with it still fits one control message
/// ([`MAX_CONTROL_LEN`](super::MAX_CONTROL_LEN)) and one datagram at the smallest MTU we
/// accept.
pub const MAX_MESSAGE_PAYLOAD: usize = 900;

/// An application message type: its index in the room's table of message names
/// ([`crate::policy::MessageConfig::kinds`], the same on every peer).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct MessageKind(pub u16);

/// Whom a message goes to. The sender never receives its own message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum MessageTarget {
    /// Every member but the sender.
    Everyone,
    /// One member.
    Peer(PeerId),
    /// Whoever owns the object when the host relays it (after a host migration, a resent
    /// message goes to the owner the new host knows).
    OwnerOf(NetId),
    /// The host.
    Host,
}

/// How a message travels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Delivery {
    /// Delivered once and in order (per sender) to every target that stays in the room, also
    /// across host migrations; the sender hears [`crate::Event::MessageDelivered`] when every
    /// target has it.
    Reliable,
    /// At most once, maybe not at all; never delays anything.
    Unreliable,
    /// Reliable, to [`MessageTarget::Everyone`] only, and kept by every member (the latest
    /// one per kind): a peer that joins later receives it after the room's objects. For
    /// messages that are state (the step a procedure is at, a bell that rang).
    Retained,
    /// Retained, per object: the latest one of each kind about this object is kept with it
    /// (a late joiner gets it after the objects) and forgotten when the object is despawned.
    /// For small custom state that belongs to an object (a valve's opening, a colour).
    ObjectState(NetId),
}

impl Delivery {
    /// Everything but unreliable.
    pub fn is_reliable(self) -> bool {
        self != Delivery::Unreliable
    }

    /// Kept by the room (retained, room-wide or per object).
    pub fn is_retained(self) -> bool {
        matches!(self, Delivery::Retained | Delivery::ObjectState(_))
    }
}

/// Why a message was not sent or not relayed. The sender's session counts every refusal by
/// reason ([`crate::stats::MessageStats::refused`]); the host's counts those it refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum MessageRefusal {
    /// Not in a room (joining, refused or dropped).
    NotConnected,
    /// The kind is not in the room's message table.
    UnknownKind,
    /// The payload is longer than the room allows.
    TooLarge,
    /// The sender exceeded the room's message rate.
    RateLimited,
    /// Too many of the sender's reliable messages are waiting for delivery, or too many
    /// unreliable ones for the next datagram.
    QueueFull,
    /// The target peer is not a member, or the object is unknown.
    NoSuchTarget,
    /// A retained message must go to everyone.
    BadDelivery,
    /// The host's filter refused it, with the application's code.
    Filtered(u16),
    /// The message could not be encoded or decoded as its type.
    Malformed,
}

impl std::fmt::Display for MessageRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MessageRefusal::NotConnected => write!(f, "not in a room"),
            MessageRefusal::UnknownKind => write!(f, "unknown message kind"),
            MessageRefusal::TooLarge => write!(f, "payload too large"),
            MessageRefusal::RateLimited => write!(f, "message rate exceeded"),
            MessageRefusal::QueueFull => write!(f, "message queue full"),
            MessageRefusal::NoSuchTarget => write!(f, "no such target"),
            MessageRefusal::BadDelivery => write!(f, "a retained message must go to everyone"),
            MessageRefusal::Filtered(code) => write!(f, "refused by the host's filter ({code})"),
            MessageRefusal::Malformed => write!(f, "malformed message"),
        }
    }
}

impl std::error::Error for MessageRefusal {}

/// An application message on the wire.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AppMessage {
    /// The peer that sent it (the host relays it unchanged).
    pub origin: PeerId,
    /// The origin's number for it, from 1, one per reliable or retained message; 0 for an
    /// unreliable one. Receivers drop a reliable message whose number they have passed
    /// (a resend after a migration).
    pub seq: u32,
    /// Its type.
    pub kind: MessageKind,
    /// Whom it goes to.
    pub to: MessageTarget,
    /// How.
    pub delivery: Delivery,
    /// The application's bytes (at most [`MAX_MESSAGE_PAYLOAD`]).
    pub payload: Vec<u8>,
}

impl AppMessage {
    /// Within bounds: payload length, a number only on reliable messages, retained ones to
    /// everyone.
    pub fn valid(&self) -> bool {
        self.payload.len() <= MAX_MESSAGE_PAYLOAD
            && (self.seq == 0) == (self.delivery == Delivery::Unreliable)
            && (!self.delivery.is_retained() || self.to == MessageTarget::Everyone)
    }

    /// Where the room keeps it: its kind, and its object for per-object state; `None` if it
    /// is not retained.
    pub fn retain_key(&self) -> Option<(MessageKind, Option<NetId>)> {
        match self.delivery {
            Delivery::Retained => Some((self.kind, None)),
            Delivery::ObjectState(id) => Some((self.kind, Some(id))),
            Delivery::Reliable | Delivery::Unreliable => None,
        }
    }
}

/// A message as the application receives it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReceivedMessage {
    /// The peer that sent it.
    pub from: PeerId,
    /// Its type.
    pub kind: MessageKind,
    /// Whom it was sent to.
    pub to: MessageTarget,
    /// How.
    pub delivery: Delivery,
    /// The application's bytes.
    pub payload: Vec<u8>,
}

impl From<AppMessage> for ReceivedMessage {
    fn from(m: AppMessage) -> Self {
        ReceivedMessage {
            from: m.origin,
            kind: m.kind,
            to: m.to,
            delivery: m.delivery,
            payload: m.payload,
        }
    }
}
