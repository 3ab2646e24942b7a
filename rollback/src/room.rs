//! Over 800 lines: the epoch switch, the snapshot served and fetched, and ggrs's socket share
//! one peer's state; issue 40 (the house without knots) splits them.
//!
//! A peer of a rollback room: the session keeps membership (hello, welcome, host, migration:
//! the host model), ggrs runs the world from everyone's inputs.
//!
//! # Epochs
//! A ggrs session has a fixed set of players and no host. Each membership the host sees (the
//! room opening, a peer joining) starts the next ggrs session, an *epoch*: the host takes its
//! newest *confirmed* frame `F` (every input up to it known, so every member's state there is
//! the same), announces `Epoch { n, frame: F, players, digest }` as a retained room message
//! (a joiner gets the newest one when welcomed; a new host has it too), and serves the
//! snapshot of `F`. Each member, once its own confirmed frame reaches `F`, takes its own saved
//! state of `F`, makes the snapshot, checks it against the host's digest (a mismatch is a
//! desync: reported, and the host's snapshot fetched instead), rebuilds the world from it and
//! starts the new ggrs session. A joiner fetches the snapshot (the share protocol, inside
//! rollback datagrams) and does the same.
//!
//! What a member sees during the switch: the world goes back to `F` (its predicted frames
//! after `F` are dropped: at most the frames between `F` and the announcement's arrival), and
//! stands still until every player of the new epoch has synchronised (ggrs's handshake: five
//! round trips, resent every 200 ms). Measured as [`RollbackStats::switch_ms_max`].
//!
//! # Desync repair
//! A desync in the middle of an epoch (ggrs's checksums differ) is repaired by the same means:
//! the peer that sees it asks the host for a new epoch of the same players (the host notes
//! its own), once per epoch, again every second until one comes. The host announces
//! its newest confirmed frame; whoever's own state of that frame differs from the host's
//! digest fetches the host's snapshot, and everyone plays on from the same state. The host's
//! world is the reference: if the host is the odd one out, everyone else is brought to it.
//! Counted as [`RollbackStats::repairs`], timed as [`RollbackStats::repair_ms_max`] (detection
//! to the new epoch's ggrs session running), reported as [`RollbackEvent::Repaired`].
//!
//! A peer that leaves or dies: ggrs marks it disconnected at a frame every survivor agrees on
//! and feeds "no input" from there (its hands open); until then the others stall once they
//! are [`RollbackConfig::max_prediction`] frames ahead of its last input, for at most the
//! disconnect timeout. Its slot is dropped at the next epoch.

// Stats time the save, load and frame costs with this machine's clock (ggrs itself keeps its
// own clock for its timers); nothing of the simulation reads it.
#![allow(clippy::disallowed_methods)]

use std::cell::RefCell;
use std::collections::{BTreeMap, VecDeque};
use std::rc::Rc;
use std::time::Duration;

use ggrs::{DesyncDetection, GgrsError, GgrsEvent, GgrsRequest, P2PSession, PlayerType};
use serde::{Deserialize, Serialize};
use softsync_net::door::{self, Door};
use softsync_net::messages::{Message, MessageTypes};
use softsync_net::share::{sha256, BlobFetch, BlobServer, FetchError};
use softsync_net::wire::{Delivery, MessageTarget};
use softsync_net::{Event, Instant, PeerEvent, PeerId, Session, Transmit};
use softsync_peer::join::Joining;
use softsync_peer::Scene;

use crate::input::PlayerInput;
use crate::socket::{self, Datagram, GgrsSocket, Queues};
use crate::world::{RollbackWorld, Snapshot, WorldError};
use crate::GgrsConfig;

/// A position and rotation.
type Pose = (glam::Vec3, glam::Quat);

/// Largest snapshot a joiner accepts, bytes.
pub const MAX_SNAPSHOT_BYTES: u64 = 8 << 20;

/// The announcement of an epoch (a retained room message, `softsync.rollback.epoch`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Epoch {
    /// Its number, from 1.
    pub n: u32,
    /// The world frame it starts from.
    pub frame: i32,
    /// Its players, in ggrs handle order.
    pub players: Vec<PeerId>,
    /// SHA-256 of the snapshot's bytes.
    pub digest: [u8; 32],
    /// The host that announced it (serves the snapshot).
    pub host: PeerId,
}

impl Message for Epoch {
    const NAME: &'static str = EPOCH_NAME;
}

/// [`Epoch`]'s name in the room's message table (a state-sync joiner refused by a rollback
/// room sees it in the host's refusal, and is told to join with `--sync rollback`).
pub const EPOCH_NAME: &str = softsync_peer::events::ROLLBACK_EPOCH_TYPE;

/// A member's word to the host that its ggrs session of epoch `epoch` failed
/// (`softsync.rollback.resync`): the host answers with a new epoch of the same players.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Resync {
    /// The epoch whose session failed.
    pub epoch: u32,
}

impl Message for Resync {
    const NAME: &'static str = "softsync.rollback.resync";
}

/// A peer whose ggrs session failed asks the host again this often until a new epoch comes.
const RESYNC_RETRY: Duration = Duration::from_secs(1);

