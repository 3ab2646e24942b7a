//! VR hand interaction on a rapier world and a soft-body set (thesis chapter 4): hover, pick
//! the closest, velocity-based hold, throw, physical controller, soft-body center or particle
//! grab, and the parent-based hold kept only for comparison (Table 1).
//!
//! Engine-agnostic: hands are streams of pose samples with grip and trigger values from any
//! source (OpenXR, a mouse, a bot script). Networking stays outside: a grab of an object the
//! local peer does not own emits [`InteractionEvent::AuthorityRequested`]; the app asks its
//! session and answers with [`Interaction::grant`] or [`Interaction::deny`].

mod config;
mod events;
mod hold;
mod input;
mod target;

use std::collections::VecDeque;

use glam::{Quat, Vec3};
use softsync_softbody::rapier3d::parry::shape::Ball;
use softsync_softbody::rapier3d::prelude::{
    ColliderBuilder, PhysicsWorld, Pose, QueryFilter, RigidBodyBuilder, RigidBodyHandle,
};
use softsync_softbody::{SoftBodyHandle, SoftBodySet, SoftPart};

pub use config::{ConfigError, HandConfig, HoldMode, SoftGrab};
pub use events::InteractionEvent;
pub use hold::{drive_particle, release_particle};
pub use input::{throw_velocity, HandInput, HandSample, InputError};
pub use target::{AllLocal, Hovered, ObjectRef, Ownership, Target};

use hold::{
    apply_release, clamp_len, parent_hold, release_without_throw, target_pose, velocity_hold,
};

/// Index of a hand in an [`Interaction`].
pub type HandId = usize;

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
    /// Holding a target another peer simulates: the hand only says where it is (the app sends
    /// it to the owner, which drives the target as it drives its own hands' targets).
    Remote {
        target: Target,
    },
}

#[derive(Clone, Debug)]
struct Hand {
    config: HandConfig,
    input: Option<HandInput>,
    history: VecDeque<HandSample>,
    state: HandState,
    hovered: Vec<Hovered>,
    grip_down: bool,
}

