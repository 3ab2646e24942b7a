//! Per-class replication policy and session configuration.

use std::time::Duration;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::quant::VecQuantizer;

/// How a soft body is replicated (thesis 5.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SoftBodyMode {
    /// Thesis 5.4.1: only the center transform; remotes simulate the particles themselves.
    CenterOnly,
    /// Thesis 5.4.2: center transform plus particle positions relative to the center.
    Particles,
}

/// Who may take an object's authority.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum AuthorityPolicy {
    /// Granted unless another peer currently holds it.
    Free,
    /// While held, the holder is asked and must agree.
    OwnerMustAgree,
    /// Never granted: stays with the host.
    Locked,
}

/// Send policy of one object class (thesis 5.3 plus rest sync and keyframes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SendPolicy {
    /// Updates per second.
    pub rate_hz: f32,
    /// Position changes below this are not sent (metres).
    pub position_threshold_m: f32,
    /// Rotation changes below this are not sent (radians).
    pub rotation_threshold_rad: f32,
    /// Particle offset changes below this are not sent (metres).
    pub particle_threshold_m: f32,
    /// An object unchanged for this long is at rest: its exact pose is sent (rest sync).
    pub rest_after: Duration,
    /// Full keyframe at least this often while moving; `None` (default): deltas are relative
    /// to acknowledged state, so loss needs no keyframes.
    pub keyframe_interval: Option<Duration>,
    /// A change smaller than the threshold is still sent once the last send is this many
    /// send intervals old (bounds how long slow motion stays wrong); `None`: thesis behaviour.
    pub stale_after_intervals: Option<f32>,
    /// When an entry is sent anyway, changes above this fraction of the threshold ride along
    /// (1.0: thesis behaviour).
    pub piggyback_fraction: f32,
    /// The class's weight when an uplink budget makes objects wait their turn
    /// ([`SessionConfig::uplink_bytes_per_s`]; 0.01 to 100, 1 by default).
    #[serde(default = "default_priority")]
    pub priority: f32,
}

fn default_priority() -> f32 {
    1.0
}

impl Default for SendPolicy {
    fn default() -> Self {
        SendPolicy {
            rate_hz: 20.0,
            position_threshold_m: 0.005,
            rotation_threshold_rad: 0.5_f32.to_radians(),
            particle_threshold_m: 0.005,
            rest_after: Duration::from_millis(150),
            keyframe_interval: None,
            stale_after_intervals: Some(4.0),
            piggyback_fraction: 0.4,
            priority: default_priority(),
        }
    }
}

impl SendPolicy {
    /// Interval between send ticks.
    pub fn interval(&self) -> Duration {
        let hz = if self.rate_hz.is_finite() && self.rate_hz > 0.1 {
            self.rate_hz
        } else {
            0.1
        };
        Duration::from_secs_f32(1.0 / hz)
    }
}

/// Everything that describes one object class; must be identical on every peer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassConfig {
    /// Human-readable name (stats are reported per class).
    pub name: String,
    /// Send policy.
    pub send: SendPolicy,
    /// Default authority policy of spawned objects.
    pub authority: AuthorityPolicy,
    /// Soft-body replication mode (ignored for rigid objects).
    pub soft_body_mode: SoftBodyMode,
    /// Lower corner of the world box positions are quantized in.
    pub bounds_min: [f32; 3],
    /// Upper corner of that box.
    pub bounds_max: [f32; 3],
    /// Position grid step (metres).
    pub position_resolution_m: f32,
    /// Bits per smallest-three component.
    pub rotation_bits: u32,
    /// Half-extent of particle offsets around the center (metres).
    pub particle_extent_m: f32,
    /// Particle offset grid step (metres).
    pub particle_resolution_m: f32,
    /// Particles per replication chunk (a soft body is split by particle ranges).
    pub particles_per_chunk: u16,
}

