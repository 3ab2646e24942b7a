//! The room session: one sans-IO state machine per local peer.
//!
//! Packets and `now` go in ([`Session::handle_packet`], [`Session::handle_timeout`], local
//! commands); datagrams, events and the next wake-up come out ([`Session::poll_transmit`],
//! [`Session::poll_event`], [`Session::poll_timeout`]).
//!
//! This module keeps the entry points; the state lives in owned parts, each in a child
//! module with its own tests, and the session orchestrates them:
//!
//! | module | owns / does |
//! |---|---|
//! | [`link`] | per remote peer: reliable channel, datagram sequences, clock, RTT, state acks |
//! | `delta` | per (link, object, part): entry numbers, acknowledged delta bases, receive rings |
//! | [`registry`] | the objects: grid state, published state, interpolation buffers, ids |
//! | `send` | replication out: send ticks, thresholds, deltas, datagram assembly |
//! | `recv` | datagrams in: sections, state entries applied against their bases, acks |
//! | `join` | joining: `Hello`/`Welcome`/`Redirect`/refusals, members joining and leaving |
//! | `access` | rooms with a key: the host's challenge, the joiner's proof |
//! | `spawn` | spawning and despawning, spawn requests, late-join snapshots |
//! | `authority` | who owns what: requests, grants, asks, releases, post-migration claims |
//! | `liveness` | heartbeats, timeouts, our own stalls, peers told they were dropped |
//! | `migration` | electing the next host, taking over, following a new host |
//! | `messages` | application messages: outbox, duplicate filter, retained table, host relay |
//! | `control` | routing control messages; the host as a client of itself |
//! | [`topology`] | tears and cuts: the owner's requests, the host's checks, per-object logs |
//! | `clock` | the room clock: the host's, learnt from its pongs, carried on by a new host |

mod access;
mod authority;
pub mod ban;
mod budget;
mod clock;
mod control;
mod delta;
mod footprint;
mod heal;
mod join;
pub mod link;
mod liveness;
mod messages;
mod migration;
mod recv;
pub mod registry;
mod restore;
mod send;
mod spawn;
#[cfg(test)]
mod testkit;
pub mod topology;

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

pub use access::{RoomKey, SIGNAL_PROOF_LIFETIME_S};
pub use ban::{KickError, MAX_BANNED};
pub use footprint::{Footprint, Leftovers, PeerFootprint};
pub use recv::MAX_VERSION_REFUSALS_PER_S;
pub use registry::{DisplayedState, ObjectState};
pub use restore::{KeptObject, RoomImage};

use self::authority::PendingAsks;
use self::link::Link;
use self::liveness::{Departed, DroppedPeers, StallWatch};
use self::migration::Succession;
use self::registry::Registry;
use self::send::SendSchedule;
use self::spawn::PendingSpawns;
use crate::ids::{AuthorityEpoch, ClassId, NetId, PeerId, Term};
use crate::interp::InterpolationConfig;
use crate::policy::{ClassConfig, SessionConfig, SoftBodyMode};
use crate::stats::Stats;
use crate::time::{min_opt, Instant};
pub use crate::transport::Transmit;
use crate::wire::{DenyReason, MessageRefusal, ReceivedMessage};

/// Non-member peers (joiners, unknown senders) we keep link state for at once.
pub const MAX_STRANGERS: usize = 32;

/// Object ids a new host skips past the highest id it knows. They cover objects the old host
/// spawned whose `Spawn` never reached the heir: a `Resync` claim can create an unknown
/// object only inside this range.
pub const LOST_ID_WINDOW: u32 = 1024;