/// The hands of one peer and what they do to the world.
#[derive(Clone, Debug, Default)]
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

    /// What a hand holds as a remote hand (a body another peer simulates).
    pub fn remote(&self, hand: HandId) -> Option<Target> {
        match self.hands.get(hand)?.state {
            HandState::Remote { target } => Some(target),
            _ => None,
        }
    }

    /// A hand's newest input sample (where it is), if it has one.
    pub fn sample(&self, hand: HandId) -> Option<HandSample> {
        self.hands.get(hand)?.input.map(|i| i.sample)
    }

    /// A hand's throw velocity now: the mean of its last samples' velocities (Figure 4.2),
    /// limited to its `max_linear_speed_mps`.
    pub fn throw_velocity(&self, hand: HandId) -> Vec3 {
        let Some(h) = self.hands.get(hand) else {
            return Vec3::ZERO;
        };
        let history: Vec<HandSample> = h.history.iter().copied().collect();
        clamp_len(throw_velocity(&history).0, h.config.max_linear_speed_mps)
    }

    /// Hands waiting for authority over `object` hold it as remote hands instead: another
    /// peer simulates it and drives the target toward the hand ([`Interaction::remote`] says
    /// what each holds; letting go emits [`InteractionEvent::RemoteReleased`]). Each such hand
    /// emits [`InteractionEvent::Grabbed`].
    pub fn hold_remote(&mut self, object: ObjectRef) {
        for (i, h) in self.hands.iter_mut().enumerate() {
            if let HandState::Waiting { target } = h.state {
                if target.object() == object {
                    h.state = HandState::Remote { target };
                    self.events
                        .push_back(InteractionEvent::Grabbed { hand: i, target });
                }
            }
        }
    }

    /// The local peer no longer simulates `object`: hands holding it go on as remote hands
    /// (no release, no throw, no event).
    pub fn hold_as_remote(&mut self, object: ObjectRef) {
        for h in &mut self.hands {
            if let HandState::Holding { target, .. } = h.state {
                if target.object() == object {
                    h.state = HandState::Remote { target };
                }
            }
        }
    }

    /// Hand `hand`, holding (here or as a remote hand), holds `target` instead — the body it
    /// held was replaced (a cut's piece took its place): offsets are taken anew at the next
    /// update, a remote hand stays remote. False if the hand holds nothing.
    pub fn retarget(&mut self, hand: HandId, target: Target) -> bool {
        let Some(h) = self.hands.get_mut(hand) else {
            return false;
        };
        h.state = match h.state {
            HandState::Holding { .. } => HandState::Holding {
                target,
                offset_m: Vec3::NAN,
                offset_rot: Quat::IDENTITY,
            },
            HandState::Remote { .. } => HandState::Remote { target },
            _ => return false,
        };
        true
    }

    /// Watch `object` until it rests ([`InteractionEvent::CameToRest`]), with the first
    /// hand's rest settings: for an object the last remote hand let go of.
    pub fn watch_until_rest(&mut self, object: ObjectRef) {
        let Some(cfg) = self.hands.first().map(|h| h.config.clone()) else {
            return;
        };
        self.resting.retain(|r| r.0 != object);
        self.resting
            .push((object, 0.0, cfg.rest_time_s, cfg.rest_speed_mps));
    }

    /// What a hand waits for authority over.
    pub fn waiting(&self, hand: HandId) -> Option<Target> {
        match self.hands.get(hand)?.state {
            HandState::Waiting { target } => Some(target),
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
    /// Remote hands on it (see [`Interaction::hold_remote`]) go on holding it here.
    pub fn grant(&mut self, object: ObjectRef) {
        for h in &mut self.hands {
            if let HandState::Waiting { target } | HandState::Remote { target } = h.state {
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

    /// Authority over `object` was denied: hands waiting for it give up; so do remote hands
    /// on it (its owner refused them).
    pub fn deny(&mut self, object: ObjectRef) {
        for (i, h) in self.hands.iter_mut().enumerate() {
            if let HandState::Waiting { target } | HandState::Remote { target } = h.state {
                if target.object() == object {
                    h.state = HandState::Free;
                    self.events
                        .push_back(InteractionEvent::GrabDenied { hand: i, object });
                }
            }
        }
    }

    /// Soft body `old` was replaced by `new` (another resolution of it): holds, waits, hovers
    /// and rest watches on `old` move to `new`, a held particle `i` becoming particle
    /// `particle(i)` of `new` (`None`: the hand lets go, without a throw). A holding hand
    /// takes its offsets anew at the next update, so the body does not jump to the hand.
    pub fn replace_soft(
        &mut self,
        old: SoftBodyHandle,
        new: SoftBodyHandle,
        particle: impl Fn(u32) -> Option<u32>,
    ) {
        let map = |t: Target| -> Option<Target> {
            match t {
                Target::SoftCenter(h) if h == old => Some(Target::SoftCenter(new)),
                Target::SoftParticle(h, i) if h == old => {
                    particle(i).map(|j| Target::SoftParticle(new, j))
                }
                t => Some(t),
            }
        };
        for h in &mut self.hands {
            h.state = match h.state {
                HandState::Waiting { target } => match map(target) {
                    Some(target) => HandState::Waiting { target },
                    None => HandState::Free,
                },
                HandState::Remote { target } => match map(target) {
                    Some(target) => HandState::Remote { target },
                    None => HandState::Free,
                },
                HandState::Holding { target, .. } if target.object() == ObjectRef::Soft(old) => {
                    match map(target) {
                        Some(target) => HandState::Holding {
                            target,
                            offset_m: Vec3::NAN,
                            offset_rot: Quat::IDENTITY,
                        },
                        None => HandState::Free,
                    }
                }
                s => s,
            };
            h.hovered.retain_mut(|hv| match map(hv.target) {
                Some(t) => {
                    hv.target = t;
                    true
                }
                None => false,
            });
        }
        for r in &mut self.resting {
            if r.0 == ObjectRef::Soft(old) {
                r.0 = ObjectRef::Soft(new);
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
                HandState::Waiting { .. } | HandState::Holding { .. } | HandState::Remote { .. }
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
        // Physical controllers (this hand's and the others') are kinematic bodies too: never
        // targets.
        let controllers: Vec<RigidBodyHandle> = (0..self.hands.len())
            .filter_map(|h| self.controller_body(h))
            .collect();
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
                // A rigid prop someone else owns is kinematic here (moved to the owner's
                // state): still a target, and grabbing it asks for authority. A kinematic body
                // of our own (a controller, a moving platform) is not.
                None if body.is_kinematic()
                    && !controllers.contains(&bh)
                    && !own.is_local(Target::Rigid(bh).object()) =>
                {
                    Target::Rigid(bh)
                }
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
                HandState::Remote { target } => {
                    let history: Vec<HandSample> = self.hands[i].history.iter().copied().collect();
                    let v = clamp_len(throw_velocity(&history).0, cfg.max_linear_speed_mps);
                    self.events.push_back(InteractionEvent::RemoteReleased {
                        hand: i,
                        target,
                        velocity_mps: v,
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