impl ClassConfig {
    /// A rigid-object class with the given send policy.
    pub fn rigid(name: &str, send: SendPolicy) -> Self {
        ClassConfig {
            name: name.to_string(),
            send,
            authority: AuthorityPolicy::Free,
            soft_body_mode: SoftBodyMode::Particles,
            bounds_min: [-16.0, -4.0, -16.0],
            bounds_max: [16.0, 12.0, 16.0],
            position_resolution_m: 0.0005,
            rotation_bits: 11,
            particle_extent_m: 0.5,
            particle_resolution_m: 0.0005,
            particles_per_chunk: 128,
        }
    }

    /// A soft-body class replicated in `mode`.
    pub fn soft_body(name: &str, send: SendPolicy, mode: SoftBodyMode) -> Self {
        ClassConfig {
            soft_body_mode: mode,
            ..ClassConfig::rigid(name, send)
        }
    }

    /// Position quantizer.
    pub fn position_quantizer(&self) -> VecQuantizer {
        VecQuantizer::new(
            Vec3::from_array(self.bounds_min),
            Vec3::from_array(self.bounds_max),
            self.position_resolution_m,
        )
    }

    /// Particle offset quantizer.
    pub fn particle_quantizer(&self) -> VecQuantizer {
        let e = self.particle_extent_m.abs().max(0.01);
        VecQuantizer::new(Vec3::splat(-e), Vec3::splat(e), self.particle_resolution_m)
    }

    /// Rotation bits clamped to a sane range.
    pub fn rot_bits(&self) -> u32 {
        self.rotation_bits.clamp(4, 16)
    }

    /// Particles per chunk, at least 1.
    pub fn chunk_len(&self) -> usize {
        usize::from(self.particles_per_chunk.max(1))
    }
}

/// Configuration of a session (the class table must match across peers: checked at join).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionConfig {
    /// Object classes, indexed by [`crate::ClassId`].
    pub classes: Vec<ClassConfig>,
    /// A peer silent this long is gone, whatever the transport says.
    pub peer_timeout: Duration,
    /// Heartbeat period (also the RTT probe). With the adaptive detector a quiet link is
    /// pinged at least this often; with the fixed one at least every 1.5 periods.
    pub heartbeat_interval: Duration,
    /// Heartbeat period of a link between two members when neither hosts (never shorter than
    /// [`heartbeat_interval`](Self::heartbeat_interval)). Such a link only matters for
    /// choosing the heir once the host is gone, and a room of `n` has `n²/2` of them against
    /// `n` links to its host: at 50 ms they were most of a bot's datagrams (issue 34). The
    /// host's death is still noticed on the fast link to it; a member that died less than
    /// about a second before the host may be named heir by some and waited for that long.
    #[serde(default = "default_member_heartbeat")]
    pub member_heartbeat_interval: Duration,
    /// Largest datagram we ever emit.
    pub mtu: usize,
    /// Minimum retransmission timeout of reliable control messages.
    pub min_rto: Duration,
    /// The host refuses joins beyond this many members (itself included).
    #[serde(default = "default_max_members")]
    pub max_members: usize,
    /// The host creates no more objects (spawn requests, post-migration claims) for a peer
    /// that already owns this many.
    #[serde(default = "default_max_objects_per_peer")]
    pub max_objects_per_peer: usize,
    /// The host creates no object for a peer whose owned objects would then hold more
    /// particles than this in total.
    #[serde(default = "default_max_particles_per_peer")]
    pub max_particles_per_peer: usize,
    /// A digest of the application's content every peer must share beyond the class table
    /// (e.g. a scene's meshes and soft-body settings); part of [`digest`](Self::digest), so
    /// a joiner with other content is refused at the handshake. 0: none.
    #[serde(default)]
    pub content_digest: u64,
    /// The application's message types and the bounds on them; part of
    /// [`digest`](Self::digest).
    #[serde(default)]
    pub messages: MessageConfig,
    /// The room's key, if it has one: the host admits only joiners that prove they hold it
    /// (challenge and response; see [`RoomKey`](crate::RoomKey)). Every peer of the room
    /// sets the same secret. Not part of the digest, never serialised, never shown.
    #[serde(skip)]
    pub room_key: Option<crate::RoomKey>,
    /// A join token to show when a room with a key challenges us and we hold no key
    /// ([`RoomToken`](crate::wire::RoomToken)). Not part of the digest, never serialised.
    #[serde(skip)]
    pub room_token: Option<crate::wire::RoomToken>,
    /// How a silent peer is judged gone (a local choice, not part of the digest).
    #[serde(default)]
    pub detector: FailureDetector,
    /// How long a peer keeps sending beacons to peers its room lost (a partition shorter
    /// than this heals into one room; see `session::heal`). Not part of the digest.
    #[serde(default = "default_heal_window")]
    pub heal_window: Duration,
    /// This peer's uplink budget, bytes a second (datagram payloads plus the estimated
    /// transport overhead), shared equally by its links; state waits its turn by priority
    /// (`session::budget`). `None` (default): no cap. A local choice, not part of the digest.
    #[serde(default)]
    pub uplink_bytes_per_s: Option<u32>,
    /// Which way object state travels: through the host (the thesis's relay, the default) or
    /// from each owner straight to every member. Part of the digest: a room has one way.
    #[serde(default)]
    pub state_route: StateRoute,
    /// What one peer may cost this peer (a local policy, not part of the digest).
    #[serde(default)]
    pub peer_budget: PeerBudget,
}