/// Add the rollback room's message types to a room's table (host and joiners alike: they are
/// part of the room's configuration digest, so a state-sync peer cannot join by mistake).
pub fn register(types: &mut MessageTypes) {
    // Registered once per table; a second time is a no-op error.
    let _ = types.register::<Epoch>();
    let _ = types.register::<Resync>();
}

/// Settings of a rollback peer.
#[derive(Clone, Debug)]
pub struct RollbackConfig {
    /// Fixed step (ggrs runs at `1 / dt_s` frames per second).
    pub dt_s: f32,
    /// Frames a peer may run ahead of the last input it has from another (ggrs's prediction
    /// window; rollbacks are at most this deep).
    pub max_prediction: usize,
    /// Frames one's own input is delayed (0: one's hands act in the next frame).
    pub input_delay: usize,
    /// A silent player is disconnected by ggrs after this.
    pub disconnect_timeout: Duration,
    /// Checksums are compared every this many frames (ggrs's desync detection).
    pub desync_interval: u32,
    /// Saved states kept for the next epoch's snapshot, frames.
    pub ring: usize,
}

impl Default for RollbackConfig {
    fn default() -> Self {
        RollbackConfig {
            dt_s: 1.0 / 60.0,
            max_prediction: 8,
            input_delay: 0,
            disconnect_timeout: Duration::from_millis(1500),
            desync_interval: 10,
            ring: 180,
        }
    }
}

/// What a rollback peer reports.
#[derive(Clone, Debug, PartialEq)]
pub enum RollbackEvent {
    /// Membership news from the session (joined, refused, dropped, a peer joined or left, a
    /// new host).
    Room(Event),
    /// A new epoch runs from `frame` with these players.
    EpochStarted {
        /// Its number.
        n: u32,
        /// The frame it started from.
        frame: i32,
        /// Its players.
        players: Vec<PeerId>,
    },
    /// Checksums differed: this peer's world and `peer`'s are not the same any more.
    Desync {
        /// The frame compared.
        frame: i32,
        /// The peer whose checksum differs.
        peer: PeerId,
    },
    /// A desync seen here was repaired: a new epoch runs from the host's state.
    Repaired {
        /// The new epoch.
        epoch: u32,
        /// From the desync's detection to the new epoch's ggrs session running, ms.
        ms: f32,
    },
    /// ggrs disconnected a player (it left or died); its hands open from an agreed frame.
    PlayerDisconnected(PeerId),
    /// Something went wrong but the peer goes on.
    Warning(String),
}

/// Counters and costs (for the `rollback` bench and the stats line).
#[derive(Clone, Debug, Default)]
pub struct RollbackStats {
    /// Frames advanced for the first time.
    pub frames: u64,
    /// Frames simulated again after a rollback.
    pub resimulated: u64,
    /// Rollbacks (loads).
    pub rollbacks: u64,
    /// Ticks that could not advance (synchronising, or too far ahead of a silent player).
    pub stalled_ticks: u64,
    /// Ticks skipped to let slower peers catch up (ggrs's frame advantage).
    pub waited_ticks: u64,
    /// Saves and their total cost, ns.
    pub saves: u64,
    /// Total save cost, ns.
    pub save_ns: u64,
    /// Total load cost, ns.
    pub load_ns: u64,
    /// Per tick: wall time of the tick's ggrs work (advance, re-simulation, saves), ms (the
    /// last 18 000 to 36 000 ticks).
    pub frame_ms: Vec<f32>,
    /// Desyncs detected.
    pub desyncs: u64,
    /// Epochs started.
    pub epochs: u64,
    /// Longest time from an epoch's announcement being seen to its ggrs session running, ms.
    pub switch_ms_max: f32,
    /// ggrs bytes sent.
    pub ggrs_bytes: u64,
    /// Rollback datagrams dropped (undecodable, or of another epoch).
    pub dropped: u64,
    /// Epoch announcements refused: not from the room's host, or naming another host than
    /// their sender, or a start frame past the frame counter's range.
    pub epochs_refused: u64,
    /// Snapshot requests refused: from a peer that is not a member of the room's session (a
    /// keyed room's snapshot goes only to peers that proved the key or a token).
    pub snapshots_refused: u64,
    /// Epochs whose ggrs session failed here (ggrs panicked) and was dropped; the host then
    /// starts a new epoch of the same players.
    pub ggrs_failures: u64,
    /// Host: epochs started because a member's ggrs session failed or a desync was seen.
    pub resyncs: u64,
    /// Desyncs seen here and repaired (a new epoch from the host's state running).
    pub repairs: u64,
    /// The longest repair here, from detection to the new epoch's ggrs session running, ms.
    pub repair_ms_max: f32,
    /// Per rollback that moved something: the largest jump of an object's center at the
    /// newest frame shown before it, mm (the last 18 000 to 36 000; what a renderer's
    /// smoothing hides: [`RollbackPeer::take_corrections`]).
    pub correction_mm: Vec<f32>,
}

