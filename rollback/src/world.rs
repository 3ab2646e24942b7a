//! The deterministic world of a rollback room: the scene's objects as rapier and soft bodies,
//! and every player's two hands, stepped at a fixed rate from everyone's inputs.
//!
//! Determinism rests on: the same scene built in the same order (body handles are the same
//! everywhere); rapier and parry with `enhanced-determinism` (softbody's `deterministic`
//! feature: libm, scalar glam, ordered maps); inputs as integers ([`PlayerInput`]), turned
//! into the same floats everywhere; hand sample times from the frame number, never a clock;
//! players in one agreed order; no iteration over unordered maps in the step.
//!
//! # Cuts and tears
//! A scalpel stroke or a cutter's sweep is part of a player's input: its hand's pose, its
//! trigger and which tool the trigger works ([`PlayerInput::cutter`]). Each step, after the
//! hands moved, every player's hands (players in their agreed order, left then right) work
//! their blades as a state-sync peer's do (`softsync_peer::peer::topology`, `…::cutter`): a
//! scalpel held in a soft body tears it every 5 mm of the tip's path (and where the path
//! turns), mapped through the body's deformation into its rest frame; letting go lifts it; a
//! cutter swept 2 cm through a body cuts it in two by the sweep's plane, and each piece after
//! the first becomes a new object at the end of [`RollbackWorld::objects`]. Each change is
//! quantised as the wire's topology events are and kept in the world's topology log (object,
//! event). The blades' strokes, the objects and the log's length are part of [`WorldState`],
//! so rolling back across a tear or a cut restores the mesh and objects before it exactly;
//! a [`Snapshot`] carries the log, and a world rebuilt from it replays the log on the scene
//! before taking the bodies' states.
//!
//! [`WorldState`] is what ggrs saves and loads (a clone of every part that changes: cost
//! measured by the `rollback` bench). [`Snapshot`] is the portable state a membership change
//! starts from: positions and velocities of every object's bodies, as bits. Every member —
//! the host, the others, a late joiner — rebuilds the world from the scene and the same
//! snapshot, so their worlds are identical again whatever rapier's caches held.

mod blades;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use softsync_interaction::{AllLocal, HandConfig, HandInput, HandSample, Interaction};
use softsync_net::wire::TopologyEvent;
use softsync_net::PeerId;
use softsync_peer::{build_body, Kind, LocalBody, Scene};
use softsync_softbody::rapier3d::dynamics::{
    ImpulseJointSet, IslandManager, MultibodyJointSet, RigidBodySet,
};
use softsync_softbody::rapier3d::geometry::{BroadPhaseBvh, ColliderSet, NarrowPhase};
use softsync_softbody::rapier3d::prelude::{PhysicsWorld, Pose, RigidBodyHandle};
use softsync_softbody::SoftBodySet;

use crate::input::PlayerInput;
use blades::{Blade, TopologyLog};

/// Why a world could not be built or loaded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorldError {
    /// A scene object could not be built.
    #[error("building the scene: {0}")]
    Build(String),
    /// A snapshot does not fit this scene (another scene, or damaged).
    #[error("snapshot does not fit the scene: {0}")]
    Snapshot(String),
}

/// One of the room's objects in the world: the scene's, in its order, then a cut's pieces.
#[derive(Clone, Debug)]
pub struct WorldObject {
    /// Its class.
    pub kind: Kind,
    /// Its body.
    pub body: LocalBody,
    /// Its rapier bodies in a fixed order (a soft body: the center, then the particles).
    pub handles: Vec<RigidBodyHandle>,
}

/// One entry of a rollback world's topology log: object `object` (index) changed by `event`
/// (rest frame, quantised as on the wire).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LogEntry {
    /// The object's index in [`RollbackWorld::objects`] when it changed.
    pub object: u32,
    /// What happened to it.
    pub event: TopologyEvent,
}

#[derive(Clone, Debug)]
struct Player {
    id: PeerId,
    hands: Interaction,
    /// The last tracked pose per hand (an untracked hand stays there with its grip open).
    last: [Option<(Vec3, Quat)>; 2],
    /// The last input this player's frame was stepped with (what others draw of its avatar).
    input: PlayerInput,
    /// Each hand's blade.
    blades: [Blade; 2],
}

