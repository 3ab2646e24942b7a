//! The body's read side and its replicated-state entry point: getters over its rapier
//! bodies, particle map and meshes, `apply_state` for replicas, and particle drives.

use glam::{Quat, Vec3};
use rapier3d::prelude::{ColliderHandle, PhysicsWorld, RigidBodyHandle, RigidBodyType};

use super::{SoftBody, TearTimings};
use crate::cluster::ParticleMap;
use crate::config::SoftBodyConfig;
use crate::cut::particles::ParticleUpdateStats;
use crate::cut::TearBoxPlanes;
use crate::mesh::{Mesh, WeldedMesh};
use crate::SoftBodyError;

/// The point of triangle `a b c` closest to `p`, and its barycentric coordinates (Ericson,
/// Real-Time Collision Detection, 5.1.5). A degenerate triangle gives its nearest corner or
/// edge point.
fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, [f32; 3]) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let denom = va + vb + vc;
    if denom.abs() < f32::MIN_POSITIVE {
        return (a, [1.0, 0.0, 0.0]);
    }
    let (v, w) = (vb / denom, vc / denom);
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

impl SoftBody {
    /// The configuration it was built with.
    pub fn config(&self) -> &SoftBodyConfig {
        &self.config
    }

    /// The particle map.
    pub fn particle_map(&self) -> &ParticleMap {
        &self.map
    }

    /// The welded mesh (topology used for volume and metrics).
    pub fn welded(&self) -> &WeldedMesh {
        &self.welded
    }

    /// Rapier handle of the center body.
    pub fn center(&self) -> RigidBodyHandle {
        self.center
    }

    /// Rapier handle of the center's collider (world mode).
    pub fn center_collider(&self) -> Option<ColliderHandle> {
        self.center_collider
    }

    /// Rapier handles of the particle bodies.
    pub fn particles(&self) -> &[RigidBodyHandle] {
        &self.particles
    }

    /// Rapier handles of the particle colliders.
    pub fn particle_colliders(&self) -> &[Option<ColliderHandle>] {
        &self.particle_colliders
    }

    /// Collider radius of each particle, metres.
    pub fn particle_radii_m(&self) -> &[f32] {
        &self.particle_radius_m
    }

    /// Number of particles.
    pub fn num_particles(&self) -> usize {
        self.particles.len()
    }

    /// Particle positions, world space.
    pub fn particle_positions(&self, world: &PhysicsWorld) -> Vec<Vec3> {
        self.particles
            .iter()
            .map(|h| {
                world
                    .bodies
                    .get(*h)
                    .map(|b| b.translation())
                    .unwrap_or(Vec3::ZERO)
            })
            .collect()
    }

    /// Particle rest positions relative to the center, in the center's frame.
    pub fn rest_offsets(&self) -> &[Vec3] {
        &self.rest_offsets
    }

    /// Center pose (translation, rotation).
    pub fn center_pose(&self, world: &PhysicsWorld) -> (Vec3, Quat) {
        world
            .bodies
            .get(self.center)
            .map(|b| (b.translation(), *b.rotation()))
            .unwrap_or((Vec3::ZERO, Quat::IDENTITY))
    }

    /// Puts the body in a replicated state: center pose and world-space particle positions,
    /// velocities zeroed, mesh deformed to match. For a peer that shows a body another peer
    /// simulates, and for the peer that just received authority. Refuses a wrong particle
    /// count or non-finite values, changing nothing.
    ///
    /// No particles at all is the centre-only state (thesis §5.4.1: only the centre is sent,
    /// every peer simulates the particles itself): the centre takes the pose and the particles
    /// come along rigidly, keeping their shape relative to it, for the local simulation to
    /// deform from there.
    pub fn apply_state(
        &mut self,
        world: &mut PhysicsWorld,
        center_pos: Vec3,
        center_rot: Quat,
        particles: &[Vec3],
    ) -> Result<(), SoftBodyError> {
        self.set_state(world, center_pos, center_rot, particles, true)
    }

    /// [`Self::apply_state`] without deforming the mesh: the bodies go where the state says
    /// (for this step's contacts) and the mesh stays as it was until the next `apply_state`
    /// or step deforms it. A replica shown before and after each step deforms once.
    pub fn place_state(
        &mut self,
        world: &mut PhysicsWorld,
        center_pos: Vec3,
        center_rot: Quat,
        particles: &[Vec3],
    ) -> Result<(), SoftBodyError> {
        self.set_state(world, center_pos, center_rot, particles, false)
    }

