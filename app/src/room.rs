//! One peer in a room: the session, its transport, the rapier world with the scene, the hands,
//! and the glue between them. The bevy plugins in `plugins.rs` call into this each frame;
//! nothing here knows about bevy.
//!
//! Who simulates what: the owner of an object simulates it (rigid props are dynamic bodies,
//! soft bodies run the particle method); everyone else shows the session's interpolated state
//! (rigid props become kinematic, soft bodies get `apply_state`).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_interaction::{
    HandConfig, HandId, HandInput, Interaction, InteractionEvent, ObjectRef, Ownership, Target,
};
use softsync_net::{
    Event, Instant, NetId, ObjectState, PeerEvent, PeerId, Session, Term, Transport,
};
use softsync_softbody::rapier3d::prelude::*;
use softsync_softbody::{SoftBodyHandle, SoftBodySet};

use crate::scene::{Kind, Scene};

/// How long a joiner waits for an answer to its `Hello` before trying the next peer.
const JOIN_RETRY: Duration = Duration::from_millis(1000);

/// How a networked object exists in the local world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Body {
    /// A pose only (avatar parts).
    Pose,
    /// A rigid body.
    Rigid(RigidBodyHandle),
    /// A soft body.
    Soft(SoftBodyHandle),
}

/// A networked object as this peer knows it.
#[derive(Clone, Debug)]
pub struct Obj {
    /// What it is.
    pub kind: Kind,
    /// Its local body.
    pub body: Body,
    /// For avatar parts: the peer whose avatar it is (its first owner).
    pub avatar_of: Option<PeerId>,
    /// Last pose of an avatar part we own (set by the bot or the device).
    pub pose: (Vec3, Quat),
}

/// Something that happened, for the log and the tests.
#[derive(Clone, Debug, PartialEq)]
pub enum Note {
    /// Joined the room.
    Joined {
        /// Host.
        host: PeerId,
        /// Term.
        term: Term,
    },
    /// The host changed.
    HostChanged {
        /// New host.
        host: PeerId,
        /// New term.
        term: Term,
    },
    /// A peer joined.
    PeerJoined(PeerId),
    /// A peer left.
    PeerLeft(PeerId),
    /// We asked for an object.
    AuthorityAsked(NetId),
    /// An object became ours.
    AuthorityGained(NetId),
    /// Our request was denied.
    AuthorityDenied(NetId),
    /// We gave an object back.
    AuthorityReleased(NetId),
    /// A hand (0 left, 1 right) started holding an object (`particle`: one particle of a soft
    /// body rather than its center).
    GrabStarted {
        /// The object.
        id: NetId,
        /// The hand.
        hand: usize,
        /// The particle held, if one.
        particle: Option<u32>,
    },
    /// A hand let go of an object, throwing it at `speed` m/s.
    GrabEnded {
        /// The object.
        id: NetId,
        /// The hand.
        hand: usize,
        /// Throw speed.
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
}

/// Why the peer must stop.
#[derive(Debug, thiserror::Error)]
pub enum RoomError {
    /// The host refused us.
    #[error("the host refused us: {0}")]
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
    /// Connected but never welcomed.
    #[error("connected to room {room:?} but no host welcomed us within {secs} s")]
    NotWelcomed {
        /// Room.
        room: String,
        /// Seconds waited.
        secs: u64,
    },
    /// A body could not be built.
    #[error("{0}")]
    Scene(String),
}

/// Counters for the stats line and the benchmarks.
#[derive(Clone, Copy, Debug, Default)]
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
}

