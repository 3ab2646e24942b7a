//! [`Peer`]: one peer of a room. It puts together the session (membership, ownership,
//! replication), the mirror of the room's objects in a rapier world, the hands, the avatar
//! and the way in ([`crate::join`]), and acts on what each says to the others: a hand that
//! reaches for someone else's object asks the session for it, a grant lets the hand hold on,
//! an object that came to rest goes back to the host, a peer the room went on without joins
//! again.
//!
//! Sans-IO: it reads no clock and owns no socket. The driver feeds it datagrams and link
//! news, calls [`Peer::pump`] and [`Peer::fixed_step`] with `now`, and sends what
//! [`Peer::poll_transmit`] gives it.

mod auto;
mod blade;
mod bounds;
mod builds;
mod comanip;
pub mod cost;
pub mod cutter;
pub mod keep;
mod orphans;
pub mod replay;
mod show;
pub mod topology;

use std::collections::{BTreeSet, HashMap, VecDeque};
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_interaction::{
    HandConfig, HandId, HandInput, Interaction, InteractionEvent, ObjectRef, Ownership, Target,
};
use softsync_net::messages::{Message, MessageTypes};
use softsync_net::{
    Delivery, Instant, MessageKind, MessageRefusal, MessageTarget, NetId, ObjectState, PeerEvent,
    PeerId, ReceivedMessage, Session, Transmit,
};

use crate::avatar::Avatar;
use crate::events::{Counters, Event, PeerError};
use crate::join::Joining;
use crate::mirror::{LocalBody, Mirror};
use crate::scene::{Kind, Scene};
use cost::Phase;

/// How a peer simulates and how patient it is.
#[derive(Clone, Debug)]
pub struct PeerConfig {
    /// Both hands' configuration.
    pub hand: HandConfig,
    /// The fixed simulation step, seconds.
    pub dt_s: f32,
    /// Spawn an avatar (head and hands); false to measure one object's traffic.
    pub avatar: bool,
    /// How many times to join again after the room went on without us within a minute
    /// ([`crate::join::REJOIN_WINDOW`]; 0: stop instead).
    pub rejoin_limit: u32,
    /// How long a joiner waits for a welcome before [`Peer::pump`] gives up.
    pub join_timeout: Duration,
    /// Whether we let other peers' hands hold the bodies we own whose class is
    /// `OwnerMustAgree` (remote hands, `peer/comanip.rs`; `Free` classes always let them,
    /// `Locked` ones never).
    pub agree_to_hands: bool,
    /// Whether objects that come with a topology history (a cut's pieces, a late joiner's
    /// torn bodies) are built on a worker thread while the frame goes on (`peer/builds.rs`),
    /// or in the frame that receives them. The body is the same either way.
    pub build_off_frame: bool,
    /// When an off-frame build lands: false, [`BUILD_LANDS_AFTER`](crate::mirror) (30 ms)
    /// after it started, the frame waiting for the worker if it is not done (the frame it
    /// lands in depends on the peer's clock alone: runs on virtual time repeat exactly);
    /// true, at 30 ms or at the first frame after that once the worker is done, so no frame
    /// ever waits for one (a slow machine's worker took 50 ms, and a frame waited 20 of
    /// them); the body is the same, landing a frame or two later. The app sets it: its
    /// peers run on the wall clock.
    pub land_when_ready: bool,
}

impl Default for PeerConfig {
    fn default() -> Self {
        PeerConfig {
            hand: HandConfig::default(),
            dt_s: 1.0 / 60.0,
            avatar: true,
            rejoin_limit: 3,
            join_timeout: Duration::from_secs(15),
            agree_to_hands: true,
            build_off_frame: true,
            land_when_ready: false,
        }
    }
}

/// After a rejoin the fresh session waits this long before its first datagram: what the old
/// session sent last (its leftovers, datagrams still in the transport from before a stall) then
/// reaches the host first. Arriving after the fresh `Hello`, an old datagram of the same term
/// is taken as the new member's — its acks name the old session's numbers — and the fresh
/// session's `Welcome` could be taken as delivered when it was not (the churn soak's stopped
/// peers that never got back in).
pub const REJOIN_QUIET: Duration = Duration::from_millis(300);

