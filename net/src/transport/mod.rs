//! Transports: one small object-safe trait and what moves through it ([`Transmit`]), a seeded
//! link conditioner (latency, jitter, bursty loss, duplication, reordering, MTU drop) wrapping
//! any transport ([`conditioner`]), and, with the `testing` feature, an in-memory hub
//! ([`memory`]).

pub mod conditioner;
#[cfg(feature = "testing")]
pub mod memory;

pub use conditioner::{ConditionerConfig, LinkConditioner};
#[cfg(feature = "testing")]
pub use memory::{HubEndpoint, MemoryHub};

use crate::ids::PeerId;
use crate::time::Instant;

/// A datagram to hand to the transport.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Transmit {
    /// Destination.
    pub to: PeerId,
    /// Bytes (≤ the session's mtu).
    pub payload: Vec<u8>,
    /// It carries control messages (or is a refusal): a transport with a reliable channel
    /// sends it there; state and heartbeats go unreliably. Said by the session, which wrote
    /// it, so no transport parses a datagram to choose.
    pub reliable: bool,
}

/// Connectivity news from the transport (informational: the session trusts only silence).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeerEvent {
    /// A peer became reachable.
    Connected(PeerId),
    /// A peer became unreachable.
    Disconnected(PeerId),
}

/// An unreliable datagram transport. Time is passed in; nothing blocks.
pub trait Transport {
    /// This endpoint's address.
    fn local_id(&self) -> PeerId;
    /// Send one datagram (best effort; on the reliable channel if `transmit.reliable` and the
    /// transport has one).
    fn send(&mut self, now: Instant, transmit: &Transmit);
    /// Next datagram that has arrived by `now`.
    fn recv(&mut self, now: Instant) -> Option<(PeerId, Vec<u8>)>;
    /// Next connectivity event.
    fn poll_peer_event(&mut self) -> Option<PeerEvent>;
    /// Largest datagram the path carries.
    fn mtu(&self) -> usize;
    /// When something queued inside the transport becomes due (virtual-time drivers).
    fn poll_timeout(&self) -> Option<Instant> {
        None
    }
    /// A signaling server to register with first when ours is lost (a new host serving
    /// signaling itself). Transports without signaling ignore it.
    fn prefer_signaling(&mut self, _url: &str) {}
    /// Whether the path to `peer` goes through a relay (TURN); `None` when unknown or for
    /// transports without relays.
    fn relayed(&self, _peer: PeerId) -> Option<bool> {
        None
    }
}