/// Everything a step changes, as ggrs saves and loads it.
#[derive(Clone)]
pub struct WorldState {
    frame: i32,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft: SoftBodySet,
    players: Vec<Player>,
    objects: Vec<WorldObject>,
    /// The topology log up to this state (shared with the world's: see [`TopologyLog`]).
    log: TopologyLog,
}

/// The portable state a membership change starts from (bincode on the wire).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// The frame it is the state after.
    pub frame: i32,
    /// Per object body (in [`WorldObject::handles`] order, objects in scene order):
    /// translation, rotation (xyzw), linear and angular velocity, as `f32` bits.
    pub bodies: Vec<[u32; 13]>,
    /// The topology log: replayed on the scene's objects before the bodies' states are set.
    #[serde(default)]
    pub log: Vec<LogEntry>,
}

/// Topology entries a snapshot may carry (a hostile one is refused before any replay).
pub const MAX_LOG_ENTRIES: usize = 100_000;

/// The world of a rollback room.
pub struct RollbackWorld {
    dt_s: f32,
    hand: HandConfig,
    world: PhysicsWorld,
    soft: SoftBodySet,
    objects: Vec<WorldObject>,
    players: Vec<Player>,
    frame: i32,
    /// Every topology change so far, in order (see the module docs).
    log: TopologyLog,
    /// Blade actions the world refused (a segment a tear refused, a plane that misses): the
    /// same on every peer, so they change nothing anywhere.
    refused: u64,
    /// A deliberate non-determinism for the tests that show it is caught: when set, every
    /// step nudges the first object by a value that differs between a step and its re-run.
    debug_noise: Option<u32>,
    /// Tests: push the first body aside on the next step, once.
    #[cfg(feature = "testing")]
    debug_kick: bool,
}

impl RollbackWorld {
    /// The scene's objects at their places, at frame 0, with `players` (in this order: every
    /// member must give the same), stepping by `dt_s`, hands as [`bot_hand`] makes them.
    pub fn new(scene: &Scene, dt_s: f32, players: &[PeerId]) -> Result<Self, WorldError> {
        Self::with_hand(scene, dt_s, players, bot_hand())
    }

    /// The same with every player's hands configured as `hand` (every member must give the
    /// same).
    pub fn with_hand(
        scene: &Scene,
        dt_s: f32,
        players: &[PeerId],
        hand: HandConfig,
    ) -> Result<Self, WorldError> {
        let mut world = PhysicsWorld::new();
        world.integration_parameters.dt = dt_s;
        scene.build_static(&mut world);
        let mut soft = SoftBodySet::new();
        let mut objects = Vec::with_capacity(scene.objects.len());
        for p in &scene.objects {
            let body = build_body(scene, p.kind, &mut world, &mut soft, p.pos, p.rot)
                .map_err(|e| WorldError::Build(e.to_string()))?;
            let handles = match body {
                LocalBody::Rigid(h) => vec![h],
                LocalBody::Soft(h) => soft
                    .get(h)
                    .map(|b| {
                        std::iter::once(b.center())
                            .chain(b.particles().iter().copied())
                            .collect()
                    })
                    .unwrap_or_default(),
                LocalBody::Pose | LocalBody::Building => Vec::new(),
            };
            objects.push(WorldObject {
                kind: p.kind,
                body,
                handles,
            });
        }
        let mut w = RollbackWorld {
            dt_s,
            hand,
            world,
            soft,
            objects,
            players: Vec::new(),
            frame: 0,
            log: TopologyLog::default(),
            refused: 0,
            debug_noise: None,
            #[cfg(feature = "testing")]
            debug_kick: false,
        };
        w.set_players(players)?;
        Ok(w)
    }