/// What one peer may cost this one: the per-peer budgets, in one place. A local policy with
/// defaults (each peer may set its own; not part of the room's digest). Other per-peer bounds
/// of the session: `max_members`, `max_objects_per_peer`, `max_particles_per_peer`,
/// [`MessageConfig`]'s rate, burst and outbox, `MAX_STRANGERS` (32 senders at once without
/// membership), the reliable receive window (`reliable::WINDOW`, 512 messages ahead).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PeerBudget {
    /// Host: a member with more unacknowledged control messages than this, the oldest
    /// waiting longer than the peer timeout, is dropped, with the reason counted
    /// (`Stats::dropped_over_quota`) and told: a member that keeps its link alive but never
    /// acknowledges would otherwise make the host keep (and walk, at every datagram) an ever
    /// longer queue. A burst (a snapshot, many spawns at once) is acknowledged within round
    /// trips. The reliable channel itself keeps at most `reliable::MAX_QUEUED` (8192).
    pub max_control_in_flight: usize,
    /// Host: a member that says `Hello` again (it turned to another contact before our
    /// `Welcome` came) is welcomed again, with the whole snapshot, never while a `Welcome` to
    /// it is still unacknowledged (~80 `Hello`s fit in one datagram), three times at once and
    /// then at most once per this.
    pub rewelcome_every: Duration,
    /// A non-member's link state (a joiner's, a refused or unknown sender's) is forgotten
    /// this long after its first datagram, talking or not (a silent one after the peer
    /// timeout): a joiner is a member within round trips.
    pub stranger_lifetime: Duration,
    /// When `MAX_STRANGERS` non-members already have state, a new one takes the place of the
    /// one heard first, if that one was first heard at least this long ago (else the newcomer
    /// is dropped): strangers that keep talking cannot hold the door shut.
    pub stranger_evictable_after: Duration,
}

impl Default for PeerBudget {
    fn default() -> Self {
        PeerBudget {
            max_control_in_flight: 2048,
            rewelcome_every: Duration::from_secs(1),
            stranger_lifetime: Duration::from_secs(30),
            stranger_evictable_after: Duration::from_secs(2),
        }
    }
}

/// Which way a client's object state travels to the other members. Membership, authority and
/// the ordering of control stay with the host either way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum StateRoute {
    /// To the host, which relays it to every other member (thesis 5.2, Figure 5.2): a client
    /// sends each update once; the host's uplink grows with the square of the room.
    #[default]
    Relay,
    /// From the owner to every member over the full mesh: one hop less (no relay delay),
    /// the host's uplink grows only with its own objects, each client's with the room.
    Direct,
}

fn default_member_heartbeat() -> Duration {
    Duration::from_millis(250)
}