/// One peer of a room: session, rapier world, soft bodies, hands, avatar.
pub struct Peer {
    session: Session,
    /// The room's message types (read from the session's configuration).
    message_types: MessageTypes,
    mirror: Mirror,
    hands: Interaction,
    /// Left and right hand.
    hand_ids: [HandId; 2],
    scene: Scene,
    config: PeerConfig,
    avatar: Avatar,
    joining: Joining,
    /// Objects our hands asked for, until the answer.
    waiting_grant: BTreeSet<NetId>,
    events: VecDeque<Event>,
    counters: Counters,
    /// Per hand: the scalpel its trigger holds (see `topology`).
    scalpels: [topology::Scalpel; 2],
    /// What each hand's trigger does, and its cutter's sweep.
    tools: [cutter::HandTool; 2],
    sweeps: [cutter::Sweep; 2],
    /// `method: auto` bodies we own.
    auto: auto::AutoBodies,
    /// Hands of several peers on one body (remote hands, both ways).
    comanip: comanip::Comanip,
    /// Cuts and tears of bodies others own (requests, both ways).
    blades: blade::Blades,
    /// Datagrams an old session had still to send when we rejoined.
    leftover: VecDeque<Transmit>,
    /// After a rejoin, the fresh session says nothing until then (see [`REJOIN_QUIET`]).
    quiet_until: Option<Instant>,
    sim_time_s: f64,
    steps: u64,
    last_step_at: Instant,
    /// A lent clock measuring where frames go (`cost.rs`).
    stopwatch: cost::Stopwatch,
    /// A recorded session played back (`replay`): bodies are shown, not simulated, and
    /// nobody else's blade cuts them.
    replaying: bool,
}

/// The hands' answer to "may this peer move that object": its session says who owns it.
struct SessionOwnership<'a> {
    me: PeerId,
    session: &'a Session,
    by_ref: &'a HashMap<ObjectRef, NetId>,
}

impl Ownership for SessionOwnership<'_> {
    fn is_local(&self, object: ObjectRef) -> bool {
        self.by_ref
            .get(&object)
            .is_some_and(|id| self.session.owner(*id) == Some(self.me))
    }
}

impl Peer {
    /// A peer around `session` (hosting, or joining through `contact`, the peer its session
    /// said `Hello` to), with `scene`'s static geometry built. A host then calls
    /// [`Peer::open`].
    pub fn new(
        now: Instant,
        session: Session,
        contact: Option<PeerId>,
        scene: Scene,
        config: PeerConfig,
    ) -> Result<Self, PeerError> {
        let mirror = Mirror::new(&scene, config.dt_s);
        let mut hands = Interaction::new();
        let mut add_hand = || {
            hands
                .add_hand(config.hand.clone())
                .map_err(|e| PeerError::Build(e.to_string()))
        };
        let hand_ids = [add_hand()?, add_hand()?];
        let joining = Joining::new(now, session.is_host(), contact);
        let message_types = MessageTypes::from_config(session.config()).ok_or_else(|| {
            PeerError::Build("the room's message table names a type twice".into())
        })?;
        Ok(Peer {
            message_types,
            session,
            mirror,
            hands,
            hand_ids,
            scene,
            config,
            avatar: Avatar::default(),
            joining,
            waiting_grant: BTreeSet::new(),
            events: VecDeque::new(),
            counters: Counters::default(),
            scalpels: Default::default(),
            tools: Default::default(),
            sweeps: Default::default(),
            auto: Default::default(),
            comanip: Default::default(),
            blades: Default::default(),
            leftover: VecDeque::new(),
            quiet_until: None,
            sim_time_s: 0.0,
            steps: 0,
            last_step_at: Instant::ZERO,
            stopwatch: cost::Stopwatch::default(),
            replaying: false,
        })
    }