/// A `NewHost` may announce a term at most this far ahead of ours (an heir may die too).
pub const MAX_TERM_JUMP: u32 = 4;

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
    /// Host: we kicked this peer out and banned it ([`Session::kick`]); a `PeerLeft` for a
    /// member precedes it.
    Kicked(PeerId),
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
    /// Entry `seq` of object `id`'s topology log (a tear segment, a lift, or the cut that made
    /// this piece): apply it to the object's mesh. If `seq` is not the next entry you applied
    /// (after a migration the new host's log replaced ours from there), rebuild the mesh from
    /// the class's and [`Session::topology_log`].
    Topology {
        /// Object.
        id: NetId,
        /// Its position in the log.
        seq: u32,
        /// The change.
        event: crate::wire::TopologyEvent,
    },
    /// Request to the application: `by` wants our object; answer with
    /// [`Session::answer_authority`].
    AuthorityAsked {
        /// Object.
        id: NetId,
        /// Asking peer.
        by: PeerId,
    },
    /// An application message for us ([`Session::send_message`]; decode a typed one with
    /// [`crate::messages::MessageTypes::decode`]).
    Message(ReceivedMessage),
    /// Our reliable message `seq` reached every target.
    MessageDelivered {
        /// Its number.
        seq: u32,
    },
    /// The host refused our message `seq`: it reached nobody.
    MessageRefused {
        /// Its number.
        seq: u32,
        /// Why.
        reason: MessageRefusal,
    },
}

/// Where this peer stands in the room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    /// Said `Hello`, not welcomed yet.
    Joining,
    /// A member; someone else hosts.
    Client,
    /// The host.
    Host,
    /// Refused or dropped: done, sends nothing more.
    Refused,
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
    /// Members and their join order (the host included).
    members: BTreeMap<PeerId, u32>,
    /// Host: the join order of the next member.
    next_join_seq: u32,
    links: BTreeMap<PeerId, Link>,
    objects: Registry,
    spawns: PendingSpawns,
    asks: PendingAsks,
    succession: Succession,
    /// Host: peers out of the room that may not know it (see [`DroppedPeers`]).
    dropped: DroppedPeers,
    /// Peers that said `Leave`: their datagrams still in flight are ignored.
    departed: Departed,
    stalls: StallWatch,
    schedule: SendSchedule,
    events: VecDeque<Event>,
    /// Datagrams written outside the per-link assembly (refusals).
    raw_out: VecDeque<Transmit>,
    stats: Stats,
    /// Host: topology requests refused, by reason.
    topology_refused: topology::TopologyRefusals,
    last_relay_at: Option<Instant>,
    messages: messages::Messages,
    challenges: access::Challenges,
    bans: ban::Bans,
    /// The second (since time zero) and how many version refusals were sent in it.
    version_refusals: (u64, u32),
    /// Peers the room lost, and the beacons that heal a partition.
    heal: heal::Heal,
    /// The room clock as this peer reads it.
    clock: clock::RoomClock,
}

impl Session {
    fn new(local: PeerId, cfg: SessionConfig, now: Instant, role: Role) -> Self {
        let schedule = SendSchedule::new(now, cfg.classes.len());
        Session {
            cfg,
            interp: InterpolationConfig::default(),
            local,
            role,
            host: None,
            term: Term(0),
            members: BTreeMap::new(),
            next_join_seq: 0,
            links: BTreeMap::new(),
            objects: Registry::default(),
            spawns: PendingSpawns::default(),
            asks: PendingAsks::default(),
            succession: Succession::default(),
            dropped: DroppedPeers::default(),
            departed: Departed::default(),
            stalls: StallWatch::default(),
            schedule,
            events: VecDeque::new(),
            raw_out: VecDeque::new(),
            stats: Stats::default(),
            topology_refused: topology::TopologyRefusals::default(),
            last_relay_at: None,
            messages: messages::Messages::default(),
            challenges: access::Challenges::default(),
            bans: ban::Bans::default(),
            version_refusals: (0, 0),
            heal: heal::Heal::default(),
            clock: clock::RoomClock::default(),
        }
    }