    /// Whether the body shows a state simulated elsewhere (a room's body another peer owns,
    /// sent particle by particle). A replica's center and particles are kinematic
    /// (position-based): [`Self::place_state`] sets where the step moves them, they push the
    /// dynamic bodies they meet and nothing pushes them, a replica at rest sleeps, and no
    /// position is a user change (rapier's narrow phase re-examines every collider a user
    /// moved, and wakes what it touches). The step neither restores nor deforms it:
    /// [`Self::update_mesh`] after the step does, once. Off (dynamic again, at rest) for a
    /// body the peer simulates itself: its own, or a centre-only body. A fixed center stays
    /// fixed.
    pub fn set_replica(&mut self, world: &mut PhysicsWorld, on: bool) {
        if self.replica == on {
            return;
        }
        self.replica = on;
        let (from, to) = if on {
            (
                RigidBodyType::Dynamic,
                RigidBodyType::KinematicPositionBased,
            )
        } else {
            (
                RigidBodyType::KinematicPositionBased,
                RigidBodyType::Dynamic,
            )
        };
        for &h in std::iter::once(&self.center).chain(&self.particles) {
            if let Some(b) = world.bodies.get_mut(h) {
                if b.body_type() == from {
                    b.set_body_type(to, true);
                    if !on {
                        b.set_linvel(Vec3::ZERO, true);
                        b.set_angvel(Vec3::ZERO, true);
                    }
                }
            }
        }
    }

    /// Deforms the mesh to where the particles are now: for a replica after the step that
    /// moved it to the state [`Self::place_state`] gave. A replica placed at the very state
    /// its mesh was last deformed for (a body at rest, or one whose owner sent nothing new)
    /// keeps its mesh: deforming it again gives the same vertices (every replica deformed
    /// every step was a quarter of the frame bench's CPU).
    pub fn update_mesh(&mut self, world: &PhysicsWorld) {
        let (placed, meshed) = self.replica_mesh;
        if self.replica && placed.is_some() && placed == meshed && !self.blend.active() {
            self.work.meshes_kept += 1;
            return;
        }
        self.deform(world);
        if self.replica {
            self.replica_mesh.1 = placed;
        }
    }

    /// See [`Self::set_replica`].
    pub fn is_replica(&self) -> bool {
        self.replica
    }

    /// The work the steps and states did on this body so far.
    pub fn work(&self) -> super::BodyWork {
        self.work
    }

    fn set_state(
        &mut self,
        world: &mut PhysicsWorld,
        center_pos: Vec3,
        center_rot: Quat,
        particles: &[Vec3],
        deform: bool,
    ) -> Result<(), SoftBodyError> {
        if particles.is_empty() && !self.particles.is_empty() {
            return self.apply_center_only(world, center_pos, center_rot);
        }
        if self.replica && !deform {
            return self.place_replica(world, center_pos, center_rot, particles);
        }
        self.check_state(center_pos, center_rot, particles)?;
        if let Some(c) = world.bodies.get_mut(self.center) {
            c.set_position(
                rapier3d::prelude::Pose::from_parts(center_pos, center_rot.normalize()),
                true,
            );
            if c.is_dynamic() {
                c.set_linvel(Vec3::ZERO, true);
                c.set_angvel(Vec3::ZERO, true);
            }
        }
        for (&h, &p) in self.particles.iter().zip(particles) {
            if let Some(b) = world.bodies.get_mut(h) {
                b.set_translation(p, true);
                b.set_linvel(Vec3::ZERO, true);
            }
        }
        if deform {
            self.deform(world);
        }
        Ok(())
    }

    /// A full state for this body: its particle count, everything finite, a rotation.
    fn check_state(
        &self,
        center_pos: Vec3,
        center_rot: Quat,
        particles: &[Vec3],
    ) -> Result<(), SoftBodyError> {
        if particles.len() != self.particles.len() {
            return Err(SoftBodyError::Config(format!(
                "state has {} particles, the body {}",
                particles.len(),
                self.particles.len()
            )));
        }
        if !(center_pos.is_finite() && center_rot.is_finite() && center_rot.length_squared() > 0.5)
            || particles.iter().any(|p| !p.is_finite())
        {
            return Err(SoftBodyError::Config("state is not finite".into()));
        }
        Ok(())
    }

