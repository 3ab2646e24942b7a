//! Control messages: serde + bincode 2, carried in reliable sections, validated on decode.

use serde::{Deserialize, Serialize};

use crate::error::{decode_err, NetError};
use crate::ids::{AuthorityEpoch, ClassId, NetId, PeerId, Term};
use crate::policy::AuthorityPolicy;

use super::message::{AppMessage, MessageRefusal};
use super::{MAX_CONTROL_LEN, MAX_MEMBERS, MAX_PARTICLES};

/// Control messages, carried reliably and in order per link.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Control {
    /// Client → host: join request.
    Hello {
        /// Protocol version (also in the header).
        protocol: u8,
        /// Digest of the class table ([`crate::SessionConfig::digest`]).
        config_digest: u64,
    },
    /// Host → client: accepted.
    Welcome {
        /// Current term.
        term: Term,
        /// The host.
        host: PeerId,
        /// Join order of the new peer.
        join_seq: u32,
        /// Every member (including host and new peer) with its join order.
        members: Vec<(PeerId, u32)>,
    },
    /// Host → client: join refused.
    Refused {
        /// Why.
        reason: String,
    },
    /// Non-host → client: the host is someone else.
    Redirect {
        /// Current host.
        host: PeerId,
    },
    /// Host → all: a peer joined.
    PeerJoined {
        /// The peer.
        peer: PeerId,
        /// Its join order.
        join_seq: u32,
    },
    /// Host → all: a peer left (timed out).
    PeerLeft {
        /// The peer.
        peer: PeerId,
    },
    /// Host → all: an object exists (also the late-join snapshot and post-migration resync).
    Spawn(SpawnInfo),
    /// Host → all: an object is gone.
    Despawn {
        /// Object.
        id: NetId,
    },
    /// Client → host: please spawn an object owned by me.
    SpawnRequest {
        /// Caller's request number (echoed in the event).
        request: u32,
        /// Class.
        class: ClassId,
        /// Particle count (0 for rigid).
        particles: u32,
        /// Initial position.
        pos: [f32; 3],
        /// Initial rotation.
        rot: [f32; 4],
    },
    /// Owner → host: please despawn.
    DespawnRequest {
        /// Object.
        id: NetId,
    },
    /// Client → host: I want authority.
    AuthorityRequest {
        /// Object.
        id: NetId,
    },
    /// Host → holder: `by` asks for your object (policy OwnerMustAgree).
    AuthorityAsk {
        /// Object.
        id: NetId,
        /// Asking peer.
        by: PeerId,
    },
    /// Holder → host: answer to an ask.
    AuthorityAnswer {
        /// Object.
        id: NetId,
        /// Asking peer.
        by: PeerId,
        /// Agreed?
        agree: bool,
    },
    /// Host → all: new owner.
    OwnerChanged {
        /// Object.
        id: NetId,
        /// New owner.
        owner: PeerId,
        /// New epoch.
        epoch: AuthorityEpoch,
        /// Held by a peer (vs. resting with the host by default).
        held: bool,
    },
    /// Host → requester: denied.
    AuthorityDenied {
        /// Object.
        id: NetId,
        /// Why.
        reason: DenyReason,
    },
    /// Owner → host: I let go.
    AuthorityRelease {
        /// Object.
        id: NetId,
    },
    /// New host → all: I am the host of `term`.
    NewHost {
        /// New term.
        term: Term,
        /// New host.
        host: PeerId,
        /// Surviving members with join order.
        members: Vec<(PeerId, u32)>,
    },
    /// Client → new host: the objects I own, so a handoff in flight is not lost.
    Resync {
        /// Claims.
        claims: Vec<SpawnInfo>,
    },
    /// Owner → host: apply `event` to my object `id`, which I hold at `epoch`. A cut names
    /// the particle count of every piece it makes, in the cut's piece order: the object keeps
    /// the first, the host spawns the others (owned by the cutter).
    TopologyRequest {
        /// Object.
        id: NetId,
        /// The authority epoch the requester holds it at (a stale one is refused).
        epoch: AuthorityEpoch,
        /// The change.
        event: TopologyEvent,
        /// Particle counts of the pieces (a cut only; at most [`MAX_CUT_PIECES`]).
        pieces: Vec<u32>,
    },
    /// Host → all: entry `seq` of object `id`'s topology log (live, in the late-join snapshot
    /// and after a migration). Applied in order to the class's mesh, the log gives every peer
    /// the identical torn or cut mesh.
    Topology {
        /// Object.
        id: NetId,
        /// Position in the log, from 0.
        seq: u32,
        /// The change.
        event: TopologyEvent,
    },
    /// Any member → the others: I am leaving now. The receivers treat the sender as gone at
    /// once instead of after `peer_timeout` (authority returns, a host is replaced).
    Leave,
    /// An application's reliable or retained message: origin → host, then host → each
    /// target (and host → a joiner, for retained ones, after the snapshot).
    Message(AppMessage),
    /// Host → origin: every reliable message of yours numbered up to `up_to` has reached
    /// all its targets (or was refused, which you were told first).
    MessagesDelivered {
        /// Highest message number covered.
        up_to: u32,
    },
    /// Host → origin: your message `seq` was not relayed.
    MessageRefused {
        /// Its number.
        seq: u32,
        /// Why.
        reason: MessageRefusal,
    },
    /// Host → joiner, or a new host → member: a retained message from the room's table (the
    /// snapshot's share of the messages); it sets the state and is not one of the origin's
    /// live messages.
    Replay(AppMessage),
    /// Host → joiner (a room with a key): prove you hold it, over this nonce.
    Challenge {
        /// The host's nonce.
        nonce: [u8; 16],
    },
    /// Joiner → host: HMAC-SHA256 under the room key of the nonce, the joiner's id and the
    /// host's id.
    Proof {
        /// The MAC.
        mac: [u8; 32],
    },
    /// Joiner → host, answering a `Challenge` without the key: a join token the key's holder
    /// issued ([`RoomToken`]). It admits one peer (the first to show it; that peer may show it
    /// again to rejoin) until it expires.
    TokenProof {
        /// The token.
        token: RoomToken,
    },
    /// Host → members (and to a joiner after its snapshot): this token admitted `peer`; every
    /// member keeps the list, so a new host after a migration refuses its replay too.
    TokenUsed {
        /// The token's nonce.
        nonce: [u8; 16],
        /// The peer it admitted.
        peer: PeerId,
        /// When it expires (seconds since the Unix epoch): forgotten after.
        expires_unix: u64,
    },
    /// Host → members (and to a joiner after its snapshot): `peer` is banned from the room
    /// for its life (kicked), with the join token it came in with; every member keeps the
    /// list, so a new host after a migration keeps it out.
    Banned {
        /// The banned peer.
        peer: PeerId,
        /// The nonce of the join token it used, if it used one.
        token: Option<[u8; 16]>,
        /// Why (at most 120 bytes).
        reason: String,
    },
    /// Host → joiner, or a new host → member: the snapshot is whole; every object the host
    /// has was named (`Spawn`) since the `Welcome` or the `NewHost`. After a takeover, a
    /// member drops the replicas it did not name that it does not own (its `Resync` claims
    /// those), so no member keeps an object the new host never had (protocol 7).
    SnapshotEnd,
}