/// One peer.
pub struct Room {
    /// The session.
    pub session: Session,
    /// The transport (WebRTC, maybe behind the link conditioner).
    pub transport: Box<dyn Transport>,
    /// rapier.
    pub world: PhysicsWorld,
    /// Soft bodies.
    pub soft: SoftBodySet,
    /// Hands.
    pub hands: Interaction,
    /// Left and right hand ids.
    pub hand_ids: [HandId; 2],
    /// Networked objects.
    pub objects: BTreeMap<NetId, Obj>,
    /// The scene.
    pub scene: Scene,
    /// This peer's avatar: head, left hand, right hand (once spawned).
    pub avatar: [Option<NetId>; 3],
    avatar_requests: [Option<u32>; 3],
    by_ref: HashMap<ObjectRef, NetId>,
    waiting_grant: BTreeSet<NetId>,
    joined: bool,
    /// Joining: peers with open data channels, in the order they connected, and the one our
    /// `Hello` went to last (another joiner cannot answer: we move on after `JOIN_RETRY`).
    contacts: Vec<PeerId>,
    contact: Option<(PeerId, std::time::Instant)>,
    started: std::time::Instant,
    /// When joining started (the front end may hold the network until it renders).
    join_started: std::time::Instant,
    /// Notes for the log and the bot.
    pub notes: Vec<Note>,
    /// Counters.
    pub counters: Counters,
    /// Simulation step.
    pub dt: f32,
    sim_time: f64,
    /// Fixed steps run.
    pub steps: u64,
    /// Spawn no avatar (measurements of one object's traffic).
    pub no_avatar: bool,
    /// How many times to join again after the room went on without us (0: stop instead).
    pub rejoin_limit: u32,
    /// The session time of the last fixed step: the time our published states stand for.
    pub last_step_at: Instant,
}

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

impl Room {
    /// A peer around `session` on `transport`, with the scene's static geometry built.
    /// `contact`: for a joiner, the peer its session sent `Hello` to.
    pub fn new(
        contact: Option<PeerId>,
        session: Session,
        transport: Box<dyn Transport>,
        scene: Scene,
        hand: HandConfig,
        dt: f32,
    ) -> Result<Self, RoomError> {
        let mut world = PhysicsWorld::new();
        world.integration_parameters.dt = dt;
        scene.build_static(&mut world);
        let mut hands = Interaction::new();
        let l = hands
            .add_hand(hand.clone())
            .map_err(|e| RoomError::Scene(e.to_string()))?;
        let r = hands
            .add_hand(hand)
            .map_err(|e| RoomError::Scene(e.to_string()))?;
        let joined = session.is_host();
        Ok(Room {
            session,
            transport,
            world,
            soft: SoftBodySet::new(),
            hands,
            hand_ids: [l, r],
            objects: BTreeMap::new(),
            scene,
            avatar: [None; 3],
            avatar_requests: [None; 3],
            by_ref: HashMap::new(),
            waiting_grant: BTreeSet::new(),
            joined,
            contacts: contact.into_iter().collect(),
            contact: contact.map(|c| (c, std::time::Instant::now())),
            started: std::time::Instant::now(),
            join_started: std::time::Instant::now(),
            notes: Vec::new(),
            counters: Counters::default(),
            dt,
            sim_time: 0.0,
            steps: 0,
            no_avatar: false,
            rejoin_limit: 3,
            last_step_at: Instant::ZERO,
        })
    }

    /// The session's clock: microseconds since this peer started.
    pub fn now(&self) -> Instant {
        Instant::from_micros(self.started.elapsed().as_micros() as u64)
    }

    /// This peer's id.
    pub fn me(&self) -> PeerId {
        self.session.local_id()
    }

    /// In the room (host, or welcomed).
    pub fn joined(&self) -> bool {
        self.joined
    }

    /// Simulated seconds.
    pub fn sim_time(&self) -> f64 {
        self.sim_time
    }

    /// The host opens the room: spawn the scene's objects.
    pub fn open(&mut self) -> Result<(), RoomError> {
        let objects = self.scene.objects.clone();
        let now = self.now();
        for p in objects {
            let body = self.build(p.kind, p.pos, Quat::IDENTITY)?;
            let state = self.body_state(body, p.pos, Quat::IDENTITY);
            let (id, _) = self
                .session
                .spawn(now, p.kind.class(), state)
                .map_err(|e| RoomError::Scene(format!("spawning {}: {e}", p.kind.name())))?;
            self.insert(id, p.kind, body, None);
        }
        self.spawn_avatar();
        Ok(())
    }

