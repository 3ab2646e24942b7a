//! VR hand interaction on a rapier world and a soft-body set (thesis chapter 4): hover, pick
//! the closest, velocity-based hold, throw, physical controller, soft-body center or particle
//! grab, and the parent-based hold kept only for comparison (Table 1).
//!
//! Engine-agnostic: hands are streams of pose samples with grip and trigger values from any
//! source (OpenXR, a mouse, a bot script). Networking stays outside: a grab of an object the
//! local peer does not own emits [`InteractionEvent::AuthorityRequested`]; the app asks its
//! session and answers with [`Interaction::grant`] or [`Interaction::deny`].

use std::collections::VecDeque;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use softsync_softbody::rapier3d::parry::shape::Ball;
use softsync_softbody::rapier3d::prelude::{
    ColliderBuilder, PhysicsWorld, Pose, QueryFilter, RigidBodyBuilder, RigidBodyHandle,
};
use softsync_softbody::{SoftBodyHandle, SoftBodySet, SoftPart};

/// Index of a hand in an [`Interaction`].
pub type HandId = usize;

/// One tracked pose of a hand.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandSample {
    /// Position in world space, metres.
    pub position_m: Vec3,
    /// Orientation in world space.
    pub rotation: Quat,
    /// Sample time, seconds (any monotonic clock the caller keeps).
    pub time_s: f64,
}

/// A hand's pose with its buttons, as read from a controller, a mouse or a bot script.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandInput {
    /// The pose.
    pub sample: HandSample,
    /// Grip (squeeze) value in [0, 1].
    pub grip: f32,
    /// Trigger value in [0, 1].
    pub trigger: f32,
}

/// A networked object as the app knows it: a rigid body or a whole soft body.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ObjectRef {
    /// A rigid body.
    Rigid(RigidBodyHandle),
    /// A soft body (its center and all particles).
    Soft(SoftBodyHandle),
}

/// What a hand holds or hovers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Target {
    /// A dynamic rigid body.
    Rigid(RigidBodyHandle),
    /// A soft body by its center (thesis 4.1.1).
    SoftCenter(SoftBodyHandle),
    /// One particle of a soft body (thesis 4.1.2).
    SoftParticle(SoftBodyHandle, u32),
}

impl Target {
    /// The networked object this target is part of.
    pub fn object(&self) -> ObjectRef {
        match *self {
            Target::Rigid(h) => ObjectRef::Rigid(h),
            Target::SoftCenter(h) | Target::SoftParticle(h, _) => ObjectRef::Soft(h),
        }
    }
}

/// How a held object follows the hand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldMode {
    /// Thesis 4.1: each step the velocity is set to reach the hand; other forces still act.
    Velocity,
    /// Thesis 4.2, for comparison only: the pose is set to the hand's; passes through walls
    /// and cannot throw.
    Parent,
}

/// What a grab on a soft body takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SoftGrab {
    /// The closest particle (thesis 4.1.2).
    Particle,
    /// The whole body by its center, where the center is dynamic (thesis 4.1.1); otherwise
    /// the closest particle.
    Center,
}

/// Per-hand settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HandConfig {
    /// Radius of the hover sphere around the hand, metres. Default 0.06.
    pub hover_radius_m: f32,
    /// Grip value at which a grab starts. Default 0.55.
    pub grip_on: f32,
    /// Grip value below which a grab ends (hysteresis). Default 0.35.
    pub grip_off: f32,
    /// Velocity (default) or parent hold.
    pub hold_mode: HoldMode,
    /// Particle (default) or center grab on soft bodies.
    pub soft_grab: SoftGrab,
    /// Largest linear speed a hold may ask for, m/s. Default 12.
    pub max_linear_speed_mps: f32,
    /// Largest angular speed a hold may ask for, rad/s. Default 25.
    pub max_angular_speed_radps: f32,
    /// A pose further than this from the previous one is a teleport: the hand restarts its
    /// history there, so no throw or hold picks up the jump. Default 0.5 m.
    pub teleport_distance_m: f32,
    /// Grip with nothing hovered makes the hand a physical body that pushes (4.1.3). Default on.
    pub physical_controller: bool,
    /// Radius of the physical controller's ball, metres. Default 0.04.
    pub controller_radius_m: f32,
    /// Mass of the physical controller, kg. Default 0.5.
    pub controller_mass_kg: f32,
    /// Speed below which a released object counts as at rest, m/s. Default 0.02.
    pub rest_speed_mps: f32,
    /// How long it must stay below that speed, seconds. Default 0.5.
    pub rest_time_s: f32,
}