    /// The host opens the room: spawn the scene's objects and our avatar.
    pub fn open(&mut self, now: Instant) -> Result<(), PeerError> {
        for p in self.scene.objects.clone() {
            let body = self.mirror.build(&self.scene, p.kind, p.pos, p.rot)?;
            let state = self.mirror.body_state(body, (p.pos, p.rot));
            let (id, _) = self
                .session
                .spawn(now, p.kind.class(), state)
                .map_err(|e| {
                    PeerError::Build(format!("spawning {}: {e}", self.scene.name_of(p.kind)))
                })?;
            self.mirror.insert(id, p.kind, body, None);
        }
        self.spawn_avatar(now);
        Ok(())
    }

    fn spawn_avatar(&mut self, now: Instant) {
        if self.config.avatar {
            self.avatar
                .spawn(now, &mut self.session, &mut self.mirror, &mut self.events);
        }
    }

    // --- Sans-IO: what the driver feeds in and takes out ---

    /// A datagram from `from` arrived.
    pub fn handle_datagram(&mut self, now: Instant, from: PeerId, datagram: &[u8]) {
        self.session.handle_packet(now, from, datagram);
    }

    /// Connectivity news from the transport: informational for the session (its heartbeats
    /// decide who is gone); a joiner uses it to find someone who can answer its `Hello`.
    pub fn handle_link_event(&mut self, event: PeerEvent) {
        self.joining.on_link_event(event);
    }

    /// Timers and the session's news: the join retry, the session's timeouts, acting on its
    /// events, the join timeout. Call once per frame, after this frame's datagrams and link
    /// events. An error means the peer must stop.
    pub fn pump(&mut self, now: Instant) -> Result<(), PeerError> {
        self.stopwatch.start();
        if let Some(next) = self.joining.next_contact(now) {
            // The same session: the peers asked before keep their sequences with us in step.
            self.session.join_via(now, next);
        }
        if self.session.poll_timeout().is_some_and(|t| t <= now) {
            self.session.handle_timeout(now);
        }
        self.stopwatch.lap(Phase::Timers);
        while let Some(e) = self.session.poll_event() {
            self.on_session_event(now, e)?;
        }
        self.stopwatch.lap(Phase::Events);
        self.land_builds(now);
        self.adopt_orphans(now);
        self.stopwatch.lap(Phase::Builds);
        if self.joining.overdue(now, self.config.join_timeout) {
            return Err(PeerError::NotWelcomed {
                secs: self.config.join_timeout.as_secs(),
            });
        }
        Ok(())
    }

    /// When [`Peer::pump`] has something to do next (for drivers on virtual time; a frame
    /// loop just pumps every frame).
    pub fn poll_timeout(&self) -> Option<Instant> {
        let join = self.joining.poll_timeout(self.config.join_timeout);
        [self.session.poll_timeout(), join, self.quiet_until]
            .into_iter()
            .flatten()
            .min()
    }

    /// The next datagram to send. Drain after [`Peer::pump`], [`Peer::fixed_step`] and
    /// [`Peer::leave`].
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Transmit> {
        if let Some(t) = self.leftover.pop_front() {
            return Some(t);
        }
        if self.quiet_until.is_some_and(|q| now < q) {
            return None;
        }
        self.quiet_until = None;
        self.session.poll_transmit(now)
    }

    /// The next thing that happened, oldest first.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// Say goodbye: the others drop us at once instead of after the peer timeout. Send what
    /// [`Peer::poll_transmit`] gives before the process ends.
    pub fn leave(&mut self, now: Instant) {
        self.session.leave(now);
    }

    /// Count the join timeout from `now` (a driver that holds the network while its front
    /// end warms up).
    pub fn restart_join_clock(&mut self, now: Instant) {
        self.joining.restart_clock(now);
    }