    fn insert(&mut self, id: NetId, kind: Kind, body: Body, avatar_of: Option<PeerId>) {
        match body {
            Body::Rigid(h) => {
                self.by_ref.insert(ObjectRef::Rigid(h), id);
            }
            Body::Soft(h) => {
                self.by_ref.insert(ObjectRef::Soft(h), id);
            }
            Body::Pose => {}
        }
        self.objects.insert(
            id,
            Obj {
                kind,
                body,
                avatar_of,
                pose: (Vec3::ZERO, Quat::IDENTITY),
            },
        );
    }

    /// Build a body of `kind` at a pose.
    fn build(&mut self, kind: Kind, pos: Vec3, rot: Quat) -> Result<Body, RoomError> {
        if kind.is_avatar() {
            return Ok(Body::Pose);
        }
        if !kind.is_soft() {
            return Ok(Body::Rigid(Scene::build_rigid(
                kind,
                &mut self.world,
                pos,
                rot,
            )));
        }
        let mesh = self.scene.soft_mesh(kind).map_err(RoomError::Scene)?;
        let h = self
            .soft
            .insert(&mesh, Scene::soft_config(kind), &mut self.world)
            .map_err(|e| RoomError::Scene(format!("{}: {e}", kind.name())))?;
        // Built around the origin, then placed: the rest shape stays in the body's own frame.
        if let Some(b) = self.soft.get_mut(h) {
            let particles: Vec<Vec3> = b.rest_offsets().iter().map(|o| pos + rot * *o).collect();
            b.apply_state(&mut self.world, pos, rot, &particles)
                .map_err(|e| RoomError::Scene(e.to_string()))?;
        }
        Ok(Body::Soft(h))
    }

    fn body_state(&self, body: Body, pos: Vec3, rot: Quat) -> ObjectState {
        match body {
            Body::Pose => ObjectState::rigid(pos, rot),
            Body::Rigid(h) => match self.world.bodies.get(h) {
                Some(b) => ObjectState::rigid(b.translation(), *b.rotation()),
                None => ObjectState::rigid(pos, rot),
            },
            Body::Soft(h) => match self.soft.get(h) {
                Some(b) => {
                    let (pos, rot) = b.center_pose(&self.world);
                    ObjectState {
                        pos,
                        rot,
                        particles: b.particle_positions(&self.world),
                    }
                }
                None => ObjectState::rigid(pos, rot),
            },
        }
    }

    /// The state this peer shows for an object now: simulated if we own it, interpolated
    /// otherwise (what the dump writes).
    pub fn shown_state(&mut self, id: NetId) -> Option<ObjectState> {
        let o = self.objects.get(&id)?.clone();
        if self.session.owner(id) == Some(self.me()) {
            Some(self.body_state(o.body, o.pose.0, o.pose.1))
        } else {
            let now = self.now();
            self.session
                .display_state(now, id)
                .map(|d| d.state)
                .or_else(|| self.session.latest_state(id))
        }
    }

    fn spawn_avatar(&mut self) {
        if self.no_avatar {
            return;
        }
        let now = self.now();
        let home = self.home();
        for (i, off) in [
            Vec3::ZERO,
            Vec3::new(-0.2, -0.45, -0.25),
            Vec3::new(0.2, -0.45, -0.25),
        ]
        .into_iter()
        .enumerate()
        {
            if self.avatar[i].is_some() || self.avatar_requests[i].is_some() {
                continue;
            }
            let kind = if i == 0 { Kind::Head } else { Kind::Hand };
            let pos = home.0 + home.1 * off;
            match self
                .session
                .spawn(now, kind.class(), ObjectState::rigid(pos, home.1))
            {
                Ok((id, request)) => {
                    if self.session.is_host() {
                        self.avatar[i] = Some(id);
                        self.insert(id, kind, Body::Pose, Some(self.me()));
                        if let Some(o) = self.objects.get_mut(&id) {
                            o.pose = (pos, home.1);
                        }
                    } else {
                        self.avatar_requests[i] = Some(request);
                    }
                }
                Err(e) => eprintln!("cannot spawn our avatar: {e}"),
            }
        }
    }

