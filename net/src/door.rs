//! The front door: every datagram a peer receives is sorted here first, by its first byte,
//! into the protocol that registered that byte ([`REGISTRY`]). Nothing else in the library
//! looks at a datagram's first byte to decide whose it is.
//!
//! Five protocols share one channel pair per peer: the room session (its first byte is the
//! protocol version, or 0 for the version-independent refusal), the scene share (`0xF5`,
//! [`crate::share`]), a rollback room's ggrs and snapshot datagrams (`0xF7`,
//! `softsync_rollback::socket`), voice (`0xF9`, [`crate::voice`]) and the transport's channel identification (`0xFF`, consumed by
//! the WebRTC transport before anything else sees it). Session versions own `1..=0x7F`; the
//! markers of other protocols live in `0x80..=0xFF`, so a session of another version is told
//! it speaks another version, and a datagram of a protocol this build does not know (a newer
//! peer's) is dropped and counted, never answered.
//!
//! # Adding a protocol
//! A new datagram protocol (voice frames, remote hands) joins by: a variant of [`Door`]; a
//! row of [`REGISTRY`] with an unused marker in `0x80..=0xFE` (the test
//! `markers_are_disjoint_and_cover_every_byte_once` checks it); its own decoder that checks
//! the marker again and never panics; a branch where the front ends route ([`FrontDoor::sort`]
//! callers: `softsync_bevy::Room::network_in`, the scene fetch, the app's rollback loop,
//! `softsync_rollback::RollbackPeer::handle_datagram`), which drop what they do not serve;
//! and its per-peer budget in ARCHITECTURE.md's table of budgets. PROTOCOL.md's table is generated from
//! [`REGISTRY`].

use crate::wire::{CHANNEL_IDENT, PROTOCOL_VERSION, REFUSAL_MARKER};

/// Whose a datagram is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Door {
    /// The room session, this version ([`crate::Session::handle_packet`]).
    Session,
    /// The room session of another version: the session answers a host's refusal.
    OtherVersion,
    /// The version-independent refusal ([`crate::wire::REFUSAL_MARKER`]): the session's.
    Refusal,
    /// Scene share ([`crate::share`]).
    Share,
    /// A rollback room's ggrs and snapshot datagrams (`softsync_rollback::socket`).
    Rollback,
    /// Voice frames and listeners' reports ([`crate::voice`]).
    Voice,
    /// The transport's channel identification (the WebRTC transport consumes it).
    Ident,
    /// Empty, or a marker no protocol of this build registered: dropped.
    Unknown,
}

/// One registered protocol: the first bytes it owns.
#[derive(Clone, Copy, Debug)]
pub struct Protocol {
    /// Which door.
    pub door: Door,
    /// Its first bytes, inclusive.
    pub first: (u8, u8),
    /// Its name in the documentation.
    pub name: &'static str,
    /// Where its code lives.
    pub module: &'static str,
    /// What its datagrams carry.
    pub carries: &'static str,
}

/// First byte of scene-share datagrams.
pub const SHARE: u8 = 0xF5;
/// First byte of a rollback room's datagrams.
pub const ROLLBACK: u8 = 0xF7;
/// First byte of voice datagrams.
pub const VOICE: u8 = 0xF9;
/// First byte of the transport's channel identification.
pub const IDENT: u8 = CHANNEL_IDENT[0];
/// Session protocol versions (first bytes) a session may ever speak.
pub const SESSION_VERSIONS: (u8, u8) = (1, 0x7F);

/// Every protocol's first bytes: disjoint, and ordered by first byte.
pub const REGISTRY: &[Protocol] = &[
    Protocol {
        door: Door::Refusal,
        first: (REFUSAL_MARKER, REFUSAL_MARKER),
        name: "refusal",
        module: "net/src/wire/mod.rs",
        carries: "a host's refusal of a peer of any version: version, length, UTF-8 reason",
    },
    Protocol {
        door: Door::Session,
        first: SESSION_VERSIONS,
        name: "session",
        module: "net/src/session",
        carries: "the room session: header, then state, control, ack, ping, keyframe-request, \
                  message and beacon sections (this build speaks one version; another is \
                  answered with a refusal by a host)",
    },
    Protocol {
        door: Door::Share,
        first: (SHARE, SHARE),
        name: "scene share",
        module: "net/src/share.rs",
        carries: "a joiner's requests for the room's scene and a member's chunks of it",
    },
    Protocol {
        door: Door::Rollback,
        first: (ROLLBACK, ROLLBACK),
        name: "rollback",
        module: "rollback/src/socket.rs",
        carries: "a rollback room's ggrs messages and epoch snapshots, by epoch",
    },
    Protocol {
        door: Door::Voice,
        first: (VOICE, VOICE),
        name: "voice",
        module: "net/src/voice.rs",
        carries: "Opus voice frames (direct, to relay, relayed) and listeners' reception reports",
    },
    Protocol {
        door: Door::Ident,
        first: (IDENT, IDENT),
        name: "channel ident",
        module: "net/matchbox/src/transport.rs",
        carries: "the sender's id on a new data channel (the transport consumes it)",
    },
];

