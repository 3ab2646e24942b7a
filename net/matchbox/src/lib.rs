//! WebRTC for softsync: [`MatchboxTransport`] implements [`softsync_net::Transport`] over
//! `matchbox_socket` data channels, and [`SignalServer`] is the room signaling server
//! (`matchbox_signaling`, full mesh), embeddable in a host or run standalone.
//!
//! Channels: datagrams that carry reliable control sections go on an ordered, reliable data
//! channel; everything else (state, acks, pings) on an unordered channel with no retransmits.
//! The session keeps its own acks and resends on top, so the reliable channel only saves
//! resends.
//!
//! Peer ids: matchbox gives every socket a UUID; softsync's [`softsync_net::PeerId`] is the
//! first 64 bits of a peer's first socket, and every new data channel begins with the
//! sender's id ([`IDENT_MAGIC`]), so a peer registered with a second signaling server after
//! its first was lost keeps its id.
//!
//! Rooms: a socket connects to `ws://ADDR/ROOM?softsync=V&role=host|join|member`. The server
//! refuses a protocol version it does not speak (HTTP 426), a join to a room nobody is in
//! (404), and a second host for a room that has peers (409); a `member` (a peer of the room
//! whose own server was lost) is let in either way. The client turns those into
//! [`ConnectError`]s.

#![allow(clippy::disallowed_methods)] // an I/O adapter: it reads the clock and waits for threads

mod gate;
mod probe;
mod refusal;
mod routes;
mod signal;
mod signaller;
mod tls;
mod transport;

pub use gate::{GateStats, MAX_HEAD_BYTES};
pub use probe::{ProbeEvent, SignalProbe};

pub use signal::{RoomInfo, SignalError, SignalLimits, SignalServer};
pub use tls::{client_connector, TlsIdentity};
pub use transport::{
    ConnectError, MatchboxConfig, MatchboxTransport, Role, TransportStats, IDENT_MAGIC,
};

/// Query parameter carrying the client's protocol version.
pub const VERSION_PARAM: &str = "softsync";
/// Query parameter carrying the client's role (`host` or `join`).
pub const ROLE_PARAM: &str = "role";
/// Query parameter: the room key's proof for the signaling server (`RoomKey::signal_proof`).
pub const PROOF_PARAM: &str = "proof";
/// Query parameter: a join token for the signaling server.
pub const TOKEN_PARAM: &str = "token";
/// Response header in which the server names the protocol version it speaks.
pub const VERSION_HEADER: &str = "x-softsync-protocol";
/// Largest datagram we hand to matchbox (it silently drops messages over about 64 KiB; the
/// session batches to an MTU far below this).
pub const DEFAULT_MTU: usize = 1200;

/// Whether `name` is a valid room name: 1–64 characters of `A–Z a–z 0–9 - _ .`.
pub fn valid_room_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
}