fn default_heal_window() -> Duration {
    Duration::from_secs(300)
}

/// How a silent peer is judged gone: a fixed timeout, or one that adapts to each link.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum FailureDetector {
    /// Silent for [`SessionConfig::peer_timeout`]: gone ([`SessionConfig::fixed_detection`]).
    Fixed,
    /// Accrual, in the spirit of phi-accrual (Hayashibara et al., 2004), from each link's
    /// last 64 datagram inter-arrival gaps: the share of gaps longer than 1.75 heartbeat
    /// intervals estimates the chance `q` that a heartbeat is lost (at least 1 %); a peer is
    /// gone once it was silent for the `k` heartbeat intervals that make `q^k` < 10^−phi (phi 9: a
    /// run of losses that long is a one-in-a-billion event), plus `deviations`
    /// standard deviations of the other gaps (jitter) — never sooner than `min_timeout`, never
    /// later than the peer timeout, and the peer timeout until a link has 16 gaps. A normal
    /// model of the gaps alone (the classic phi) raised false alarms under 20 % loss in the
    /// harness: a geometric run of losses has a longer tail than a normal gap. Every peer of
    /// a room should use the same heartbeat interval.
    Adaptive {
        /// The suspicion threshold: a peer is gone once its silence is a 10^−phi event for a
        /// live one (9 by default).
        phi: f32,
        /// How many standard deviations of the jitter to allow past the heartbeats.
        deviations: f32,
        /// The least silence that counts as gone.
        min_timeout: Duration,
    },
}

impl FailureDetector {
    /// The adaptive detector with its defaults (the default detector, with a 50 ms heartbeat):
    /// phi 9, 4 deviations, and at least 345 ms of silence. A peer stopped for less than
    /// 250 ms must never be taken for gone ([`FailureDetector::TOLERATED_STALL`]): its last
    /// datagram before the stop may be 1.25 heartbeat intervals older (62.5 ms), and the first
    /// after it may come 30 ms later than its rhythm (jitter, a reordered datagram), so
    /// 250 + 62.5 + 30 ≈ 345. A heartbeat lost just before such a stop is not covered.
    pub const ADAPTIVE: FailureDetector = FailureDetector::Adaptive {
        phi: 9.0,
        deviations: 4.0,
        min_timeout: Duration::from_millis(345),
    };

    /// The longest stop of a live peer (a starved process, a page fault storm, a debugger's
    /// breakpoint) the default detector lets pass without a verdict: a host stopped for less
    /// is not replaced. Longer stops are taken for a crash (a host SIGSTOPped for 0.5 s is
    /// replaced).
    pub const TOLERATED_STALL: Duration = Duration::from_millis(250);
}

impl Default for FailureDetector {
    fn default() -> Self {
        FailureDetector::ADAPTIVE
    }
}

/// The application's message types and the room's bounds on messages. Every peer enforces
/// the bounds on what it sends, the host again on what it relays.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MessageConfig {
    /// Message type names; a [`MessageKind`](crate::wire::MessageKind) is an index here
    /// ([`crate::messages::MessageTypes::configure`] fills it from the registered types).
    pub kinds: Vec<String>,
    /// Largest payload, bytes (at most [`MAX_MESSAGE_PAYLOAD`](crate::wire::MAX_MESSAGE_PAYLOAD)).
    pub max_payload: usize,
    /// Reliable messages (every delivery but unreliable) per second a peer may send,
    /// sustained.
    pub rate_per_s: f32,
    /// Reliable messages a peer may send at once above the rate.
    pub burst: u32,
    /// Unreliable messages per second a peer may send, sustained: a bucket of their own,
    /// since they cost the host no ledger and a stream of them (the built-in remote hands:
    /// one per hand per step, 2 × 90 Hz) must leave the reliable rate to the app.
    pub unreliable_rate_per_s: f32,
    /// Unreliable messages a peer may send at once above their rate.
    pub unreliable_burst: u32,
    /// A peer's reliable messages not yet delivered to all their targets; more are refused
    /// ([`MessageRefusal::QueueFull`](crate::wire::MessageRefusal::QueueFull)).
    pub max_outbox: usize,
    /// Unreliable messages waiting for the next datagram to one peer; more are dropped.
    pub max_unreliable_queue: usize,
}