    /// Where this peer stands: around the table, by its id.
    pub fn home(&self) -> (Vec3, Quat) {
        let angle = (self.me().0 % 8) as f32 * std::f32::consts::FRAC_PI_4;
        let rot = Quat::from_rotation_y(angle);
        (rot * Vec3::new(0.0, 1.6, 0.75), rot)
    }

    /// Set a pose for one of our avatar parts (0 head, 1 left, 2 right).
    pub fn set_avatar_pose(&mut self, part: usize, pos: Vec3, rot: Quat) {
        if let Some(id) = self.avatar.get(part).copied().flatten() {
            if let Some(o) = self.objects.get_mut(&id) {
                o.pose = (pos, rot);
            }
        }
    }

    /// Network in: datagrams, peer events, timers, session events. Call every frame.
    pub fn pump(&mut self) -> Result<(), RoomError> {
        let now = self.now();
        while let Some((from, bytes)) = self.transport.recv(now) {
            self.session.handle_packet(now, from, &bytes);
        }
        // Connectivity news is informational for the session (its heartbeats decide who is
        // gone); a joiner uses it to find someone who can answer its Hello.
        while let Some(e) = self.transport.poll_peer_event() {
            match e {
                PeerEvent::Connected(p) if !self.contacts.contains(&p) => self.contacts.push(p),
                PeerEvent::Disconnected(p) => self.contacts.retain(|q| *q != p),
                _ => {}
            }
        }
        self.retry_join(now);
        if self.session.poll_timeout().is_some_and(|t| t <= now) {
            self.session.handle_timeout(now);
        }
        while let Some(e) = self.session.poll_event() {
            self.on_event(e)?;
        }
        self.flush();
        Ok(())
    }

    /// Say goodbye: the others drop us at once instead of after the peer timeout. Waits a
    /// moment so the WebRTC thread sends it before the process ends.
    pub fn leave(&mut self) {
        let now = self.now();
        self.session.leave(now);
        self.flush();
        std::thread::sleep(Duration::from_millis(100));
    }

    /// A joiner whose contact has not answered within `JOIN_RETRY` (it may be a joiner
    /// itself, which knows no host yet) says Hello to the next connected peer. The host
    /// answers `Welcome`, a member `Redirect`, another joiner nothing.
    fn retry_join(&mut self, now: Instant) {
        if self.joined {
            return;
        }
        let Some((current, since)) = self.contact else {
            return;
        };
        if since.elapsed() < JOIN_RETRY || self.contacts.is_empty() {
            return;
        }
        let next = self
            .contacts
            .iter()
            .position(|p| *p == current)
            .map_or(0, |i| (i + 1) % self.contacts.len());
        let next = self.contacts[next];
        // The same session: the peers asked before keep their sequences with us in step.
        self.session.join_via(now, next);
        self.contact = Some((next, std::time::Instant::now()));
    }

    /// The room went on without us: its objects have other owners, and our replica is stale.
    /// Let go of everything, drop every networked object from the local world (the static
    /// scene stays) and join `host` again with a fresh session; the room's snapshot then
    /// rebuilds the objects, and `Joined` respawns our avatar.
    fn rejoin(&mut self, host: PeerId, reason: String) {
        let now = self.now();
        self.counters.rejoins += 1;
        self.hands.release_all();
        let ids: Vec<NetId> = self.objects.keys().copied().collect();
        for id in ids {
            self.remove(id);
        }
        self.avatar = [None; 3];
        self.avatar_requests = [None; 3];
        self.waiting_grant.clear();
        self.joined = false;
        let cfg = self.session.config().clone();
        self.session = Session::join(self.me(), host, cfg, now);
        if !self.contacts.contains(&host) {
            self.contacts.push(host);
        }
        self.contact = Some((host, std::time::Instant::now()));
        self.join_started = std::time::Instant::now();
        self.notes.push(Note::Rejoining { host, reason });
    }

