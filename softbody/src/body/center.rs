//! What acts on a soft body's center besides rapier: rolling resistance (rapier has none)
//! and the hold of its orientation while hands grab it. Both are part of the step's first
//! phase (`SoftBody::apply_restoring_velocities` calls them before the particles' velocities).

use rapier3d::prelude::PhysicsWorld;

use super::SoftBody;
use crate::config::SimulationSpace;

/// Rolling speed (spin × center radius) below which rolling resistance leaves a body alone,
/// m/s: rapier's sleep takes over from there (its thresholds are 5 cm/s and 0.5 rad/s).
const ROLLING_AT_REST_MPS: f32 = 0.01;

impl SoftBody {
    /// A hand holds the body, not one particle alone: while any particle is driven (a grab),
    /// the center keeps the orientation it had when the first grab began, turned back toward
    /// it a fraction `1 − exp(−stiffness·dt)` of the way per step (the restoring rate). The
    /// particles follow the center one way (thesis), so without this a held body whose
    /// center tips — half a bunny after a cut between two hands, pulled by gravity off its cut
    /// face — turns away under the hand and leaves the held particle behind: a collapse of
    /// centimetres. Only the orientation: the center still moves, and a particle grab still
    /// deforms the body as the thesis's does (a particle grab carries no rotation). Freed
    /// when the last grab lets go.
    pub(super) fn turn_center_by_hands(&mut self, world: &mut PhysicsWorld, dt_s: f32) {
        if self.config.space != SimulationSpace::World || self.drives.iter().all(Option::is_none) {
            self.held_rotation = None;
            return;
        }
        let Some(center) = world.bodies.get_mut(self.center) else {
            return;
        };
        if !center.is_dynamic() {
            return;
        }
        let r = *center.rotation();
        let Some(held) = self.held_rotation else {
            self.held_rotation = Some(r);
            return;
        };
        let (axis, angle) = (held * r.inverse()).to_axis_angle();
        // the short way round
        let angle = if angle > std::f32::consts::PI {
            angle - std::f32::consts::TAU
        } else {
            angle
        };
        let turn = axis * angle;
        if !turn.is_finite() {
            return;
        }
        let dt = dt_s.max(1e-6);
        let alpha = 1.0 - (-self.config.stiffness * dt).exp();
        center.set_angvel(turn * (alpha / dt), true);
    }

    /// Rolling resistance (`SoftBodyConfig::rolling_resistance`), above a rolling speed of
    /// [`ROLLING_AT_REST_MPS`]: while the center touches
    /// something, an angular impulse of `μ_r · r · Σ normal impulse` (the contacts' normal
    /// impulses of the last step, so the torque follows the load) against the center's spin,
    /// capped so that it stops the spin and never reverses it. The contact's friction then
    /// slows the rolling body: for a ball, `(m + I/r²)·a = μ_r·N`, i.e. `a = 5/7·μ_r·g` on a
    /// level floor. A body in flight has no contact and keeps its spin.
    pub(super) fn apply_rolling_resistance(&self, world: &mut PhysicsWorld) {
        let mu = self.config.rolling_resistance;
        if mu <= 0.0 || self.config.space != SimulationSpace::World {
            return;
        }
        let Some(collider) = self.center_collider else {
            return;
        };
        // a resting body costs nothing here (no walk over its contacts)
        if world
            .bodies
            .get(self.center)
            .is_none_or(|c| c.is_sleeping())
        {
            return;
        }
        let load: f32 = world
            .contact_pairs_with(collider)
            .map(|p| p.total_impulse_magnitude())
            .filter(|j| j.is_finite())
            .sum();
        if load <= 0.0 {
            return;
        }
        let Some(center) = world.bodies.get_mut(self.center) else {
            return;
        };
        let w = center.angvel();
        let spin = w.length();
        // below a rolling speed of 1 cm/s the body is at rest as far as rolling goes (rapier
        // puts it to sleep from there): a ball resting on a dynamic prop that the body's own
        // particles keep jiggling (the thesis room's plate) spins a little in place, and
        // stopping that spin would let the jiggling carry it away
        if center.is_sleeping()
            || !spin.is_finite()
            || spin * self.roll_radius_m < ROLLING_AT_REST_MPS
        {
            return;
        }
        let axis = w / spin;
        let dw = center.mass_properties().effective_world_inv_inertia
            * (-axis * (mu * self.roll_radius_m * load));
        // the part along the spin stops it at most; what the impulse would turn past zero
        // is not applied
        let along = -dw.dot(axis);
        let scale = if along > spin { spin / along } else { 1.0 };
        let new_w = w + dw * scale;
        if new_w.is_finite() {
            center.set_angvel(new_w, false);
        }
    }
}