/// Whose `datagram` is (the registry's word; a protocol's decoder still checks the rest).
pub fn classify(datagram: &[u8]) -> Door {
    let Some(&b) = datagram.first() else {
        return Door::Unknown;
    };
    if b == PROTOCOL_VERSION {
        return Door::Session;
    }
    match REGISTRY
        .iter()
        .find(|p| (p.first.0..=p.first.1).contains(&b))
    {
        Some(p) if p.door == Door::Session => Door::OtherVersion,
        Some(p) => p.door,
        None => Door::Unknown,
    }
}

/// The front door of one peer: sorts datagrams ([`classify`]) and counts them per door, so
/// what was dropped unread is seen.
#[derive(Clone, Debug, Default)]
pub struct FrontDoor {
    /// Datagrams per door, in [`Door`]'s order (see [`count`](Self::count)).
    counts: [u64; 8],
    /// Datagrams a front end had no use for (a door it does not serve: a rollback datagram
    /// in a state-sync room, an ident past the transport, an unknown marker).
    pub dropped: u64,
}

impl FrontDoor {
    /// Whose `datagram` is, counted.
    pub fn sort(&mut self, datagram: &[u8]) -> Door {
        let d = classify(datagram);
        self.counts[d as usize] += 1;
        d
    }

    /// A datagram the caller does not serve.
    pub fn drop_unserved(&mut self) {
        self.dropped += 1;
    }

    /// Datagrams sorted to `door` so far.
    pub fn count(&self, door: Door) -> u64 {
        self.counts[door as usize]
    }
}

/// Whether a datagram opens with the session's bytes (its version or a refusal): what
/// [`crate::Session::handle_packet`] takes.
pub fn is_session(datagram: &[u8]) -> bool {
    matches!(
        classify(datagram),
        Door::Session | Door::OtherVersion | Door::Refusal
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markers_are_disjoint_and_cover_every_byte_once() {
        for w in REGISTRY.windows(2) {
            assert!(
                w[0].first.1 < w[1].first.0,
                "{:?} overlaps {:?}",
                w[0],
                w[1]
            );
        }
        for p in REGISTRY {
            assert!(p.first.0 <= p.first.1);
            // other protocols' markers sit above the session's versions
            if !matches!(p.door, Door::Session | Door::Refusal) {
                assert!(p.first.0 > SESSION_VERSIONS.1, "{p:?}");
            }
        }
        assert!((SESSION_VERSIONS.0..=SESSION_VERSIONS.1).contains(&PROTOCOL_VERSION));
        let mut owners = [0u8; 256];
        for b in 0..=255u8 {
            owners[b as usize] = REGISTRY
                .iter()
                .filter(|p| (p.first.0..=p.first.1).contains(&b))
                .count() as u8;
        }
        assert!(owners.iter().all(|n| *n <= 1));
    }

    #[test]
    fn each_protocols_datagrams_go_through_its_door() {
        use crate::share::{ShareMsg, SHARE_MARKER};
        assert_eq!(SHARE, SHARE_MARKER);
        let share = ShareMsg::Unavailable("no".into()).encode();
        assert_eq!(classify(&share), Door::Share);
        let refusal = crate::wire::encode_refusal("go away", crate::Term(0));
        assert_eq!(classify(&refusal), Door::Refusal);
        assert_eq!(classify(&[PROTOCOL_VERSION, 0, 0, 0, 0]), Door::Session);
        assert_eq!(classify(&[PROTOCOL_VERSION + 1]), Door::OtherVersion);
        assert_eq!(classify(&CHANNEL_IDENT), Door::Ident);
        assert_eq!(classify(&[ROLLBACK, 1]), Door::Rollback);
        assert_eq!(classify(&[VOICE, 1]), Door::Voice);
        assert_eq!(classify(&[]), Door::Unknown);
        assert_eq!(classify(&[0xF6, 1, 2]), Door::Unknown);
        assert_eq!(classify(&[0x80]), Door::Unknown);
        let mut d = FrontDoor::default();
        for b in [&share[..], &refusal, &[0xF6][..], &[0xF6][..]] {
            d.sort(b);
        }
        assert_eq!(
            (
                d.count(Door::Share),
                d.count(Door::Refusal),
                d.count(Door::Unknown)
            ),
            (1, 1, 2)
        );
    }
}
