//! The set of soft bodies, in the rapier style: generational handles over slots, which
//! rapier body belongs to which soft body, and the one pipeline step over all of them.

use rapier3d::prelude::{PhysicsWorld, RigidBodyHandle};

use super::handle::SoftBodyHandle;
use super::topology::StageClock;
use super::SoftBody;
use crate::cut::{CutError, CutPlane, TearSegment, TearStats};
use crate::{Mesh, SoftBodyConfig, SoftBodyError};

/// A set of soft bodies in the rapier style: generational handles, one pipeline step.
#[derive(Clone, Debug, Default)]
pub struct SoftBodySet {
    slots: Vec<(u32, Option<SoftBody>)>,
    free: Vec<u32>,
    groups_used: u32,
    /// Rapier body → (soft body, particle index or `None` for the center).
    owners: std::collections::HashMap<RigidBodyHandle, (SoftBodyHandle, Option<u32>)>,
    /// Times the stages of a tear ([`SoftBody::last_tear_timings`]); none by default.
    stage_clock: Option<StageClock>,
}

/// What a rapier body is to a soft body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SoftPart {
    /// The center body.
    Center(SoftBodyHandle),
    /// Particle `index` of the soft body.
    Particle(SoftBodyHandle, u32),
}

impl SoftBodySet {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Gives the set a clock to time the stages of each tear with (a bench's wall clock; the
    /// simulation never reads it), or takes it away.
    pub fn set_stage_clock(&mut self, clock: Option<StageClock>) {
        self.stage_clock = clock;
    }

    /// Builds a soft body from `mesh` (already baked into world space) and inserts its bodies
    /// and colliders into `world`.
    pub fn insert(
        &mut self,
        mesh: &Mesh,
        config: SoftBodyConfig,
        world: &mut PhysicsWorld,
    ) -> Result<SoftBodyHandle, SoftBodyError> {
        let plan = super::SoftBodyPlan::new(mesh, config)?;
        Ok(self.insert_plan(&plan, world))
    }

    /// Inserts a body of `plan` into `world`, at rest where its mesh was baked: the body
    /// [`insert`](Self::insert) builds from the same mesh and config, without clustering
    /// again.
    pub fn insert_plan(
        &mut self,
        plan: &super::SoftBodyPlan,
        world: &mut PhysicsWorld,
    ) -> SoftBodyHandle {
        let bit = self.next_group_bit();
        let body = super::BodyPlan::clone(&plan.0).instantiate(world, bit, &super::Spawn::AT_REST);
        self.insert_built(body)
    }

    /// Inserts a body of `plan` at rest with its center at `pos`, turned by `rot` (its rest
    /// shape placed there, no velocity). Refused, removing it again, if the pose is not
    /// finite.
    pub fn insert_plan_at(
        &mut self,
        plan: &super::SoftBodyPlan,
        world: &mut PhysicsWorld,
        pos: glam::Vec3,
        rot: glam::Quat,
    ) -> Result<SoftBodyHandle, SoftBodyError> {
        let h = self.insert_plan(plan, world);
        let placed = match self.get_mut(h) {
            Some(b) => {
                let particles: Vec<glam::Vec3> =
                    b.rest_offsets().iter().map(|o| pos + rot * *o).collect();
                b.apply_state(world, pos, rot, &particles)
            }
            None => Err(SoftBodyError::InvalidHandle(h)),
        };
        match placed {
            Ok(()) => Ok(h),
            Err(e) => {
                self.remove(h, world);
                Err(e)
            }
        }
    }

    /// The collision-group bit pair of the next body.
    fn next_group_bit(&mut self) -> u32 {
        let bit = 1 + 2 * (self.groups_used % 15);
        self.groups_used += 1;
        bit
    }

    /// Gives a built body a slot and a handle.
    fn insert_built(&mut self, body: SoftBody) -> SoftBodyHandle {
        let index = match self.free.pop() {
            Some(i) => {
                let slot = &mut self.slots[i as usize];
                slot.0 = slot.0.wrapping_add(1);
                slot.1 = Some(body);
                i
            }
            None => {
                self.slots.push((0, Some(body)));
                (self.slots.len() - 1) as u32
            }
        };
        let handle = SoftBodyHandle {
            index,
            generation: self.slots[index as usize].0,
        };
        if let Some(b) = self.slots[index as usize].1.as_ref() {
            self.owners.insert(b.center, (handle, None));
            for (i, &p) in b.particles.iter().enumerate() {
                self.owners.insert(p, (handle, Some(i as u32)));
            }
        }
        handle
    }

    /// Tears body `handle` along `segment`, given in the body's rest frame (see
    /// [`SoftBody::rest_vertices`]: relative to the rest center, in the center body's local
    /// frame, so the same event means the same on every peer whatever the body's pose).
    ///
    /// The body's rest mesh is torn (tear paper Algorithm 1, a slit `tear_width_m` wide) and
    /// its welded and render meshes rebuilt; then its particle map follows (Algorithm 4):
    /// new vertices join particles as in clustering, neighbour links through the tear box go,
    /// and particles let go of vertices across the tear (weights renormalised). The particles
    /// and their rapier bodies stay; the body keeps simulating. Consecutive segments continue
    /// one slit until [`end_tear_stroke`](Self::end_tear_stroke). Refused (changing nothing)
    /// for an unknown handle or a segment [`TearMesh::tear`](crate::cut::TearMesh::tear)
    /// refuses. The particle update's figures: [`SoftBody::last_particle_update`]; the time of
    /// each stage, with a [stage clock](Self::set_stage_clock): [`SoftBody::last_tear_timings`].
    pub fn tear(
        &mut self,
        handle: SoftBodyHandle,
        world: &mut PhysicsWorld,
        segment: &TearSegment,
    ) -> Result<TearStats, CutError> {
        let clock = self.stage_clock;
        self.get_mut(handle)
            .ok_or_else(|| unknown(handle))?
            .tear_rest(world, segment, clock)
    }

    /// Ends body `handle`'s current tear stroke (the scalpel lifted); false for an unknown
    /// handle.
    pub fn end_tear_stroke(&mut self, handle: SoftBodyHandle) -> bool {
        match self.get_mut(handle) {
            Some(b) => {
                b.lift_tear();
                true
            }
            None => false,
        }
    }

    /// Cuts body `handle` by `plane`, given in its rest frame (as for [`tear`](Self::tear)),
    /// into new soft bodies, one per piece (tear paper Algorithm 2, capped: `cut::cut_mesh`),
    /// positive side first. Each piece has its own center body and particles, clustered with
    /// the old body's config (finer for a piece under 4 particles: radii, or closest-N's
    /// count, halved up to 6 times); it starts where its part of the body was (the old
    /// center's pose, its particles displaced by the mean displacement of their old
    /// vertices), moving with the old center's rigid velocity (linear velocity at its own
    /// center, same angular velocity). The old body is removed. A refused cut (unknown handle,
    /// a plane that is not finite or misses, a piece that cannot be a body) changes nothing.
    pub fn cut(
        &mut self,
        handle: SoftBodyHandle,
        world: &mut PhysicsWorld,
        plane: &CutPlane,
    ) -> Result<Vec<SoftBodyHandle>, CutError> {
        let plans = self
            .get(handle)
            .ok_or_else(|| unknown(handle))?
            .plan_cut(world, plane)?;
        self.remove(handle, world);
        let mut out = Vec::with_capacity(plans.len());
        for (plan, spawn) in plans {
            let bit = self.next_group_bit();
            let body = plan.instantiate(world, bit, &spawn);
            out.push(self.insert_built(body));
        }
        Ok(out)
    }

    /// Cuts body `handle` by `plane` (rest frame, as for [`cut`](Self::cut)) keeping only
    /// piece `keep` (in `cut`'s order): the same body `cut` makes for that piece, without
    /// planning the others (a room makes each piece an object of its own, and every peer
    /// builds each from the log: planning only the piece it keeps, a peer does one cut's
    /// work per cut, not one per piece). The old body is removed. Refused like `cut`, and for
    /// a `keep` past the pieces, changing nothing.
    pub fn cut_keep(
        &mut self,
        handle: SoftBodyHandle,
        world: &mut PhysicsWorld,
        plane: &CutPlane,
        keep: usize,
    ) -> Result<SoftBodyHandle, CutError> {
        let mut plans = self
            .get(handle)
            .ok_or_else(|| unknown(handle))?
            .plan_cut_pieces(world, plane, Some(keep))?;
        let Some((plan, spawn)) = plans.pop() else {
            return Err(CutError::Mesh(format!("the cut made no piece {keep}")));
        };
        self.remove(handle, world);
        let bit = self.next_group_bit();
        let body = plan.instantiate(world, bit, &spawn);
        Ok(self.insert_built(body))
    }

    /// The particle count of every piece [`cut`](Self::cut) would make of body `handle` with
    /// `plane` (rest frame), in the same order, changing nothing: what a peer names when it
    /// asks the room for a cut, since every peer makes the same pieces.
    pub fn cut_piece_particles(
        &self,
        handle: SoftBodyHandle,
        world: &PhysicsWorld,
        plane: &CutPlane,
    ) -> Result<Vec<usize>, CutError> {
        let plans = self
            .get(handle)
            .ok_or_else(|| unknown(handle))?
            .plan_cut(world, plane)?;
        Ok(plans.iter().map(|(p, _)| p.map.len()).collect())
    }

    /// How many particles body `handle` would have clustered with `config` (what
    /// [`reconfigure`](Self::reconfigure) would make of it: a cut's piece clusters its own
    /// mesh, so its count is not its class's), changing nothing.
    pub fn particles_with(
        &self,
        handle: SoftBodyHandle,
        world: &PhysicsWorld,
        config: SoftBodyConfig,
    ) -> Result<usize, SoftBodyError> {
        config.validate()?;
        let body = self.get(handle).ok_or_else(|| {
            SoftBodyError::Config(format!("soft body {handle:?} is not in this set"))
        })?;
        Ok(body.plan_reconfigure(world, config)?.plan.map.len())
    }

    /// Rebuilds body `handle` clustered with `config` (another resolution of the same rest
    /// mesh), where it is now and moving as it moves, and returns its new handle; the old
    /// handle is gone. The change shows no pop: the mesh is where it was, and the difference
    /// the new particles cannot hold fades out at most 0.5 mm per step (see
    /// [`SoftBody::is_blending`]). Particle drives are dropped (a hand holding the body takes
    /// its new particle at its next update). Refused, changing nothing, for an unknown handle,
    /// a torn body, or a config or clustering that fails.
    pub fn reconfigure(
        &mut self,
        handle: SoftBodyHandle,
        world: &mut PhysicsWorld,
        config: SoftBodyConfig,
    ) -> Result<SoftBodyHandle, SoftBodyError> {
        config.validate()?;
        let planned = self
            .get(handle)
            .ok_or_else(|| {
                SoftBodyError::Config(format!("soft body {handle:?} is not in this set"))
            })?
            .plan_reconfigure(world, config)?;
        // the particles go, the center stays (with its collision bit pair)
        let Some(old) = self.take(handle) else {
            return Err(SoftBodyError::Config(format!(
                "soft body {handle:?} is not in this set"
            )));
        };
        for &p in &old.particles {
            world.remove_body(p);
        }
        let bit = match old
            .center_collider
            .and_then(|c| world.colliders.get(c))
            .map(|c| c.collision_groups().memberships.bits())
        {
            Some(b) if b.trailing_zeros() >= 1 => b.trailing_zeros() - 1,
            _ => self.next_group_bit(),
        };
        let body = planned.instantiate(world, bit);
        Ok(self.insert_built(body))
    }

    /// Which soft body (and which part of it) a rapier body belongs to, if any.
    pub fn part_of(&self, body: RigidBodyHandle) -> Option<SoftPart> {
        self.owners.get(&body).map(|&(h, p)| match p {
            None => SoftPart::Center(h),
            Some(i) => SoftPart::Particle(h, i),
        })
    }

    /// Removes a soft body and its rapier bodies.
    pub fn remove(&mut self, handle: SoftBodyHandle, world: &mut PhysicsWorld) -> Option<SoftBody> {
        let body = self.take(handle)?;
        for &h in body.particles.iter().chain(std::iter::once(&body.center)) {
            world.remove_body(h);
        }
        Some(body)
    }

    /// Moves body `handle` out of this set and `world` into `to` and `to_world`, as it is:
    /// its rapier bodies and colliders are copied over (state, velocities, sleep) and removed
    /// here, with the collision bits of its new set. What a body built in a private world —
    /// on a worker thread, off the frame — becomes when it joins the room's world. `None`
    /// (nothing moved) for an unknown handle.
    pub fn move_body(
        &mut self,
        handle: SoftBodyHandle,
        world: &mut PhysicsWorld,
        to: &mut SoftBodySet,
        to_world: &mut PhysicsWorld,
    ) -> Option<SoftBodyHandle> {
        let mut body = self.take(handle)?;
        let bit = to.next_group_bit();
        let (pg, cg) = super::groups(bit, body.config.self_collisions);
        let mut copy = |h: RigidBodyHandle,
                        collider: Option<rapier3d::prelude::ColliderHandle>,
                        groups: rapier3d::prelude::InteractionGroups| {
            let rb = world.bodies.get(h).cloned();
            let co = collider.and_then(|c| world.colliders.get(c).cloned());
            world.remove_body(h);
            let nh = to_world.insert_body(
                rb.unwrap_or_else(|| rapier3d::prelude::RigidBodyBuilder::dynamic().build()),
            );
            let nc = co.map(|mut c| {
                c.set_collision_groups(groups);
                to_world.insert_collider(c, Some(nh))
            });
            (nh, nc)
        };
        let (c, cc) = copy(body.center, body.center_collider, cg);
        body.center = c;
        body.center_collider = cc;
        for i in 0..body.particles.len() {
            let (p, pc) = copy(body.particles[i], body.particle_colliders[i], pg);
            body.particles[i] = p;
            body.particle_colliders[i] = pc;
        }
        Some(to.insert_built(body))
    }

    /// Takes a body out of the set, leaving its rapier bodies in the world.
    fn take(&mut self, handle: SoftBodyHandle) -> Option<SoftBody> {
        let slot = self.slots.get_mut(handle.index as usize)?;
        if slot.0 != handle.generation {
            return None;
        }
        let body = slot.1.take()?;
        self.free.push(handle.index);
        self.owners.remove(&body.center);
        for p in &body.particles {
            self.owners.remove(p);
        }
        Some(body)
    }

    /// The body behind a handle.
    pub fn get(&self, handle: SoftBodyHandle) -> Option<&SoftBody> {
        self.slots
            .get(handle.index as usize)
            .filter(|s| s.0 == handle.generation)
            .and_then(|s| s.1.as_ref())
    }

    /// The body behind a handle, mutably.
    pub fn get_mut(&mut self, handle: SoftBodyHandle) -> Option<&mut SoftBody> {
        self.slots
            .get_mut(handle.index as usize)
            .filter(|s| s.0 == handle.generation)
            .and_then(|s| s.1.as_mut())
    }

    /// All bodies with their handles.
    pub fn iter(&self) -> impl Iterator<Item = (SoftBodyHandle, &SoftBody)> {
        self.slots.iter().enumerate().filter_map(|(i, (g, b))| {
            b.as_ref().map(|b| {
                (
                    SoftBodyHandle {
                        index: i as u32,
                        generation: *g,
                    },
                    b,
                )
            })
        })
    }

    /// Number of bodies.
    pub fn len(&self) -> usize {
        self.slots.iter().filter(|s| s.1.is_some()).count()
    }

    /// True if the set holds no body.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Sets every body's particle velocities for the coming step (thesis 3.2.2). Call before
    /// stepping `world` with the same `dt_s`.
    pub fn pre_physics(&mut self, world: &mut PhysicsWorld, dt_s: f32) {
        for (_, b) in self.slots.iter_mut() {
            if let Some(b) = b {
                b.apply_restoring_velocities(world, dt_s);
            }
        }
    }

    /// Deforms every body's mesh from its particles (thesis 3.3). Call after stepping `world`.
    pub fn post_physics(&mut self, world: &PhysicsWorld) {
        for (_, b) in self.slots.iter_mut() {
            if let Some(b) = b {
                // a dormant body did not move: its mesh is as it was; a replica's mesh is made
                // by its next apply_state (unless a resolution change's blend moves it on)
                if (!b.dormant && !b.replica) || b.blend.active() {
                    b.blend.start_step();
                    b.deform(world);
                }
            }
        }
    }

    /// One fixed step: restoring velocities, `world.step()` at `dt_s`, deformation.
    pub fn step(&mut self, world: &mut PhysicsWorld, dt_s: f32) {
        world.integration_parameters.dt = dt_s;
        self.pre_physics(world, dt_s);
        world.step();
        self.post_physics(world);
    }
}

/// The refusal for a handle not in the set.
fn unknown(handle: SoftBodyHandle) -> CutError {
    CutError::Mesh(format!("soft body {handle:?} is not in this set"))
}