impl HandConfig {
    /// Rejects values outside their range with a message naming the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let check = |name: &'static str, v: f32, lo: f32, hi: f32| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(ConfigError {
                    field: name,
                    value: v,
                    min: lo,
                    max: hi,
                })
            }
        };
        check("hover_radius_m", self.hover_radius_m, 1e-4, 2.0)?;
        check("grip_on", self.grip_on, 0.0, 1.0)?;
        check("grip_off", self.grip_off, 0.0, self.grip_on)?;
        check("max_linear_speed_mps", self.max_linear_speed_mps, 1e-3, 1e3)?;
        check(
            "max_angular_speed_radps",
            self.max_angular_speed_radps,
            1e-3,
            1e4,
        )?;
        check("teleport_distance_m", self.teleport_distance_m, 1e-3, 1e4)?;
        check("controller_radius_m", self.controller_radius_m, 1e-4, 1.0)?;
        check("controller_mass_kg", self.controller_mass_kg, 1e-4, 1e3)?;
        check("rest_speed_mps", self.rest_speed_mps, 0.0, 10.0)?;
        check("rest_time_s", self.rest_time_s, 0.0, 60.0)?;
        Ok(())
    }
}

/// A hand setting out of its range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("hand config: {field} = {value} is outside [{min}, {max}]")]
pub struct ConfigError {
    /// The field.
    pub field: &'static str,
    /// Its value.
    pub value: f32,
    /// Lowest allowed.
    pub min: f32,
    /// Highest allowed.
    pub max: f32,
}

impl Default for HandConfig {
    fn default() -> Self {
        Self {
            hover_radius_m: 0.06,
            grip_on: 0.55,
            grip_off: 0.35,
            hold_mode: HoldMode::Velocity,
            soft_grab: SoftGrab::Particle,
            max_linear_speed_mps: 12.0,
            max_angular_speed_radps: 25.0,
            teleport_distance_m: 0.5,
            physical_controller: true,
            controller_radius_m: 0.04,
            controller_mass_kg: 0.5,
            rest_speed_mps: 0.02,
            rest_time_s: 0.5,
        }
    }
}

/// Tells the interaction which objects the local peer owns (simulates).
pub trait Ownership {
    /// True if the local peer may move `object` now.
    fn is_local(&self, object: ObjectRef) -> bool;
}

/// Every object is local: single-user use and tests.
#[derive(Clone, Copy, Debug, Default)]
pub struct AllLocal;

impl Ownership for AllLocal {
    fn is_local(&self, _: ObjectRef) -> bool {
        true
    }
}

/// Something the app must act on (authority) or may show (HUD).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InteractionEvent {
    /// The hand wants `object`, which the local peer does not own: ask for authority, then
    /// call [`Interaction::grant`] or [`Interaction::deny`].
    AuthorityRequested {
        /// The hand.
        hand: HandId,
        /// The object.
        object: ObjectRef,
    },
    /// The hand started holding `target`.
    Grabbed {
        /// The hand.
        hand: HandId,
        /// What it holds.
        target: Target,
    },
    /// Authority for the grab was denied.
    GrabDenied {
        /// The hand.
        hand: HandId,
        /// The object.
        object: ObjectRef,
    },
    /// The grip opened while authority was still pending: the app may release it when granted.
    GrabCancelled {
        /// The hand.
        hand: HandId,
        /// The object.
        object: ObjectRef,
    },
    /// The hand let go, throwing with `velocity_mps`.
    Released {
        /// The hand.
        hand: HandId,
        /// What it held.
        target: Target,
        /// Throw velocity given to the target.
        velocity_mps: Vec3,
    },
    /// A released object has been at rest for `rest_time_s`: its authority may go back.
    CameToRest {
        /// The object.
        object: ObjectRef,
    },
    /// The hand became a physical body (4.1.3).
    PhysicalControllerStarted {
        /// The hand.
        hand: HandId,
    },
    /// The hand's physical body was removed.
    PhysicalControllerEnded {
        /// The hand.
        hand: HandId,
    },
    /// A pose jumped further than `teleport_distance_m`; the hand restarted there.
    HandTeleported {
        /// The hand.
        hand: HandId,
        /// Length of the jump, metres.
        distance_m: f32,
    },
}