/// A join token: admission to room `room` until `expires_unix` (seconds since the Unix
/// epoch, the host's clock), for one peer, signed by the holder of the room key: `mac` is the
/// first 16 bytes of HMAC-SHA256 under the key of `"softsync-token-v1" ‖ room ‖ expires (u64
/// LE) ‖ nonce`. Written `st1:ROOM:EXPIRES:NONCE:MAC` (hex) for the command line.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RoomToken {
    /// The room's name.
    pub room: String,
    /// Expiry, seconds since the Unix epoch.
    pub expires_unix: u64,
    /// Random, from the issuer: what makes the token one of its kind.
    pub nonce: [u8; 16],
    /// The signature.
    pub mac: [u8; 16],
}

/// Longest room name a token carries.
pub const MAX_TOKEN_ROOM: usize = 64;

impl std::fmt::Display for RoomToken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let hex = |b: &[u8]| b.iter().map(|x| format!("{x:02x}")).collect::<String>();
        write!(
            f,
            "st1:{}:{}:{}:{}",
            self.room,
            self.expires_unix,
            hex(&self.nonce),
            hex(&self.mac)
        )
    }
}

impl std::str::FromStr for RoomToken {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let parts: Vec<&str> = s.trim().split(':').collect();
        let [tag, room, expires, nonce, mac] = parts.as_slice() else {
            return Err("a join token is st1:ROOM:EXPIRES:NONCE:MAC".into());
        };
        if *tag != "st1" {
            return Err(format!("unknown token version {tag:?} (expected st1)"));
        }
        if room.is_empty() || room.len() > MAX_TOKEN_ROOM {
            return Err(format!("token room: 1 to {MAX_TOKEN_ROOM} characters"));
        }
        let expires_unix = expires
            .parse()
            .map_err(|_| format!("token expiry {expires:?} is not a number"))?;
        fn hex<const N: usize>(what: &str, s: &str) -> Result<[u8; N], String> {
            if s.len() != 2 * N || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err(format!("token {what}: {} hex digits expected", 2 * N));
            }
            let mut out = [0u8; N];
            for (i, o) in out.iter_mut().enumerate() {
                *o = u8::from_str_radix(s.get(2 * i..2 * i + 2).unwrap_or("00"), 16)
                    .map_err(|_| format!("token {what}: not hex"))?;
            }
            Ok(out)
        }
        Ok(RoomToken {
            room: (*room).to_owned(),
            expires_unix,
            nonce: hex("nonce", nonce)?,
            mac: hex("mac", mac)?,
        })
    }
}