/// How a rollback moved an object at the frame shown before it: add `pos` to the corrected
/// position and turn by `rot` (about its center) to get where it was drawn. A renderer starts
/// its offset there and lets it decay, so the correction is seen as a short glide, not a jump.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Correction {
    /// Drawn minus corrected position, metres.
    pub pos: glam::Vec3,
    /// Drawn rotation times the inverse of the corrected one.
    pub rot: glam::Quat,
}

/// A pending switch to an announced epoch.
#[derive(Debug)]
struct Pending {
    epoch: Epoch,
    seen: std::time::Instant,
    fetch: Option<BlobFetch>,
}

/// One peer of a rollback room.
pub struct RollbackPeer {
    scene: Scene,
    cfg: RollbackConfig,
    session: Session,
    types: MessageTypes,
    me: PeerId,
    world: Option<RollbackWorld>,
    ggrs: Option<P2PSession<GgrsConfig>>,
    queues: Rc<RefCell<Queues>>,
    /// The running epoch and the world frame it started from.
    epoch: Option<(Epoch, i32)>,
    /// Saved states by ggrs frame of the running epoch.
    ring: BTreeMap<i32, Rc<crate::WorldState>>,
    pending: Option<Pending>,
    /// The running epoch's snapshot, served to joiners.
    server: Option<(u32, BlobServer)>,
    /// Host: the players of the epoch announced last (a new one when members differ).
    announced: Option<Vec<PeerId>>,
    local_input: PlayerInput,
    outbox: VecDeque<Transmit>,
    events: VecDeque<RollbackEvent>,
    stats: RollbackStats,
    switch_started: Option<std::time::Instant>,
    ticks: u64,
    /// Our ggrs session failed: the world frame it had confirmed (our saved states up to it
    /// are right), and when we last asked the host for a new epoch.
    failed: Option<(i32, Option<Instant>)>,
    /// A desync seen in this epoch (its number), when we last asked the host for a new one,
    /// and when it was seen.
    desynced: Option<(u32, Option<Instant>, std::time::Instant)>,
    /// The epoch that repairs it, switched to and not running yet, and when it was seen.
    repairing: Option<(u32, std::time::Instant)>,
    /// Host: a member's (or our own) ggrs session of this epoch failed; a new one is due.
    resync: Option<u32>,
    /// A joiner's way in: the next connected peer is asked when a contact stays silent (it
    /// may be another joiner), as a state-sync peer does.
    joining: Joining,
    /// Per object (scene order): the corrections of the rollbacks since the last
    /// [`take_corrections`](Self::take_corrections), composed.
    corrections: Option<Vec<Correction>>,
}

impl RollbackPeer {
    /// A peer with its session (hosting, or joining through `contact`; its configuration must
    /// have [`register`]ed the epoch message), at `now`.
    pub fn new(
        now: Instant,
        scene: Scene,
        cfg: RollbackConfig,
        session: Session,
        contact: Option<PeerId>,
    ) -> Result<Self, WorldError> {
        let types = MessageTypes::from_config(session.config()).ok_or_else(|| {
            WorldError::Build("the room's message table names a type twice".into())
        })?;
        if types.kind::<Epoch>().is_none() || types.kind::<Resync>().is_none() {
            return Err(WorldError::Build(
                "the session's message table has no rollback epoch type (rollback::room::register)"
                    .into(),
            ));
        }
        let me = session.local_id();
        let session_is_host = session.is_host();
        Ok(RollbackPeer {
            scene,
            cfg,
            session,
            types,
            me,
            world: None,
            ggrs: None,
            queues: Rc::new(RefCell::new(Queues::default())),
            epoch: None,
            ring: BTreeMap::new(),
            pending: None,
            server: None,
            announced: None,
            failed: None,
            desynced: None,
            repairing: None,
            resync: None,
            local_input: PlayerInput::default(),
            outbox: VecDeque::new(),
            events: VecDeque::new(),
            stats: RollbackStats::default(),
            switch_started: None,
            ticks: 0,
            joining: Joining::new(now, session_is_host, contact),
            corrections: None,
        })
    }

    /// This peer's id.
    pub fn me(&self) -> PeerId {
        self.me
    }

    /// The session (membership).
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The room's scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The world, once an epoch runs.
    pub fn world(&self) -> Option<&RollbackWorld> {
        self.world.as_ref()
    }

    /// The running epoch.
    pub fn epoch(&self) -> Option<&Epoch> {
        self.epoch.as_ref().map(|e| &e.0)
    }

    /// Counters and costs.
    pub fn stats(&self) -> &RollbackStats {
        &self.stats
    }

    /// The newest frame whose inputs every player has given (world frame), once running.
    pub fn confirmed_frame(&self) -> Option<i32> {
        if let Some((f, _)) = self.failed {
            return Some(f);
        }
        let (g, (_, start)) = (self.ggrs.as_ref()?, self.epoch.as_ref()?);
        let c = g.confirmed_frame();
        if c < 0 {
            return None;
        }
        start.checked_add(c)
    }

    /// The checksum of this peer's saved state of world frame `frame`, if it still has it
    /// (final once `frame` is confirmed).
    pub fn checksum_at(&self, frame: i32) -> Option<u128> {
        let (_, start) = self.epoch.as_ref()?;
        self.ring
            .get(&frame.checked_sub(*start)?)
            .map(|s| RollbackWorld::checksum_of(s))
    }

