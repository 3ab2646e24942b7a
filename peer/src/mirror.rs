//! The mirror: the room's networked objects as bodies in this peer's rapier world.
//!
//! Who simulates what: the owner of an object simulates it (rigid props are dynamic bodies,
//! soft bodies run the particle method); everyone else shows the session's interpolated state
//! (rigid props become kinematic, soft bodies get `apply_state`). The mirror owns the world,
//! the soft bodies and the map both ways between network ids and bodies; the [`Peer`]
//! decides, from the session, which objects are whose.
//!
//! [`Peer`]: crate::Peer

use std::collections::{BTreeMap, HashMap};

use glam::{Quat, Vec3};
use softsync_interaction::ObjectRef;
use softsync_net::wire::TopologyEvent;
use softsync_net::{NetId, ObjectState, PeerId};
use softsync_softbody::rapier3d::prelude::*;
use softsync_softbody::{BuildStep, SoftBodyHandle, SoftBodySet};

use crate::events::{PeerError, TopologyError};
use crate::peer::topology::{plane_of, segment_of};
/// Where a scene's class becomes a body (`scene/body.rs`), re-exported where it was.
pub use crate::scene::body::{build_body, LocalBody};
use crate::scene::{Kind, Scene};

/// A networked object as this peer knows it.
#[derive(Clone, Debug)]
pub struct MirroredObject {
    /// What it is.
    pub kind: Kind,
    /// Its body in the local world.
    pub body: LocalBody,
    /// For avatar parts: the peer whose avatar it is (its first owner).
    pub avatar_of: Option<PeerId>,
    /// Last pose of an avatar part we own (set by the bot or the device).
    pub pose: (Vec3, Quat),
    /// Entries of its topology log applied to its body.
    pub topology: u32,
    /// Its resolution level (`method: auto`), if a resolution change named one; `None`: the
    /// class's spawn level.
    pub level: Option<u8>,
}

/// The local world and the networked objects in it.
pub(crate) struct Mirror {
    /// rapier: the scene's static geometry and the objects' bodies.
    pub(crate) world: PhysicsWorld,
    /// Soft bodies.
    pub(crate) soft: SoftBodySet,
    /// Networked objects by id.
    pub(crate) objects: BTreeMap<NetId, MirroredObject>,
    /// Networked ids by body (what the hands touch).
    pub(crate) by_ref: HashMap<ObjectRef, NetId>,
    /// Objects being built off the frame (`LocalBody::Building`): the build, and the log
    /// entries it replays.
    pub(crate) builds: HashMap<NetId, Build>,
    /// Soft objects the room despawned while builds were running (the body a cut replaced,
    /// shown until its pieces land, so it does not blink out), and since when.
    pub(crate) leaving: Vec<(NetId, softsync_net::Instant)>,
}

/// An object's body being built off the frame.
pub(crate) struct Build {
    pub(crate) job: softsync_softbody::BodyBuild,
    /// The log entries it replays (the object's log when it started).
    pub(crate) entries: Vec<TopologyEvent>,
    /// When it started (the peer's clock): it lands [`BUILD_LANDS_AFTER`] later.
    pub(crate) started: softsync_net::Instant,
}

/// How long after it starts a build lands, whatever the worker's speed: the same frame on
/// every run (virtual time stays deterministic), and time enough for the worker (a bunny's
/// piece takes ~8 ms on two cores), so the frame seldom waits for it.
pub(crate) const BUILD_LANDS_AFTER: std::time::Duration = std::time::Duration::from_millis(30);

impl Mirror {
    /// A world stepping by `dt_s` with `scene`'s static geometry, and no objects yet.
    pub(crate) fn new(scene: &Scene, dt_s: f32) -> Self {
        let mut world = PhysicsWorld::new();
        world.integration_parameters.dt = dt_s;
        scene.build_static(&mut world);
        Mirror {
            world,
            soft: SoftBodySet::new(),
            objects: BTreeMap::new(),
            by_ref: HashMap::new(),
            builds: HashMap::new(),
            leaving: Vec::new(),
        }
    }