    /// The room went on without us: its objects have other owners, and our replica is stale.
    /// Let go of everything, drop every networked object from the local world (the static
    /// scene stays) and join `host` again with a fresh session; the room's snapshot then
    /// rebuilds the objects, and `Joined` respawns our avatar.
    fn rejoin(&mut self, now: Instant, host: PeerId, reason: String) {
        self.counters.rejoins += 1;
        // what we owned here and did while apart is not the room's: counted, then dropped
        let me = self.me();
        self.counters.discarded_objects += self
            .mirror
            .objects
            .iter()
            .filter(|(id, o)| !o.kind.is_avatar() && self.session.owner(**id) == Some(me))
            .count() as u64;
        // what the old session still had to send goes first (a yielding host's word to its
        // members, after a partition healed)
        while let Some(t) = self.session.poll_transmit(now) {
            self.leftover.push_back(t);
        }
        self.hands.release_all();
        self.comanip.clear();
        self.blades.clear();
        self.mirror.clear();
        self.avatar.clear();
        self.waiting_grant.clear();
        let cfg = self.session.config().clone();
        let fresh = Session::join(self.me(), host, cfg, now);
        let mut old = std::mem::replace(&mut self.session, fresh);
        self.session.take_message_filter_from(&mut old);
        // our messages the old room never delivered everywhere are lost with it: say so
        for seq in old.undelivered_messages() {
            self.events
                .push_back(Event::Room(softsync_net::Event::MessageRefused {
                    seq,
                    reason: MessageRefusal::NotConnected,
                }));
        }
        self.joining.restart(now, host);
        self.quiet_until = Some(now + REJOIN_QUIET);
        self.events.push_back(Event::Rejoining { host, reason });
    }