/// A pose that was refused; the hand keeps its previous state.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// No such hand.
    #[error("hand {0} does not exist")]
    NoSuchHand(HandId),
    /// Position, rotation, time, grip or trigger is NaN or infinite.
    #[error("hand {hand}: non-finite pose or button value")]
    NonFinite {
        /// The hand.
        hand: HandId,
    },
    /// The sample is not newer than the previous one.
    #[error("hand {hand}: sample time {time_s} s is not after the previous {previous_s} s")]
    TimeNotIncreasing {
        /// The hand.
        hand: HandId,
        /// The refused time.
        time_s: f64,
        /// The previous time.
        previous_s: f64,
    },
}

/// An object or particle near a hand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hovered {
    /// The target.
    pub target: Target,
    /// Distance from the hand to the target's body position, metres.
    pub distance_m: f32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum HandState {
    Free,
    Waiting {
        target: Target,
    },
    Holding {
        target: Target,
        offset_m: Vec3,
        offset_rot: Quat,
    },
    Controller {
        body: RigidBodyHandle,
    },
}

#[derive(Debug)]
struct Hand {
    config: HandConfig,
    input: Option<HandInput>,
    history: VecDeque<HandSample>,
    state: HandState,
    hovered: Vec<Hovered>,
    grip_down: bool,
}

/// Throw velocity from samples: the mean of the last three sample-to-sample velocities
/// (thesis Figure 4.2).
pub fn throw_velocity(history: &[HandSample]) -> (Vec3, Vec3) {
    let n = history.len();
    let mut lin = Vec3::ZERO;
    let mut ang = Vec3::ZERO;
    let mut k = 0;
    for i in n.saturating_sub(3).max(1)..n {
        let (a, b) = (history[i - 1], history[i]);
        let dt = (b.time_s - a.time_s) as f32;
        if dt > 1e-5 {
            lin += (b.position_m - a.position_m) / dt;
            ang += rotation_vector(b.rotation * a.rotation.inverse()) / dt;
            k += 1;
        }
    }
    if k == 0 {
        (Vec3::ZERO, Vec3::ZERO)
    } else {
        (lin / k as f32, ang / k as f32)
    }
}

/// Axis × angle of the shortest rotation equal to `q`.
fn rotation_vector(q: Quat) -> Vec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let (axis, angle) = q.normalize().to_axis_angle();
    if angle.is_finite() && axis.is_finite() {
        axis * angle
    } else {
        Vec3::ZERO
    }
}

fn clamp_len(v: Vec3, max: f32) -> Vec3 {
    let l = v.length();
    if l > max && l > 0.0 {
        v * (max / l)
    } else {
        v
    }
}

/// The hands of one peer and what they do to the world.
#[derive(Debug, Default)]
pub struct Interaction {
    hands: Vec<Hand>,
    events: VecDeque<InteractionEvent>,
    /// Released objects watched until they rest: (object, seconds at rest so far, needed).
    resting: Vec<(ObjectRef, f32, f32, f32)>,
}

impl Interaction {
    /// No hands yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a hand; returns its id, or which setting is out of range.
    pub fn add_hand(&mut self, config: HandConfig) -> Result<HandId, ConfigError> {
        config.validate()?;
        self.hands.push(Hand {
            config,
            input: None,
            history: VecDeque::with_capacity(8),
            state: HandState::Free,
            hovered: Vec::new(),
            grip_down: false,
        });
        Ok(self.hands.len() - 1)
    }

