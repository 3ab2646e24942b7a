//! The one trait every soft-body method implements, and the fixed-step driver.

use glam::Vec3;
use rapier3d::prelude::PhysicsWorld;

use crate::methods::pbd::Energy;

/// A deformable object simulated by some method, seen from outside: it steps around
/// `world.step()`, exposes its welded surface in world space, and says when it is asleep.
///
/// Methods that live inside rapier (the particle method, rapier's own soft bodies) do their
/// work in [`Self::pre_physics`] and are moved by `world.step()`; the position-based methods
/// are not rapier bodies: they read the world's colliders after the step (kinematic props
/// already at their new poses) in [`Self::post_physics`] and push their particles out of them.
pub trait DeformableModel {
    /// Short method name for tables and `RESULT` lines.
    fn name(&self) -> &str;
    /// Work before `world.step()` (default: none).
    fn pre_physics(&mut self, _world: &mut PhysicsWorld, _dt_s: f32) {}
    /// Work after `world.step()`: solve, collide, update the surface.
    fn post_physics(&mut self, world: &mut PhysicsWorld, dt_s: f32);
    /// Welded surface vertices, world space, after the last step.
    fn surface(&self) -> &[Vec3];
    /// Outward triangles over [`Self::surface`].
    fn triangles(&self) -> &[[u32; 3]];
    /// True while the object is at rest and untouched: its steps then cost (almost) nothing.
    fn is_sleeping(&self) -> bool;
    /// Simulated degrees of freedom (particles or nodes), the resolution knob's effect.
    fn num_particles(&self) -> usize;
    /// Elements turned inside out (tetrahedral methods; 0 for the others).
    fn inverted_elements(&self) -> usize {
        0
    }
    /// Contact thickness of the surface (particle radius, contact radius), metres.
    fn contact_thickness_m(&self) -> f32 {
        0.0
    }
    /// Fastest particle speed after the last step, m/s.
    fn max_speed_mps(&self) -> f32;
    /// Pins (makes immovable) the simulated points inside the box `[min_m, max_m]`; returns how
    /// many were pinned. Scenarios hold a body this way where the particle method uses its
    /// fixed center.
    fn pin_region(&mut self, world: &mut PhysicsWorld, min_m: Vec3, max_m: Vec3) -> usize;
    /// Gives every particle the velocity `v_mps` (a throw).
    fn set_velocity(&mut self, world: &mut PhysicsWorld, v_mps: Vec3);
    /// The body's kinetic, gravitational and elastic energy under `gravity`, if the method
    /// defines one (default: none).
    fn energy(&self, _gravity: Vec3) -> Option<Energy> {
        None
    }
    /// How often a hard floor on an element's volume engaged, in all elements and in those at
    /// least half material (the reference's tets; zeros for the others).
    fn volume_floor_hits(&self) -> (u64, u64) {
        (0, 0)
    }
}

/// One fixed step of a world holding several models: every model's `pre_physics`, one
/// `world.step()` at `dt_s`, every model's `post_physics`.
pub fn step_models(world: &mut PhysicsWorld, models: &mut [Box<dyn DeformableModel>], dt_s: f32) {
    world.integration_parameters.dt = dt_s;
    for m in models.iter_mut() {
        m.pre_physics(world, dt_s);
    }
    world.step();
    for m in models.iter_mut() {
        m.post_physics(world, dt_s);
    }
}