impl Default for MessageConfig {
    fn default() -> Self {
        MessageConfig {
            kinds: Vec::new(),
            max_payload: crate::wire::MAX_MESSAGE_PAYLOAD,
            rate_per_s: 60.0,
            burst: 120,
            unreliable_rate_per_s: 240.0,
            unreliable_burst: 240,
            max_outbox: 256,
            max_unreliable_queue: 64,
        }
    }
}

fn default_max_members() -> usize {
    64
}

fn default_max_objects_per_peer() -> usize {
    256
}

fn default_max_particles_per_peer() -> usize {
    1 << 18
}

impl Default for SessionConfig {
    fn default() -> Self {
        SessionConfig {
            classes: vec![ClassConfig::rigid("rigid", SendPolicy::default())],
            peer_timeout: Duration::from_secs(1),
            heartbeat_interval: Duration::from_millis(50),
            member_heartbeat_interval: default_member_heartbeat(),
            mtu: 1200,
            min_rto: Duration::from_millis(60),
            max_members: default_max_members(),
            max_objects_per_peer: default_max_objects_per_peer(),
            max_particles_per_peer: default_max_particles_per_peer(),
            content_digest: 0,
            messages: MessageConfig::default(),
            room_key: None,
            room_token: None,
            detector: FailureDetector::ADAPTIVE,
            heal_window: default_heal_window(),
            uplink_bytes_per_s: None,
            state_route: StateRoute::Relay,
            peer_budget: PeerBudget::default(),
        }
    }
}

impl SessionConfig {
    /// The configuration of class `c` (none for a class this room does not have).
    pub fn class(&self, c: crate::ClassId) -> Option<&ClassConfig> {
        self.classes.get(usize::from(c.0))
    }

    /// This configuration with the adaptive failure detector ([`FailureDetector::ADAPTIVE`])
    /// and 50 ms heartbeats (the default): a dead host is noticed in about a third of a
    /// second on a good link, a host stopped for less than
    /// [`FailureDetector::TOLERATED_STALL`] never is.
    pub fn fast_detection(mut self) -> Self {
        self.detector = FailureDetector::ADAPTIVE;
        self.heartbeat_interval = Duration::from_millis(50);
        self
    }

    /// This configuration with the fixed detector and 200 ms heartbeats (the default before
    /// the adaptive one): a peer is gone after [`peer_timeout`](Self::peer_timeout) of
    /// silence, whatever its link; a fifth of the heartbeats.
    pub fn fixed_detection(mut self) -> Self {
        self.detector = FailureDetector::Fixed;
        self.heartbeat_interval = Duration::from_millis(200);
        self
    }

    /// The largest application payload this room takes: the configured bound, within
    /// [`MAX_MESSAGE_PAYLOAD`](crate::wire::MAX_MESSAGE_PAYLOAD) and small enough that its
    /// envelope fits one datagram of [`mtu`](Self::mtu) (100 bytes for the datagram header
    /// and the envelope).
    pub fn max_message_payload(&self) -> usize {
        self.messages
            .max_payload
            .min(crate::wire::MAX_MESSAGE_PAYLOAD)
            .min(self.mtu.saturating_sub(100))
    }

    /// A digest of everything that must agree across peers (compared in the join handshake).
    pub fn digest(&self) -> u64 {
        // FNV-1a over the class table's JSON-free debug text: stable within one build.
        let mut text = format!(
            "{:?}|{}|{:?}",
            self.classes, self.content_digest, self.messages
        );
        if self.state_route == StateRoute::Direct {
            text.push_str("|direct");
        }
        // a room's size cap must survive a migration: every peer has the same
        if self.max_members != default_max_members() {
            text.push_str(&format!("|max{}", self.max_members));
        }
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in text.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        h
    }
}