    /// Sends an application message to the room (the room's message table: `register` adds
    /// the rollback's own type to it). Messages go through the session, beside the
    /// simulation, as in a state-sync room.
    pub fn send<M: Message>(
        &mut self,
        now: Instant,
        to: MessageTarget,
        delivery: Delivery,
        msg: &M,
    ) -> Result<u32, softsync_net::wire::MessageRefusal> {
        self.session.send(now, &self.types, to, delivery, msg)
    }

    /// This peer's input for the next frame.
    pub fn set_input(&mut self, input: PlayerInput) {
        self.local_input = input;
    }

    /// Next event.
    pub fn poll_event(&mut self) -> Option<RollbackEvent> {
        self.events.pop_front()
    }

    /// Connectivity news from the transport (a joiner's contacts).
    pub fn handle_link_event(&mut self, e: PeerEvent) {
        self.joining.on_link_event(e);
    }

    /// A datagram from the transport (session, ggrs or snapshot).
    pub fn handle_datagram(&mut self, now: Instant, from: PeerId, bytes: &[u8]) {
        // the front door: the session's datagrams to it, ours below, the rest (a scene share
        // the caller did not serve, an unknown marker) dropped and counted
        match door::classify(bytes) {
            Door::Rollback => {}
            Door::Session | Door::OtherVersion | Door::Refusal => {
                self.session.handle_packet(now, from, bytes);
                return;
            }
            Door::Share | Door::Voice | Door::Ident | Door::Unknown => {
                self.stats.dropped += 1;
                return;
            }
        }
        match socket::decode(bytes) {
            Ok(Datagram::Ggrs { epoch, msg }) => {
                let mut q = self.queues.borrow_mut();
                if self.ggrs.is_some() && epoch == q.epoch {
                    q.inbox.push((from, msg));
                } else {
                    self.stats.dropped += 1;
                }
            }
            Ok(Datagram::Snapshot { epoch, share }) => {
                self.on_snapshot_datagram(now, from, epoch, share)
            }
            Err(_) => self.stats.dropped += 1,
        }
    }

    fn on_snapshot_datagram(&mut self, now: Instant, from: PeerId, epoch: u32, share: &[u8]) {
        if let Some(p) = self.pending.as_mut() {
            if p.epoch.n == epoch {
                if let Some(f) = p.fetch.as_mut() {
                    f.handle(from, share);
                    return;
                }
            }
        }
        if let Some((n, server)) = self.server.as_mut() {
            // Only to members of the room's session: they passed its key or token check at
            // their join (a stranger of a keyed room gets nothing; the session's members are
            // the epochs' players).
            if *n == epoch && !self.session.members().contains_key(&from) {
                self.stats.snapshots_refused += 1;
                return;
            }
            if *n == epoch {
                if let Some(t) = server.handle(now, from, share) {
                    self.outbox.push_back(Transmit {
                        to: t.to,
                        payload: socket::encode_snapshot(epoch, &t.payload),
                        reliable: false,
                    });
                }
                return;
            }
        }
        self.stats.dropped += 1;
    }

    /// Host only: open the room (epoch 1: the scene at frame 0, this peer alone).
    pub fn open(&mut self, now: Instant) -> Result<(), WorldError> {
        let world = RollbackWorld::new(&self.scene, self.cfg.dt_s, &[self.me])?;
        let snap = world.snapshot();
        self.announce(now, 1, &snap, vec![self.me]);
        Ok(())
    }

    fn announce(&mut self, now: Instant, n: u32, snap: &Snapshot, players: Vec<PeerId>) {
        let blob = encode_snapshot(snap);
        let epoch = Epoch {
            n,
            frame: snap.frame,
            players: players.clone(),
            digest: sha256(&blob),
            host: self.me,
        };
        if let Err(e) = self.session.send(
            now,
            &self.types,
            MessageTarget::Everyone,
            Delivery::Retained,
            &epoch,
        ) {
            self.events.push_back(RollbackEvent::Warning(format!(
                "epoch {n} not announced: {e:?}"
            )));
        }
        self.announced = Some(players);
        // The host switches at once (it has the state it announced).
        self.switch_to(epoch, snap.clone(), blob);
    }

    /// One tick of the fixed rate (1 / dt): timers, membership, epochs, ggrs (advance, roll
    /// back and re-simulate as it asks). Send what [`Self::poll_transmit`] gives after it.
    pub fn tick(&mut self, now: Instant) {
        self.session.handle_timeout(now);
        if let Some(next) = self.joining.next_contact(now) {
            self.session.join_via(now, next);
        }
        self.drain_session(now);
        self.ask_resync(now);
        self.ask_repair(now);
        self.host_duties(now);
        self.try_switch(now);
        self.run_ggrs();
        let mut q = self.queues.borrow_mut();
        self.stats.ggrs_bytes = q.bytes_sent;
        self.outbox.extend(q.outbox.drain(..));
    }

