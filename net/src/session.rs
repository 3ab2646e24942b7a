//! The room session: one sans-IO state machine per local peer.
//!
//! Packets and `now` go in ([`Session::handle_packet`], [`Session::handle_timeout`], local
//! commands); datagrams, events and the next wake-up come out ([`Session::poll_transmit`],
//! [`Session::poll_event`], [`Session::poll_timeout`]).

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use glam::{Quat, Vec3};

use crate::bits::BitWriter;
use crate::error::NetError;
use crate::ids::{AuthorityEpoch, ClassId, NetId, PeerId, Term};
use crate::interp::{InterpolationConfig, Snapshot, SnapshotBuffer};
use crate::policy::{AuthorityPolicy, ClassConfig, SessionConfig, SoftBodyMode};
use crate::quant::{angle_between, dequantize_quat, quantize_quat, QuatQ, VecQuantizer};
use crate::reliable::ReliableChannel;
use crate::stats::Stats;
use crate::time::{min_opt, Instant};
use crate::wire::{
    self, decode_packet, decode_refusal, decode_state_block, encode_refusal, entry_id_bits,
    reliable_len, write_entry_id, write_reliable, ChunkEnc, Control, DenyReason, EntryLayout,
    PacketHeader, PartBody, PosEnc, Section, SpawnInfo, StateEntry, ENTRY_SEQ_MOD,
    PROTOCOL_VERSION,
};

/// Non-member peers (joiners, unknown senders) we keep link state for at once.
pub const MAX_STRANGERS: usize = 32;

/// Object ids a new host skips past the highest id it knows. They cover objects the old host
/// spawned whose `Spawn` never reached the heir: a `Resync` claim can create an unknown
/// object only inside this range.
pub const LOST_ID_WINDOW: u32 = 1024;

/// A `NewHost` may announce a term at most this far ahead of ours (an heir may die too).
pub const MAX_TERM_JUMP: u32 = 4;

/// A datagram this many or more datagrams older than the newest one received from its
/// sender is too late for its state entries to be used (their 5-bit sequences may alias).
const MAX_STATE_LATENESS: u8 = 16;

/// A datagram that looks 128 or more behind the newest is taken as the newest when nothing
/// advanced the datagram sequence for this long (many datagrams were lost, not one delayed).
const IN_SEQ_RESYNC_AFTER: Duration = Duration::from_millis(250);

/// Departed peers remembered (their in-flight datagrams are ignored); the set is cleared when
/// full (peers that left long ago send nothing).
const MAX_DEPARTED: usize = 256;

/// An object's state as the application sees it: center transform and world-space particles.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct ObjectState {
    /// Center position.
    pub pos: Vec3,
    /// Center rotation.
    pub rot: Quat,
    /// Particle positions in world space (empty for rigid objects).
    pub particles: Vec<Vec3>,
}

impl ObjectState {
    /// A rigid pose.
    pub fn rigid(pos: Vec3, rot: Quat) -> Self {
        ObjectState {
            pos,
            rot,
            particles: Vec::new(),
        }
    }

    fn is_finite(&self) -> bool {
        self.pos.is_finite() && self.rot.is_finite() && self.particles.iter().all(|p| p.is_finite())
    }

    /// The state's rotation, normalized, if the state is finite and the rotation is a unit
    /// quaternion up to rounding (|q|² within [0.98, 1.02]; a zero quaternion is refused).
    fn checked_rotation(&self) -> Result<Quat, NetError> {
        if !self.is_finite() {
            return Err(NetError::InvalidState("non-finite state"));
        }
        if !(0.98..=1.02).contains(&self.rot.length_squared()) {
            return Err(NetError::InvalidState("rotation is not a unit quaternion"));
        }
        Ok(self.rot.normalize())
    }
}

/// What a remote peer displays for an object.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayedState {
    /// The interpolated state.
    pub state: ObjectState,
    /// The time, in the sending peer's clock, that this state represents.
    pub source_time: Instant,
    /// Interpolation delay applied.
    pub delay: Duration,
}

/// A datagram to hand to the transport.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Transmit {
    /// Destination.
    pub to: PeerId,
    /// Bytes (≤ mtu).
    pub payload: Vec<u8>,
}

/// Things the application should know or act on.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// We are in the room.
    Joined {
        /// Host.
        host: PeerId,
        /// Term.
        term: Term,
    },
    /// The host refused us (while joining): another protocol version or class table, or a
    /// full room. The session is done.
    Refused {
        /// Why.
        reason: String,
    },
    /// This peer was in the room, but the room went on without it: it was out of touch (its
    /// loop stalled, or its link was cut) for longer than the peer timeout, so the host timed
    /// it out, or, if it was the host, the others elected a new one. Its objects have other
    /// owners now. The session is done and sends nothing more; to come back, join `host`
    /// again with a fresh session ([`Session::join`]): it gets the room's current state.
    Dropped {
        /// The room's host (the peer that said so).
        host: PeerId,
        /// Why, for people.
        reason: String,
    },
    /// A peer joined.
    PeerJoined(PeerId),
    /// A peer left or timed out.
    PeerLeft(PeerId),
    /// A new host took over.
    HostChanged {
        /// New host.
        host: PeerId,
        /// New term.
        term: Term,
    },
    /// An object now exists locally.
    Spawned {
        /// Object.
        id: NetId,
        /// Class.
        class: ClassId,
        /// Owner.
        owner: PeerId,
        /// Our spawn request number, if we asked for it.
        request: Option<u32>,
    },
    /// An object is gone.
    Despawned(NetId),
    /// An object changed owner.
    AuthorityChanged {
        /// Object.
        id: NetId,
        /// New owner.
        owner: PeerId,
        /// New epoch.
        epoch: AuthorityEpoch,
    },
    /// Our authority request was denied.
    AuthorityDenied {
        /// Object.
        id: NetId,
        /// Why.
        reason: DenyReason,
    },
    /// Request to the application: `by` wants our object; answer with
    /// [`Session::answer_authority`].
    AuthorityAsked {
        /// Object.
        id: NetId,
        /// Asking peer.
        by: PeerId,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    Joining,
    Client,
    Host,
    Refused,
}

#[derive(Clone, Debug, PartialEq)]
enum PartQ {
    Transform { pos: [u32; 3], rot: QuatQ },
    Chunk(Vec<[u32; 3]>),
}

#[derive(Clone, Debug)]
struct SendPart {
    /// Last entry number used (never wraps; the wire carries it mod [`ENTRY_SEQ_MOD`]).
    seq: u64,
    /// Newest acknowledged entry (number) and the state the peer holds after it.
    acked: Option<(u64, PartQ)>,
    /// Sent, not yet acknowledged: (entry number, state after it, send time).
    unacked: VecDeque<(u64, PartQ, Instant)>,
    last_key_at: Instant,
    /// When each field was last sent (transform: position, rotation; chunk: per particle).
    sent_at: Vec<Instant>,
}

#[derive(Clone, Debug)]
struct RecvPart {
    /// State after each recently received entry, by sequence (delta bases).
    ring: Vec<Option<(u8, PartQ)>>,
    /// Sequence of the entry whose state is shown.
    latest: Option<u8>,
}

/// A `NewHost` kept for later, with the control messages its sender sent after it (the
/// snapshot, ownership changes), replayed once it is adopted.
#[derive(Debug)]
struct PendingNewHost {
    at: Instant,
    term: Term,
    members: Vec<(PeerId, u32)>,
    later: Vec<Control>,
}

/// Control messages kept after a `NewHost` not adopted yet (more drop the `NewHost`).
const MAX_DEFERRED_CONTROLS: usize = 4096;

/// (object, part, entry number) of an entry carried by a datagram.
type EntryRef = (NetId, u32, u64);

/// Wire sequence of an entry number.
fn wire_seq(n: u64) -> u8 {
    (n % u64::from(ENTRY_SEQ_MOD)) as u8
}

#[derive(Clone, Debug, Default)]
struct LinkClock {
    last_full_ms: Option<i64>,
    last_ms: u16,
    min_offset_us: Option<i64>,
    jitter_us: f64,
}

#[derive(Debug, Default)]
struct Link {
    reliable: ReliableChannel,
    last_sent: Option<Instant>,
    last_ping: Option<Instant>,
    last_heard: Option<Instant>,
    out_seq: u8,
    in_seq: Option<u8>,
    /// When `in_seq` last advanced.
    in_seq_at: Option<Instant>,
    send: BTreeMap<(NetId, u32), SendPart>,
    recv: BTreeMap<(NetId, u32), RecvPart>,
    spawn_pending: BTreeMap<NetId, u16>,
    pending: Vec<StateEntry>,
    /// Time the owner's pending entries describe (the datagram is stamped with it).
    pending_sample: Option<Instant>,
    keyreq_out: BTreeSet<NetId>,
    keyreq_sent: BTreeMap<NetId, Instant>,
    pong_due: Option<u32>,
    ping_due: bool,
    clock: LinkClock,
    /// Datagrams that carried state entries: (datagram seq, [(object, part, entry number)]).
    inflight: VecDeque<(u8, Vec<EntryRef>)>,
    /// State datagrams received from the peer: newest seq and the 32 before it.
    state_rx: Option<(u8, u32)>,
    /// We owe the peer a state ack.
    state_ack_pending: bool,
    srtt: Option<Duration>,
}

#[derive(Debug)]
struct Object {
    info: SpawnInfo,
    pos: [u32; 3],
    rot: QuatQ,
    particles: Vec<[u32; 3]>,
    rest: bool,
    last_change: Instant,
    published: Option<ObjectState>,
    published_at: Instant,
    buffer: SnapshotBuffer,
    source: Option<PeerId>,
}

/// Book-keep one outgoing entry of a part: a new sequence number, the state the peer will
/// hold once it applies it, per-field send times. Returns `None` (send nothing) when the
/// same state is already in flight and its acknowledgement is not overdue.
#[allow(clippy::too_many_arguments)]
fn emit(
    link: &mut Link,
    key: (NetId, u32),
    after: PartQ,
    is_key: bool,
    force: bool,
    now: Instant,
    ack_wait: Duration,
    fields: &[usize],
    field_count: usize,
) -> Option<u8> {
    let sp = link.send.entry(key).or_insert_with(|| SendPart {
        seq: u64::from(ENTRY_SEQ_MOD) - 1,
        acked: None,
        unacked: VecDeque::new(),
        last_key_at: now,
        sent_at: vec![now; field_count],
    });
    if !force {
        if let Some((_, st, at)) = sp.unacked.back() {
            if *st == after && now < *at + ack_wait {
                return None;
            }
        }
    }
    sp.seq = sp.seq.wrapping_add(1);
    sp.unacked.push_back((sp.seq, after, now));
    while sp.unacked.len() > usize::from(ENTRY_SEQ_MOD) - 8 {
        sp.unacked.pop_front();
    }
    if is_key {
        sp.last_key_at = now;
    }
    sp.sent_at.resize(field_count, now);
    for f in fields {
        if let Some(t) = sp.sent_at.get_mut(*f) {
            *t = now;
        }
    }
    Some(wire_seq(sp.seq))
}

/// Seq `a` is newer than `b` in wrapping entry-sequence order.
fn seq_newer(a: u8, b: u8) -> bool {
    let d = a.wrapping_sub(b) % ENTRY_SEQ_MOD;
    (1..ENTRY_SEQ_MOD / 2).contains(&d)
}

