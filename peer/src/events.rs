//! What a peer tells its driver: the news it queues ([`Event`], drained with
//! [`Peer::poll_event`](crate::Peer::poll_event)), why it must stop ([`PeerError`]) and what
//! it counts ([`Counters`]).
//!
//! Membership news is the session's own [`softsync_net::Event`], carried as [`Event::Room`]
//! rather than declared again; the peer adds what only it sees: its hands, the authority they
//! ask for, and rejoining.

use softsync_net::{NetId, PeerId};

/// Something that happened to this peer, for the driver's log, HUD and tests.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// Room membership news, as the session said it: [`softsync_net::Event::Joined`],
    /// `HostChanged`, `PeerJoined` or `PeerLeft` (the peer acts on the session's other
    /// events itself).
    Room(softsync_net::Event),
    /// Our hand reached for an object another peer owns: we asked for it.
    AuthorityAsked(NetId),
    /// An object became ours.
    AuthorityGained(NetId),
    /// Our request for an object was denied.
    AuthorityDenied(NetId),
    /// We gave an object back (it came to rest after our hands let go).
    AuthorityReleased(NetId),
    /// A hand (0 left, 1 right) started holding an object (`particle`: one particle of a soft
    /// body rather than its center).
    GrabStarted {
        /// The object.
        id: NetId,
        /// The hand: 0 left, 1 right.
        hand: usize,
        /// The particle held, if one.
        particle: Option<u32>,
    },
    /// A hand let go of an object, throwing it at `speed` m/s.
    GrabEnded {
        /// The object.
        id: NetId,
        /// The hand: 0 left, 1 right.
        hand: usize,
        /// Throw speed, m/s.
        speed: f32,
    },
    /// The room went on without us (we were out of touch past the peer timeout): we dropped
    /// our replica and join `host` again.
    Rejoining {
        /// The room's host.
        host: PeerId,
        /// What it said.
        reason: String,
    },
    /// An object we simulate left the room's bounds (the box positions are quantized in: past
    /// it, the others would see it stuck at the edge): we put it back at its class's place in
    /// the scene, at rest.
    ReturnedHome {
        /// The object.
        id: NetId,
        /// Where its center was.
        from: glam::Vec3,
    },
    /// Who holds object `id` changed (its owner's word; ours for what we simulate): every
    /// hand on it, local and remote (see [`crate::messages::Holders`]).
    Holders {
        /// The object.
        id: NetId,
        /// The hands, sorted.
        hands: Vec<crate::messages::Holder>,
    },
    /// Something went wrong that the peer carried on through (an avatar not spawned, a hand
    /// input refused, a state not published); the text says what, for the log.
    Warning(String),
}

/// The name of a rollback room's epoch message type: a host whose refusal lists it runs a
/// rollback room (`softsync-rollback` registers it).
pub const ROLLBACK_EPOCH_TYPE: &str = "softsync.rollback.epoch";

/// What a joiner refused for its room configuration should do when the room's sync mode
/// differs from its own (the host lists its message types in such a refusal).
fn sync_hint(reason: &str) -> &'static str {
    if reason.contains("configuration differs") && reason.contains(ROLLBACK_EPOCH_TYPE) {
        "\n  the room syncs by rollback (its host ran --sync rollback): join with --sync rollback"
    } else {
        ""
    }
}

/// Why the peer must stop.
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    /// The host refused us.
    #[error("the host refused us: {0}{hint}", hint = sync_hint(.0))]
    Refused(String),
    /// The room went on without us, and we may not join again.
    #[error(
        "the room went on without us: {reason} (joined again {rejoins} times; --rejoin-limit)"
    )]
    Dropped {
        /// What the host said.
        reason: String,
        /// Times we joined again already.
        rejoins: u64,
    },
    /// No host welcomed us within the join timeout (the driver names the room it connected
    /// to: "connected to room … but" this).
    #[error("no host welcomed us within {secs} s")]
    NotWelcomed {
        /// Seconds waited.
        secs: u64,
    },
    /// A body or a hand could not be built.
    #[error("{0}")]
    Build(String),
}

/// Why a tear or cut was not asked for or not applied (the peer goes on).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct TopologyError(pub String);

/// Counters for the driver's reports and benchmarks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Authority requests sent.
    pub authority_requests: u64,
    /// Grants received.
    pub authority_grants: u64,
    /// Host changes seen.
    pub host_changes: u64,
    /// States that could not be applied (wrong particle count, non-finite).
    pub apply_errors: u64,
    /// Times we joined the room again after it went on without us.
    pub rejoins: u64,
    /// Topology log entries (tears, lifts, cuts) applied to our mirror.
    pub topology_events: u64,
    /// Objects we owned when the room went on without us or our room yielded to another
    /// after a partition: what we did to them apart was dropped when we joined again.
    pub discarded_objects: u64,
    /// `method: auto`: resolution changes we asked for as an owner.
    pub resolution_requests: u64,
    /// `method: auto`: our bodies' mode changes (asleep, touched, squeezed) as their owner.
    pub auto_mode_changes: u64,
    /// Grabs our hands made as remote hands (on a body another peer simulates).
    pub remote_grabs: u64,
    /// Our remote hands their owner refused (`Locked`, an `OwnerMustAgree` owner that said no).
    pub remote_hands_denied: u64,
    /// Owner: other peers' remote hands taken on our bodies.
    pub remote_hands_taken: u64,
    /// Owner: remote hands refused by policy.
    pub remote_hands_refused: u64,
    /// Owner: remote hands let go because they went silent (their peer died or left).
    pub remote_hands_expired: u64,
    /// Owner: remote hand samples dropped as malformed (not finite, no such hand, a particle
    /// past the body, an object that is not a soft body here, bytes that do not decode).
    pub remote_hands_malformed: u64,
    /// Owner: remote hands dropped because one hand of one peer started grabs faster than
    /// one per 100 ms.
    pub remote_hands_too_fast: u64,
    /// Blade requests (cuts and tears of bodies other peers own) we sent.
    pub blade_requests_sent: u64,
    /// Owner: other peers' blade requests applied on our bodies.
    pub blade_requests_applied: u64,
    /// Owner: blade requests refused (not ours, a `Locked` class, not finite, too many
    /// actions, bytes that do not decode).
    pub blade_requests_refused: u64,
    /// Our hands moved onto a piece of a body a cut replaced (the nearest particle).
    pub holds_kept_through_cuts: u64,
    /// Bodies with a topology history (a cut's pieces, torn bodies at a join) built off the
    /// frame and landed in the world.
    pub bodies_built_off_frame: u64,
    /// Cuts made by sweeping a hand's cutter through a body (`HandTool::Cutter`).
    pub cut_gestures: u64,
    /// Builds restarted because the log they replayed was rewritten meanwhile (a migration).
    pub builds_restarted: u64,
    /// `Holders` messages dropped: not from the object's owner, or too long.
    pub holders_refused: u64,
}