    fn drain_session(&mut self, now: Instant) {
        while let Some(e) = self.session.poll_event() {
            match e {
                Event::Message(ref m) => match self.types.decode::<Epoch>(m) {
                    // only the room's host announces epochs, and names itself in them: a
                    // member's forged one would freeze joins (n = u32::MAX) or make everyone
                    // fetch its snapshot
                    Some(Ok(epoch))
                        if Some(m.from) == self.session.host_id()
                            && epoch.host == m.from
                            && epoch.frame >= 0 =>
                    {
                        self.on_epoch(now, epoch)
                    }
                    Some(Ok(epoch)) => {
                        self.stats.epochs_refused += 1;
                        self.events.push_back(RollbackEvent::Warning(format!(
                            "epoch {} from {} refused: only the host ({}) announces epochs",
                            epoch.n,
                            m.from.0,
                            self.session.host_id().map_or(0, |h| h.0)
                        )))
                    }
                    Some(Err(r)) => self
                        .events
                        .push_back(RollbackEvent::Warning(format!("bad epoch message: {r:?}"))),
                    None => match self.types.decode::<Resync>(m) {
                        Some(Ok(r)) => {
                            let running = self.epoch.as_ref().map(|e| e.0.n);
                            if self.session.is_host()
                                && running == Some(r.epoch)
                                && self.session.members().contains_key(&m.from)
                            {
                                self.resync = Some(r.epoch);
                            }
                        }
                        Some(Err(_)) => self.stats.dropped += 1,
                        None => self.events.push_back(RollbackEvent::Room(e)),
                    },
                },
                other => {
                    if matches!(other, Event::Joined { .. }) {
                        self.joining.set_joined();
                    }
                    self.events.push_back(RollbackEvent::Room(other))
                }
            }
        }
    }

    fn on_epoch(&mut self, _now: Instant, epoch: Epoch) {
        let current = self.epoch.as_ref().map_or(0, |e| e.0.n);
        let pending = self.pending.as_ref().map_or(0, |p| p.epoch.n);
        if epoch.n <= current.max(pending) || epoch.players.len() > 256 {
            return;
        }
        self.pending = Some(Pending {
            epoch,
            seen: std::time::Instant::now(),
            fetch: None,
        });
    }

    /// Our ggrs session failed: ask the host for a new epoch (the host notes its own), again
    /// every [`RESYNC_RETRY`] until one comes (the message or the host may be lost).
    fn ask_resync(&mut self, now: Instant) {
        let Some((_, asked)) = self.failed.as_mut() else {
            return;
        };
        let Some(n) = self.epoch.as_ref().map(|e| e.0.n) else {
            return;
        };
        if self.pending.is_some() || asked.is_some_and(|t| now - t < RESYNC_RETRY) {
            return;
        }
        *asked = Some(now);
        self.ask_new_epoch(now, n, "for a new epoch");
    }

    /// A desync seen in the running epoch: ask the host for a new epoch of the same players
    /// (the host notes its own), again every [`RESYNC_RETRY`] until one comes.
    fn ask_repair(&mut self, now: Instant) {
        let Some((n, asked, _)) = self.desynced.as_mut() else {
            return;
        };
        let n = *n;
        if self.epoch.as_ref().map(|e| e.0.n) != Some(n)
            || self.pending.is_some()
            || asked.is_some_and(|t| now - t < RESYNC_RETRY)
        {
            return;
        }
        *asked = Some(now);
        self.ask_new_epoch(now, n, "to repair a desync");
    }

    /// A new epoch to replace epoch `n`: the host notes its own wish, a member asks the host.
    fn ask_new_epoch(&mut self, now: Instant, n: u32, why: &str) {
        if self.session.is_host() {
            self.resync = Some(n);
        } else if let Err(e) = self.session.send(
            now,
            &self.types,
            MessageTarget::Host,
            Delivery::Reliable,
            &Resync { epoch: n },
        ) {
            self.events.push_back(RollbackEvent::Warning(format!(
                "cannot ask the host {why}: {e:?}"
            )));
        }
    }

    /// Host: a new epoch when the members are not the running epoch's players, or when a
    /// player's ggrs session failed or a desync was seen.
    fn host_duties(&mut self, now: Instant) {
        if !self.session.is_host() || self.pending.is_some() {
            return;
        }
        let members: Vec<PeerId> = self.session.members().keys().copied().collect();
        let mut players = members.clone();
        if !players.contains(&self.me) {
            players.push(self.me);
        }
        players.sort();
        let Some((running, _)) = self.epoch.as_ref() else {
            return;
        };
        let resync = self.resync == Some(running.n);
        if self.announced.as_ref() == Some(&players) && !resync {
            return;
        }
        // Only joins (and failed sessions) need a new ggrs session; a player that left is
        // disconnected by ggrs (its slot goes at the next epoch). A new host announces
        // nothing until someone joins.
        let joined = players.iter().any(|p| !running.players.contains(p));
        if !joined && !resync {
            self.announced = Some(players);
            return;
        }
        let Some(frame) = self.confirmed_frame() else {
            return;
        };
        let Some(snap) = self.snapshot_at(frame) else {
            return;
        };
        let n = running.n + 1;
        if resync {
            self.stats.resyncs += 1;
        }
        self.announce(now, n, &snap, players);
    }