/// One peer's view of the room.
#[derive(Debug)]
pub struct Session {
    cfg: SessionConfig,
    interp: InterpolationConfig,
    local: PeerId,
    role: Role,
    host: Option<PeerId>,
    term: Term,
    members: BTreeMap<PeerId, u32>,
    links: BTreeMap<PeerId, Link>,
    objects: BTreeMap<NetId, Object>,
    next_net_id: u32,
    next_join_seq: u32,
    next_request: u32,
    /// Our spawn requests not answered yet: (class, initial state).
    pending_spawns: BTreeMap<u32, (ClassId, ObjectState)>,
    pending_asks: BTreeMap<NetId, BTreeSet<PeerId>>,
    events: VecDeque<Event>,
    raw_out: VecDeque<Transmit>,
    next_tick: Vec<Instant>,
    next_heartbeat: Instant,
    stats: Stats,
    last_relay_at: Option<Instant>,
    /// After we took over as host: `Resync` claims are accepted until then.
    resync_until: Option<Instant>,
    /// After we took over as host: ids `lo..hi` the old host may have spawned unseen by us.
    lost_ids: Option<(u32, u32)>,
    /// `NewHost` messages not acceptable yet, per sender: (received, term, members).
    pending_new_hosts: BTreeMap<PeerId, PendingNewHost>,
    /// Peers that said `Leave`: their datagrams still in flight are ignored (bounded).
    departed: BTreeSet<PeerId>,
    /// Host: peers out of the room that may not know it, with why and when it last told them
    /// so: members it timed out, and peers still speaking for an older term (a host or member
    /// that stalled while the room elected this host). A peer whose loop stalled past the peer
    /// timeout does not know it is out; when it talks again it is told (a refusal), rather
    /// than carrying on alone as the host of a room of one, owning objects others now own.
    dropped: BTreeMap<PeerId, Dropped>,
    /// When the application last drove the session (a datagram or a timer), to see our own
    /// stalls: time this peer was not listening is not the others' silence.
    last_driven: Option<Instant>,
    /// When this peer last found it had stalled for the peer timeout or longer (the others
    /// have timed it out, and may have elected another host meanwhile).
    stalled_at: Option<Instant>,
}

/// Why a peer is out of the room ([`Session::dropped`]).
#[derive(Clone, Copy, Debug)]
enum DropWhy {
    /// This host timed it out.
    TimedOut,
    /// It spoke for this older term: the room elected a host while it was silent.
    OlderTerm(Term),
}

#[derive(Clone, Copy, Debug)]
struct Dropped {
    why: DropWhy,
    /// When it was last told (at most once per heartbeat interval).
    told: Option<Instant>,
}

impl Session {
    fn new(local: PeerId, cfg: SessionConfig, now: Instant, role: Role) -> Self {
        let ticks = vec![now; cfg.classes.len()];
        Session {
            cfg,
            interp: InterpolationConfig::default(),
            local,
            role,
            host: None,
            term: Term(0),
            members: BTreeMap::new(),
            links: BTreeMap::new(),
            objects: BTreeMap::new(),
            next_net_id: 1,
            next_join_seq: 0,
            next_request: 0,
            pending_spawns: BTreeMap::new(),
            pending_asks: BTreeMap::new(),
            events: VecDeque::new(),
            raw_out: VecDeque::new(),
            next_tick: ticks,
            next_heartbeat: now,
            stats: Stats::default(),
            last_relay_at: None,
            resync_until: None,
            lost_ids: None,
            pending_new_hosts: BTreeMap::new(),
            departed: BTreeSet::new(),
            dropped: BTreeMap::new(),
            last_driven: None,
            stalled_at: None,
        }
    }

    /// Create a room and host it (term 1, join order 0).
    pub fn host(local: PeerId, cfg: SessionConfig, now: Instant) -> Self {
        let mut s = Session::new(local, cfg, now, Role::Host);
        s.host = Some(local);
        s.term = Term(1);
        s.members.insert(local, 0);
        s.next_join_seq = 1;
        s
    }

    /// Join the room hosted by `host`.
    pub fn join(local: PeerId, host: PeerId, cfg: SessionConfig, now: Instant) -> Self {
        let mut s = Session::new(local, cfg, now, Role::Joining);
        s.host = Some(host);
        let hello = Control::Hello {
            protocol: PROTOCOL_VERSION,
            config_digest: s.cfg.digest(),
        };
        s.send_control(now, host, &hello);
        s
    }

    /// A joiner whose contact has not answered (another joiner knows no host yet) asks
    /// `contact` instead, with this same session: its sequences with the peers it asked
    /// before stay in step (a fresh session would restart them, and a peer that saw the first
    /// `Hello` would later take this peer's first reliable message for a duplicate). False,
    /// and nothing sent, unless the session is still joining.
    pub fn join_via(&mut self, now: Instant, contact: PeerId) -> bool {
        if self.role != Role::Joining || contact == self.local {
            return false;
        }
        self.host = Some(contact);
        let hello = Control::Hello {
            protocol: PROTOCOL_VERSION,
            config_digest: self.cfg.digest(),
        };
        self.send_control(now, contact, &hello);
        true
    }

    /// Override the interpolation settings (made sane first: see
    /// [`InterpolationConfig::sanitized`]).
    pub fn set_interpolation(&mut self, cfg: InterpolationConfig) {
        self.interp = cfg.sanitized();
    }

    /// The interpolation settings in use.
    pub fn interpolation(&self) -> InterpolationConfig {
        self.interp
    }

    // ---------------------------------------------------------------- queries

    /// Our peer id.
    pub fn local_id(&self) -> PeerId {
        self.local
    }

    /// Current host, if known.
    pub fn host_id(&self) -> Option<PeerId> {
        self.host
    }

    /// Are we the host?
    pub fn is_host(&self) -> bool {
        self.role == Role::Host
    }

    /// Have we joined (or do we host) a room?
    pub fn is_connected(&self) -> bool {
        matches!(self.role, Role::Host | Role::Client)
    }

    /// Current room term.
    pub fn term(&self) -> Term {
        self.term
    }

    /// Members and their join order.
    pub fn members(&self) -> &BTreeMap<PeerId, u32> {
        &self.members
    }

    /// Known objects.
    pub fn object_ids(&self) -> Vec<NetId> {
        self.objects.keys().copied().collect()
    }

    /// Owner of an object according to our replica.
    pub fn owner(&self, id: NetId) -> Option<PeerId> {
        self.objects.get(&id).map(|o| o.info.owner)
    }

    /// Authority epoch of an object according to our replica.
    pub fn epoch(&self, id: NetId) -> Option<AuthorityEpoch> {
        self.objects.get(&id).map(|o| o.info.epoch)
    }

    /// Class of an object.
    pub fn class_of(&self, id: NetId) -> Option<ClassId> {
        self.objects.get(&id).map(|o| o.info.class)
    }

    /// Statistics.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }

    /// Last time we (as host) relayed a state entry from one client to another.
    pub fn last_relay_at(&self) -> Option<Instant> {
        self.last_relay_at
    }

    /// The configuration.
    pub fn config(&self) -> &SessionConfig {
        &self.cfg
    }

    /// Latest replicated state (no interpolation): what the last update said.
    pub fn latest_state(&self, id: NetId) -> Option<ObjectState> {
        let o = self.objects.get(&id)?;
        if o.info.owner == self.local {
            if let Some(p) = &o.published {
                return Some(p.clone());
            }
        }
        let class = self.class(o.info.class)?;
        Some(self.compose(o, class))
    }

    /// What this peer displays at `now`: the owner's published state for our own objects,
    /// otherwise the interpolated remote state.
    pub fn display_state(&mut self, now: Instant, id: NetId) -> Option<DisplayedState> {
        let local = self.local;
        let interp = self.interp;
        let o = self.objects.get(&id)?;
        if o.info.owner == local {
            if let Some(p) = &o.published {
                return Some(DisplayedState {
                    state: p.clone(),
                    source_time: now,
                    delay: Duration::ZERO,
                });
            }
        }
        let class = self.cfg.classes.get(usize::from(o.info.class.0))?.clone();
        let (delay, min_offset) = match o.source.and_then(|s| self.links.get(&s)) {
            Some(l) => {
                let base = class.send.interval().as_secs_f32() * interp.intervals;
                let j = interp.jitter_factor * l.clock.jitter_us as f32 * 1e-6;
                let cap = class.send.interval().as_secs_f32() * 4.0 + 0.1;
                (
                    Duration::try_from_secs_f32((base + j).min(cap).max(0.0))
                        .unwrap_or(Duration::ZERO),
                    l.clock.min_offset_us.unwrap_or(0),
                )
            }
            None => (Duration::ZERO, 0),
        };
        let t = now - delay;
        let o = self.objects.get_mut(&id)?;
        let snap = match o.buffer.sample(t, &interp) {
            Some(s) => s,
            None => {
                let st = self.latest_state(id)?;
                return Some(DisplayedState {
                    state: st,
                    source_time: t,
                    delay,
                });
            }
        };
        let particles = if class.soft_body_mode == SoftBodyMode::Particles {
            snap.offsets
                .iter()
                .map(|o| snap.pos + snap.rot * *o)
                .collect()
        } else {
            Vec::new()
        };
        let src = t.as_micros() as i64 - min_offset;
        Some(DisplayedState {
            state: ObjectState {
                pos: snap.pos,
                rot: snap.rot,
                particles,
            },
            source_time: Instant::from_micros(src.max(0) as u64),
            delay,
        })
    }

    fn class(&self, c: ClassId) -> Option<&ClassConfig> {
        self.cfg.classes.get(usize::from(c.0))
    }

    fn compose(&self, o: &Object, class: &ClassConfig) -> ObjectState {
        let pos = class.position_quantizer().dequantize(o.pos);
        let rot = dequantize_quat(o.rot, class.rot_bits());
        let pq = class.particle_quantizer();
        let particles = if class.soft_body_mode == SoftBodyMode::Particles {
            o.particles
                .iter()
                .map(|q| pos + rot * pq.dequantize(*q))
                .collect()
        } else {
            Vec::new()
        };
        ObjectState {
            pos,
            rot,
            particles,
        }
    }

    // ---------------------------------------------------------------- local commands

    /// Leave the room: tell every member (and the host) that we are gone, so that they act
    /// at once instead of after `peer_timeout`. Send what `poll_transmit` gives afterwards;
    /// the session is not meant to be used after that.
    pub fn leave(&mut self, now: Instant) {
        let peers: BTreeSet<PeerId> = self
            .members
            .keys()
            .copied()
            .chain(self.host)
            .filter(|p| *p != self.local)
            .collect();
        for p in peers {
            self.send_control(now, p, &Control::Leave);
        }
    }

    /// Spawn an object. On the host it exists at once (owned by the host) and its id is
    /// returned; on a client the host is asked and `Event::Spawned { request }` follows,
    /// with the returned number as `request` (and `NetId(0)` returned here). The state is
    /// checked as in [`Session::publish_state`].
    pub fn spawn(
        &mut self,
        now: Instant,
        class: ClassId,
        state: ObjectState,
    ) -> Result<(NetId, u32), NetError> {
        if self.class(class).is_none() {
            return Err(NetError::UnknownClass(class.0));
        }
        let state = ObjectState {
            rot: state.checked_rotation()?,
            ..state
        };
        if state.particles.len() > wire::MAX_PARTICLES as usize {
            return Err(NetError::InvalidState("too many particles"));
        }
        let request = self.next_request;
        self.next_request = self.next_request.wrapping_add(1);
        match self.role {
            Role::Host => {
                let id = self.host_spawn_own(now, class, &state, request)?;
                Ok((id, request))
            }
            Role::Client => {
                let host = self.host.ok_or(NetError::NotConnected)?;
                self.pending_spawns.insert(request, (class, state.clone()));
                let msg = Control::SpawnRequest {
                    request,
                    class,
                    particles: state.particles.len() as u32,
                    pos: state.pos.to_array(),
                    rot: state.rot.to_array(),
                };
                self.send_control(now, host, &msg);
                Ok((NetId(0), request))
            }
            _ => Err(NetError::NotConnected),
        }
    }

    /// As host: create an object we own (our spawn request number `request`) and announce it.
    fn host_spawn_own(
        &mut self,
        now: Instant,
        class: ClassId,
        state: &ObjectState,
        request: u32,
    ) -> Result<NetId, NetError> {
        let policy = self
            .class(class)
            .ok_or(NetError::UnknownClass(class.0))?
            .authority;
        let id = self.alloc_id().ok_or(NetError::IdsExhausted)?;
        let info = SpawnInfo {
            id,
            class,
            owner: self.local,
            epoch: AuthorityEpoch {
                term: self.term.0,
                grant: 0,
            },
            held: false,
            policy,
            particles: state.particles.len() as u32,
            pos: state.pos.to_array(),
            rot: state.rot.to_array(),
            request: None,
        };
        self.insert_object(now, info.clone(), Some(request));
        let _ = self.publish_state(now, id, state);
        self.broadcast(now, &Control::Spawn(info), None);
        Ok(id)
    }

    /// Despawn an object we own (or any object, on the host).
    pub fn despawn(&mut self, now: Instant, id: NetId) -> Result<(), NetError> {
        let o = self.objects.get(&id).ok_or(NetError::UnknownObject(id))?;
        if self.role == Role::Host {
            self.host_despawn(now, id);
            Ok(())
        } else if o.info.owner == self.local {
            let host = self.host.ok_or(NetError::NotConnected)?;
            self.send_control(now, host, &Control::DespawnRequest { id });
            Ok(())
        } else {
            Err(NetError::NotOwner(id, o.info.owner))
        }
    }