    fn on_session_event(&mut self, now: Instant, e: softsync_net::Event) -> Result<(), PeerError> {
        use softsync_net::Event as SessionEvent;
        let me = self.me();
        match e {
            SessionEvent::Joined { .. } => {
                self.joining.set_joined();
                self.events.push_back(Event::Room(e));
                self.spawn_avatar(now);
            }
            SessionEvent::Refused { reason } => return Err(PeerError::Refused(reason)),
            SessionEvent::Dropped { host, reason } => {
                if !self.joining.may_rejoin(now, self.config.rejoin_limit) {
                    return Err(PeerError::Dropped {
                        reason,
                        rejoins: self.counters.rejoins,
                    });
                }
                self.rejoin(now, host, reason);
            }
            SessionEvent::PeerJoined(_) | SessionEvent::Kicked(_) => {
                self.events.push_back(Event::Room(e))
            }
            SessionEvent::PeerLeft(p) => {
                self.forget_hands_of(p);
                self.events.push_back(Event::Room(e));
                if self.session.is_host() {
                    self.despawn_avatars_of_absent(now);
                }
            }
            SessionEvent::HostChanged { host, .. } => {
                self.counters.host_changes += 1;
                self.events.push_back(Event::Room(e));
                if host == me {
                    self.despawn_avatars_of_absent(now);
                }
            }
            SessionEvent::Spawned {
                id,
                class,
                owner,
                request,
            } => {
                self.mirror.forget_leaving(id);
                if self.mirror.objects.contains_key(&id) {
                    return Ok(());
                }
                let kind = Kind::of_class(class);
                if self.scene.class(kind).is_none() {
                    return Ok(());
                }
                let s = self
                    .session
                    .latest_state(id)
                    .unwrap_or_else(|| ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY));
                let avatar_of = kind.is_avatar().then_some(owner);
                if !self.build_off_frame(now, id, kind, avatar_of, &s)? {
                    let body = self.mirror.build(&self.scene, kind, s.pos, s.rot)?;
                    self.mirror.insert(id, kind, body, avatar_of);
                }
                if let (true, Some(request)) = (owner == me, request) {
                    self.avatar
                        .on_spawned(request, id, (s.pos, s.rot), &mut self.mirror);
                }
            }
            SessionEvent::Despawned(id) => {
                self.orphan_hands_of(now, id);
                self.despawn_shown(now, id);
            }
            SessionEvent::AuthorityChanged { id, owner, .. } => {
                if !self.mirror.objects.contains_key(&id) {
                    return Ok(()); // despawned meanwhile (the avatar of a peer that left)
                }
                self.on_owner_changed(id, owner == me);
                if owner == me {
                    self.counters.authority_grants += 1;
                    self.events.push_back(Event::AuthorityGained(id));
                    // Take over from what we showed.
                    if let Some(s) = self.session.latest_state(id) {
                        self.apply_shown(id, &s);
                    }
                    self.waiting_grant.remove(&id);
                    // hands waiting for it, and remote hands on it, hold it here now
                    if let Some(r) = self.mirror.object_ref(id) {
                        self.hands.grant(r);
                    }
                } else if let Some(r) = self.mirror.object_ref(id) {
                    // hands holding what another peer simulates now go on as remote hands
                    self.hands.hold_as_remote(r);
                }
                self.mirror.set_simulated(id, owner == me);
            }
            SessionEvent::AuthorityDenied { id, reason } => {
                let waited = self.waiting_grant.remove(&id);
                if waited && self.grab_as_remote_on_denial(id, reason) {
                    return Ok(()); // someone holds it: our hand holds it with theirs
                }
                self.events.push_back(Event::AuthorityDenied(id));
                if waited {
                    if let Some(r) = self.mirror.object_ref(id) {
                        self.hands.deny(r);
                    }
                }
            }
            SessionEvent::Topology { id, seq, event } => {
                self.on_topology(now, id, seq, event);
                self.events.push_back(Event::Room(e));
            }
            SessionEvent::Message(ref m) if self.on_comanip_message(now, m) => {}
            SessionEvent::Message(_)
            | SessionEvent::MessageDelivered { .. }
            | SessionEvent::MessageRefused { .. } => self.events.push_back(Event::Room(e)),
            SessionEvent::AuthorityAsked { id, by } => {
                // Not while one of our hands holds it.
                let held = self.mirror.object_ref(id).is_some_and(|r| self.is_held(r));
                self.session.answer_authority(now, id, by, !held);
            }
        }
        Ok(())
    }

    /// The host removes the avatars of peers that are no longer members.
    fn despawn_avatars_of_absent(&mut self, now: Instant) {
        let members = self.session.members();
        let gone: Vec<NetId> = self
            .mirror
            .objects
            .iter()
            .filter(|(_, o)| o.avatar_of.is_some_and(|p| !members.contains_key(&p)))
            .map(|(id, _)| *id)
            .collect();
        for id in gone {
            if self.session.despawn(now, id).is_ok() {
                self.mirror.remove(id);
            }
        }
    }

    fn apply_shown(&mut self, id: NetId, s: &ObjectState) {
        if !self.mirror.apply_shown(id, s) {
            self.counters.apply_errors += 1;
        }
    }

    fn is_held(&self, r: ObjectRef) -> bool {
        self.hand_ids
            .iter()
            .any(|h| self.hands.held(*h).is_some_and(|t| t.object() == r))
    }

    // --- Application messages ---

    /// Send a typed message through the room (see [`Session::send_message`]: whom to,
    /// how, the bounds); what happens to it comes back as [`Event::Room`] with
    /// `MessageDelivered` or `MessageRefused`. `M` must be in the room's message table.
    pub fn send<M: Message>(
        &mut self,
        now: Instant,
        to: MessageTarget,
        delivery: Delivery,
        msg: &M,
    ) -> Result<u32, MessageRefusal> {
        self.session
            .send(now, &self.message_types, to, delivery, msg)
    }

    /// Host: kick `peer` out of the room and ban it for the room's life, telling it `reason`
    /// ([`Session::kick`]: its id and join token stay out after a migration too).
    pub fn kick(
        &mut self,
        now: Instant,
        peer: PeerId,
        reason: &str,
    ) -> Result<(), softsync_net::KickError> {
        self.session.kick(now, peer, reason)
    }

    /// Send raw bytes of message type `kind`.
    pub fn send_message(
        &mut self,
        now: Instant,
        kind: MessageKind,
        to: MessageTarget,
        delivery: Delivery,
        payload: Vec<u8>,
    ) -> Result<u32, MessageRefusal> {
        self.session.send_message(now, kind, to, delivery, payload)
    }

    /// A received message as an `M`: `None` if it is another type, an error if its bytes
    /// are not an `M`.
    pub fn decode<M: Message>(&self, m: &ReceivedMessage) -> Option<Result<M, MessageRefusal>> {
        self.message_types.decode(m)
    }

    /// The room's message types.
    pub fn message_types(&self) -> &MessageTypes {
        &self.message_types
    }

    /// The host's check on every message it relays (see [`Session::set_message_filter`];
    /// install it on every peer, since any may become the host).
    pub fn set_message_filter(
        &mut self,
        filter: impl FnMut(&ReceivedMessage) -> Result<(), u16> + Send + Sync + 'static,
    ) {
        self.session.set_message_filter(filter);
    }

    // --- Simulation ---

    /// Asks the host for authority over `id` (a bot's `own`); the answer comes as
    /// [`Event::AuthorityGained`] or [`Event::AuthorityDenied`].
    pub fn ask_authority(&mut self, now: Instant, id: NetId) {
        self.counters.authority_requests += 1;
        let _ = self.session.request_authority(now, id);
    }

    /// Hand input for the next step (0 left, 1 right), from a bot or a device.
    pub fn set_hand_input(&mut self, hand: usize, input: HandInput) {
        if let Some(s) = self.scalpels.get_mut(hand) {
            s.input = Some((
                input.sample.position_m,
                input.sample.rotation,
                input.trigger,
            ));
        }
        if let Some(h) = self.hand_ids.get(hand).copied() {
            if let Err(e) = self.hands.set_input(h, input) {
                self.events
                    .push_back(Event::Warning(format!("hand input refused: {e}")));
            }
        }
    }

    /// Set a pose for one of our avatar parts (0 head, 1 left hand, 2 right hand).
    pub fn set_avatar_pose(&mut self, part: usize, pos: Vec3, rot: Quat) {
        if let Some(id) = self.avatar.parts.get(part).copied().flatten() {
            self.mirror.set_pose(id, pos, rot);
        }
    }

    /// Advance the simulation by one fixed step at `now` and publish what we own (then send
    /// what [`Peer::poll_transmit`] gives).
    pub fn fixed_step(&mut self, now: Instant) {
        self.stopwatch.start();
        let me = self.me();
        let dt = self.config.dt_s;
        self.sim_time_s += dt as f64;
        self.steps += 1;
        self.last_step_at = now;
        // Show what others simulate (before the step, so our bodies collide with it).
        let remote: Vec<NetId> = self
            .mirror
            .objects
            .keys()
            .copied()
            .filter(|id| self.session.owner(*id).is_some_and(|o| o != me))
            .collect();
        for id in &remote {
            self.mirror.set_simulated(*id, false);
            if let Some(mut d) = self.session.display_state(now, *id) {
                self.predict_shown(*id, &mut d.state);
                if !self.mirror.place_shown(*id, &d.state) {
                    self.counters.apply_errors += 1;
                }
            }
        }
        // Under an uplink budget, what is near each peer's head goes to it first.
        if self.session.config().uplink_bytes_per_s.is_some() {
            let heads: Vec<(PeerId, NetId)> = self
                .mirror
                .objects
                .iter()
                .filter(|(_, o)| o.kind == Kind::HEAD)
                .filter_map(|(id, o)| Some((o.avatar_of.filter(|p| *p != me)?, *id)))
                .collect();
            for (p, id) in heads {
                let at = self.session.latest_state(id).map(|s| s.pos);
                self.session.set_interest(p, at);
            }
        }
        self.stopwatch.lap(Phase::Shown);
        // Hands, then physics.
        let own = SessionOwnership {
            me,
            session: &self.session,
            by_ref: &self.mirror.by_ref,
        };
        self.hands
            .update(&mut self.mirror.world, &mut self.mirror.soft, &own, dt);
        while let Some(e) = self.hands.poll_event() {
            self.on_hand_event(now, e);
        }
        self.send_remote_hands(now);
        self.apply_remote_hands(now);
        self.stopwatch.lap(Phase::Hands);
        self.use_scalpels(now);
        self.flush_blades(now);
        self.stopwatch.lap(Phase::Blades);
        // `SoftBodySet::step`, its three parts timed apart
        self.mirror.world.integration_parameters.dt = dt;
        self.mirror.soft.pre_physics(&mut self.mirror.world, dt);
        self.stopwatch.lap(Phase::Restoring);
        self.mirror.world.step();
        self.stopwatch.lap(Phase::Rapier);
        self.mirror.soft.post_physics(&self.mirror.world);
        self.stopwatch.lap(Phase::Deform);
        self.run_auto(now);
        self.publish_holders(now);
        self.age_fades();
        self.stopwatch.lap(Phase::Publish);
        // Remote soft bodies: show exactly the interpolated state again after the step.
        for id in &remote {
            let soft = matches!(
                self.mirror.objects.get(id).map(|o| o.body),
                Some(LocalBody::Soft(_))
            );
            if soft {
                if let Some(mut d) = self.session.display_state(now, *id) {
                    self.predict_shown(*id, &mut d.state);
                    if !self.mirror.finish_shown(*id, &d.state) {
                        self.counters.apply_errors += 1;
                    }
                }
            }
        }
        self.stopwatch.lap(Phase::Shown);
        // Publish ours.
        let owned: Vec<NetId> = self
            .mirror
            .objects
            .keys()
            .copied()
            .filter(|id| self.session.owner(*id) == Some(me))
            .collect();
        for id in owned {
            // Ours since a grant or a migration: simulate it (idempotent).
            self.mirror.set_simulated(id, true);
            let Some((body, kind, pose)) = self
                .mirror
                .objects
                .get(&id)
                .map(|o| (o.body, o.kind, o.pose))
            else {
                continue;
            };
            let s = self.mirror.body_state(body, pose);
            let s = self.keep_in_bounds(id, body, kind, s);
            if body == LocalBody::Building {
                continue; // nothing to publish until it lands
            }
            let layout = self.session.particles_of(id).map(|n| n as usize);
            if matches!(body, LocalBody::Soft(_)) && layout != Some(s.particles.len()) {
                // a resolution change the session has and our body gets at the next pump
                continue;
            }
            if let Err(e) = self.session.publish_state(now, id, &s) {
                let msg = format!("not publishing {}: {e}", self.scene.name_of(kind));
                self.events.push_back(Event::Warning(msg));
            }
        }
        self.stopwatch.lap(Phase::Publish);
    }

    fn on_hand_event(&mut self, now: Instant, e: InteractionEvent) {
        match e {
            InteractionEvent::AuthorityRequested { object, .. } => {
                if self.grab_as_remote_if_held(object) {
                    return; // someone holds it: our hand holds it with theirs
                }
                if let Some(id) = self.mirror.id_of(object) {
                    self.counters.authority_requests += 1;
                    self.events.push_back(Event::AuthorityAsked(id));
                    match self.session.request_authority(now, id) {
                        Ok(()) => {
                            self.waiting_grant.insert(id);
                        }
                        Err(_) => self.hands.deny(object),
                    }
                }
            }
            InteractionEvent::Grabbed { hand, target } => {
                if let Some(id) = self.mirror.id_of(target.object()) {
                    let particle = match target {
                        Target::SoftParticle(_, p) => Some(p),
                        _ => None,
                    };
                    self.events
                        .push_back(Event::GrabStarted { id, hand, particle });
                }
            }
            InteractionEvent::Released {
                hand,
                target,
                velocity_mps,
            } => {
                if let Some(id) = self.mirror.id_of(target.object()) {
                    let speed = velocity_mps.length();
                    self.events.push_back(Event::GrabEnded { id, hand, speed });
                }
            }
            InteractionEvent::RemoteReleased {
                hand,
                target,
                velocity_mps,
            } => {
                self.remote_released(hand, velocity_mps);
                if let Some(id) = self.mirror.id_of(target.object()) {
                    let speed = velocity_mps.length();
                    self.events.push_back(Event::GrabEnded { id, hand, speed });
                }
            }
            InteractionEvent::CameToRest { object } => {
                if let Some(id) = self.mirror.id_of(object) {
                    if !self.session.is_host()
                        && self.session.owner(id) == Some(self.me())
                        && !self.is_held(object)
                        && !self.remote_hands_on(id)
                        && self.session.release_authority(now, id).is_ok()
                    {
                        self.events.push_back(Event::AuthorityReleased(id));
                    }
                }
            }
            _ => {}
        }
    }
}