    /// The portable state of world frame `frame`, from the ring.
    fn snapshot_at(&self, frame: i32) -> Option<Snapshot> {
        let (_, start) = self.epoch.as_ref()?;
        let state = self.ring.get(&frame.checked_sub(*start)?)?;
        let world = self.world.as_ref()?;
        Some(world.snapshot_of(state))
    }

    fn try_switch(&mut self, now: Instant) {
        let Some(p) = self.pending.as_mut() else {
            return;
        };
        if !p.epoch.players.contains(&self.me) {
            // Not ours (we joined after it was made): the host makes one with us.
            return;
        }
        if let Some(f) = p.fetch.as_mut() {
            while let Some(t) = f.poll_transmit(now) {
                self.outbox.push_back(Transmit {
                    to: t.to,
                    payload: socket::encode_snapshot(p.epoch.n, &t.payload),
                    reliable: false,
                });
            }
            match f.outcome() {
                None => return,
                Some(Ok(blob)) => {
                    let Some(p) = self.pending.take() else { return };
                    match decode_snapshot(&blob) {
                        Ok(snap) if sha256(&blob) == p.epoch.digest => {
                            self.switch_started = Some(p.seen);
                            self.switch_to(p.epoch, snap, blob)
                        }
                        Ok(_) | Err(_) => self.events.push_back(RollbackEvent::Warning(
                            "the epoch's snapshot does not match its digest".into(),
                        )),
                    }
                    return;
                }
                Some(Err(e)) => {
                    self.events.push_back(RollbackEvent::Warning(format!(
                        "fetching epoch {}'s snapshot: {}",
                        p.epoch.n,
                        fetch_error(&e)
                    )));
                    // Ask the host the session knows now (the old one may be gone).
                    let from = self.session.host_id().unwrap_or(p.epoch.host);
                    p.fetch = Some(BlobFetch::new(
                        now,
                        from,
                        MAX_SNAPSHOT_BYTES,
                        Duration::from_secs(10),
                    ));
                    return;
                }
            }
        }
        // A member of the epoch before it: our own confirmed state of the frame, once we have
        // it. (From an older epoch our frames are another timeline: ask the host.)
        let frame = p.epoch.frame;
        let previous = self.epoch.as_ref().map(|e| e.0.n + 1) == Some(p.epoch.n);
        let mine = match self.confirmed_frame() {
            _ if !previous => None,
            Some(c) if c >= frame => self.snapshot_at(frame),
            // not confirmed that far yet (unless our ggrs failed: then never)
            Some(_) if self.failed.is_none() => return,
            Some(_) | None => None,
        };
        let Some(p) = self.pending.as_mut() else {
            return;
        };
        if let Some(snap) = mine {
            let blob = encode_snapshot(&snap);
            if sha256(&blob) == p.epoch.digest {
                let Some(p) = self.pending.take() else { return };
                self.switch_started = Some(p.seen);
                self.switch_to(p.epoch, snap, blob);
                return;
            }
            self.stats.desyncs += 1;
            self.events.push_back(RollbackEvent::Desync {
                frame,
                peer: p.epoch.host,
            });
        }
        // No state of that frame here (a joiner, or it left our ring), or ours differs.
        let from = p.epoch.host;
        p.fetch = Some(BlobFetch::new(
            now,
            from,
            MAX_SNAPSHOT_BYTES,
            Duration::from_secs(10),
        ));
    }

    fn switch_to(&mut self, epoch: Epoch, snap: Snapshot, blob: Vec<u8>) {
        let world =
            match RollbackWorld::from_snapshot(&self.scene, self.cfg.dt_s, &epoch.players, &snap) {
                Ok(w) => w,
                Err(e) => {
                    self.events
                        .push_back(RollbackEvent::Warning(format!("epoch {}: {e}", epoch.n)));
                    return;
                }
            };
        let mut b = ggrs::SessionBuilder::<GgrsConfig>::new()
            .with_max_prediction_window(self.cfg.max_prediction)
            .with_input_delay(self.cfg.input_delay)
            .with_disconnect_timeout(self.cfg.disconnect_timeout)
            .with_desync_detection_mode(DesyncDetection::On {
                interval: self.cfg.desync_interval.max(1),
            });
        let fps = (1.0 / self.cfg.dt_s).round().max(1.0) as usize;
        let built = (|| -> Result<P2PSession<GgrsConfig>, GgrsError> {
            b = b.with_num_players(epoch.players.len())?.with_fps(fps)?;
            for (handle, p) in epoch.players.iter().enumerate() {
                let t = if *p == self.me {
                    PlayerType::Local
                } else {
                    PlayerType::Remote(*p)
                };
                b = b.add_player(t, handle)?;
            }
            {
                let mut q = self.queues.borrow_mut();
                q.epoch = epoch.n;
                q.inbox.clear();
            }
            b.start_p2p_session(GgrsSocket(self.queues.clone()))
        })();
        match built {
            Ok(s) => {
                self.ggrs = Some(s);
                self.failed = None;
                self.resync = None;
                self.world = Some(world);
                self.ring.clear();
                self.server = Some((epoch.n, BlobServer::new(blob)));
                self.events.push_back(RollbackEvent::EpochStarted {
                    n: epoch.n,
                    frame: snap.frame,
                    players: epoch.players.clone(),
                });
                self.stats.epochs += 1;
                // a desync seen in an earlier epoch: this one starts from the host's state (the
                // repair is done when its ggrs session runs)
                if let Some((old, _, seen)) = self.desynced.take() {
                    if old < epoch.n {
                        self.repairing = Some((epoch.n, seen));
                    }
                }
                if self.switch_started.is_none() {
                    self.switch_started = Some(std::time::Instant::now());
                }
                self.epoch = Some((epoch, snap.frame));
            }
            Err(e) => self.events.push_back(RollbackEvent::Warning(format!(
                "epoch {}: ggrs: {e}",
                epoch.n
            ))),
        }
    }