    /// Network out.
    pub fn flush(&mut self) {
        let now = self.now();
        while let Some(t) = self.session.poll_transmit(now) {
            self.transport.send(now, t.to, &t.payload);
        }
    }

    /// Start counting the join timeout now (when the network starts being pumped).
    #[cfg_attr(not(feature = "desktop"), allow(dead_code))]
    pub fn start_join_clock(&mut self) {
        self.join_started = std::time::Instant::now();
    }

    /// Whether a joiner has been waiting too long (for the caller to give up).
    pub fn join_deadline_passed(&self, room: &str, timeout: Duration) -> Result<(), RoomError> {
        if self.joined || self.join_started.elapsed() < timeout {
            return Ok(());
        }
        Err(RoomError::NotWelcomed {
            room: room.into(),
            secs: timeout.as_secs(),
        })
    }

    fn on_event(&mut self, e: Event) -> Result<(), RoomError> {
        let me = self.me();
        match e {
            Event::Joined { host, term } => {
                self.joined = true;
                self.notes.push(Note::Joined { host, term });
                self.spawn_avatar();
            }
            Event::Refused { reason } => return Err(RoomError::Refused(reason)),
            Event::Dropped { host, reason } => {
                if self.counters.rejoins >= u64::from(self.rejoin_limit) {
                    return Err(RoomError::Dropped {
                        reason,
                        rejoins: self.counters.rejoins,
                    });
                }
                self.rejoin(host, reason);
            }
            Event::PeerJoined(p) => self.notes.push(Note::PeerJoined(p)),
            Event::PeerLeft(p) => {
                self.notes.push(Note::PeerLeft(p));
                if self.session.is_host() {
                    self.despawn_avatars_of_absent();
                }
            }
            Event::HostChanged { host, term } => {
                self.counters.host_changes += 1;
                self.notes.push(Note::HostChanged { host, term });
                if host == me {
                    self.despawn_avatars_of_absent();
                }
            }
            Event::Spawned {
                id,
                class,
                owner,
                request,
            } => {
                if self.objects.contains_key(&id) {
                    return Ok(());
                }
                let Some(kind) = Kind::of_class(class) else {
                    return Ok(());
                };
                let s = self
                    .session
                    .latest_state(id)
                    .unwrap_or_else(|| ObjectState::rigid(Vec3::ZERO, Quat::IDENTITY));
                let body = self.build(kind, s.pos, s.rot)?;
                let avatar_of = kind.is_avatar().then_some(owner);
                self.insert(id, kind, body, avatar_of);
                if owner == me {
                    if let Some(i) = self
                        .avatar_requests
                        .iter()
                        .position(|r| r.is_some() && *r == request)
                    {
                        self.avatar[i] = Some(id);
                        self.avatar_requests[i] = None;
                        if let Some(o) = self.objects.get_mut(&id) {
                            o.pose = (s.pos, s.rot);
                        }
                    }
                }
            }
            Event::Despawned(id) => self.remove(id),
            Event::AuthorityChanged { id, owner, .. } => {
                if !self.objects.contains_key(&id) {
                    return Ok(()); // despawned meanwhile (the avatar of a peer that left)
                }
                if owner == me {
                    self.counters.authority_grants += 1;
                    self.notes.push(Note::AuthorityGained(id));
                    // Take over from what we showed.
                    if let Some(s) = self.session.latest_state(id) {
                        self.apply_shown(id, &s);
                    }
                    if self.waiting_grant.remove(&id) {
                        if let Some(r) = self.obj_ref(id) {
                            self.hands.grant(r);
                        }
                    }
                }
                self.set_simulated(id, owner == me);
            }
            Event::AuthorityDenied { id, .. } => {
                self.notes.push(Note::AuthorityDenied(id));
                if self.waiting_grant.remove(&id) {
                    if let Some(r) = self.obj_ref(id) {
                        self.hands.deny(r);
                    }
                }
            }
            Event::AuthorityAsked { id, by } => {
                let held = self.obj_ref(id).is_some_and(|r| self.is_held(r));
                let now = self.now();
                self.session.answer_authority(now, id, by, !held);
            }
        }
        Ok(())
    }

