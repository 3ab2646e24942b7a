//! The thesis's particle method ([`SoftBodySet`] on rapier) behind [`DeformableModel`]: an
//! adapter, the method itself is unchanged.

use glam::Vec3;
use rapier3d::prelude::PhysicsWorld;

use crate::methods::model::DeformableModel;
use crate::{Mesh, SoftBodyConfig, SoftBodyError, SoftBodyHandle, SoftBodySet};

/// One particle soft body in its own [`SoftBodySet`].
pub struct ParticleModel {
    name: String,
    set: SoftBodySet,
    handle: SoftBodyHandle,
    triangles: Vec<[u32; 3]>,
    sleeping: bool,
    max_speed: f32,
}

impl ParticleModel {
    /// Inserts a particle body for `mesh` (world space) into `world`.
    pub fn new(
        name: impl Into<String>,
        mesh: &Mesh,
        config: SoftBodyConfig,
        world: &mut PhysicsWorld,
    ) -> Result<Self, SoftBodyError> {
        let mut set = SoftBodySet::new();
        let handle = set.insert(mesh, config, world)?;
        let triangles = set
            .get(handle)
            .map(|b| b.welded().triangles.clone())
            .ok_or(SoftBodyError::InvalidHandle(handle))?;
        Ok(Self {
            name: name.into(),
            set,
            handle,
            triangles,
            sleeping: false,
            max_speed: 0.0,
        })
    }

    /// The wrapped set and handle.
    pub fn inner(&self) -> (&SoftBodySet, SoftBodyHandle) {
        (&self.set, self.handle)
    }
}

impl DeformableModel for ParticleModel {
    fn name(&self) -> &str {
        &self.name
    }

    fn pre_physics(&mut self, world: &mut PhysicsWorld, dt_s: f32) {
        self.set.pre_physics(world, dt_s);
    }

    fn post_physics(&mut self, world: &mut PhysicsWorld, _dt_s: f32) {
        self.set.post_physics(world);
        let Some(b) = self.set.get(self.handle) else {
            return;
        };
        let mut all_asleep = true;
        let mut max_speed = 0.0f32;
        for h in b.particles().iter().chain(std::iter::once(&b.center())) {
            if let Some(rb) = world.bodies.get(*h) {
                all_asleep &= rb.is_sleeping() || rb.is_fixed();
                max_speed = max_speed.max(rb.linvel().length());
            }
        }
        self.sleeping = all_asleep;
        self.max_speed = max_speed;
    }

    fn surface(&self) -> &[Vec3] {
        self.set.get(self.handle).map_or(&[], |b| b.vertices())
    }

    fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    fn is_sleeping(&self) -> bool {
        self.sleeping
    }

    fn num_particles(&self) -> usize {
        self.set.get(self.handle).map_or(0, |b| b.num_particles())
    }

    fn max_speed_mps(&self) -> f32 {
        self.max_speed
    }

    fn contact_thickness_m(&self) -> f32 {
        self.set.get(self.handle).map_or(0.0, |b| {
            let mut r = b.particle_radii_m().to_vec();
            r.sort_unstable_by(f32::total_cmp);
            r.get(r.len() / 2).copied().unwrap_or(0.0)
        })
    }

    fn pin_region(&mut self, world: &mut PhysicsWorld, min_m: Vec3, max_m: Vec3) -> usize {
        // The particle method holds particles by driving them to a goal (a grab).
        let Some(b) = self.set.get_mut(self.handle) else {
            return 0;
        };
        let pos = b.particle_positions(world);
        let mut n = 0;
        for (i, p) in pos.iter().enumerate() {
            if p.cmpge(min_m).all() && p.cmple(max_m).all() {
                b.set_particle_drive(i, Some(*p));
                n += 1;
            }
        }
        n
    }

    fn set_velocity(&mut self, world: &mut PhysicsWorld, v_mps: Vec3) {
        let Some(b) = self.set.get(self.handle) else {
            return;
        };
        for h in b.particles().iter().chain(std::iter::once(&b.center())) {
            if let Some(rb) = world.bodies.get_mut(*h) {
                if rb.is_dynamic() {
                    rb.set_linvel(v_mps, true);
                }
            }
        }
        self.max_speed = v_mps.length();
    }
}