    /// The same scene rebuilt at `snapshot`'s state, with `players` (a membership change).
    pub fn from_snapshot(
        scene: &Scene,
        dt_s: f32,
        players: &[PeerId],
        snapshot: &Snapshot,
    ) -> Result<Self, WorldError> {
        let mut w = Self::new(scene, dt_s, players)?;
        if snapshot.log.len() > MAX_LOG_ENTRIES {
            return Err(WorldError::Snapshot(format!(
                "{} topology entries (at most {MAX_LOG_ENTRIES})",
                snapshot.log.len()
            )));
        }
        for (k, e) in snapshot.log.iter().enumerate() {
            w.record(e.object as usize, e.event)
                .map_err(|why| WorldError::Snapshot(format!("topology entry {k}: {why}")))?;
        }
        let n: usize = w.objects.iter().map(|o| o.handles.len()).sum();
        if n != snapshot.bodies.len() {
            return Err(WorldError::Snapshot(format!(
                "{} bodies in the snapshot, {n} in the scene",
                snapshot.bodies.len()
            )));
        }
        let f = f32::from_bits;
        for (h, b) in w
            .objects
            .iter()
            .flat_map(|o| o.handles.iter())
            .zip(&snapshot.bodies)
        {
            let t = Vec3::new(f(b[0]), f(b[1]), f(b[2]));
            let r = Quat::from_xyzw(f(b[3]), f(b[4]), f(b[5]), f(b[6]));
            let v = Vec3::new(f(b[7]), f(b[8]), f(b[9]));
            let a = Vec3::new(f(b[10]), f(b[11]), f(b[12]));
            if !(t.is_finite() && r.is_finite() && v.is_finite() && a.is_finite())
                || (r.length_squared() - 1.0).abs() > 1e-3
            {
                return Err(WorldError::Snapshot(
                    "a non-finite or non-unit body state".into(),
                ));
            }
            if let Some(body) = w.world.bodies.get_mut(*h) {
                body.set_position(Pose::from_parts(t, r), true);
                body.set_linvel(v, true);
                body.set_angvel(a, true);
            }
        }
        w.frame = snapshot.frame;
        Ok(w)
    }

    /// Replace the players (each gets two fresh hands; their bodies are added after the
    /// objects', in this order).
    fn set_players(&mut self, players: &[PeerId]) -> Result<(), WorldError> {
        self.players.clear();
        for &id in players {
            let mut hands = Interaction::new();
            for _ in 0..2 {
                hands
                    .add_hand(self.hand.clone())
                    .map_err(|e| WorldError::Build(e.to_string()))?;
            }
            self.players.push(Player {
                id,
                hands,
                last: [None, None],
                input: PlayerInput::default(),
                blades: Default::default(),
            });
        }
        Ok(())
    }

    /// The portable state now.
    pub fn snapshot(&self) -> Snapshot {
        let bodies = body_bits(&self.objects, &self.world.bodies);
        Snapshot {
            frame: self.frame,
            bodies,
            log: self.log.to_vec(),
        }
    }

    /// The portable state of a saved state of this world.
    pub fn snapshot_of(&self, state: &WorldState) -> Snapshot {
        Snapshot {
            frame: state.frame,
            bodies: body_bits(&state.objects, &state.bodies),
            log: state.log.to_vec(),
        }
    }

    /// One fixed step with every player's input (in player order; a missing one is "no
    /// input").
    pub fn step(&mut self, inputs: &[PlayerInput]) {
        let dt = self.dt_s;
        self.frame += 1;
        let time_s = f64::from(self.frame) * f64::from(dt);
        for (i, p) in self.players.iter_mut().enumerate() {
            let input = inputs.get(i).copied().unwrap_or_default();
            p.input = input;
            let d = input.to_device();
            for h in 0..2 {
                if let Some(pose) = d.hands[h] {
                    p.last[h] = Some(pose);
                }
                let Some((pos, rot)) = p.last[h] else {
                    continue;
                };
                let tracked = d.hands[h].is_some();
                let sample = HandSample {
                    position_m: pos,
                    rotation: rot,
                    time_s,
                };
                let _ = p.hands.set_input(
                    h,
                    HandInput {
                        sample,
                        grip: if tracked { d.grip[h] } else { 0.0 },
                        trigger: if tracked { d.trigger[h] } else { 0.0 },
                    },
                );
            }
            p.hands
                .update(&mut self.world, &mut self.soft, &AllLocal, dt);
            while p.hands.poll_event().is_some() {}
        }
        for i in 0..self.players.len() {
            let d = self.players[i].input.to_device();
            for h in 0..2 {
                self.work_blade(i, h, &d);
            }
        }
        #[cfg(feature = "testing")]
        if std::mem::take(&mut self.debug_kick) {
            if let Some(h) = self.objects.first().and_then(|o| o.handles.first()) {
                if let Some(b) = self.world.bodies.get_mut(*h) {
                    let v = b.linvel() + Vec3::X * 0.05;
                    b.set_linvel(v, true);
                }
            }
        }
        if let Some(n) = self.debug_noise.as_mut() {
            *n = n.wrapping_add(1);
            if let Some(h) = self.objects.first().and_then(|o| o.handles.first()) {
                if let Some(b) = self.world.bodies.get_mut(*h) {
                    let v = b.linvel() + Vec3::X * (*n as f32 * 1e-4);
                    b.set_linvel(v, true);
                }
            }
        }
        self.soft.step(&mut self.world, dt);
    }