    fn is_held(&self, r: ObjectRef) -> bool {
        self.hand_ids
            .iter()
            .any(|h| self.hands.held(*h).is_some_and(|t| t.object() == r))
    }

    fn obj_ref(&self, id: NetId) -> Option<ObjectRef> {
        match self.objects.get(&id)?.body {
            Body::Rigid(h) => Some(ObjectRef::Rigid(h)),
            Body::Soft(h) => Some(ObjectRef::Soft(h)),
            Body::Pose => None,
        }
    }

    /// The host removes the avatars of peers that are no longer members.
    fn despawn_avatars_of_absent(&mut self) {
        let members = self.session.members().clone();
        let gone: Vec<NetId> = self
            .objects
            .iter()
            .filter(|(_, o)| o.avatar_of.is_some_and(|p| !members.contains_key(&p)))
            .map(|(id, _)| *id)
            .collect();
        let now = self.now();
        for id in gone {
            if self.session.despawn(now, id).is_ok() {
                self.remove(id);
            }
        }
    }

    fn remove(&mut self, id: NetId) {
        let Some(o) = self.objects.remove(&id) else {
            return;
        };
        match o.body {
            Body::Rigid(h) => {
                self.by_ref.remove(&ObjectRef::Rigid(h));
                self.world.remove_body(h);
            }
            Body::Soft(h) => {
                self.by_ref.remove(&ObjectRef::Soft(h));
                self.soft.remove(h, &mut self.world);
            }
            Body::Pose => {}
        }
    }

    /// Rigid props we own are dynamic; the others follow the network, kinematically.
    fn set_simulated(&mut self, id: NetId, ours: bool) {
        let Some(Body::Rigid(h)) = self.objects.get(&id).map(|o| o.body) else {
            return;
        };
        if let Some(b) = self.world.bodies.get_mut(h) {
            let want = if ours {
                RigidBodyType::Dynamic
            } else {
                RigidBodyType::KinematicPositionBased
            };
            if b.body_type() != want {
                b.set_body_type(want, true);
            }
        }
    }

    fn apply_shown(&mut self, id: NetId, s: &ObjectState) {
        let Some(o) = self.objects.get(&id) else {
            return;
        };
        match o.body {
            Body::Pose => {}
            Body::Rigid(h) => {
                if let Some(b) = self.world.bodies.get_mut(h) {
                    let pose = Pose::from_parts(s.pos, s.rot);
                    if b.is_kinematic() {
                        b.set_next_kinematic_position(pose);
                    } else {
                        b.set_position(pose, true);
                        b.set_linvel(Vec3::ZERO, true);
                        b.set_angvel(Vec3::ZERO, true);
                    }
                }
            }
            Body::Soft(h) => {
                if let Some(b) = self.soft.get_mut(h) {
                    if b.apply_state(&mut self.world, s.pos, s.rot, &s.particles)
                        .is_err()
                    {
                        self.counters.apply_errors += 1;
                    }
                }
            }
        }
    }

    /// Objects our hands hover now (the view tints them).
    #[cfg_attr(not(feature = "desktop"), allow(dead_code))]
    pub fn hovered_ids(&self) -> BTreeSet<NetId> {
        self.hand_ids
            .iter()
            .flat_map(|h| self.hands.hovered(*h))
            .filter_map(|hv| self.by_ref.get(&hv.target.object()).copied())
            .collect()
    }

    /// Hand inputs for this step (from a bot or a device).
    pub fn set_hand_input(&mut self, hand: usize, input: HandInput) {
        if let Some(h) = self.hand_ids.get(hand).copied() {
            if let Err(e) = self.hands.set_input(h, input) {
                eprintln!("hand input refused: {e}");
            }
        }
    }