    /// Create a room and host it (term 1, join order 0).
    pub fn host(local: PeerId, cfg: SessionConfig, now: Instant) -> Self {
        let mut s = Session::new(local, cfg, now, Role::Host);
        s.host = Some(local);
        s.clock.host();
        s.term = Term(1);
        s.members.insert(local, 0);
        s.next_join_seq = 1;
        s
    }

    /// Join the room hosted by `host`.
    pub fn join(local: PeerId, host: PeerId, cfg: SessionConfig, now: Instant) -> Self {
        let mut s = Session::new(local, cfg, now, Role::Joining);
        s.host = Some(host);
        s.say_hello(now, host);
        s
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

    /// The room time at our local time `now`: one clock every peer of the room reads alike
    /// (within a few milliseconds, the round trip's asymmetry), the host's, carried on by the
    /// next host when it goes. `None` until this peer has heard the host's clock (a joiner's
    /// first pong). Readings never go back. See `session::clock`.
    pub fn room_time(&self, now: Instant) -> Option<Duration> {
        self.clock.read(now)
    }

    /// The round trip the room clock's estimate rests on (`None` for the host, and before
    /// the first sample): half of it bounds the estimate's error.
    pub fn room_clock_rtt(&self) -> Option<Duration> {
        self.clock.best_rtt()
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

    /// Interpolate object `id` with its own settings (`None`: the session's again), e.g. a
    /// speaking avatar's head with one send interval of delay instead of two, so that what is
    /// seen of a mouth keeps up with what is heard (`softsync_bevy::voice`). Local: nothing is
    /// sent. False for an unknown object.
    pub fn set_object_interpolation(
        &mut self,
        id: NetId,
        cfg: Option<InterpolationConfig>,
    ) -> bool {
        match self.objects.get_mut(id) {
            Some(o) => {
                o.interp = cfg.map(InterpolationConfig::sanitized);
                true
            }
            None => false,
        }
    }

    /// Known objects.
    pub fn object_ids(&self) -> Vec<NetId> {
        self.objects.ids()
    }

    /// Owner of an object according to our replica.
    pub fn owner(&self, id: NetId) -> Option<PeerId> {
        self.objects.owner(id)
    }

    /// Authority epoch of an object according to our replica.
    pub fn epoch(&self, id: NetId) -> Option<AuthorityEpoch> {
        self.objects.get(id).map(|o| o.info.epoch)
    }

    /// An object's particle count (its layout: set at spawn, changed by a resolution change
    /// in its topology log, which the application applies at the [`Event::Topology`]).
    pub fn particles_of(&self, id: NetId) -> Option<u32> {
        self.objects.get(id).map(|o| o.info.particles)
    }

    /// An object's class.
    pub fn class_of(&self, id: NetId) -> Option<ClassId> {
        self.objects.get(id).map(|o| o.info.class)
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

    /// The peer whose updates of `id` we show: the owner, or the host relaying for it
    /// ([`DisplayedState::source_time`] is on that peer's clock). `None` before any update.
    pub fn state_source(&self, id: NetId) -> Option<PeerId> {
        self.objects.get(id)?.source
    }

    /// Latest replicated state (no interpolation): what the last update said.
    pub fn latest_state(&self, id: NetId) -> Option<ObjectState> {
        let o = self.objects.get(id)?;
        if o.info.owner == self.local {
            if let Some(p) = &o.published {
                return Some(p.clone());
            }
        }
        let class = self.class(o.info.class)?;
        Some(o.compose(class))
    }

    /// What this peer displays at `now`: the owner's published state for our own objects,
    /// otherwise the interpolated remote state.
    pub fn display_state(&mut self, now: Instant, id: NetId) -> Option<DisplayedState> {
        let o = self.objects.get(id)?;
        let interp = o.interp.unwrap_or(self.interp);
        if o.info.owner == self.local {
            if let Some(p) = &o.published {
                return Some(DisplayedState {
                    state: p.clone(),
                    source_time: now,
                    delay: Duration::ZERO,
                });
            }
        }
        let class = self.class(o.info.class)?.clone();
        let link = o.source.and_then(|s| self.links.get(&s));
        let delay = link.map_or(Duration::ZERO, |l| {
            let interval = class.send.interval().as_secs_f32();
            let base = interval * interp.intervals;
            let j = interp.jitter_factor * l.clock.jitter_us() as f32 * 1e-6;
            let cap = interval * 4.0 + 0.1;
            Duration::try_from_secs_f32((base + j).min(cap).max(0.0)).unwrap_or(Duration::ZERO)
        });
        let clock = link.map(|l| l.clock.clone()).unwrap_or_default();
        let t = now - delay;
        let o = self.objects.get_mut(id)?;
        let Some(snap) = o.buffer.sample(t, &interp) else {
            let state = self.latest_state(id)?;
            return Some(DisplayedState {
                state,
                source_time: t,
                delay,
            });
        };
        let particles = if class.soft_body_mode == SoftBodyMode::Particles {
            snap.offsets
                .iter()
                .map(|o| snap.pos + snap.rot * *o)
                .collect()
        } else {
            Vec::new()
        };
        Some(DisplayedState {
            state: ObjectState {
                pos: snap.pos,
                rot: snap.rot,
                particles,
            },
            source_time: clock.to_sender_time(t),
            delay,
        })
    }

    /// Every member but us, and our host (a joiner's contact before it is a member).
    fn others(&self) -> std::collections::BTreeSet<PeerId> {
        self.members
            .keys()
            .copied()
            .chain(self.host)
            .filter(|p| *p != self.local)
            .collect()
    }

    fn class(&self, c: ClassId) -> Option<&ClassConfig> {
        self.cfg.class(c)
    }

    // ---------------------------------------------------------------- outputs

    /// Next event.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// When to call [`Session::handle_timeout`] next.
    pub fn poll_timeout(&self) -> Option<Instant> {
        if self.role == Role::Refused {
            return None;
        }
        let mut t = min_opt(Some(self.schedule.next_heartbeat), self.heal_deadline());
        for (c, tick) in self.schedule.next_tick.iter().enumerate() {
            let owns = self
                .objects
                .iter()
                .any(|o| usize::from(o.info.class.0) == c && o.info.owner == self.local);
            if owns {
                t = min_opt(t, Some(*tick));
            }
        }
        for (p, l) in &self.links {
            t = min_opt(t, l.reliable.next_deadline());
            if self.members.contains_key(p) && *p != self.local {
                // a deadline already judged is not one to wake for again (a member waiting
                // for the heir of a dead host would be woken at once, for ever)
                let judged = self.schedule.judged_at;
                if let Some(d) = l.last_heard.map(|h| h + self.silence_allowed(*p)) {
                    if judged.is_none_or(|j| d > j) {
                        t = min_opt(t, Some(d));
                    }
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
        peers.into_iter().find_map(|p| self.build_datagram(now, p))
    }

    // ---------------------------------------------------------------- inputs

    /// Advance timers: heartbeats, timeouts, migration, send ticks, rest sync repeats.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.role == Role::Refused {
            return;
        }
        self.note_time(now);
        self.heartbeat(now);
        self.check_liveness(now);
        self.heal_tick(now);
        self.forget_silent_strangers(now);
        self.send_ticks(now);
        self.advance_deliveries(now);
    }

    /// Feed a datagram received from `from`.
    pub fn handle_packet(&mut self, now: Instant, from: PeerId, bytes: &[u8]) {
        self.note_time(now);
        self.receive(now, from, bytes);
    }

    /// Queue any control message to `to` on the reliable channel, exactly as a modified
    /// client could. For tests and fuzzing of the receiving side; applications never need it.
    #[cfg(feature = "testing")]
    pub fn send_raw_control(&mut self, now: Instant, to: PeerId, msg: &crate::wire::Control) {
        self.send_control(now, to, msg);
    }
}