    /// This epoch's ggrs session failed, having confirmed its frame `confirmed`: drop it and
    /// ask for a new epoch.
    fn ggrs_failed(&mut self, confirmed: i32) {
        self.ggrs = None;
        self.stats.ggrs_failures += 1;
        let start = self.epoch.as_ref().map_or(0, |e| e.1);
        self.failed = Some((start.saturating_add(confirmed.max(0)), None));
        self.events.push_back(RollbackEvent::Warning(
            "ggrs failed in this epoch (a rollback past its window): a new epoch is asked for"
                .into(),
        ));
    }

    /// Tests: a non-determinism on this peer alone, once (its next step pushes its first
    /// object's first body aside), to show a desync is detected and repaired. Only with the
    /// `testing` feature (tests turn it on; the shipped binary does not).
    #[cfg(feature = "testing")]
    #[doc(hidden)]
    pub fn inject_desync(&mut self) {
        if let Some(w) = self.world.as_mut() {
            w.kick_once();
        }
    }

    /// Tests: what a ggrs panic does to this peer (its session dropped at its confirmed
    /// frame). ggrs 0.13's panic cannot be provoked on purpose.
    #[doc(hidden)]
    pub fn simulate_ggrs_failure(&mut self) {
        if let Some(c) = self.ggrs.as_ref().map(|g| g.confirmed_frame()) {
            self.ggrs_failed(c);
        }
    }