/// One change of an object's mesh topology, in the object's rest frame (the frame of its
/// class's mesh), quantised to [`TOPOLOGY_QUANTUM_M`]: the owner applies the quantised event
/// too, so every peer starts from bit-identical input.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum TopologyEvent {
    /// One tear segment (tear paper Algorithm 1): the blade's tip moved from `from` to `to`;
    /// the blade's back end is at tip + `blade`.
    Tear {
        /// Tip at the previous sample.
        from: [i32; 3],
        /// Tip now.
        to: [i32; 3],
        /// Tip to back end.
        blade: [i32; 3],
    },
    /// The scalpel left the object: the next tear starts a new stroke.
    Lift,
    /// A plane cut (tear paper Algorithm 2) through `point` with normal `normal` (a unit vector
    /// times 32767); the object keeps piece `keep` of the cut's pieces.
    Cut {
        /// A point of the plane.
        point: [i32; 3],
        /// The plane's normal.
        normal: [i16; 3],
        /// Which piece this object is.
        keep: u8,
    },
    /// `method: auto`: the object's soft body now runs at resolution `level` of its class's
    /// ladder, with `particles` particles; its replicated particle layout changes with it.
    Resolution {
        /// Level in the class's ladder, coarsest 0.
        level: u8,
        /// Particles at that level.
        particles: u32,
    },
}

/// The unit of [`TopologyEvent`] coordinates, metres (10 µm).
pub const TOPOLOGY_QUANTUM_M: f32 = 1e-5;
/// Largest coordinate of a topology event, in quanta (10 m).
pub const MAX_TOPOLOGY_COORD: i32 = 1_000_000;
/// Most pieces one cut may make.
pub const MAX_CUT_PIECES: usize = 16;
/// Levels a [`TopologyEvent::Resolution`] may name.
pub const MAX_RESOLUTION_LEVELS: u8 = 16;

impl TopologyEvent {
    /// Within bounds: coordinates at most [`MAX_TOPOLOGY_COORD`], a non-zero normal, a piece
    /// index below [`MAX_CUT_PIECES`], a level below [`MAX_RESOLUTION_LEVELS`] with 1 to
    /// [`MAX_PARTICLES`] particles.
    pub fn valid(&self) -> bool {
        let small = |a: &[i32; 3]| {
            a.iter()
                .all(|c| c.unsigned_abs() <= MAX_TOPOLOGY_COORD as u32)
        };
        match self {
            TopologyEvent::Tear { from, to, blade } => small(from) && small(to) && small(blade),
            TopologyEvent::Lift => true,
            TopologyEvent::Cut {
                point,
                normal,
                keep,
            } => {
                small(point)
                    && normal.iter().any(|&n| n != 0)
                    && usize::from(*keep) < MAX_CUT_PIECES
            }
            TopologyEvent::Resolution { level, particles } => {
                *level < MAX_RESOLUTION_LEVELS && *particles >= 1 && *particles <= MAX_PARTICLES
            }
        }
    }

    /// Quantises metres to quanta (`None` if not finite or out of range).
    pub fn quantise(v: [f32; 3]) -> Option<[i32; 3]> {
        let mut out = [0i32; 3];
        for (o, c) in out.iter_mut().zip(v) {
            let q = (c / TOPOLOGY_QUANTUM_M).round();
            if !q.is_finite() || q.abs() > MAX_TOPOLOGY_COORD as f32 {
                return None;
            }
            *o = q as i32;
        }
        Some(out)
    }

    /// Quanta back to metres.
    pub fn metres(q: [i32; 3]) -> [f32; 3] {
        q.map(|c| c as f32 * TOPOLOGY_QUANTUM_M)
    }

    /// Quantises a direction to a normal (`None` if zero or not finite).
    pub fn quantise_normal(n: [f32; 3]) -> Option<[i16; 3]> {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if !len.is_finite() || len < 1e-12 {
            return None;
        }
        let q = n.map(|c| (c / len * 32767.0).round() as i16);
        q.iter().any(|&c| c != 0).then_some(q)
    }
}