    /// Ask for authority over an object (grab). The answer is an event.
    pub fn request_authority(&mut self, now: Instant, id: NetId) -> Result<(), NetError> {
        if !self.objects.contains_key(&id) {
            return Err(NetError::UnknownObject(id));
        }
        match self.role {
            Role::Host => {
                let me = self.local;
                self.host_authority_request(now, me, id);
                Ok(())
            }
            Role::Client => {
                let host = self.host.ok_or(NetError::NotConnected)?;
                self.send_control(now, host, &Control::AuthorityRequest { id });
                Ok(())
            }
            _ => Err(NetError::NotConnected),
        }
    }

    /// Give authority back to the host (release).
    pub fn release_authority(&mut self, now: Instant, id: NetId) -> Result<(), NetError> {
        let o = self.objects.get(&id).ok_or(NetError::UnknownObject(id))?;
        if o.info.owner != self.local {
            return Err(NetError::NotOwner(id, o.info.owner));
        }
        match self.role {
            Role::Host => {
                let me = self.local;
                self.host_release(now, me, id);
                Ok(())
            }
            Role::Client => {
                let host = self.host.ok_or(NetError::NotConnected)?;
                self.send_control(now, host, &Control::AuthorityRelease { id });
                Ok(())
            }
            _ => Err(NetError::NotConnected),
        }
    }

    /// Answer an [`Event::AuthorityAsked`].
    pub fn answer_authority(&mut self, now: Instant, id: NetId, by: PeerId, agree: bool) {
        match self.role {
            Role::Host => {
                let me = self.local;
                self.host_authority_answer(now, me, id, by, agree);
            }
            Role::Client => {
                if let Some(host) = self.host {
                    self.send_control(now, host, &Control::AuthorityAnswer { id, by, agree });
                }
            }
            _ => {}
        }
    }

    /// Publish the current state of an object we own (call every frame; the send policy
    /// decides what goes on the wire). The rotation must be a unit quaternion up to rounding
    /// (|q|² within [0.98, 1.02], else [`NetError::InvalidState`]); it is normalized.
    pub fn publish_state(
        &mut self,
        now: Instant,
        id: NetId,
        state: &ObjectState,
    ) -> Result<(), NetError> {
        let local = self.local;
        let o = self.objects.get(&id).ok_or(NetError::UnknownObject(id))?;
        if o.info.owner != local {
            return Err(NetError::NotOwner(id, o.info.owner));
        }
        let unit = state.checked_rotation()?;
        if state.particles.len() != o.info.particles as usize {
            return Err(NetError::InvalidState("particle count differs from spawn"));
        }
        let class = self
            .class(o.info.class)
            .ok_or(NetError::UnknownClass(o.info.class.0))?;
        let pos = class.position_quantizer().quantize(state.pos);
        let rot = quantize_quat(unit, class.rot_bits());
        let pq = class.particle_quantizer();
        let inv = unit.inverse();
        let particles: Vec<[u32; 3]> = state
            .particles
            .iter()
            .map(|p| pq.quantize(inv * (*p - state.pos)))
            .collect();
        let o = self
            .objects
            .get_mut(&id)
            .ok_or(NetError::UnknownObject(id))?;
        if o.pos != pos || o.rot != rot || o.particles != particles {
            o.pos = pos;
            o.rot = rot;
            o.particles = particles;
            o.last_change = now;
            o.rest = false;
        }
        o.published = Some(ObjectState {
            pos: state.pos,
            rot: unit,
            particles: state.particles.clone(),
        });
        o.published_at = now;
        Ok(())
    }

    /// Queue any control message to `to` on the reliable channel, exactly as a modified
    /// client could. For tests and fuzzing of the receiving side; applications never need it.
    pub fn send_raw_control(&mut self, now: Instant, to: PeerId, msg: &Control) {
        self.send_control(now, to, msg);
    }

    // ---------------------------------------------------------------- outputs