    fn run_ggrs(&mut self) {
        let Some(g) = self.ggrs.as_mut() else { return };
        let t0 = std::time::Instant::now();
        g.poll_remote_clients();
        for e in g.events() {
            match e {
                GgrsEvent::Disconnected { addr } => self
                    .events
                    .push_back(RollbackEvent::PlayerDisconnected(addr)),
                GgrsEvent::DesyncDetected { frame, addr, .. } => {
                    self.stats.desyncs += 1;
                    let start = self.epoch.as_ref().map_or(0, |e| e.1);
                    if let Some(n) = self.epoch.as_ref().map(|e| e.0.n) {
                        if self.desynced.is_none_or(|d| d.0 != n) {
                            self.desynced = Some((n, None, std::time::Instant::now()));
                        }
                    }
                    self.events.push_back(RollbackEvent::Desync {
                        frame: start.saturating_add(frame),
                        peer: addr,
                    });
                }
                _ => {}
            }
        }
        if g.current_state() != ggrs::SessionState::Running {
            self.stats.stalled_ticks += 1;
            return;
        }
        if let Some(s) = self.switch_started.take() {
            let ms = s.elapsed().as_secs_f32() * 1000.0;
            self.stats.switch_ms_max = self.stats.switch_ms_max.max(ms);
        }
        if let Some((epoch, seen)) = self.repairing.take() {
            let ms = seen.elapsed().as_secs_f32() * 1000.0;
            self.stats.repairs += 1;
            self.stats.repair_ms_max = self.stats.repair_ms_max.max(ms);
            self.events.push_back(RollbackEvent::Repaired { epoch, ms });
        }
        // Far ahead of the others: skip a tick now and then so they catch up.
        self.ticks += 1;
        if g.frames_ahead() >= 2 && self.ticks % 4 == 0 {
            self.stats.waited_ticks += 1;
            return;
        }
        for h in g.local_player_handles() {
            let _ = g.add_local_input(h, self.local_input);
        }
        // ggrs 0.13 panics when a disconnect makes it roll back past its prediction window (a
        // peer stalled, then died, and the survivors disagree on its last frame; seen once in
        // CI under load): that epoch's ggrs session cannot go on, but our world is untouched
        // (the panic comes before any request) and our saved states up to the frame it had
        // confirmed are right. The session is dropped and the host starts a new epoch of the
        // same players from a confirmed frame (`ask_resync`). A peer must not die of it.
        let confirmed = g.confirmed_frame();
        let advanced = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| g.advance_frame()));
        let Ok(advanced) = advanced else {
            self.ggrs_failed(confirmed);
            return;
        };
        let requests = match advanced {
            Ok(r) => r,
            Err(GgrsError::PredictionThreshold) | Err(GgrsError::NotSynchronized) => {
                self.stats.stalled_ticks += 1;
                return;
            }
            Err(e) => {
                self.events
                    .push_back(RollbackEvent::Warning(format!("ggrs: {e}")));
                return;
            }
        };
        let Some(world) = self.world.as_mut() else {
            return;
        };
        let mut advances = 0u64;
        // the newest frame as it was before a rollback (what was drawn), to measure how the
        // re-simulation moved each object there
        let mut before: Option<(i32, Vec<Option<Pose>>)> = None;
        for r in requests {
            match r {
                GgrsRequest::SaveGameState { cell, frame } => {
                    let s0 = std::time::Instant::now();
                    let state = Rc::new(world.save());
                    let sum = world.checksum();
                    self.stats.save_ns += s0.elapsed().as_nanos() as u64;
                    self.stats.saves += 1;
                    cell.save(frame, Some(state.clone()), Some(sum));
                    self.ring.insert(frame, state);
                    while self.ring.len() > self.cfg.ring {
                        self.ring.pop_first();
                    }
                }
                GgrsRequest::LoadGameState { cell, .. } => {
                    if before.is_none() {
                        let poses = (0..world.objects().len())
                            .map(|i| world.object_pose(i))
                            .collect();
                        before = Some((world.frame(), poses));
                    }
                    let s0 = std::time::Instant::now();
                    if let Some(s) = cell.load() {
                        world.load(&s);
                    }
                    self.stats.load_ns += s0.elapsed().as_nanos() as u64;
                    self.stats.rollbacks += 1;
                }
                GgrsRequest::AdvanceFrame { inputs } => {
                    let inputs: Vec<PlayerInput> = inputs.iter().map(|(i, _)| *i).collect();
                    world.step(&inputs);
                    advances += 1;
                    let frame = world.frame();
                    if let Some((_, poses)) = before.take_if(|(f, _)| *f == frame) {
                        Self::note_correction(
                            world,
                            &poses,
                            &mut self.corrections,
                            &mut self.stats.correction_mm,
                        );
                    }
                }
            }
        }
        self.stats.frames += 1;
        self.stats.resimulated += advances.saturating_sub(1);
        // the last 10 minutes of frames (a long run must not grow without bound)
        if self.stats.frame_ms.len() >= 36_000 {
            self.stats.frame_ms.drain(..18_000);
        }
        self.stats
            .frame_ms
            .push(t0.elapsed().as_secs_f32() * 1000.0);
    }

    /// How the rollback re-simulation moved each object at the frame drawn before it.
    fn note_correction(
        world: &RollbackWorld,
        before: &[Option<Pose>],
        acc: &mut Option<Vec<Correction>>,
        mm: &mut Vec<f32>,
    ) {
        let none = Correction {
            pos: glam::Vec3::ZERO,
            rot: glam::Quat::IDENTITY,
        };
        let acc = acc.get_or_insert_with(|| vec![none; before.len()]);
        acc.resize(before.len(), none);
        let mut largest = 0.0f32;
        for (i, b) in before.iter().enumerate() {
            let (Some((p0, r0)), Some((p1, r1))) = (b, world.object_pose(i)) else {
                continue;
            };
            let c = &mut acc[i];
            c.pos += *p0 - p1;
            c.rot = (*r0 * r1.inverse()).normalize() * c.rot;
            largest = largest.max(p0.distance(p1));
        }
        if largest > 1e-6 {
            if mm.len() >= 36_000 {
                mm.drain(..18_000);
            }
            mm.push(largest * 1000.0);
        }
    }

    /// The corrections of the rollbacks since the last call, per object in scene order (`None`
    /// when nothing rolled back): see [`Correction`].
    pub fn take_corrections(&mut self) -> Option<Vec<Correction>> {
        self.corrections.take()
    }

    /// Next datagram to send: the session's, then ggrs's and the snapshot's.
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Transmit> {
        if let Some(t) = self.session.poll_transmit(now) {
            return Some(t);
        }
        self.outbox.pop_front()
    }

    /// Leave the room (the session says goodbye; ggrs's peers disconnect us by timeout).
    pub fn leave(&mut self, now: Instant) {
        self.session.leave(now);
    }

    /// Whether a ggrs session runs (not synchronising).
    pub fn running(&self) -> bool {
        self.ggrs
            .as_ref()
            .is_some_and(|g| g.current_state() == ggrs::SessionState::Running)
    }
}

fn fetch_error(e: &FetchError) -> String {
    format!("{e}")
}

/// A snapshot's bytes (bincode, standard).
pub fn encode_snapshot(s: &Snapshot) -> Vec<u8> {
    bincode::serde::encode_to_vec(s, bincode::config::standard()).unwrap_or_default()
}

/// A snapshot from bytes (bounded: never allocates more than [`MAX_SNAPSHOT_BYTES`]).
pub fn decode_snapshot(bytes: &[u8]) -> Result<Snapshot, String> {
    let cfg = bincode::config::standard().with_limit::<{ MAX_SNAPSHOT_BYTES as usize }>();
    bincode::serde::decode_from_slice::<Snapshot, _>(bytes, cfg)
        .map(|(s, _)| s)
        .map_err(|e| e.to_string())
}