    /// Feeds a new pose and button state. Non-finite values and samples that are not newer
    /// are refused and change nothing.
    pub fn set_input(&mut self, hand: HandId, input: HandInput) -> Result<(), InputError> {
        let h = self
            .hands
            .get_mut(hand)
            .ok_or(InputError::NoSuchHand(hand))?;
        let s = input.sample;
        if !(s.position_m.is_finite()
            && s.rotation.is_finite()
            && s.rotation.length_squared() > 1e-6
            && s.time_s.is_finite()
            && input.grip.is_finite()
            && input.trigger.is_finite())
        {
            return Err(InputError::NonFinite { hand });
        }
        let sample = HandSample {
            rotation: s.rotation.normalize(),
            ..s
        };
        if let Some(last) = h.history.back() {
            if sample.time_s <= last.time_s {
                return Err(InputError::TimeNotIncreasing {
                    hand,
                    time_s: sample.time_s,
                    previous_s: last.time_s,
                });
            }
            let jump = sample.position_m.distance(last.position_m);
            if jump > h.config.teleport_distance_m {
                h.history.clear();
                self.events.push_back(InteractionEvent::HandTeleported {
                    hand,
                    distance_m: jump,
                });
            }
        }
        if h.history.len() == 8 {
            h.history.pop_front();
        }
        h.history.push_back(sample);
        h.input = Some(HandInput {
            sample,
            grip: input.grip.clamp(0.0, 1.0),
            trigger: input.trigger.clamp(0.0, 1.0),
        });
        Ok(())
    }

    /// What a hand hovers, closest first (for highlighting).
    pub fn hovered(&self, hand: HandId) -> &[Hovered] {
        self.hands
            .get(hand)
            .map(|h| h.hovered.as_slice())
            .unwrap_or(&[])
    }

    /// What a hand holds.
    pub fn held(&self, hand: HandId) -> Option<Target> {
        match self.hands.get(hand)?.state {
            HandState::Holding { target, .. } => Some(target),
            _ => None,
        }
    }

    /// True while the hand waits for authority.
    pub fn is_waiting(&self, hand: HandId) -> bool {
        matches!(
            self.hands.get(hand).map(|h| h.state),
            Some(HandState::Waiting { .. })
        )
    }

    /// The hand's physical controller body, while it is one.
    pub fn controller_body(&self, hand: HandId) -> Option<RigidBodyHandle> {
        match self.hands.get(hand)?.state {
            HandState::Controller { body } => Some(body),
            _ => None,
        }
    }

    /// Next event for the app.
    pub fn poll_event(&mut self) -> Option<InteractionEvent> {
        self.events.pop_front()
    }

    /// Authority over `object` was granted: hands waiting for it start holding at the next
    /// [`update`](Self::update).
    pub fn grant(&mut self, object: ObjectRef) {
        for h in &mut self.hands {
            if let HandState::Waiting { target } = h.state {
                if target.object() == object {
                    // Offsets are taken at the next update, where the world is at hand.
                    h.state = HandState::Holding {
                        target,
                        offset_m: Vec3::NAN,
                        offset_rot: Quat::IDENTITY,
                    };
                }
            }
        }
    }

    /// Authority over `object` was denied: hands waiting for it give up.
    pub fn deny(&mut self, object: ObjectRef) {
        for (i, h) in self.hands.iter_mut().enumerate() {
            if let HandState::Waiting { target } = h.state {
                if target.object() == object {
                    h.state = HandState::Free;
                    self.events
                        .push_back(InteractionEvent::GrabDenied { hand: i, object });
                }
            }
        }
    }

    /// Forgets every hold and every wait for authority, with no throw and no event, and the
    /// objects watched until they rest: for when the objects are about to go (the peer
    /// leaves the room and joins it again). The hands stay, and so does a physical controller;
    /// a grip still held down grabs again only after it is let go and pressed anew.
    pub fn release_all(&mut self) {
        for h in &mut self.hands {
            if matches!(
                h.state,
                HandState::Waiting { .. } | HandState::Holding { .. }
            ) {
                h.state = HandState::Free;
            }
            h.hovered.clear();
        }
        self.resting.clear();
    }