    /// Next event.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// When to call [`Session::handle_timeout`] next.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let mut t = Some(self.next_heartbeat);
        if self.role == Role::Refused {
            return None;
        }
        for (c, tick) in self.next_tick.iter().enumerate() {
            let owns = self
                .objects
                .values()
                .any(|o| usize::from(o.info.class.0) == c && o.info.owner == self.local);
            if owns {
                t = min_opt(t, Some(*tick));
            }
        }
        for (p, l) in &self.links {
            t = min_opt(t, l.reliable.next_deadline());
            if self.members.contains_key(p) && *p != self.local {
                if let Some(h) = l.last_heard {
                    t = min_opt(t, Some(h + self.cfg.peer_timeout));
                }
            }
        }
        t
    }

    /// Next datagram to send.
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Transmit> {
        if let Some(t) = self.raw_out.pop_front() {
            return Some(t);
        }
        let peers: Vec<PeerId> = self.links.keys().copied().collect();
        for p in peers {
            if let Some(t) = self.build_datagram(now, p) {
                return Some(t);
            }
        }
        None
    }

    fn build_datagram(&mut self, now: Instant, to: PeerId) -> Option<Transmit> {
        let mtu = self.cfg.mtu;
        let term = self.term;
        let rto = self.rto(to);
        let link = self.links.get_mut(&to)?;
        let has_work = link.reliable.ack_pending
            || link.pong_due.is_some()
            || link.ping_due
            || !link.keyreq_out.is_empty()
            || !link.pending.is_empty()
            || link.state_ack_pending
            || link.reliable.has_due(now);
        if !has_work {
            return None;
        }
        let header = PacketHeader {
            term,
            seq: link.out_seq,
            time_ms: now.wire_ms(),
        };
        let mut out = Vec::with_capacity(mtu.min(1500));
        header.write(&mut out);
        if link.reliable.ack_pending {
            out.push(wire::tag::ACK);
            out.extend_from_slice(&link.reliable.next_expected().to_le_bytes());
            link.reliable.ack_pending = false;
        }
        if link.state_ack_pending {
            if let Some((latest, mask)) = link.state_rx {
                out.push(wire::tag::STATE_ACK);
                out.push(latest);
                out.extend_from_slice(&mask.to_le_bytes());
            }
            link.state_ack_pending = false;
        }
        if let Some(t) = link.pong_due.take() {
            out.push(wire::tag::PONG);
            crate::bits::write_varint(&mut out, u64::from(t));
        }
        if link.ping_due {
            link.ping_due = false;
            link.last_ping = Some(now);
            out.push(wire::tag::PING);
            crate::bits::write_varint(&mut out, (now.as_micros() / 1000) & 0xFFFF_FFFF);
        }
        if !link.keyreq_out.is_empty() {
            let ids: Vec<NetId> = link
                .keyreq_out
                .iter()
                .copied()
                .take(wire::MAX_KEYFRAME_REQUEST)
                .collect();
            let need = 2 + ids.len() * 5;
            if out.len() + need <= mtu {
                out.push(wire::tag::KEYFRAME_REQUEST);
                crate::bits::write_varint(&mut out, ids.len() as u64);
                for id in &ids {
                    crate::bits::write_varint(&mut out, u64::from(id.0));
                    link.keyreq_out.remove(id);
                }
            }
        }
        link.reliable.take_due(now, rto, |seq, bytes| {
            if out.len() + reliable_len(bytes) <= mtu {
                write_reliable(&mut out, seq, bytes);
                true
            } else {
                false
            }
        });
        // state entries
        if !link.pending.is_empty() {
            link.pending.sort_by_key(|e| e.id);
            let budget_bits = mtu.saturating_sub(out.len() + 1 + 3 + 3) * 8;
            let mut w = BitWriter::new();
            let mut prev: Option<NetId> = None;
            let mut taken = 0usize;
            let mut oversize = 0u64;
            let mut carried: Vec<EntryRef> = Vec::new();
            let mut count = 0usize;
            let mut class_bits: BTreeMap<u16, usize> = BTreeMap::new();
            for (i, e) in link.pending.iter().enumerate() {
                let Some(o) = self.objects.get(&e.id) else {
                    taken = i + 1;
                    continue;
                };
                let Some(class) = self.cfg.classes.get(usize::from(o.info.class.0)) else {
                    taken = i + 1;
                    continue;
                };
                let layout = EntryLayout {
                    class,
                    particles: o.info.particles,
                };
                let mut body = BitWriter::new();
                e.encode_body(&layout, &mut body);
                let bits = entry_id_bits(prev, e.id) + body.bit_len();
                if w.bit_len() + bits > budget_bits {
                    if w.bit_len() == 0 {
                        oversize += 1;
                        taken = i + 1;
                        continue;
                    }
                    break;
                }
                write_entry_id(&mut w, prev, e.id);
                w.append(&body);
                *class_bits.entry(o.info.class.0).or_default() += bits;
                count += 1;
                // the entry's number: the unacknowledged one with its wire sequence (unique,
                // at most 24 are kept)
                let part = e.part();
                let number = link.send.get(&(e.id, part)).and_then(|sp| {
                    sp.unacked
                        .iter()
                        .rev()
                        .find(|(n, _, _)| wire_seq(*n) == e.seq)
                        .map(|x| x.0)
                });
                if let Some(n) = number {
                    carried.push((e.id, part, n));
                }
                prev = Some(e.id);
                taken = i + 1;
            }
            self.stats.oversize_dropped += oversize;
            if !carried.is_empty() {
                link.inflight.push_back((link.out_seq, carried));
                // a state ack names 8-bit datagram sequences: forget datagrams old enough
                // to alias
                let seq = link.out_seq;
                link.inflight.retain(|(ds, _)| seq.wrapping_sub(*ds) < 128);
                while link.inflight.len() > 64 {
                    link.inflight.pop_front();
                }
            }
            link.pending.drain(..taken);
            if link.pending.is_empty() {
                if let Some(ts) = link.pending_sample.take() {
                    // stamp the datagram with the time its samples describe
                    let at = header.len() - 2;
                    if let Some(b) = out.get_mut(at..at + 2) {
                        b.copy_from_slice(&ts.wire_ms().to_le_bytes());
                    }
                }
            }
            if w.bit_len() > 0 {
                let bytes = w.into_bytes();
                out.push(wire::tag::STATE);
                crate::bits::write_varint(&mut out, count as u64);
                crate::bits::write_varint(&mut out, bytes.len() as u64);
                out.extend_from_slice(&bytes);
                for (c, bits) in class_bits {
                    if let Some(cl) = self.cfg.classes.get(usize::from(c)) {
                        *self
                            .stats
                            .class_up_bytes
                            .entry(cl.name.clone())
                            .or_default() += bits as f64 / 8.0;
                    }
                }
            }
        }
        if out.len() <= header.len() {
            return None;
        }
        link.out_seq = link.out_seq.wrapping_add(1);
        link.last_sent = Some(now);
        debug_assert!(out.len() <= mtu);
        self.stats.on_send(to, out.len(), mtu);
        Some(Transmit { to, payload: out })
    }

    fn rto(&self, to: PeerId) -> Duration {
        let srtt = self
            .links
            .get(&to)
            .and_then(|l| l.srtt)
            .unwrap_or(Duration::from_millis(200));
        (srtt * 5 / 4 + Duration::from_millis(20)).max(self.cfg.min_rto)
    }

    // ---------------------------------------------------------------- timers

    /// Advance timers: heartbeats, timeouts, migration, send ticks, rest sync repeats.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.role == Role::Refused {
            return;
        }
        self.note_time(now);
        if now >= self.next_heartbeat {
            let peers: Vec<PeerId> = self
                .members
                .keys()
                .copied()
                .chain(self.host)
                .filter(|p| *p != self.local)
                .collect();
            let hb = self.cfg.heartbeat_interval;
            for p in peers {
                let l = self.links.entry(p).or_default();
                // Any datagram is a heartbeat: an explicit ping only if the link was quiet,
                // and at least once a second for the RTT estimate.
                let quiet = l.last_sent.is_none_or(|t| now >= t + hb);
                let rtt_due = l
                    .last_ping
                    .is_none_or(|t| now >= t + Duration::from_secs(1));
                if quiet || rtt_due {
                    l.ping_due = true;
                }
            }
            self.next_heartbeat = now + self.cfg.heartbeat_interval;
        }
        self.check_liveness(now);
        self.forget_silent_strangers(now);
        for c in 0..self.next_tick.len() {
            let due = self.next_tick.get(c).is_some_and(|t| now >= *t);
            if due {
                let interval = self
                    .cfg
                    .classes
                    .get(c)
                    .map_or(Duration::from_millis(50), |cl| cl.send.interval());
                if let Some(t) = self.next_tick.get_mut(c) {
                    *t += interval;
                    if *t <= now {
                        *t = now + interval;
                    }
                }
                self.owner_tick(now, c as u16);
            }
        }
    }

    /// Peers we keep link state for that are neither members nor our host.
    fn stranger_count(&self) -> usize {
        self.links
            .keys()
            .filter(|p| !self.members.contains_key(p) && Some(**p) != self.host)
            .count()
    }

    /// Drops the state of non-members silent for `peer_timeout` (a joiner that gave up, a
    /// refused or spoofed sender), with whatever was still queued for them.
    fn forget_silent_strangers(&mut self, now: Instant) {
        let timeout = self.cfg.peer_timeout;
        let gone: Vec<PeerId> = self
            .links
            .iter()
            .filter(|(p, l)| {
                !self.members.contains_key(p)
                    && Some(**p) != self.host
                    && l.last_heard.is_some_and(|h| now >= h + timeout)
            })
            .map(|(p, _)| *p)
            .collect();
        for p in gone {
            self.links.remove(&p);
            self.stats.links.remove(&p);
        }
    }

    /// Sees our own stalls (the application did not drive the session for a while: a frozen
    /// loop, a debugger, a suspended process). Datagrams that arrived meanwhile wait in the
    /// transport, so the silence of the others over that time says nothing: their `last_heard`
    /// moves on by the gap, and nobody is timed out, nor a host elected, for our own pause.
    /// A stall as long as the peer timeout is remembered: the others have timed us out.
    fn note_time(&mut self, now: Instant) {
        let Some(last) = self.last_driven.replace(now) else {
            return;
        };
        let gap = now.saturating_since(last);
        // A session driven only at its deadlines sees gaps of up to a heartbeat interval.
        let pause = (self.cfg.peer_timeout / 2).max(self.cfg.heartbeat_interval * 2);
        if gap < pause || self.role == Role::Joining {
            return;
        }
        // Members and our host only: strangers are forgotten on their own schedule.
        for (p, l) in self.links.iter_mut() {
            if !self.members.contains_key(p) && Some(*p) != self.host {
                continue;
            }
            if let Some(h) = l.last_heard.as_mut() {
                *h = (*h + gap).min(now);
            }
        }
        if gap >= self.cfg.peer_timeout {
            self.stalled_at = Some(now);
        }
    }

    /// Whether we stalled past the peer timeout lately (see [`Session::note_time`]).
    fn stalled_recently(&self, now: Instant) -> bool {
        self.stalled_at
            .is_some_and(|t| now.saturating_since(t) < self.cfg.peer_timeout * 5)
    }

    /// Host: sends a dropped peer its refusal, at most once per heartbeat interval.
    fn tell_dropped(&mut self, now: Instant, to: PeerId) {
        let heartbeat = self.cfg.heartbeat_interval;
        let Some(d) = self.dropped.get_mut(&to) else {
            return;
        };
        if d.told.is_some_and(|t| now.saturating_since(t) < heartbeat) {
            return;
        }
        d.told = Some(now);
        let reason = match d.why {
            DropWhy::TimedOut => format!(
                "dropped from the room: silent for longer than the peer timeout ({} ms); \
                 join again",
                self.cfg.peer_timeout.as_millis()
            ),
            DropWhy::OlderTerm(old) => format!(
                "the room moved on: peer {} became host in term {} while this peer was out of \
                 touch (it still spoke for term {}); join again",
                self.local.0, self.term.0, old.0
            ),
        };
        self.raw_out.push_back(Transmit {
            to,
            payload: encode_refusal(&reason, self.term),
        });
    }

    fn alive(&self, p: PeerId, now: Instant) -> bool {
        if p == self.local {
            return true;
        }
        self.links
            .get(&p)
            .and_then(|l| l.last_heard)
            .is_some_and(|h| now < h + self.cfg.peer_timeout)
    }

    fn check_liveness(&mut self, now: Instant) {
        match self.role {
            Role::Host => {
                let gone: Vec<PeerId> = self
                    .members
                    .keys()
                    .copied()
                    .filter(|p| *p != self.local && !self.alive(*p, now))
                    .collect();
                for p in gone {
                    if self.dropped.len() >= MAX_DEPARTED {
                        self.dropped.clear();
                    }
                    self.dropped.insert(
                        p,
                        Dropped {
                            why: DropWhy::TimedOut,
                            told: None,
                        },
                    );
                    self.host_peer_left(now, p);
                }
            }
            Role::Client => {
                if self.retry_new_hosts(now) {
                    return;
                }
                let Some(host) = self.host else { return };
                if self.alive(host, now) {
                    return;
                }
                // Host silent: the earliest-joined surviving member takes over (no vote).
                let candidate = self
                    .members
                    .iter()
                    .filter(|(p, _)| **p != host && self.alive(**p, now))
                    .min_by_key(|(_, seq)| **seq)
                    .map(|(p, _)| *p);
                if candidate == Some(self.local) {
                    self.become_host(now, host);
                }
            }
            Role::Joining | Role::Refused => {}
        }
    }

    fn become_host(&mut self, now: Instant, old_host: PeerId) {
        let Some(next_term) = self.term.0.checked_add(1) else {
            return; // the term space is used up: nobody can take over
        };
        self.term = Term(next_term);
        self.role = Role::Host;
        self.host = Some(self.local);
        let term = self.term;
        let dead: Vec<PeerId> = self
            .members
            .keys()
            .copied()
            .filter(|p| *p == old_host || !self.alive(*p, now))
            .collect();
        for p in &dead {
            self.members.remove(p);
            if let Some(l) = self.links.get_mut(p) {
                l.pending.clear();
            }
        }
        self.next_join_seq = self
            .members
            .values()
            .max()
            .map_or(1, |m| m.saturating_add(1));
        // ids the old host may have spawned without our hearing of it are reserved for claims
        let lo = self
            .objects
            .keys()
            .max()
            .map_or(1, |m| m.0.saturating_add(1));
        let hi = lo.saturating_add(LOST_ID_WINDOW);
        self.next_net_id = self.next_net_id.max(hi);
        self.lost_ids = Some((lo, hi));
        self.resync_until = Some(now + self.cfg.peer_timeout * 2);
        let me = self.local;
        let mut changed = Vec::new();
        for o in self.objects.values_mut() {
            if !self.members.contains_key(&o.info.owner) {
                o.info.owner = me;
                o.info.epoch = o.info.epoch.bumped(term);
                o.info.held = false;
                if o.published.is_none() {
                    // we take over from our replica
                    o.published = None;
                }
                changed.push((o.info.id, o.info.epoch));
            }
        }
        for (id, epoch) in changed {
            self.adopt_replica_as_published(id);
            self.events.push_back(Event::AuthorityChanged {
                id,
                owner: me,
                epoch,
            });
        }
        let members: Vec<(PeerId, u32)> = self.members.iter().map(|(p, s)| (*p, *s)).collect();
        let others: Vec<PeerId> = self.members.keys().copied().filter(|p| *p != me).collect();
        for p in others {
            if let Some(l) = self.links.get_mut(&p) {
                l.send.clear();
                l.spawn_pending.clear();
            }
            self.send_control(
                now,
                p,
                &Control::NewHost {
                    term,
                    host: me,
                    members: members.clone(),
                },
            );
            self.send_snapshot(now, p);
        }
        self.events.push_back(Event::HostChanged { host: me, term });
        // our own spawn requests the old host never answered: we create them now
        let pending = std::mem::take(&mut self.pending_spawns);
        for (request, (class, st)) in pending {
            let _ = self.host_spawn_own(now, class, &st, request);
        }
        for p in dead {
            if p != me {
                self.events.push_back(Event::PeerLeft(p));
            }
        }
    }

    fn adopt_replica_as_published(&mut self, id: NetId) {
        let Some(o) = self.objects.get(&id) else {
            return;
        };
        let Some(class) = self.class(o.info.class) else {
            return;
        };
        let st = self.compose(o, class);
        if let Some(o) = self.objects.get_mut(&id) {
            if o.published.is_none() {
                o.published = Some(st);
            }
        }
    }

    fn send_snapshot(&mut self, now: Instant, to: PeerId) {
        let infos: Vec<SpawnInfo> = self
            .objects
            .values()
            .map(|o| {
                let mut i = o.info.clone();
                if let Some(class) = self.class(o.info.class) {
                    let st = self.compose(o, class);
                    i.pos = st.pos.to_array();
                    i.rot = st.rot.to_array();
                }
                i
            })
            .collect();
        for info in infos {
            let id = info.id;
            let seq = self.send_control(now, to, &Control::Spawn(info));
            if let Some(l) = self.links.get_mut(&to) {
                l.spawn_pending.insert(id, seq);
            }
        }
    }

    /// One send tick of class `c`: replicate the objects we own.
    fn owner_tick(&mut self, now: Instant, c: u16) {
        let Some(class) = self.cfg.classes.get(usize::from(c)) else {
            return;
        };
        let rest_after = class.send.rest_after;
        let of_class: Vec<(NetId, PeerId)> = self
            .objects
            .values()
            .filter(|o| o.info.class.0 == c)
            .map(|o| (o.info.id, o.info.owner))
            .collect();
        let members: Vec<PeerId> = self
            .members
            .keys()
            .copied()
            .filter(|p| *p != self.local)
            .collect();
        for (id, owner) in of_class {
            let mine = owner == self.local;
            let targets: Vec<PeerId> = match (self.role, mine) {
                (Role::Host, true) => members.clone(),
                // relay tick: repeat what a client's peers have not acknowledged yet
                (Role::Host, false) => members.iter().copied().filter(|p| *p != owner).collect(),
                (Role::Client, true) => self.host.into_iter().collect(),
                _ => Vec::new(),
            };
            if mine {
                if let Some(o) = self.objects.get_mut(&id) {
                    // rest sync: an object unchanged for `rest_after` drops its thresholds,
                    // so its exact pose goes out (and is repeated until acknowledged)
                    if !o.rest && now.saturating_since(o.last_change) >= rest_after {
                        o.rest = true;
                    }
                }
            }
            let sampled = self.objects.get(&id).map_or(now, |o| o.published_at);
            for &p in &targets {
                let entries = self.build_entries(now, p, id, mine, false);
                if let Some(l) = self.links.get_mut(&p) {
                    if mine && !entries.is_empty() {
                        l.pending_sample =
                            Some(l.pending_sample.map_or(sampled, |t| t.max(sampled)));
                    }
                    l.pending.extend(entries);
                }
            }
        }
    }

    /// Entries that bring link `to`'s view of `id` up to date.
    ///
    /// Deltas are relative to the newest state the peer acknowledged (so a lost datagram
    /// costs nothing but itself); everything differing from that base by more than the
    /// threshold goes out until acknowledged. `owner_thresholds`: apply the class's send
    /// thresholds (we own it and it moves); otherwise send any grid change (relay, rest sync).
    fn build_entries(
        &mut self,
        now: Instant,
        to: PeerId,
        id: NetId,
        owner_thresholds: bool,
        force_key: bool,
    ) -> Vec<StateEntry> {
        let mut out = Vec::new();
        let Some(o) = self.objects.get(&id) else {
            return out;
        };
        let Some(class) = self.cfg.classes.get(usize::from(o.info.class.0)) else {
            return out;
        };
        let Some(link) = self.links.get_mut(&to) else {
            return out;
        };
        if link.spawn_pending.contains_key(&id) {
            return out; // the peer does not know the object yet
        }
        let srtt = link.srtt.unwrap_or(Duration::from_millis(200));
        // an unacknowledged entry is repeated only once its ack is overdue
        let ack_wait = srtt * 3 / 2 + Duration::from_millis(30);
        let use_thr = owner_thresholds && !o.rest;
        let interval = class.send.interval();
        let max_stale = class
            .send
            .stale_after_intervals
            .map(|k| interval.mul_f32(k.clamp(0.0, 1e4)));
        // half an interval of slack so the tick phase does not alias with the bound
        let half = interval / 2;
        // a change below the threshold is still sent once its last send is this old
        let stale = |at: Instant| use_thr && max_stale.is_some_and(|m| now + half >= at + m);
        let piggy = class.send.piggyback_fraction.clamp(0.0, 1.0);
        let (pos_thr, rot_thr, part_thr) = if use_thr {
            (
                class.send.position_threshold_m / class.position_resolution_m,
                class.send.rotation_threshold_rad,
                class.send.particle_threshold_m / class.particle_resolution_m,
            )
        } else {
            (0.0, 0.0, 0.0)
        };
        let key_interval = class.send.keyframe_interval;
        let rest = o.rest;
        let tag = o.info.epoch.tag();
        let bits = class.rot_bits();
        // the newest acknowledged state, unless too old for the peer's history ring
        let base_of = |sp: Option<&SendPart>| -> Option<(u8, PartQ)> {
            let sp = sp?;
            let (n, st) = sp.acked.as_ref()?;
            let age = sp.seq.saturating_sub(*n);
            (age < u64::from(ENTRY_SEQ_MOD - 8)).then(|| (wire_seq(*n), st.clone()))
        };
        let key_due = |sp: Option<&SendPart>| {
            !rest && key_interval.is_some_and(|k| sp.is_some_and(|sp| now >= sp.last_key_at + k))
        };
        // particle chunks (thesis 5.4.2), skipped in center-only mode (5.4.1)
        if class.soft_body_mode == SoftBodyMode::Particles && !o.particles.is_empty() {
            let per = class.chunk_len();
            for (ci, chunk) in o.particles.chunks(per).enumerate() {
                let part = ci as u32 + 1;
                let sp = link.send.get(&(id, part));
                let base = base_of(sp);
                let key = force_key || base.is_none() || key_due(sp);
                let planned = match (&base, key) {
                    (Some((b, PartQ::Chunk(bv))), false) if bv.len() == chunk.len() => {
                        let sent_at = sp.map(|s| s.sent_at.as_slice()).unwrap_or_default();
                        let dist: Vec<f32> = chunk
                            .iter()
                            .zip(bv.iter())
                            .map(|(c, p)| VecQuantizer::step_distance(*c, *p))
                            .collect();
                        let over = |i: usize| {
                            dist.get(i).is_some_and(|d| *d > part_thr)
                                || sent_at.get(i).is_some_and(|t| stale(*t))
                        };
                        let differs = |i: usize| chunk.get(i) != bv.get(i);
                        let triggered = (0..chunk.len()).any(|i| differs(i) && over(i));
                        // when the chunk goes out anyway, particles past a fraction of the
                        // threshold ride along (fewer particles left stale at the threshold)
                        let list: Vec<(u32, [i32; 3])> = (0..chunk.len())
                            .filter(|&i| {
                                differs(i)
                                    && (over(i)
                                        || (triggered
                                            && dist.get(i).is_some_and(|d| *d > part_thr * piggy)))
                            })
                            .filter_map(|i| {
                                let (c, p) = (chunk.get(i)?, bv.get(i)?);
                                Some((i as u32, [0, 1, 2].map(|k| c[k] as i32 - p[k] as i32)))
                            })
                            .collect();
                        if list.is_empty() {
                            None
                        } else {
                            let mut after = bv.clone();
                            for (i, _) in &list {
                                if let (Some(d), Some(c)) =
                                    (after.get_mut(*i as usize), chunk.get(*i as usize))
                                {
                                    *d = *c;
                                }
                            }
                            let fields: Vec<usize> =
                                list.iter().map(|(i, _)| *i as usize).collect();
                            Some((
                                false,
                                *b,
                                PartQ::Chunk(after),
                                ChunkEnc::Delta(list),
                                fields,
                            ))
                        }
                    }
                    _ => Some((
                        true,
                        0,
                        PartQ::Chunk(chunk.to_vec()),
                        ChunkEnc::Abs(chunk.to_vec()),
                        (0..chunk.len()).collect(),
                    )),
                };
                let Some((key, base_seq, after, values, fields)) = planned else {
                    continue;
                };
                let Some(seq) = emit(
                    link,
                    (id, part),
                    after,
                    key,
                    force_key,
                    now,
                    ack_wait,
                    &fields,
                    chunk.len(),
                ) else {
                    continue;
                };
                out.push(StateEntry {
                    id,
                    epoch_tag: tag,
                    seq,
                    key,
                    base: base_seq,
                    rest,
                    body: PartBody::Chunk {
                        chunk: ci as u32,
                        values,
                    },
                });
            }
        }
        // transform part (position and rotation sent separately, thesis 5.3); when particles
        // went out, any center change rides along: particle offsets are relative to it
        let chunks_sent = !out.is_empty();
        let (pos_thr, rot_thr) = if chunks_sent {
            (0.0, 0.0)
        } else {
            (pos_thr, rot_thr)
        };
        let sp = link.send.get(&(id, 0));
        let base = base_of(sp);
        let key = force_key || base.is_none() || key_due(sp);
        let planned = match (&base, key) {
            (Some((b, PartQ::Transform { pos, rot })), false) => {
                let sent_at = sp.map(|s| s.sent_at.as_slice()).unwrap_or_default();
                let dpos = VecQuantizer::step_distance(*pos, o.pos);
                let ang = angle_between(dequantize_quat(*rot, bits), dequantize_quat(o.rot, bits));
                let pos_over = dpos > pos_thr || sent_at.first().is_some_and(|t| stale(*t));
                let rot_over = ang > rot_thr || sent_at.get(1).is_some_and(|t| stale(*t));
                // once an entry is paid for, smaller changes of the other field ride along
                let send_pos = *pos != o.pos && (pos_over || (rot_over && dpos > pos_thr * piggy));
                let send_rot = *rot != o.rot && (rot_over || (pos_over && ang > rot_thr * piggy));
                if send_pos || send_rot {
                    let after = PartQ::Transform {
                        pos: if send_pos { o.pos } else { *pos },
                        rot: if send_rot { o.rot } else { *rot },
                    };
                    let body = PartBody::Transform {
                        pos: send_pos.then(|| {
                            PosEnc::Delta([0, 1, 2].map(|i| o.pos[i] as i32 - pos[i] as i32))
                        }),
                        rot: send_rot.then_some(o.rot),
                    };
                    let mut fields = Vec::new();
                    if send_pos {
                        fields.push(0);
                    }
                    if send_rot {
                        fields.push(1);
                    }
                    Some((false, *b, after, body, fields))
                } else {
                    None
                }
            }
            _ => Some((
                true,
                0,
                PartQ::Transform {
                    pos: o.pos,
                    rot: o.rot,
                },
                PartBody::Transform {
                    pos: Some(PosEnc::Abs(o.pos)),
                    rot: Some(o.rot),
                },
                vec![0, 1],
            )),
        };
        if let Some((key, base_seq, after, body, fields)) = planned {
            if let Some(seq) = emit(
                link,
                (id, 0),
                after,
                key,
                force_key,
                now,
                ack_wait,
                &fields,
                2,
            ) {
                out.insert(
                    0,
                    StateEntry {
                        id,
                        epoch_tag: tag,
                        seq,
                        key,
                        base: base_seq,
                        rest,
                        body,
                    },
                );
            }
        }
        out
    }

    // ---------------------------------------------------------------- input

    /// Feed a datagram received from `from`.
    pub fn handle_packet(&mut self, now: Instant, from: PeerId, bytes: &[u8]) {
        self.note_time(now);
        if self.departed.contains(&from) {
            return;
        }
        if self.role == Role::Host && self.dropped.contains_key(&from) {
            // A fresh session of the dropped peer (term 0: it joins again) is heard out as any
            // joiner, with fresh link state (its sequences start over); the rest is answered
            // with the refusal.
            let rejoining = decode_packet(bytes).is_ok_and(|(h, _)| h.term.0 == 0);
            if !rejoining {
                self.tell_dropped(now, from);
                return;
            }
            self.dropped.remove(&from);
            self.links.remove(&from);
            self.stats.links.remove(&from);
        }
        // State is kept for members and at most MAX_STRANGERS others (joiners, peers we have
        // not heard of yet): a flood of datagrams from made-up ids costs no memory.
        let known = self.links.contains_key(&from)
            || self.members.contains_key(&from)
            || Some(from) == self.host;
        if known {
            self.stats.on_recv(from, bytes.len());
        } else {
            // Per-peer statistics start once the sender has link state (below).
            self.stats.down.add(bytes.len());
            if self.stranger_count() >= MAX_STRANGERS {
                self.stats.dropped_strangers += 1;
                return;
            }
        }
        if let Some(refusal) = decode_refusal(bytes) {
            // A joiner refused, or a member the host dropped (it stalled past the timeout).
            let from_our_host =
                matches!(self.role, Role::Joining | Role::Client) && Some(from) == self.host;
            // Or the host of a newer term: the room elected it while this peer was silent
            // (a host or member that stalled past the peer timeout, or was cut off that long).
            // Only after a stall of our own: a peer cut off from the room elects itself host of
            // a newer term too, and must not depose a host that never stopped.
            let newer = matches!(self.role, Role::Host | Role::Client)
                && refusal.term.is_some_and(|t| t > self.term)
                && self.stalled_recently(now);
            if from_our_host || newer {
                let was_in = matches!(self.role, Role::Host | Role::Client);
                self.role = Role::Refused;
                self.events.push_back(if was_in {
                    Event::Dropped {
                        host: from,
                        reason: refusal.reason,
                    }
                } else {
                    Event::Refused {
                        reason: refusal.reason,
                    }
                });
            }
            return;
        }
        let (header, sections) = match decode_packet(bytes) {
            Ok(x) => x,
            Err(NetError::VersionMismatch { ours, theirs }) => {
                self.stats.decode_errors += 1;
                if self.role == Role::Host {
                    let reason = format!(
                        "protocol version mismatch: host speaks {ours}, you speak {theirs}"
                    );
                    self.raw_out.push_back(Transmit {
                        to: from,
                        payload: encode_refusal(&reason, self.term),
                    });
                }
                return;
            }
            Err(_) => {
                self.stats.decode_errors += 1;
                return;
            }
        };
        let is_member = self.members.contains_key(&from) || Some(from) == self.host;
        // A non-member speaking for an older term of this room: it was out of touch while the
        // room elected this host (a stalled old host, or a member the election left out as
        // dead). Its objects have new owners; it is told, and ignored until it joins again.
        if !is_member && self.role == Role::Host && header.term.0 != 0 && header.term < self.term {
            if self.dropped.len() >= MAX_DEPARTED {
                self.dropped.clear();
            }
            self.dropped.insert(
                from,
                Dropped {
                    why: DropWhy::OlderTerm(header.term),
                    told: None,
                },
            );
            self.tell_dropped(now, from);
            return;
        }
        // term 0: a joiner's datagrams before it learned the term
        if is_member && header.term < self.term && header.term.0 != 0 {
            self.stats.dropped_old_term += 1;
            return;
        }
        let link = self.links.entry(from).or_default();
        link.last_heard = Some(now);
        // loss statistics from the datagram sequence
        let ls = self.stats.links.entry(from).or_default();
        if !known {
            ls.down.add(bytes.len());
        }
        // the newest datagram from the peer so far: its entries are newer than any received
        // before (entry sequences alone cannot tell after a gap of 16 or more)
        let mut fresh = true;
        match link.in_seq {
            Some(prev) => {
                let gap = header.seq.wrapping_sub(prev);
                // 8-bit sequences: after 128 or more lost datagrams every new one looks late;
                // once nothing has advanced the sequence for a while, take it as the newest
                let stuck = link
                    .in_seq_at
                    .is_some_and(|t| now >= t + IN_SEQ_RESYNC_AFTER);
                if (1..128).contains(&gap) {
                    ls.expected += u64::from(gap);
                    ls.lost += u64::from(gap - 1);
                    link.in_seq = Some(header.seq);
                    link.in_seq_at = Some(now);
                } else if gap >= 128 && stuck {
                    ls.expected += 1;
                    link.in_seq = Some(header.seq);
                    link.in_seq_at = Some(now);
                } else {
                    fresh = false;
                    if gap >= 128 && ls.lost > 0 {
                        ls.lost -= 1; // a late (reordered) datagram
                    }
                }
            }
            None => {
                ls.expected += 1;
                link.in_seq = Some(header.seq);
                link.in_seq_at = Some(now);
            }
        }
        // State entries carry 5-bit sequences: those of a datagram this far behind the newest
        // from the peer could alias a newer entry's slot in the base ring. Such a datagram's
        // state is neither applied nor acknowledged (the sender repeats what is unacknowledged).
        let too_late = link.in_seq.is_some_and(|newest| {
            (MAX_STATE_LATENESS..128).contains(&newest.wrapping_sub(header.seq))
        });
        // clock mapping for interpolation timing
        let c = &mut link.clock;
        let full = match c.last_full_ms {
            Some(last) => last + i64::from(header.time_ms.wrapping_sub(c.last_ms) as i16),
            None => i64::from(header.time_ms),
        };
        if c.last_full_ms.is_none_or(|l| full > l) {
            c.last_full_ms = Some(full);
            c.last_ms = header.time_ms;
        }
        let offset = now.as_micros() as i64 - full * 1000;
        let min = match c.min_offset_us {
            Some(m) => (m + 20).min(offset),
            None => offset,
        };
        c.min_offset_us = Some(min);
        c.jitter_us = 0.9 * c.jitter_us + 0.1 * (offset - min) as f64;
        let sample_time = Instant::from_micros((full * 1000 + min).max(0) as u64);

        let mut states = Vec::new();
        let mut controls = Vec::new();
        for s in sections {
            match s {
                Section::Ack { next_expected } => {
                    if let Some(l) = self.links.get_mut(&from) {
                        l.reliable.on_ack(next_expected);
                        let acked: Vec<NetId> = l
                            .spawn_pending
                            .iter()
                            .filter(|(_, seq)| l.reliable.is_acked(**seq))
                            .map(|(id, _)| *id)
                            .collect();
                        for id in &acked {
                            l.spawn_pending.remove(id);
                        }
                        // the peer now knows these objects: give it their current state at
                        // once (a resting object would otherwise never be sent again)
                        if self.role == Role::Host {
                            for id in acked {
                                if self.owner(id) != Some(from) {
                                    let e = self.build_entries(now, from, id, false, true);
                                    if let Some(l) = self.links.get_mut(&from) {
                                        l.pending.extend(e);
                                    }
                                }
                            }
                        }
                    }
                }
                Section::Reliable { seq, bytes } => {
                    if let Some(l) = self.links.get_mut(&from) {
                        for m in l.reliable.on_receive(seq, bytes) {
                            match Control::decode(&m) {
                                Ok(c) => controls.push(c),
                                Err(_) => self.stats.decode_errors += 1,
                            }
                        }
                    }
                }
                Section::Ping { time_ms } => {
                    if let Some(l) = self.links.get_mut(&from) {
                        l.pong_due = Some(time_ms);
                    }
                }
                Section::Pong { time_ms } => {
                    let now_ms = (now.as_micros() / 1000) & 0xFFFF_FFFF;
                    let rtt_ms = (now_ms as u32).wrapping_sub(time_ms);
                    if rtt_ms < 60_000 {
                        let rtt = Duration::from_millis(u64::from(rtt_ms));
                        if let Some(l) = self.links.get_mut(&from) {
                            l.srtt = Some(match l.srtt {
                                Some(s) => (s * 7 + rtt) / 8,
                                None => rtt,
                            });
                            self.stats.links.entry(from).or_default().rtt = l.srtt;
                        }
                    }
                }
                Section::KeyframeRequest { ids } => {
                    for id in ids {
                        let sends = self
                            .objects
                            .get(&id)
                            .is_some_and(|o| o.info.owner == self.local || self.role == Role::Host);
                        if sends {
                            let e = self.build_entries(now, from, id, false, true);
                            if let Some(l) = self.links.get_mut(&from) {
                                l.pending.extend(e);
                            }
                        }
                    }
                }
                Section::State { count, bits } => states.push((count, bits)),
                Section::StateAck { latest, mask } => self.on_state_ack(from, latest, mask),
            }
        }
        for c in controls {
            // after a NewHost we have not adopted yet, its sender's messages wait for it
            if !matches!(c, Control::NewHost { .. }) {
                if let Some(p) = self.pending_new_hosts.get_mut(&from) {
                    if p.later.len() < MAX_DEFERRED_CONTROLS {
                        p.later.push(c);
                    } else {
                        self.pending_new_hosts.remove(&from);
                        self.stats.refused_controls += 1;
                    }
                    continue;
                }
            }
            self.handle_control(now, from, c);
        }
        if !self.members.contains_key(&from) && Some(from) != self.host {
            return; // state only from members
        }
        let mut touched = BTreeSet::new();
        let carried_state = !states.is_empty();
        let mut complete = !too_late;
        for (count, bits) in states {
            if too_late {
                break;
            }
            let cfg = &self.cfg;
            let objects = &self.objects;
            let parsed = decode_state_block(count, bits, |id| {
                let o = objects.get(&id)?;
                Some(EntryLayout {
                    class: cfg.classes.get(usize::from(o.info.class.0))?,
                    particles: o.info.particles,
                })
            });
            let entries = match parsed {
                Ok((e, all)) => {
                    complete &= all;
                    e
                }
                Err(_) => {
                    self.stats.decode_errors += 1;
                    complete = false;
                    continue;
                }
            };
            for e in entries {
                // per-class down bytes: the entry's encoded size (re-encoded, bits / 8)
                if let Some(o) = self.objects.get(&e.id) {
                    if let Some(class) = self.cfg.classes.get(usize::from(o.info.class.0)) {
                        let mut w = BitWriter::new();
                        let layout = EntryLayout {
                            class,
                            particles: o.info.particles,
                        };
                        e.encode_body(&layout, &mut w);
                        *self
                            .stats
                            .class_down_bytes
                            .entry(class.name.clone())
                            .or_default() += w.bit_len() as f64 / 8.0;
                    }
                }
                self.apply_entry(now, from, e, fresh, &mut touched);
            }
        }
        // acknowledge the datagram (its entries become delta bases at the sender) unless
        // we could not read all of it
        if carried_state && complete {
            if let Some(l) = self.links.get_mut(&from) {
                let s = header.seq;
                l.state_rx = Some(match l.state_rx {
                    None => (s, 0),
                    Some((latest, mask)) => {
                        let d = s.wrapping_sub(latest);
                        if d == 0 {
                            (latest, mask)
                        } else if d < 128 {
                            let shifted = if d >= 32 {
                                0
                            } else {
                                (mask << d) | (1 << (d - 1))
                            };
                            let shifted = if d == 32 { 1 << 31 } else { shifted };
                            (s, shifted)
                        } else {
                            let back = latest.wrapping_sub(s);
                            let bit = if (1..=32).contains(&back) {
                                1u32 << (back - 1)
                            } else {
                                0
                            };
                            (latest, mask | bit)
                        }
                    }
                });
                l.state_ack_pending = true;
            }
        }
        for id in touched {
            self.after_update(now, from, id, sample_time);
        }
    }

    fn on_state_ack(&mut self, from: PeerId, latest: u8, mask: u32) {
        let Some(l) = self.links.get_mut(&from) else {
            return;
        };
        let acked = |s: u8| {
            let back = latest.wrapping_sub(s);
            back == 0 || ((1..=32).contains(&back) && mask & (1 << (back - 1)) != 0)
        };
        let mut done = Vec::new();
        l.inflight.retain(|(ds, entries)| {
            if acked(*ds) {
                done.extend(entries.iter().copied());
                false
            } else {
                true
            }
        });
        for (id, part, eseq) in done {
            let Some(sp) = l.send.get_mut(&(id, part)) else {
                continue;
            };
            let Some((q, st, _)) = sp.unacked.iter().find(|(q, _, _)| *q == eseq).cloned() else {
                continue;
            };
            if sp.acked.as_ref().is_none_or(|(a, _)| q > *a) {
                sp.acked = Some((q, st));
                sp.unacked.retain(|(x, _, _)| *x > q);
            }
        }
    }

    /// An entry we decoded but did not apply. Its datagram is still acknowledged, so the
    /// sender takes the entry as a delta base: forget whatever the ring holds in its slot (a
    /// state 32 entries older), so that a delta naming it breaks the chain and asks for a
    /// keyframe instead of silently applying to the wrong base.
    fn forget_entry(&mut self, from: PeerId, id: NetId, part: u32, seq: u8) {
        if let Some(rp) = self
            .links
            .get_mut(&from)
            .and_then(|l| l.recv.get_mut(&(id, part)))
        {
            if let Some(x) = rp.ring.get_mut(usize::from(seq % ENTRY_SEQ_MOD)) {
                *x = None;
            }
        }
    }

    fn apply_entry(
        &mut self,
        now: Instant,
        from: PeerId,
        e: StateEntry,
        fresh: bool,
        touched: &mut BTreeSet<NetId>,
    ) {
        let (id, part, seq) = (e.id, e.part(), e.seq);
        if !self.try_apply_entry(now, from, e, fresh, touched) {
            self.forget_entry(from, id, part, seq);
        }
    }

    /// Applies one entry; false if it was dropped (true: applied or kept as a delta base).
    fn try_apply_entry(
        &mut self,
        now: Instant,
        from: PeerId,
        e: StateEntry,
        fresh: bool,
        touched: &mut BTreeSet<NetId>,
    ) -> bool {
        let Some(o) = self.objects.get(&e.id) else {
            return false;
        };
        if o.info.owner == self.local {
            self.stats.dropped_non_owner += 1;
            return false;
        }
        let sender_ok = if self.role == Role::Host {
            from == o.info.owner
        } else {
            Some(from) == self.host
        };
        if !sender_ok {
            self.stats.dropped_non_owner += 1;
            return false;
        }
        if e.epoch_tag != o.info.epoch.tag() {
            self.stats.dropped_stale_epoch += 1;
            return false;
        }
        let Some(class) = self.cfg.classes.get(usize::from(o.info.class.0)) else {
            return false;
        };
        let pq = class.position_quantizer();
        let part = e.part();
        let Some(link) = self.links.get_mut(&from) else {
            return false;
        };
        let rp = link.recv.entry((e.id, part)).or_insert_with(|| RecvPart {
            ring: vec![None; usize::from(ENTRY_SEQ_MOD)],
            latest: None,
        });
        let slot = |s: u8| usize::from(s % ENTRY_SEQ_MOD);
        let state = if e.key {
            match &e.body {
                PartBody::Transform {
                    pos: Some(PosEnc::Abs(p)),
                    rot: Some(r),
                } => Some(PartQ::Transform {
                    pos: pq.clamp(p.map(i64::from)),
                    rot: *r,
                }),
                PartBody::Chunk {
                    values: ChunkEnc::Abs(v),
                    ..
                } => Some(PartQ::Chunk(v.clone())),
                _ => None,
            }
        } else {
            let base = rp
                .ring
                .get(slot(e.base))
                .and_then(|x| x.as_ref())
                .filter(|(s, _)| *s == e.base)
                .map(|(_, st)| st.clone());
            match (&e.body, base) {
                (PartBody::Transform { pos, rot }, Some(PartQ::Transform { pos: bp, rot: br })) => {
                    let np = match pos {
                        Some(PosEnc::Delta(d)) => {
                            pq.clamp([0, 1, 2].map(|i| i64::from(bp[i]) + i64::from(d[i])))
                        }
                        Some(PosEnc::Abs(p)) => pq.clamp(p.map(i64::from)),
                        None => bp,
                    };
                    Some(PartQ::Transform {
                        pos: np,
                        rot: rot.unwrap_or(br),
                    })
                }
                (
                    PartBody::Chunk {
                        values: ChunkEnc::Delta(list),
                        ..
                    },
                    Some(PartQ::Chunk(mut v)),
                ) => {
                    let q = class.particle_quantizer();
                    for (i, d) in list {
                        if let Some(x) = v.get_mut(*i as usize) {
                            *x = q.clamp([0, 1, 2].map(|k| i64::from(x[k]) + i64::from(d[k])));
                        }
                    }
                    Some(PartQ::Chunk(v))
                }
                (_, None) => {
                    // the base is unknown (history reset): ask for a keyframe, rate-limited
                    self.stats.chain_breaks += 1;
                    let limit = link
                        .srtt
                        .unwrap_or(Duration::from_millis(100))
                        .max(Duration::from_millis(50));
                    if link
                        .keyreq_sent
                        .get(&e.id)
                        .is_none_or(|t| now >= *t + limit)
                    {
                        link.keyreq_sent.insert(e.id, now);
                        link.keyreq_out.insert(e.id);
                    }
                    return false;
                }
                _ => None,
            }
        };
        let Some(state) = state else {
            return false;
        };
        if let Some(x) = rp.ring.get_mut(slot(e.seq)) {
            *x = Some((e.seq, state.clone()));
        }
        if !fresh && rp.latest.is_some_and(|l| !seq_newer(e.seq, l)) {
            return true; // older than what we show (reordered); kept only as a base
        }
        rp.latest = Some(e.seq);
        let chunk_len = class.chunk_len();
        let Some(o) = self.objects.get_mut(&e.id) else {
            return false;
        };
        match state {
            PartQ::Transform { pos, rot } => {
                o.pos = pos;
                o.rot = rot;
            }
            PartQ::Chunk(v) => {
                let start = (part as usize - 1) * chunk_len;
                for (i, x) in v.into_iter().enumerate() {
                    if let Some(d) = o.particles.get_mut(start + i) {
                        *d = x;
                    }
                }
            }
        }
        if o.rest != e.rest {
            o.rest = e.rest;
            if e.rest {
                o.last_change = now;
            }
        }
        o.source = Some(from);
        touched.insert(e.id);
        true
    }

    fn after_update(&mut self, now: Instant, from: PeerId, id: NetId, sample_time: Instant) {
        let interp = self.interp;
        let Some(o) = self.objects.get(&id) else {
            return;
        };
        let Some(class) = self.class(o.info.class) else {
            return;
        };
        let pos = class.position_quantizer().dequantize(o.pos);
        let rot = dequantize_quat(o.rot, class.rot_bits());
        let pq = class.particle_quantizer();
        let offsets = o.particles.iter().map(|q| pq.dequantize(*q)).collect();
        let rest = o.rest;
        if let Some(o) = self.objects.get_mut(&id) {
            o.buffer.push(
                Snapshot {
                    time: sample_time,
                    pos,
                    rot,
                    offsets,
                    rest,
                },
                &interp,
            );
        }
        if self.role == Role::Host {
            // relay (thesis Figure 5.2): forward to every other member
            let targets: Vec<PeerId> = self
                .members
                .keys()
                .copied()
                .filter(|p| *p != self.local && *p != from)
                .collect();
            for p in targets {
                let entries = self.build_entries(now, p, id, false, false);
                if !entries.is_empty() {
                    self.last_relay_at = Some(now);
                }
                if let Some(l) = self.links.get_mut(&p) {
                    l.pending.extend(entries);
                }
            }
        }
    }

    // ---------------------------------------------------------------- control plane

    fn send_control(&mut self, now: Instant, to: PeerId, msg: &Control) -> u16 {
        let bytes = msg.encode();
        self.links.entry(to).or_default().reliable.push(now, bytes)
    }

    fn broadcast(&mut self, now: Instant, msg: &Control, except: Option<PeerId>) {
        let peers: Vec<PeerId> = self
            .members
            .keys()
            .copied()
            .filter(|p| *p != self.local && Some(*p) != except)
            .collect();
        for p in peers {
            let seq = self.send_control(now, p, msg);
            if let Control::Spawn(info) = msg {
                if let Some(l) = self.links.get_mut(&p) {
                    l.spawn_pending.insert(info.id, seq);
                }
            }
        }
    }

    fn handle_control(&mut self, now: Instant, from: PeerId, msg: Control) {
        let from_host = Some(from) == self.host && self.role != Role::Host;
        match msg {
            Control::Hello {
                protocol,
                config_digest,
            } => self.on_hello(now, from, protocol, config_digest),
            Control::Welcome {
                term,
                host,
                join_seq: _,
                members,
            } if self.role == Role::Joining && from == host => {
                self.role = Role::Client;
                self.term = term;
                self.host = Some(host);
                self.members = members.into_iter().collect();
                self.events.push_back(Event::Joined { host, term });
            }
            Control::Refused { reason } if self.role == Role::Joining => {
                self.role = Role::Refused;
                self.events.push_back(Event::Refused { reason });
            }
            Control::Redirect { host } if self.role == Role::Joining && from != host => {
                self.join_via(now, host);
            }
            Control::PeerJoined { peer, join_seq } if from_host => {
                self.members.insert(peer, join_seq);
                self.links.entry(peer).or_default();
                self.events.push_back(Event::PeerJoined(peer));
            }
            Control::Leave
                if from != self.local
                    && (self.members.contains_key(&from) || Some(from) == self.host) =>
            {
                if self.departed.len() >= MAX_DEPARTED {
                    self.departed.clear();
                }
                self.departed.insert(from);
                if let Some(l) = self.links.get_mut(&from) {
                    l.last_heard = None;
                }
                // Gone now, not after the timeout: the host drops the member (authority
                // returns); if the host left, the earliest joiner takes over.
                self.check_liveness(now);
            }
            Control::PeerLeft { peer } if from_host => {
                self.members.remove(&peer);
                // Its sequences die with its membership: should it join again, it does so
                // with a fresh session, and both ends start over.
                self.links.remove(&peer);
                self.stats.links.remove(&peer);
                self.events.push_back(Event::PeerLeft(peer));
            }
            Control::Spawn(info) if from_host => self.on_spawn_from_host(now, info),
            Control::Despawn { id } if from_host && self.objects.remove(&id).is_some() => {
                self.events.push_back(Event::Despawned(id));
            }
            Control::OwnerChanged {
                id,
                owner,
                epoch,
                held,
            } if from_host => self.set_owner(id, owner, epoch, held),
            Control::AuthorityDenied { id, reason } if from_host => {
                self.events.push_back(Event::AuthorityDenied { id, reason });
            }
            Control::AuthorityAsk { id, by } if from_host => {
                self.events.push_back(Event::AuthorityAsked { id, by });
            }
            Control::NewHost {
                term,
                host,
                members,
            } if host == from && self.role == Role::Client => {
                self.on_new_host(now, from, term, members);
            }
            // ---- host side
            Control::SpawnRequest {
                request,
                class,
                particles,
                pos,
                rot,
            } if self.is_member_client(from) => {
                let Some(c) = self.class(class) else { return };
                let policy = c.authority;
                // a request repeated after a migration whose object we already have
                let existing = self
                    .objects
                    .values()
                    .find(|o| o.info.owner == from && o.info.request == Some(request))
                    .map(|o| o.info.clone());
                if let Some(info) = existing {
                    let id = info.id;
                    let seq = self.send_control(now, from, &Control::Spawn(info));
                    if let Some(l) = self.links.get_mut(&from) {
                        l.spawn_pending.insert(id, seq);
                    }
                    return;
                }
                if !self.may_create_for(from, particles) {
                    self.stats.refused_controls += 1;
                    return;
                }
                let Some(id) = self.alloc_id() else {
                    self.stats.refused_controls += 1;
                    return;
                };
                let info = SpawnInfo {
                    id,
                    class,
                    owner: from,
                    epoch: AuthorityEpoch {
                        term: self.term.0,
                        grant: 0,
                    },
                    held: true,
                    policy,
                    particles,
                    pos,
                    rot,
                    request: Some(request),
                };
                self.insert_object(now, info.clone(), None);
                self.broadcast(now, &Control::Spawn(info.clone()), Some(from));
                let seq = self.send_control(now, from, &Control::Spawn(info));
                if let Some(l) = self.links.get_mut(&from) {
                    l.spawn_pending.insert(id, seq);
                }
                if let Some(o) = self.objects.get_mut(&id) {
                    o.source = Some(from);
                }
            }
            Control::DespawnRequest { id }
                if self.is_member_client(from) && self.owner(id) == Some(from) =>
            {
                self.host_despawn(now, id);
            }
            Control::AuthorityRequest { id } if self.is_member_client(from) => {
                self.host_authority_request(now, from, id);
            }
            Control::AuthorityAnswer { id, by, agree } if self.is_member_client(from) => {
                self.host_authority_answer(now, from, id, by, agree);
            }
            Control::AuthorityRelease { id } if self.is_member_client(from) => {
                self.host_release(now, from, id);
            }
            // claims are answers to our NewHost: only shortly after we took over
            Control::Resync { claims } if self.is_member_client(from) => {
                if self.resync_until.is_some_and(|t| now < t) {
                    for c in claims {
                        self.host_merge_claim(now, from, c);
                    }
                } else {
                    self.stats.refused_controls += 1;
                }
            }
            _ => {}
        }
    }

    /// A `NewHost` from `from`: adopted only from the peer that should take over (the
    /// lowest-join-order member we believe alive, our host aside), once our host is silent or
    /// about to be, and for a term at most [`MAX_TERM_JUMP`] ahead. One that is not
    /// acceptable yet is kept (per sender) and looked at again as time passes.
    fn on_new_host(&mut self, now: Instant, from: PeerId, term: Term, members: Vec<(PeerId, u32)>) {
        let ahead = term.0.saturating_sub(self.term.0);
        if !(1..=MAX_TERM_JUMP).contains(&ahead) || !self.members.contains_key(&from) {
            self.stats.refused_controls += 1;
            return;
        }
        if self.new_host_acceptable(now, from) {
            let later = self
                .pending_new_hosts
                .remove(&from)
                .map(|p| p.later)
                .unwrap_or_default();
            self.adopt_new_host(now, from, term, members);
            for c in later {
                self.handle_control(now, from, c);
            }
        } else {
            let later = self
                .pending_new_hosts
                .remove(&from)
                .map(|p| p.later)
                .unwrap_or_default();
            self.pending_new_hosts.insert(
                from,
                PendingNewHost {
                    at: now,
                    term,
                    members,
                    later,
                },
            );
        }
    }

    /// Is `from` the peer that takes over from our (silent) host?
    fn new_host_acceptable(&self, now: Instant, from: PeerId) -> bool {
        let Some(host) = self.host else {
            return false;
        };
        if from == host || self.role != Role::Client {
            return false;
        }
        // our host is silent, or will be within a heartbeat (timeouts differ a little)
        let host_failing = !self.alive(host, now + self.cfg.heartbeat_interval);
        let heir = self
            .members
            .iter()
            .filter(|(p, _)| **p != host && self.alive(**p, now))
            .min_by_key(|(_, seq)| **seq)
            .map(|(p, _)| *p);
        host_failing && heir == Some(from)
    }

    /// Looks again at `NewHost` messages kept for later; true if one was adopted.
    fn retry_new_hosts(&mut self, now: Instant) -> bool {
        let timeout = self.cfg.peer_timeout * 3;
        self.pending_new_hosts.retain(|_, p| now < p.at + timeout);
        let term = self.term;
        let ready = self
            .pending_new_hosts
            .iter()
            .find(|(p, n)| n.term > term && self.new_host_acceptable(now, **p))
            .map(|(p, _)| *p);
        let Some(from) = ready else {
            return false;
        };
        let Some(p) = self.pending_new_hosts.remove(&from) else {
            return false;
        };
        self.adopt_new_host(now, from, p.term, p.members);
        for c in p.later {
            self.handle_control(now, from, c);
        }
        true
    }

    fn adopt_new_host(
        &mut self,
        now: Instant,
        host: PeerId,
        term: Term,
        members: Vec<(PeerId, u32)>,
    ) {
        self.term = term;
        self.host = Some(host);
        self.role = Role::Client;
        self.members = members.into_iter().collect();
        self.pending_new_hosts.clear();
        // Peers the new room does not have (the old host, members it found dead) lose their
        // link state: should one come back, it joins with a fresh session, and both ends
        // start their sequences over.
        let gone: Vec<PeerId> = self
            .links
            .keys()
            .copied()
            .filter(|p| !self.members.contains_key(p) && *p != host)
            .collect();
        for p in gone {
            self.links.remove(&p);
            self.stats.links.remove(&p);
        }
        for l in self.links.values_mut() {
            l.send.clear();
            l.recv.clear();
            l.pending.clear();
            l.inflight.clear();
            l.state_rx = None;
            l.spawn_pending.clear();
        }
        // tell the new host what we own, so an in-flight handoff is not lost
        let claims: Vec<SpawnInfo> = self
            .objects
            .values()
            .filter(|o| o.info.owner == self.local)
            .map(|o| o.info.clone())
            .collect();
        for chunk in claims.chunks(16) {
            self.send_control(
                now,
                host,
                &Control::Resync {
                    claims: chunk.to_vec(),
                },
            );
        }
        // spawn requests the old host may never have answered go to the new one (it
        // answers a request it already has with the existing object)
        let pending: Vec<(u32, ClassId, ObjectState)> = self
            .pending_spawns
            .iter()
            .map(|(r, (c, st))| (*r, *c, st.clone()))
            .collect();
        for (request, class, st) in pending {
            let msg = Control::SpawnRequest {
                request,
                class,
                particles: st.particles.len() as u32,
                pos: st.pos.to_array(),
                rot: st.rot.to_array(),
            };
            self.send_control(now, host, &msg);
        }
        self.events.push_back(Event::HostChanged { host, term });
    }

    fn is_member_client(&self, p: PeerId) -> bool {
        self.role == Role::Host && p != self.local && self.members.contains_key(&p)
    }

    fn on_hello(&mut self, now: Instant, from: PeerId, protocol: u8, digest: u64) {
        if self.role != Role::Host {
            if let Some(host) = self.host {
                if self.is_connected() {
                    self.send_control(now, from, &Control::Redirect { host });
                }
            }
            return;
        }
        if self.members.contains_key(&from) {
            return;
        }
        if protocol != PROTOCOL_VERSION {
            let reason = format!(
                "protocol version mismatch: host speaks {PROTOCOL_VERSION}, you speak {protocol}"
            );
            self.send_control(now, from, &Control::Refused { reason });
            return;
        }
        if digest != self.cfg.digest() {
            let reason = "object class configuration differs from the host's".to_string();
            self.send_control(now, from, &Control::Refused { reason });
            return;
        }
        if self.members.len() >= self.cfg.max_members {
            let reason = format!("the room is full ({} members)", self.cfg.max_members);
            self.send_control(now, from, &Control::Refused { reason });
            return;
        }
        let join_seq = self.next_join_seq;
        self.next_join_seq = self.next_join_seq.saturating_add(1);
        self.members.insert(from, join_seq);
        let members: Vec<(PeerId, u32)> = self.members.iter().map(|(p, s)| (*p, *s)).collect();
        let welcome = Control::Welcome {
            term: self.term,
            host: self.local,
            join_seq,
            members,
        };
        self.send_control(now, from, &welcome);
        self.send_snapshot(now, from);
        self.broadcast(
            now,
            &Control::PeerJoined {
                peer: from,
                join_seq,
            },
            Some(from),
        );
        self.events.push_back(Event::PeerJoined(from));
    }

    fn insert_object(&mut self, now: Instant, info: SpawnInfo, request: Option<u32>) {
        let Some(class) = self.class(info.class) else {
            return;
        };
        let pos = class
            .position_quantizer()
            .quantize(Vec3::from_array(info.pos));
        let rot = quantize_quat(Quat::from_array(info.rot), class.rot_bits());
        let particles =
            vec![class.particle_quantizer().quantize(Vec3::ZERO); info.particles as usize];
        let id = info.id;
        let ev = Event::Spawned {
            id,
            class: info.class,
            owner: info.owner,
            request,
        };
        self.objects.insert(
            id,
            Object {
                info,
                pos,
                rot,
                particles,
                rest: false,
                last_change: now,
                published: None,
                published_at: now,
                buffer: SnapshotBuffer::default(),
                source: None,
            },
        );
        self.events.push_back(ev);
    }

    fn on_spawn_from_host(&mut self, now: Instant, info: SpawnInfo) {
        if self.class(info.class).is_none() {
            return;
        }
        if let Some(o) = self.objects.get(&info.id) {
            if o.info.class == info.class && o.info.particles == info.particles {
                self.set_owner(info.id, info.owner, info.epoch, info.held);
                return;
            }
            self.objects.remove(&info.id);
        }
        // a spawn we asked for: the host names our request
        let mut request = None;
        let mut published = None;
        if info.owner == self.local {
            if let Some(r) = info.request {
                if let Some((_, st)) = self.pending_spawns.remove(&r) {
                    request = Some(r);
                    published = Some(st);
                }
            }
        }
        let id = info.id;
        self.insert_object(now, info, request);
        if let Some(st) = published {
            let _ = self.publish_state(now, id, &st);
        } else if self.owner(id) == Some(self.local) {
            self.adopt_replica_as_published(id);
        }
    }

    fn set_owner(&mut self, id: NetId, owner: PeerId, epoch: AuthorityEpoch, held: bool) {
        let local = self.local;
        let Some(o) = self.objects.get_mut(&id) else {
            return;
        };
        if epoch < o.info.epoch {
            return;
        }
        let changed = o.info.owner != owner || o.info.epoch != epoch;
        let was_mine = o.info.owner == local;
        o.info.owner = owner;
        o.info.epoch = epoch;
        o.info.held = held;
        if owner != local {
            o.published = None;
        }
        if changed && (was_mine || owner == local) && self.role != Role::Host {
            // a client's chains toward the host restart with keyframes (the host dropped its
            // side of them when it granted)
            for l in self.links.values_mut() {
                l.send.retain(|(o, _), _| *o != id);
            }
        }
        if changed {
            if owner == local {
                self.adopt_replica_as_published(id);
            }
            self.events
                .push_back(Event::AuthorityChanged { id, owner, epoch });
        }
    }

    fn host_grant(&mut self, now: Instant, id: NetId, to: PeerId, held: bool) {
        let term = self.term;
        let Some(o) = self.objects.get(&id) else {
            return;
        };
        let epoch = o.info.epoch.bumped(term);
        self.set_owner(id, to, epoch, held);
        // the new owner sends keyframes on its own link; our relay chains restart
        for l in self.links.values_mut() {
            l.recv.retain(|(oid, _), _| *oid != id);
        }
        self.broadcast(
            now,
            &Control::OwnerChanged {
                id,
                owner: to,
                epoch,
                held,
            },
            None,
        );
    }

    fn host_authority_request(&mut self, now: Instant, from: PeerId, id: NetId) {
        let Some(o) = self.objects.get(&id) else {
            self.deny(now, from, id, DenyReason::Unknown);
            return;
        };
        let (owner, held, policy) = (o.info.owner, o.info.held, o.info.policy);
        if owner == from {
            self.host_grant(now, id, from, true);
            return;
        }
        match policy {
            AuthorityPolicy::Locked => self.deny(now, from, id, DenyReason::Locked),
            AuthorityPolicy::Free if held => self.deny(now, from, id, DenyReason::Held(owner)),
            AuthorityPolicy::OwnerMustAgree if held => {
                let asks = self.pending_asks.entry(id).or_default();
                if asks.insert(from) {
                    if owner == self.local {
                        self.events
                            .push_back(Event::AuthorityAsked { id, by: from });
                    } else {
                        self.send_control(now, owner, &Control::AuthorityAsk { id, by: from });
                    }
                }
            }
            _ => self.host_grant(now, id, from, true),
        }
    }

    fn host_authority_answer(
        &mut self,
        now: Instant,
        from: PeerId,
        id: NetId,
        by: PeerId,
        agree: bool,
    ) {
        if self.owner(id) != Some(from) {
            return;
        }
        let asked = self
            .pending_asks
            .get_mut(&id)
            .is_some_and(|s| s.remove(&by));
        if !asked {
            return;
        }
        if agree && self.members.contains_key(&by) {
            self.pending_asks.remove(&id);
            self.host_grant(now, id, by, true);
        } else {
            self.deny(now, by, id, DenyReason::OwnerRefused);
        }
    }

    fn deny(&mut self, now: Instant, to: PeerId, id: NetId, reason: DenyReason) {
        if to == self.local {
            self.events.push_back(Event::AuthorityDenied { id, reason });
        } else {
            self.send_control(now, to, &Control::AuthorityDenied { id, reason });
        }
    }

    fn host_release(&mut self, now: Instant, from: PeerId, id: NetId) {
        if self.owner(id) == Some(from) {
            let me = self.local;
            self.host_grant(now, id, me, false);
        }
    }

    fn host_despawn(&mut self, now: Instant, id: NetId) {
        if self.objects.remove(&id).is_some() {
            self.events.push_back(Event::Despawned(id));
            for l in self.links.values_mut() {
                l.spawn_pending.remove(&id);
                l.pending.retain(|e| e.id != id);
                l.send.retain(|(o, _), _| *o != id);
                l.recv.retain(|(o, _), _| *o != id);
            }
            self.broadcast(now, &Control::Despawn { id }, None);
        }
    }

    fn host_peer_left(&mut self, now: Instant, p: PeerId) {
        self.members.remove(&p);
        if let Some(l) = self.links.get_mut(&p) {
            l.pending.clear();
        }
        self.links.remove(&p);
        self.events.push_back(Event::PeerLeft(p));
        self.broadcast(now, &Control::PeerLeft { peer: p }, None);
        // authority returns to the host
        let owned: Vec<NetId> = self
            .objects
            .values()
            .filter(|o| o.info.owner == p)
            .map(|o| o.info.id)
            .collect();
        let me = self.local;
        for id in owned {
            self.host_grant(now, id, me, false);
        }
        for asks in self.pending_asks.values_mut() {
            asks.remove(&p);
        }
    }

    /// A fresh object id (never 0), or `None` once the id space is used up.
    fn alloc_id(&mut self) -> Option<NetId> {
        let id = self.next_net_id.max(1);
        self.next_net_id = id.checked_add(1)?;
        Some(NetId(id))
    }

    /// May the host create one more object of `particles` particles owned by `p`?
    fn may_create_for(&self, p: PeerId, particles: u32) -> bool {
        let (count, total) = self
            .objects
            .values()
            .filter(|o| o.info.owner == p)
            .fold((0usize, 0usize), |(n, t), o| {
                (n + 1, t.saturating_add(o.info.particles as usize))
            });
        count < self.cfg.max_objects_per_peer
            && total.saturating_add(particles as usize) <= self.cfg.max_particles_per_peer
    }

    /// A member's claim after our takeover (`Resync`): what it owns according to its replica.
    ///
    /// Only what the claimant can know is believed: an epoch of an older term (every grant of
    /// our term is ours), at most one grant ahead of our record; an unknown object only
    /// with an id the old host may have spawned unseen by us ([`LOST_ID_WINDOW`]) and within
    /// the per-peer limits. An implausible claim on an object we know is answered by
    /// re-granting it to its recorded owner in our term, so every replica converges.
    fn host_merge_claim(&mut self, now: Instant, from: PeerId, claim: SpawnInfo) {
        if claim.owner != from || claim.epoch.term >= self.term.0 {
            self.stats.refused_controls += 1;
            return;
        }
        let Some(class_policy) = self.class(claim.class).map(|c| c.authority) else {
            self.stats.refused_controls += 1;
            return;
        };
        let Some(o) = self.objects.get(&claim.id) else {
            let lost = self
                .lost_ids
                .is_some_and(|(lo, hi)| (lo..hi).contains(&claim.id.0));
            if !lost || !self.may_create_for(from, claim.particles) {
                self.stats.refused_controls += 1;
                return;
            }
            let info = SpawnInfo {
                policy: class_policy,
                ..claim
            };
            let id = info.id;
            self.insert_object(now, info.clone(), None);
            if let Some(o) = self.objects.get_mut(&id) {
                o.source = Some(from);
            }
            self.broadcast(now, &Control::Spawn(info), Some(from));
            return;
        };
        let (owner, epoch, held, policy) = (o.info.owner, o.info.epoch, o.info.held, o.info.policy);
        let same_object = o.info.class == claim.class && o.info.particles == claim.particles;
        if claim.epoch <= epoch && same_object {
            if owner != from {
                // the claimant missed a later grant: tell it
                self.send_control(
                    now,
                    from,
                    &Control::OwnerChanged {
                        id: claim.id,
                        owner,
                        epoch,
                        held,
                    },
                );
            }
            return;
        }
        // at most one grant we did not hear of: the first of a later term, or the next one
        let next = if claim.epoch.term == epoch.term {
            claim.epoch.grant <= epoch.grant.saturating_add(1)
        } else {
            claim.epoch.grant == 0
        };
        let plausible = same_object && next && (policy != AuthorityPolicy::Locked || owner == from);
        if plausible {
            self.set_owner(claim.id, from, claim.epoch, claim.held);
            for l in self.links.values_mut() {
                l.recv.retain(|(oid, _), _| *oid != claim.id);
            }
            self.broadcast(
                now,
                &Control::OwnerChanged {
                    id: claim.id,
                    owner: from,
                    epoch: claim.epoch,
                    held: claim.held,
                },
                None,
            );
            return;
        }
        self.stats.refused_controls += 1;
        if epoch.term < self.term.0 {
            // replicas may hold epochs newer than our record: a grant of our term beats them
            self.host_grant(now, claim.id, owner, held);
        } else if owner != from {
            self.send_control(
                now,
                from,
                &Control::OwnerChanged {
                    id: claim.id,
                    owner,
                    epoch,
                    held,
                },
            );
        }
    }
}