/// Why authority was denied.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum DenyReason {
    /// Policy Locked.
    Locked,
    /// Someone else holds it.
    Held(PeerId),
    /// The holder said no.
    OwnerRefused,
    /// No such object.
    Unknown,
}

/// Everything needed to create an object replica.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpawnInfo {
    /// Id.
    pub id: NetId,
    /// Class.
    pub class: ClassId,
    /// Owner.
    pub owner: PeerId,
    /// Authority epoch.
    pub epoch: AuthorityEpoch,
    /// Held by a peer.
    pub held: bool,
    /// Authority policy.
    pub policy: AuthorityPolicy,
    /// Particle count.
    pub particles: u32,
    /// Position.
    pub pos: [f32; 3],
    /// Rotation (x, y, z, w).
    pub rot: [f32; 4],
    /// The `SpawnRequest` number of the client that asked for the object (its first
    /// owner), if one did: the requester matches its request exactly, also after a migration.
    pub request: Option<u32>,
    /// Length of the object's topology log, whose entries follow as [`Control::Topology`]
    /// messages: a replica is complete (its mesh known) once it has them all.
    pub topology: u32,
}

fn bincode_config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_CONTROL_LEN>()
}

/// Longest reason a [`Control::Refused`] carries, bytes (longer ones are refused by the
/// decoder: make refusals with [`Control::refused`]).
pub const MAX_REFUSED_REASON: usize = 512;

impl Control {
    /// A refusal whose reason always arrives: one longer than [`MAX_REFUSED_REASON`] is cut
    /// at a character boundary and says its whole length (`… (N bytes)`).
    pub fn refused(reason: impl AsRef<str>) -> Control {
        Control::Refused {
            reason: super::shorten_reason(reason.as_ref(), MAX_REFUSED_REASON).into_owned(),
        }
    }

    /// Encode with bincode 2: an error, never empty bytes, for a message over
    /// [`MAX_CONTROL_LEN`].
    pub fn encode(&self) -> Result<Vec<u8>, NetError> {
        bincode::serde::encode_to_vec(self, bincode_config()).map_err(|e| NetError::Encode {
            what: format!("control message ({e}; at most {MAX_CONTROL_LEN} bytes)"),
        })
    }

    /// Decode and validate (finite floats, bounded lists).
    pub fn decode(bytes: &[u8]) -> Result<Control, NetError> {
        if bytes.len() > MAX_CONTROL_LEN {
            return Err(decode_err(0, "control message too long"));
        }
        let (msg, used): (Control, usize) =
            bincode::serde::decode_from_slice(bytes, bincode_config())
                .map_err(|_| decode_err(0, "malformed control message"))?;
        if used != bytes.len() {
            return Err(decode_err(used, "trailing bytes after control message"));
        }
        msg.validate()?;
        Ok(msg)
    }

    fn validate(&self) -> Result<(), NetError> {
        let finite = |a: &[f32]| a.iter().all(|v| v.is_finite() && v.abs() < 1e6);
        let ok = match self {
            Control::Spawn(s) => s.valid(),
            Control::Resync { claims } => claims.iter().all(SpawnInfo::valid),
            Control::SpawnRequest {
                pos,
                rot,
                particles,
                ..
            } => finite(pos) && finite(rot) && *particles <= MAX_PARTICLES,
            Control::Welcome { members, .. } | Control::NewHost { members, .. } => {
                members.len() <= MAX_MEMBERS
            }
            Control::Refused { reason } => reason.len() <= MAX_REFUSED_REASON,
            Control::TopologyRequest { event, pieces, .. } => {
                event.valid()
                    && pieces.len() <= MAX_CUT_PIECES
                    && pieces.iter().all(|&p| p <= MAX_PARTICLES)
            }
            Control::Topology { event, .. } => event.valid(),
            Control::Message(m) => m.valid() && m.delivery.is_reliable(),
            Control::Replay(m) => m.valid() && m.delivery.is_retained(),
            Control::TokenProof { token } => {
                !token.room.is_empty() && token.room.len() <= MAX_TOKEN_ROOM
            }
            _ => true,
        };
        if ok {
            Ok(())
        } else {
            Err(decode_err(0, "control message fails validation"))
        }
    }
}

impl SpawnInfo {
    fn valid(&self) -> bool {
        self.pos
            .iter()
            .chain(self.rot.iter())
            .all(|v| v.is_finite() && v.abs() < 1e6)
            && self.particles <= MAX_PARTICLES
    }
}