    /// The body an object's hands would touch (none for avatar parts).
    pub(crate) fn object_ref(&self, id: NetId) -> Option<ObjectRef> {
        match self.objects.get(&id)?.body {
            LocalBody::Rigid(h) => Some(ObjectRef::Rigid(h)),
            LocalBody::Soft(h) => Some(ObjectRef::Soft(h)),
            LocalBody::Pose | LocalBody::Building => None,
        }
    }

    /// The networked id of a body.
    pub(crate) fn id_of(&self, r: ObjectRef) -> Option<NetId> {
        self.by_ref.get(&r).copied()
    }

    /// Build a body of `kind` at a pose (not yet a networked object: see [`Mirror::insert`]).
    pub(crate) fn build(
        &mut self,
        scene: &Scene,
        kind: Kind,
        pos: Vec3,
        rot: Quat,
    ) -> Result<LocalBody, PeerError> {
        build_body(scene, kind, &mut self.world, &mut self.soft, pos, rot)
    }

    /// Make `body` the networked object `id`.
    pub(crate) fn insert(
        &mut self,
        id: NetId,
        kind: Kind,
        body: LocalBody,
        avatar_of: Option<PeerId>,
    ) {
        match body {
            LocalBody::Rigid(h) => {
                self.by_ref.insert(ObjectRef::Rigid(h), id);
            }
            LocalBody::Soft(h) => {
                self.by_ref.insert(ObjectRef::Soft(h), id);
            }
            LocalBody::Pose | LocalBody::Building => {}
        }
        self.objects.insert(
            id,
            MirroredObject {
                kind,
                body,
                avatar_of,
                pose: (Vec3::ZERO, Quat::IDENTITY),
                topology: 0,
                level: None,
            },
        );
    }

    /// Object `from` is object `to` from now on (a body built before the session named it).
    pub(crate) fn rename(&mut self, from: NetId, to: NetId) {
        let Some(o) = self.objects.remove(&from) else {
            return;
        };
        match o.body {
            LocalBody::Rigid(h) => {
                self.by_ref.insert(ObjectRef::Rigid(h), to);
            }
            LocalBody::Soft(h) => {
                self.by_ref.insert(ObjectRef::Soft(h), to);
            }
            LocalBody::Pose | LocalBody::Building => {}
        }
        self.objects.insert(to, o);
    }

    /// Drop object `id` and its body from the world.
    pub(crate) fn remove(&mut self, id: NetId) {
        let Some(o) = self.objects.remove(&id) else {
            return;
        };
        match o.body {
            LocalBody::Rigid(h) => {
                self.by_ref.remove(&ObjectRef::Rigid(h));
                self.world.remove_body(h);
            }
            LocalBody::Soft(h) => {
                self.by_ref.remove(&ObjectRef::Soft(h));
                self.soft.remove(h, &mut self.world);
            }
            LocalBody::Building => {
                self.builds.remove(&id);
            }
            LocalBody::Pose => {}
        }
        self.leaving.retain(|(l, _)| *l != id);
    }

    /// Drop every networked object (the static scene stays).
    pub(crate) fn clear(&mut self) {
        let ids: Vec<NetId> = self.objects.keys().copied().collect();
        for id in ids {
            self.remove(id);
        }
    }

    /// Object `id` is no longer leaving (the room spawned it again): dropped now.
    pub(crate) fn forget_leaving(&mut self, id: NetId) {
        if self.leaving.iter().any(|(l, _)| *l == id) {
            self.remove(id);
        }
    }

    /// Entries of `id`'s topology log applied so far.
    pub(crate) fn topology_applied(&self, id: NetId) -> u32 {
        self.objects.get(&id).map_or(0, |o| o.topology)
    }