    /// One fixed step of interaction, before the soft bodies and the world are stepped with
    /// the same `dt_s`: hover, grip edges, holds, throws, the physical controller, rest watch.
    pub fn update(
        &mut self,
        world: &mut PhysicsWorld,
        soft: &mut SoftBodySet,
        ownership: &dyn Ownership,
        dt_s: f32,
    ) {
        let dt = dt_s.max(1e-5);
        for i in 0..self.hands.len() {
            self.update_hand(i, world, soft, ownership, dt);
        }
        self.watch_rest(world, soft, dt);
    }

    fn update_hand(
        &mut self,
        i: HandId,
        world: &mut PhysicsWorld,
        soft: &mut SoftBodySet,
        own: &dyn Ownership,
        dt: f32,
    ) {
        let Some(input) = self.hands[i].input else {
            return;
        };
        let pos = input.sample.position_m;
        let rot = input.sample.rotation;
        let controller = self.controller_body(i);
        // Hover (4.1, Figure 4.1): everything grabbable within the hover sphere.
        let cfg = self.hands[i].config.clone();
        let ball = Ball::new(cfg.hover_radius_m);
        let mut filter = QueryFilter::default().exclude_sensors();
        if let Some(c) = controller {
            filter = filter.exclude_rigid_body(c);
        }
        let mut hovered: Vec<Hovered> = Vec::new();
        for (_, co) in world.intersect_shape(Pose::from_translation(pos), &ball, filter) {
            let Some(bh) = co.parent() else { continue };
            let Some(body) = world.bodies.get(bh) else {
                continue;
            };
            let target = match soft.part_of(bh) {
                Some(SoftPart::Particle(sh, p)) => {
                    let center_dynamic = soft
                        .get(sh)
                        .and_then(|b| world.bodies.get(b.center()))
                        .is_some_and(|c| c.is_dynamic());
                    if cfg.soft_grab == SoftGrab::Center && center_dynamic {
                        Target::SoftCenter(sh)
                    } else {
                        Target::SoftParticle(sh, p)
                    }
                }
                Some(SoftPart::Center(sh)) => Target::SoftCenter(sh),
                None if body.is_dynamic() => Target::Rigid(bh),
                None => continue,
            };
            let d = body.translation().distance(pos);
            match hovered.iter_mut().find(|h| h.target == target) {
                Some(h) => h.distance_m = h.distance_m.min(d),
                None => hovered.push(Hovered {
                    target,
                    distance_m: d,
                }),
            }
        }
        hovered.sort_by(|a, b| a.distance_m.total_cmp(&b.distance_m));
        self.hands[i].hovered = hovered;

        // Grip edges with hysteresis.
        let was_down = self.hands[i].grip_down;
        let down = if was_down {
            input.grip >= cfg.grip_off
        } else {
            input.grip >= cfg.grip_on
        };
        self.hands[i].grip_down = down;
        if down && !was_down {
            if let Some(first) = self.hands[i].hovered.first().copied() {
                let object = first.target.object();
                if own.is_local(object) {
                    self.hands[i].state = HandState::Holding {
                        target: first.target,
                        offset_m: Vec3::NAN,
                        offset_rot: Quat::IDENTITY,
                    };
                } else {
                    self.hands[i].state = HandState::Waiting {
                        target: first.target,
                    };
                    self.events
                        .push_back(InteractionEvent::AuthorityRequested { hand: i, object });
                }
            } else if cfg.physical_controller {
                let body = world.insert_body(
                    RigidBodyBuilder::dynamic()
                        .translation(pos)
                        .gravity_scale(0.0)
                        .ccd_enabled(true)
                        .can_sleep(false),
                );
                world.insert_collider(
                    ColliderBuilder::ball(cfg.controller_radius_m).mass(cfg.controller_mass_kg),
                    Some(body),
                );
                self.hands[i].state = HandState::Controller { body };
                self.events
                    .push_back(InteractionEvent::PhysicalControllerStarted { hand: i });
            }
        } else if !down && was_down {
            match self.hands[i].state {
                HandState::Holding {
                    target, offset_m, ..
                } => {
                    // Another hand still on the same body (two hands on one object, or on two
                    // particles of one soft body): no throw of a shared body, no rest watch.
                    let object = target.object();
                    let other_holds_object = self.other_hand_on(i, object);
                    let other_holds_body = self.hands.iter().enumerate().any(|(k, h)| {
                        k != i && matches!(h.state, HandState::Holding { target: t, .. } if t == target)
                    });
                    let v = if other_holds_body {
                        Vec3::ZERO
                    } else if cfg.hold_mode == HoldMode::Velocity && offset_m.is_finite() {
                        let history: Vec<HandSample> =
                            self.hands[i].history.iter().copied().collect();
                        let (lin, ang) = throw_velocity(&history);
                        let lin = clamp_len(lin, cfg.max_linear_speed_mps);
                        let ang = clamp_len(ang, cfg.max_angular_speed_radps);
                        apply_release(world, soft, target, lin, ang);
                        lin
                    } else {
                        release_without_throw(world, soft, target);
                        Vec3::ZERO
                    };
                    self.events.push_back(InteractionEvent::Released {
                        hand: i,
                        target,
                        velocity_mps: v,
                    });
                    self.resting.retain(|r| r.0 != object);
                    if !other_holds_object {
                        self.resting
                            .push((object, 0.0, cfg.rest_time_s, cfg.rest_speed_mps));
                    }
                }
                HandState::Waiting { target } => {
                    self.events.push_back(InteractionEvent::GrabCancelled {
                        hand: i,
                        object: target.object(),
                    });
                }
                HandState::Controller { body } => {
                    world.remove_body(body);
                    self.events
                        .push_back(InteractionEvent::PhysicalControllerEnded { hand: i });
                }
                HandState::Free => {}
            }
            self.hands[i].state = HandState::Free;
        }

        // Holding: drive the target toward the hand.
        if let HandState::Holding {
            target,
            mut offset_m,
            mut offset_rot,
        } = self.hands[i].state
        {
            if !offset_m.is_finite() {
                // First step of the hold: keep the grasped pose relative to the hand.
                let Some((x, q)) = target_pose(world, soft, target) else {
                    self.hands[i].state = HandState::Free;
                    return;
                };
                offset_m = rot.inverse() * (x - pos);
                offset_rot = rot.inverse() * q;
                if let Target::SoftParticle(..) = target {
                    offset_m = Vec3::ZERO; // the particle comes to the hand
                }
                self.hands[i].state = HandState::Holding {
                    target,
                    offset_m,
                    offset_rot,
                };
                self.resting.retain(|r| r.0 != target.object());
                self.events
                    .push_back(InteractionEvent::Grabbed { hand: i, target });
            }
            let goal = pos + rot * offset_m;
            let goal_rot = rot * offset_rot;
            match cfg.hold_mode {
                HoldMode::Velocity => velocity_hold(world, soft, target, goal, goal_rot, &cfg, dt),
                HoldMode::Parent => parent_hold(world, soft, target, goal, goal_rot),
            }
        }
        if let HandState::Controller { body } = self.hands[i].state {
            if let Some(b) = world.bodies.get_mut(body) {
                let v = clamp_len((pos - b.translation()) / dt, cfg.max_linear_speed_mps);
                b.set_linvel(v, true);
            }
        }
    }