    /// Advance the simulation by one fixed step and publish what we own.
    pub fn fixed_step(&mut self) {
        let now = self.now();
        let me = self.me();
        self.sim_time += self.dt as f64;
        self.steps += 1;
        self.last_step_at = now;
        // Show what others simulate (before the step, so our bodies collide with it).
        let remote: Vec<NetId> = self
            .objects
            .keys()
            .copied()
            .filter(|id| self.session.owner(*id).is_some_and(|o| o != me))
            .collect();
        for id in &remote {
            self.set_simulated(*id, false);
            if let Some(d) = self.session.display_state(now, *id) {
                self.apply_shown(*id, &d.state);
            }
        }
        // Hands, then physics.
        let own = SessionOwnership {
            me,
            session: &self.session,
            by_ref: &self.by_ref,
        };
        self.hands
            .update(&mut self.world, &mut self.soft, &own, self.dt);
        while let Some(e) = self.hands.poll_event() {
            self.on_hand_event(e);
        }
        self.soft.step(&mut self.world, self.dt);
        // Remote soft bodies: show exactly the interpolated state again after the step.
        for id in &remote {
            if matches!(self.objects.get(id).map(|o| o.body), Some(Body::Soft(_))) {
                if let Some(d) = self.session.display_state(now, *id) {
                    self.apply_shown(*id, &d.state);
                }
            }
        }
        // Publish ours.
        let owned: Vec<NetId> = self
            .objects
            .keys()
            .copied()
            .filter(|id| self.session.owner(*id) == Some(me))
            .collect();
        for id in owned {
            // Ours since a grant or a migration: simulate it (idempotent).
            self.set_simulated(id, true);
            let Some(o) = self.objects.get(&id) else {
                continue;
            };
            let s = self.body_state(o.body, o.pose.0, o.pose.1);
            if let Err(e) = self.session.publish_state(now, id, &s) {
                eprintln!("not publishing {}: {e}", o.kind.name());
            }
        }
        self.flush();
    }

    fn on_hand_event(&mut self, e: InteractionEvent) {
        let now = self.now();
        match e {
            InteractionEvent::AuthorityRequested { object, .. } => {
                if let Some(id) = self.by_ref.get(&object).copied() {
                    self.counters.authority_requests += 1;
                    self.notes.push(Note::AuthorityAsked(id));
                    match self.session.request_authority(now, id) {
                        Ok(()) => {
                            self.waiting_grant.insert(id);
                        }
                        Err(_) => self.hands.deny(object),
                    }
                }
            }
            InteractionEvent::Grabbed { hand, target } => {
                if let Some(id) = self.by_ref.get(&target.object()).copied() {
                    let particle = match target {
                        Target::SoftParticle(_, p) => Some(p),
                        _ => None,
                    };
                    self.notes.push(Note::GrabStarted { id, hand, particle });
                }
            }
            InteractionEvent::Released {
                hand,
                target,
                velocity_mps,
            } => {
                if let Some(id) = self.by_ref.get(&target.object()).copied() {
                    let speed = velocity_mps.length();
                    self.notes.push(Note::GrabEnded { id, hand, speed });
                }
            }
            InteractionEvent::CameToRest { object } => {
                if let Some(id) = self.by_ref.get(&object).copied() {
                    if !self.session.is_host()
                        && self.session.owner(id) == Some(self.me())
                        && !self.is_held(object)
                        && self.session.release_authority(now, id).is_ok()
                    {
                        self.notes.push(Note::AuthorityReleased(id));
                    }
                }
            }
            _ => {}
        }
    }

    /// What a hand holds, as a networked id.
    pub fn held(&self, hand: usize) -> Option<(NetId, Target)> {
        let t = self.hands.held(*self.hand_ids.get(hand)?)?;
        Some((*self.by_ref.get(&t.object())?, t))
    }

    /// Objects we own.
    pub fn owned_count(&self) -> usize {
        let me = self.me();
        self.objects
            .keys()
            .filter(|id| self.session.owner(**id) == Some(me))
            .count()
    }
}