    /// A replica's state: where the step moves its kinematic bodies (a particle a topology
    /// change made dynamic again is made kinematic first).
    fn place_replica(
        &mut self,
        world: &mut PhysicsWorld,
        center_pos: Vec3,
        center_rot: Quat,
        particles: &[Vec3],
    ) -> Result<(), SoftBodyError> {
        self.check_state(center_pos, center_rot, particles)?;
        self.replica_mesh.0 = Some(state_fingerprint(center_pos, center_rot, particles));
        let kinematic = |b: &mut rapier3d::prelude::RigidBody| {
            if b.body_type() == RigidBodyType::Dynamic {
                b.set_body_type(RigidBodyType::KinematicPositionBased, true);
            }
        };
        if let Some(c) = world.bodies.get_mut(self.center) {
            kinematic(c);
            c.set_next_kinematic_position(rapier3d::prelude::Pose::from_parts(
                center_pos,
                center_rot.normalize(),
            ));
        }
        for (&h, &p) in self.particles.iter().zip(particles) {
            if let Some(b) = world.bodies.get_mut(h) {
                kinematic(b);
                b.set_next_kinematic_translation(p);
            }
        }
        Ok(())
    }

    /// [`Self::apply_state`] with the centre only: the particles follow the centre's move
    /// rigidly.
    fn apply_center_only(
        &mut self,
        world: &mut PhysicsWorld,
        center_pos: Vec3,
        center_rot: Quat,
    ) -> Result<(), SoftBodyError> {
        if !(center_pos.is_finite() && center_rot.is_finite() && center_rot.length_squared() > 0.5)
        {
            return Err(SoftBodyError::Config("state is not finite".into()));
        }
        let new = rapier3d::prelude::Pose::from_parts(center_pos, center_rot.normalize());
        let Some(c) = world.bodies.get_mut(self.center) else {
            return Ok(());
        };
        let old = *c.position();
        c.set_position(new, true);
        if c.is_dynamic() {
            c.set_linvel(Vec3::ZERO, true);
            c.set_angvel(Vec3::ZERO, true);
        }
        for &h in &self.particles {
            if let Some(b) = world.bodies.get_mut(h) {
                let local = old.inverse_transform_point(b.translation());
                b.set_translation(new.transform_point(local), true);
                b.set_linvel(Vec3::ZERO, true);
            }
        }
        self.deform(world);
        Ok(())
    }

    /// Sets the whole body moving rigidly: the center at `linvel` and spinning at `angvel`,
    /// each particle at `linvel + angvel × (particle − center)` (a throw or a push from code;
    /// a hand's throw goes through the particle drives instead). Refuses non-finite
    /// velocities, changing nothing. A local-mode body's fixed center does not move.
    pub fn set_rigid_velocity(
        &self,
        world: &mut PhysicsWorld,
        linvel: Vec3,
        angvel: Vec3,
    ) -> Result<(), SoftBodyError> {
        if !(linvel.is_finite() && angvel.is_finite()) {
            return Err(SoftBodyError::Config("velocity is not finite".into()));
        }
        let c = world
            .bodies
            .get_mut(self.center)
            .map(|c| {
                if c.is_dynamic() {
                    c.set_linvel(linvel, true);
                    c.set_angvel(angvel, true);
                }
                c.translation()
            })
            .unwrap_or(Vec3::ZERO);
        for &h in &self.particles {
            if let Some(b) = world.bodies.get_mut(h) {
                let x = b.translation();
                b.set_linvel(linvel + angvel.cross(x - c), true);
            }
        }
        Ok(())
    }