    /// True if a hand other than `hand` holds or waits for any part of `object`.
    fn other_hand_on(&self, hand: HandId, object: ObjectRef) -> bool {
        self.hands.iter().enumerate().any(|(k, h)| {
            k != hand
                && match h.state {
                    HandState::Holding { target, .. } | HandState::Waiting { target } => {
                        target.object() == object
                    }
                    _ => false,
                }
        })
    }

    fn watch_rest(&mut self, world: &PhysicsWorld, soft: &SoftBodySet, dt: f32) {
        // A watched object that a hand has taken again is no longer resting.
        let held: Vec<ObjectRef> = self
            .resting
            .iter()
            .map(|r| r.0)
            .filter(|o| self.other_hand_on(usize::MAX, *o))
            .collect();
        self.resting.retain(|r| !held.contains(&r.0));
        let mut done = Vec::new();
        for (k, (object, timer, need, speed)) in self.resting.iter_mut().enumerate() {
            let max_speed = match *object {
                ObjectRef::Rigid(h) => world.bodies.get(h).map(|b| b.linvel().length()),
                ObjectRef::Soft(h) => soft.get(h).map(|b| {
                    b.particles()
                        .iter()
                        .chain(std::iter::once(&b.center()))
                        .filter_map(|p| world.bodies.get(*p))
                        .map(|p| p.linvel().length())
                        .fold(0.0f32, f32::max)
                }),
            };
            match max_speed {
                None => done.push((k, None)),
                Some(s) if s < *speed => {
                    *timer += dt;
                    if *timer >= *need {
                        done.push((k, Some(*object)));
                    }
                }
                Some(_) => *timer = 0.0,
            }
        }
        for (k, obj) in done.into_iter().rev() {
            self.resting.remove(k);
            if let Some(object) = obj {
                self.events
                    .push_back(InteractionEvent::CameToRest { object });
            }
        }
    }
}

