//! The set of soft bodies, in the rapier style: generational handles over slots, which
//! rapier body belongs to which soft body, and the one pipeline step over all of them.

use rapier3d::prelude::{PhysicsWorld, RigidBodyHandle};

use super::handle::SoftBodyHandle;
use super::SoftBody;
use crate::{Mesh, SoftBodyConfig, SoftBodyError};

/// A set of soft bodies in the rapier style: generational handles, one pipeline step.
#[derive(Debug, Default)]
pub struct SoftBodySet {
    slots: Vec<(u32, Option<SoftBody>)>,
    free: Vec<u32>,
    groups_used: u32,
    /// Rapier body → (soft body, particle index or `None` for the center).
    owners: std::collections::HashMap<RigidBodyHandle, (SoftBodyHandle, Option<u32>)>,
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

    /// Builds a soft body from `mesh` (already baked into world space) and inserts its bodies
    /// and colliders into `world`.
    pub fn insert(
        &mut self,
        mesh: &Mesh,
        config: SoftBodyConfig,
        world: &mut PhysicsWorld,
    ) -> Result<SoftBodyHandle, SoftBodyError> {
        config.validate()?;
        mesh.validate("<soft body mesh>")?;
        let bit = 1 + 2 * (self.groups_used % 15);
        self.groups_used += 1;
        let body = SoftBody::build(mesh, config, world, bit)?;
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
        Ok(handle)
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
        for &h in body.particles.iter().chain(std::iter::once(&body.center)) {
            world.remove_body(h);
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
                b.deform(world);
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