    /// Everything a step changes (ggrs's save).
    pub fn save(&self) -> WorldState {
        let w = &self.world;
        WorldState {
            frame: self.frame,
            islands: w.islands.clone(),
            broad_phase: w.broad_phase.clone(),
            narrow_phase: w.narrow_phase.clone(),
            bodies: w.bodies.clone(),
            colliders: w.colliders.clone(),
            impulse_joints: w.impulse_joints.clone(),
            multibody_joints: w.multibody_joints.clone(),
            soft: self.soft.clone(),
            players: self.players.clone(),
            objects: self.objects.clone(),
            log: self.log.clone(),
        }
    }

    /// Back to a saved state (ggrs's load). The deliberate noise, if on, is not rolled back:
    /// that is what makes it a non-determinism.
    pub fn load(&mut self, s: &WorldState) {
        let w = &mut self.world;
        self.frame = s.frame;
        w.islands = s.islands.clone();
        w.broad_phase = s.broad_phase.clone();
        w.narrow_phase = s.narrow_phase.clone();
        w.bodies = s.bodies.clone();
        w.colliders = s.colliders.clone();
        w.impulse_joints = s.impulse_joints.clone();
        w.multibody_joints = s.multibody_joints.clone();
        self.soft = s.soft.clone();
        self.players = s.players.clone();
        self.objects = s.objects.clone();
        self.log = s.log.clone();
    }

    /// A hash of every body's position, rotation and velocities (bits) and the frame: equal on
    /// two peers exactly when their worlds agree.
    pub fn checksum(&self) -> u128 {
        checksum(self.frame, self.log.len(), &self.world.bodies)
    }

    /// The checksum of a saved state.
    pub fn checksum_of(state: &WorldState) -> u128 {
        checksum(state.frame, state.log.len(), &state.bodies)
    }

    /// The topology log so far (see the module docs).
    pub fn topology_log(&self) -> Vec<LogEntry> {
        self.log.to_vec()
    }

    /// Blade actions refused so far (the same on every peer).
    pub fn refused_blades(&self) -> u64 {
        self.refused
    }

    /// Tests: a non-determinism once (the next step pushes the first body aside).
    #[cfg(feature = "testing")]
    #[doc(hidden)]
    pub fn kick_once(&mut self) {
        self.debug_kick = true;
    }

    /// Turn the deliberate non-determinism on (tests only show it is caught).
    pub fn inject_nondeterminism(&mut self) {
        self.debug_noise = Some(0);
    }

    /// Frames stepped (the frame whose state this is).
    pub fn frame(&self) -> i32 {
        self.frame
    }

    /// The players, in step order.
    pub fn players(&self) -> Vec<PeerId> {
        self.players.iter().map(|p| p.id).collect()
    }

    /// The last input player `i` was stepped with.
    pub fn player_input(&self, i: usize) -> Option<PlayerInput> {
        self.players.get(i).map(|p| p.input)
    }

    /// Which object player `i`'s hand `hand` holds, if any (index into [`Self::objects`]).
    pub fn held(&self, player: usize, hand: usize) -> Option<usize> {
        let target = self.players.get(player)?.hands.held(hand)?;
        let r = target.object();
        self.objects.iter().position(|o| match o.body {
            LocalBody::Rigid(h) => r == softsync_interaction::ObjectRef::Rigid(h),
            LocalBody::Soft(h) => r == softsync_interaction::ObjectRef::Soft(h),
            LocalBody::Pose | LocalBody::Building => false,
        })
    }