fn target_body(soft: &SoftBodySet, target: Target) -> Option<RigidBodyHandle> {
    match target {
        Target::Rigid(h) => Some(h),
        Target::SoftCenter(h) => soft.get(h).map(|b| b.center()),
        Target::SoftParticle(h, i) => soft
            .get(h)
            .and_then(|b| b.particles().get(i as usize).copied()),
    }
}

fn target_pose(world: &PhysicsWorld, soft: &SoftBodySet, target: Target) -> Option<(Vec3, Quat)> {
    let b = world.bodies.get(target_body(soft, target)?)?;
    Some((b.translation(), *b.rotation()))
}

/// Thesis 4.1: set the velocity that reaches the goal in one step (gravity compensated),
/// limited, so contacts and masses still act: a held box stops at a wall.
fn velocity_hold(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    target: Target,
    goal: Vec3,
    goal_rot: Quat,
    cfg: &HandConfig,
    dt: f32,
) {
    let gravity = world.gravity;
    match target {
        Target::SoftParticle(h, i) => {
            let Some(x) = soft
                .get(h)
                .and_then(|b| b.particles().get(i as usize).copied())
                .and_then(|p| world.bodies.get(p))
                .map(|b| b.translation())
            else {
                return;
            };
            let step = clamp_len(goal - x, cfg.max_linear_speed_mps * dt);
            if let Some(b) = soft.get_mut(h) {
                b.set_particle_drive(i as usize, Some(x + step));
            }
        }
        _ => {
            let Some(bh) = target_body(soft, target) else {
                return;
            };
            let Some(b) = world.bodies.get_mut(bh) else {
                return;
            };
            let v = (goal - b.translation()) / dt - gravity * b.gravity_scale() * dt;
            let w = rotation_vector(goal_rot * b.rotation().inverse()) / dt;
            b.set_linvel(clamp_len(v, cfg.max_linear_speed_mps), true);
            b.set_angvel(clamp_len(w, cfg.max_angular_speed_radps), true);
        }
    }
}

/// Thesis 4.2, kept to compare: the pose is set, velocity zeroed; physics is skipped.
fn parent_hold(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    target: Target,
    goal: Vec3,
    goal_rot: Quat,
) {
    let Some(bh) = target_body(soft, target) else {
        return;
    };
    let Some(b) = world.bodies.get_mut(bh) else {
        return;
    };
    match target {
        Target::SoftParticle(..) => b.set_translation(goal, true),
        _ => b.set_position(Pose::from_parts(goal, goal_rot), true),
    }
    b.set_linvel(Vec3::ZERO, true);
    b.set_angvel(Vec3::ZERO, true);
}

fn apply_release(
    world: &mut PhysicsWorld,
    soft: &mut SoftBodySet,
    target: Target,
    lin: Vec3,
    ang: Vec3,
) {
    if let Target::SoftParticle(h, i) = target {
        if let Some(b) = soft.get_mut(h) {
            b.set_particle_drive(i as usize, None);
        }
    }
    if let Some(b) = target_body(soft, target).and_then(|h| world.bodies.get_mut(h)) {
        b.set_linvel(lin, true);
        if !matches!(target, Target::SoftParticle(..)) {
            b.set_angvel(ang, true);
        }
    }
}

fn release_without_throw(world: &mut PhysicsWorld, soft: &mut SoftBodySet, target: Target) {
    apply_release(world, soft, target, Vec3::ZERO, Vec3::ZERO);
}