    /// Applies one topology log entry to `id`'s soft body: a tear segment, a lift, the cut
    /// that made this piece (the body becomes piece `keep`; the other pieces are dropped, they
    /// are objects of their own), a resolution change.
    pub(crate) fn apply_topology(
        &mut self,
        scene: &Scene,
        id: NetId,
        event: &TopologyEvent,
    ) -> Result<(), TopologyError> {
        let Some(o) = self.objects.get(&id) else {
            return Ok(());
        };
        let LocalBody::Soft(h) = o.body else {
            return Err(TopologyError(format!("object {} is not a soft body", id.0)));
        };
        // the resolution's particle count is checked here, once the body is replaced
        let kind = o.kind;
        let step = build_step(scene, kind, event, false)?;
        let new = step
            .apply(&mut self.soft, &mut self.world, h)
            .map_err(TopologyError)?;
        if new != h {
            self.replace_soft(id, h, new);
        }
        if let TopologyEvent::Resolution { level, particles } = event {
            if let Some(o) = self.objects.get_mut(&id) {
                o.level = Some(*level);
            }
            let n = self.soft.get(new).map_or(0, |b| b.num_particles());
            if n != *particles as usize {
                return Err(TopologyError(format!(
                    "level {level} of {} has {n} particles here, {particles} at its owner",
                    scene.name_of(kind)
                )));
            }
        }
        if let Some(o) = self.objects.get_mut(&id) {
            o.topology += 1;
        }
        Ok(())
    }

    /// Object `id`'s soft body `old` was replaced by `new` (a cut's piece, another
    /// resolution).
    fn replace_soft(&mut self, id: NetId, old: SoftBodyHandle, new: SoftBodyHandle) {
        self.by_ref.remove(&ObjectRef::Soft(old));
        self.by_ref.insert(ObjectRef::Soft(new), id);
        if let Some(o) = self.objects.get_mut(&id) {
            o.body = LocalBody::Soft(new);
        }
    }

    /// Set the pose of a pose-only object (an avatar part).
    pub(crate) fn set_pose(&mut self, id: NetId, pos: Vec3, rot: Quat) {
        if let Some(o) = self.objects.get_mut(&id) {
            o.pose = (pos, rot);
        }
    }