    /// The scene's objects.
    pub fn objects(&self) -> &[WorldObject] {
        &self.objects
    }

    /// Center position and rotation of object `i`.
    pub fn object_pose(&self, i: usize) -> Option<(Vec3, Quat)> {
        match self.objects.get(i)?.body {
            LocalBody::Rigid(h) => self
                .world
                .bodies
                .get(h)
                .map(|b| (b.translation(), *b.rotation())),
            LocalBody::Soft(h) => self.soft.get(h).map(|b| b.center_pose(&self.world)),
            LocalBody::Pose | LocalBody::Building => None,
        }
    }

    /// Linear and angular velocity of object `i`'s center body (a soft body's center follows
    /// its particles' mean): what a renderer extrapolates with between two ticks.
    pub fn object_velocity(&self, i: usize) -> Option<(Vec3, Vec3)> {
        let h = *self.objects.get(i)?.handles.first()?;
        self.world.bodies.get(h).map(|b| (b.linvel(), b.angvel()))
    }

    /// Particle positions of object `i` if it is soft.
    pub fn particles(&self, i: usize) -> Option<Vec<Vec3>> {
        match self.objects.get(i)?.body {
            LocalBody::Soft(h) => self.soft.get(h).map(|b| b.particle_positions(&self.world)),
            _ => None,
        }
    }

    /// The rapier world (read only).
    pub fn physics(&self) -> &PhysicsWorld {
        &self.world
    }

    /// The soft bodies (read only).
    pub fn soft_bodies(&self) -> &SoftBodySet {
        &self.soft
    }

    /// The fixed step, seconds.
    pub fn dt_s(&self) -> f32 {
        self.dt_s
    }
}

fn checksum(frame: i32, log_len: usize, bodies: &RigidBodySet) -> u128 {
    let mut h = Fnv128::new();
    h.word(frame as u32);
    h.word(log_len as u32);
    for (_, b) in bodies.iter() {
        let t = b.translation();
        let r = *b.rotation();
        let (v, a) = (b.linvel(), b.angvel());
        for x in [
            t.x, t.y, t.z, r.x, r.y, r.z, r.w, v.x, v.y, v.z, a.x, a.y, a.z,
        ] {
            h.word(x.to_bits());
        }
    }
    h.finish()
}

/// The hands of a rollback room: the ones the binary gives its bots and desktop peers (no
/// physical controller body, which would shove what the hand reaches for; a 3 cm hover
/// sphere), so a state-sync room and a rollback room of bots move alike.
pub fn bot_hand() -> HandConfig {
    HandConfig {
        physical_controller: false,
        hover_radius_m: 0.03,
        ..HandConfig::default()
    }
}

/// Translation, rotation, velocities of every object body, as bits.
fn body_bits(objects: &[WorldObject], bodies: &RigidBodySet) -> Vec<[u32; 13]> {
    objects
        .iter()
        .flat_map(|o| o.handles.iter())
        .map(|h| {
            let mut out = [0u32; 13];
            if let Some(b) = bodies.get(*h) {
                let t = b.translation();
                let r = *b.rotation();
                let (v, a) = (b.linvel(), b.angvel());
                let vals = [
                    t.x, t.y, t.z, r.x, r.y, r.z, r.w, v.x, v.y, v.z, a.x, a.y, a.z,
                ];
                for (o, x) in out.iter_mut().zip(vals) {
                    *o = x.to_bits();
                }
            }
            out
        })
        .collect()
}

/// FNV-1a over 32-bit words in two 64-bit lanes with different offsets.
struct Fnv128 {
    a: u64,
    b: u64,
}

impl Fnv128 {
    fn new() -> Self {
        Fnv128 {
            a: 0xcbf2_9ce4_8422_2325,
            b: 0x6c62_272e_07bb_0142,
        }
    }
    fn word(&mut self, w: u32) {
        for byte in w.to_le_bytes() {
            self.a = (self.a ^ u64::from(byte)).wrapping_mul(0x0000_0100_0000_01b3);
            self.b = (self.b ^ u64::from(byte))
                .wrapping_mul(0x0000_0100_0000_01b3)
                .rotate_left(7);
        }
    }
    fn finish(&self) -> u128 {
        (u128::from(self.a) << 64) | u128::from(self.b)
    }
}