    /// The rest-frame point (relative to the rest center, in the center body's frame: the
    /// frame of [`SoftBody::rest_vertices`] and of tear and cut events) that corresponds to
    /// world point `x` in the body's current deformed shape: the closest point of the
    /// deformed surface (after the last step or [`apply_state`](Self::apply_state)), taken to
    /// the same face and barycentric coordinates of the rest surface, plus `x`'s offset from
    /// it turned into the rest frame. Exact on the surface, where a tear clips faces; the
    /// centre pose alone, `R⁻¹(x − c)`, puts a blade's path through a squeezed body where the
    /// tissue was at rest, not where it is (`examples/tear_deformed.rs` measures both).
    /// Non-finite `x`, or a body with no faces, gets the centre-pose mapping.
    pub fn rest_point(&self, world: &PhysicsWorld, x: Vec3) -> Vec3 {
        let (c, r) = self.center_pose(world);
        let inv = r.inverse();
        let rigid = inv * (x - c);
        if !x.is_finite() || self.vertices.len() != self.rest_vertices.len() {
            return rigid;
        }
        let mut best: Option<(f32, Vec3, usize, [f32; 3])> = None;
        for (k, t) in self.welded.triangles.iter().enumerate() {
            let [a, b, cc] = t.map(|i| self.vertices[i as usize]);
            let (p, bary) = closest_on_triangle(x, a, b, cc);
            let d = p.distance_squared(x);
            if best.is_none_or(|(bd, ..)| d < bd) {
                best = Some((d, p, k, bary));
            }
        }
        let Some((_, p, k, bary)) = best else {
            return rigid;
        };
        let t = self.welded.triangles[k];
        let rest: Vec3 = (0..3)
            .map(|i| self.rest_vertices[t[i] as usize] * bary[i])
            .sum();
        let out = rest + inv * (x - p);
        if out.is_finite() {
            out
        } else {
            rigid
        }
    }

    /// Drives particle `i` to `goal` (a grab of one particle, thesis 4.1.2), or releases it.
    pub fn set_particle_drive(&mut self, i: usize, goal: Option<Vec3>) {
        if let Some(d) = self.drives.get_mut(i) {
            *d = goal.filter(|g| g.is_finite());
        }
    }

    /// Deformed welded vertices, world space (after the last step).
    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    /// Welded rest vertices in the rest frame: relative to the rest center, in the center
    /// body's local frame (a vertex is at `center + rotation · rest` when undeformed).
    pub fn rest_vertices(&self) -> &[Vec3] {
        &self.rest_vertices
    }

    /// The rest center in the frame the mesh was given in at insertion (the world then); the
    /// rest frame is that frame moved to this point.
    pub fn rest_center(&self) -> Vec3 {
        self.rest_center
    }

    /// The render mesh at rest, in the rest frame, after every tear so far: the mesh tears
    /// and cuts act on and peers compare (`cut::topology_hash`).
    pub fn rest_mesh(&self) -> &Mesh {
        &self.rest_mesh
    }

    /// Every tear box applied so far (those that removed or split a face), in the rest frame.
    pub fn tear_boxes(&self) -> &[TearBoxPlanes] {
        &self.tear_boxes
    }

    /// What the particle update of the last tear did.
    pub fn last_particle_update(&self) -> ParticleUpdateStats {
        self.last_particle_update
    }

    /// Where the last tear segment's time went, stage by stage.
    pub fn last_tear_timings(&self) -> TearTimings {
        self.last_tear_timings
    }

    /// Deformed render vertex positions, ready for a renderer.
    pub fn render_positions(&self) -> &[Vec3] {
        &self.render_positions
    }

    /// Recomputed render vertex normals.
    pub fn render_normals(&self) -> &[Vec3] {
        &self.render_normals
    }

    /// Render triangles (indices into the render vertices).
    pub fn render_triangles(&self) -> &[[u32; 3]] {
        &self.render_triangles
    }

    /// Enclosed volume of the rest mesh, m³.
    pub fn rest_volume_m3(&self) -> f32 {
        self.rest_volume_m3
    }

    /// Largest extent of the rest mesh, metres.
    pub fn size_m(&self) -> f32 {
        self.size_m
    }

    /// How many times a non-finite particle state was reset (should stay 0).
    pub fn non_finite_recoveries(&self) -> u64 {
        self.non_finite_recoveries
    }
}

/// A fingerprint of a state's exact bits (FNV-1a over the center's pose and every particle).
fn state_fingerprint(center_pos: Vec3, center_rot: Quat, particles: &[Vec3]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let c = [center_pos.x, center_pos.y, center_pos.z];
    let r = [center_rot.x, center_rot.y, center_rot.z, center_rot.w];
    let ps = particles.iter().flat_map(|p| [p.x, p.y, p.z]);
    for x in c.into_iter().chain(r).chain(ps) {
        h ^= u64::from(x.to_bits());
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}