    /// The state of a body in the local world (`pose`: for a pose-only body, or a body that
    /// is gone).
    pub(crate) fn body_state(&self, body: LocalBody, pose: (Vec3, Quat)) -> ObjectState {
        let (pos, rot) = pose;
        match body {
            LocalBody::Pose | LocalBody::Building => ObjectState::rigid(pos, rot),
            LocalBody::Rigid(h) => match self.world.bodies.get(h) {
                Some(b) => ObjectState::rigid(b.translation(), *b.rotation()),
                None => ObjectState::rigid(pos, rot),
            },
            LocalBody::Soft(h) => match self.soft.get(h) {
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

    /// The state of object `id`'s body in the local world.
    pub(crate) fn state(&self, id: NetId) -> Option<ObjectState> {
        let o = self.objects.get(&id)?;
        Some(self.body_state(o.body, o.pose))
    }

    /// Rigid props we own are dynamic; the others follow the network, kinematically.
    pub(crate) fn set_simulated(&mut self, id: NetId, ours: bool) {
        let body = self.objects.get(&id).map(|o| o.body);
        if let (Some(LocalBody::Soft(h)), true) = (body, ours) {
            // ours: simulated here again (a replica is made by `place_shown`)
            if let Some(b) = self.soft.get_mut(h) {
                b.set_replica(&mut self.world, false);
            }
        }
        let Some(LocalBody::Rigid(h)) = body else {
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

    /// Put object `id`'s body at `pos`, `rot`, at rest (a soft body in its rest shape), with no
    /// velocity: for an object that left the room's bounds. False for a pose-only object or
    /// one with no body.
    pub(crate) fn return_home(&mut self, id: NetId, pos: Vec3, rot: Quat) -> bool {
        let Some(o) = self.objects.get(&id) else {
            return false;
        };
        match o.body {
            LocalBody::Pose | LocalBody::Building => false,
            LocalBody::Rigid(h) => match self.world.bodies.get_mut(h) {
                Some(b) => {
                    b.set_position(Pose::from_parts(pos, rot), true);
                    b.set_linvel(Vec3::ZERO, true);
                    b.set_angvel(Vec3::ZERO, true);
                    true
                }
                None => false,
            },
            LocalBody::Soft(h) => match self.soft.get_mut(h) {
                Some(b) => {
                    let particles: Vec<Vec3> =
                        b.rest_offsets().iter().map(|o| pos + rot * *o).collect();
                    b.apply_state(&mut self.world, pos, rot, &particles).is_ok()
                }
                None => false,
            },
        }
    }

    /// Show state `s` on object `id`'s body. False when a soft body refused it (wrong particle
    /// count, non-finite values): the body keeps its last state.
    pub(crate) fn apply_shown(&mut self, id: NetId, s: &ObjectState) -> bool {
        self.show(id, s, true)
    }

    /// [`Self::apply_shown`] before a step: a soft body's particles go where the state says
    /// (for the step's contacts) and it becomes a replica, deformed by the `apply_shown` after
    /// the step alone.
    pub(crate) fn place_shown(&mut self, id: NetId, s: &ObjectState) -> bool {
        self.show(id, s, false)
    }

    /// After the step: a replica (kinematic, moved by the step to the state placed before it)
    /// only has its mesh deformed; any other soft body we show takes `s` again.
    pub(crate) fn finish_shown(&mut self, id: NetId, s: &ObjectState) -> bool {
        if let Some(LocalBody::Soft(h)) = self.objects.get(&id).map(|o| o.body) {
            if let Some(b) = self.soft.get_mut(h).filter(|b| b.is_replica()) {
                b.update_mesh(&self.world);
                return true;
            }
        }
        self.show(id, s, true)
    }

    fn show(&mut self, id: NetId, s: &ObjectState, deform: bool) -> bool {
        let Some(o) = self.objects.get(&id) else {
            return true;
        };
        match o.body {
            LocalBody::Pose | LocalBody::Building => true,
            LocalBody::Rigid(h) => {
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
                true
            }
            LocalBody::Soft(h) => match self.soft.get_mut(h) {
                Some(b) if deform => b
                    .apply_state(&mut self.world, s.pos, s.rot, &s.particles)
                    .is_ok(),
                Some(b) => {
                    // sent particle by particle: the owner simulates it, we show it; centre
                    // only: we simulate the particles around the centre we are given
                    b.set_replica(&mut self.world, !s.particles.is_empty());
                    b.place_state(&mut self.world, s.pos, s.rot, &s.particles)
                        .is_ok()
                }
                None => true,
            },
        }
    }
}

/// The body step a topology log entry of a `kind` object is (a resolution: its level's
/// settings, and its particle count if `check_particles`).
pub(crate) fn build_step(
    scene: &Scene,
    kind: Kind,
    event: &TopologyEvent,
    check_particles: bool,
) -> Result<BuildStep, TopologyError> {
    Ok(match event {
        TopologyEvent::Tear { .. } => {
            BuildStep::Tear(segment_of(event).ok_or_else(|| TopologyError("not a tear".into()))?)
        }
        TopologyEvent::Lift => BuildStep::Lift,
        TopologyEvent::Cut { keep, .. } => BuildStep::Cut {
            plane: plane_of(event)?,
            keep: usize::from(*keep),
        },
        TopologyEvent::Resolution { level, particles } => BuildStep::Reconfigure {
            config: scene
                .level_config(kind, usize::from(*level))
                .ok_or_else(|| {
                    TopologyError(format!(
                        "{} has no resolution level {level}",
                        scene.name_of(kind)
                    ))
                })?
                .clone(),
            particles: check_particles.then_some(*particles as usize),
        },
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::path::Path;

    fn scene() -> Scene {
        Scene::by_name(
            "bench-ball",
            Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets")),
        )
        .unwrap()
    }

    fn kind(s: &Scene, name: &str) -> Kind {
        s.kind(name).unwrap()
    }

    #[test]
    fn bodies_and_ids_map_both_ways_until_removed() {
        let scene = scene();
        let mut m = Mirror::new(&scene, 1.0 / 60.0);
        let statics = m.world.bodies.len();
        let pos = Vec3::new(0.0, 1.0, 0.0);
        let ball = m
            .build(&scene, kind(&scene, "softball"), pos, Quat::IDENTITY)
            .unwrap();
        let block = m
            .build(&scene, kind(&scene, "block"), pos, Quat::IDENTITY)
            .unwrap();
        let head = m.build(&scene, Kind::HEAD, pos, Quat::IDENTITY).unwrap();
        assert_eq!(head, LocalBody::Pose);
        m.insert(NetId(1), kind(&scene, "softball"), ball, None);
        m.insert(NetId(2), kind(&scene, "block"), block, None);
        m.insert(NetId(3), Kind::HEAD, head, Some(PeerId(7)));
        for id in [NetId(1), NetId(2)] {
            let r = m.object_ref(id).unwrap();
            assert_eq!(m.id_of(r), Some(id));
        }
        assert_eq!(
            m.object_ref(NetId(3)),
            None,
            "avatar parts have no body to touch"
        );
        // A soft body is placed where it was built: its center is at `pos`.
        let s = m.state(NetId(1)).unwrap();
        assert!(s.pos.distance(pos) < 0.01, "{}", s.pos);
        assert_eq!(s.particles.len(), 60);
        m.set_pose(NetId(3), Vec3::ONE, Quat::IDENTITY);
        assert_eq!(m.state(NetId(3)).unwrap().pos, Vec3::ONE);
        let r = m.object_ref(NetId(1)).unwrap();
        m.remove(NetId(1));
        assert_eq!(m.id_of(r), None);
        m.clear();
        assert!(m.objects.is_empty() && m.by_ref.is_empty());
        assert_eq!(m.world.bodies.len(), statics, "the static scene stays");
    }

    #[test]
    fn remote_rigid_props_are_kinematic_and_a_bad_soft_state_is_refused() {
        let scene = scene();
        let mut m = Mirror::new(&scene, 1.0 / 60.0);
        let pos = Vec3::new(0.0, 1.0, 0.0);
        let block = m
            .build(&scene, kind(&scene, "block"), pos, Quat::IDENTITY)
            .unwrap();
        m.insert(NetId(2), kind(&scene, "block"), block, None);
        let LocalBody::Rigid(h) = block else {
            panic!("a block is rigid")
        };
        m.set_simulated(NetId(2), false);
        assert!(m.world.bodies.get(h).unwrap().is_kinematic());
        m.set_simulated(NetId(2), true);
        assert!(m.world.bodies.get(h).unwrap().is_dynamic());
        // A dynamic body takes a shown state at once.
        let to = Vec3::new(0.2, 1.1, 0.0);
        assert!(m.apply_shown(NetId(2), &ObjectState::rigid(to, Quat::IDENTITY)));
        assert_eq!(m.state(NetId(2)).unwrap().pos, to);

        let ball = m
            .build(&scene, kind(&scene, "softball"), pos, Quat::IDENTITY)
            .unwrap();
        m.insert(NetId(1), kind(&scene, "softball"), ball, None);
        let mut s = m.state(NetId(1)).unwrap();
        s.particles.pop();
        assert!(!m.apply_shown(NetId(1), &s), "one particle short");
        let mut s = m.state(NetId(1)).unwrap();
        s.particles[0].x = f32::NAN;
        assert!(!m.apply_shown(NetId(1), &s), "non-finite");
        assert!(m.state(NetId(1)).unwrap().particles[0].is_finite());
    }
}
