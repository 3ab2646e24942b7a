//! Changing a running body's resolution (its particle clustering) without a visible pop:
//! what `method: auto` does when a body is touched, squeezed or comes to rest.
//!
//! The new body is clustered from the same rest mesh with the new config, placed where the
//! old one is (its center's pose and rigid velocity) and its particles start displaced by the
//! weighted mean displacement of their vertices, as a cut's pieces do. That resampling
//! smooths the deformation, and the new particles (other sizes, other colliders) settle into
//! their own equilibrium under whatever presses the body, in a few steps: the surface would
//! jump by millimetres (8 mm in the first step for a 10 cm box squeezed 4 cm, switched from
//! 3 cm to 1.5 cm clusters). It does not: the switch shows the mesh where it was, and the
//! *shown deformation* (in the body's frame, so rigid motion passes untouched) then follows
//! the simulated one by at most [`BLEND_STEP_M`] (0.5 mm) per vertex per step until they
//! meet. A body deformed faster than that during the blend lags instead of jumping; after
//! [`MAX_BLEND_STEPS`] the limit doubles every 30 steps, so the blend always ends.

use glam::Vec3;
use rapier3d::prelude::PhysicsWorld;

use super::{BodyPlan, SoftBody, Spawn};
use crate::{SoftBodyConfig, SoftBodyError};

/// Largest change a fading correction makes to a vertex in one step, metres.
pub const BLEND_STEP_M: f32 = 0.0005;
/// Most steps a correction fades over.
pub const MAX_BLEND_STEPS: u32 = 90;

/// What the steps computed for one body, counted ([`SoftBody::work`]): the per-frame work a
/// replica costs is bounded by counting, not by timing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BodyWork {
    /// Meshes deformed from the particles (a step's, or an `apply_state`'s).
    pub deformations: u64,
    /// Restoring passes (every particle's velocity planned).
    pub restorings: u64,
    /// A replica's mesh kept: placed at the very state it was last deformed for.
    pub meshes_kept: u64,
}

/// What a body is doing, for choosing its resolution ([`crate::methods::auto`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Activity {
    /// A particle is driven (held by a hand).
    pub driven: bool,
    /// The largest particle displacement from its rigid rest target, metres.
    pub max_displacement_m: f32,
    /// The center's linear speed, m/s.
    pub speed_mps: f32,
    /// The fastest particle's speed relative to the body's rigid motion, m/s: how fast the
    /// body is changing shape.
    pub deformation_speed_mps: f32,
    /// The center and every particle are asleep.
    pub asleep: bool,
}

/// The shown deformation after a resolution change, per welded vertex in the center's frame:
/// it follows the simulated one at most `limit` per step until they meet.
#[derive(Clone, Debug, Default)]
pub(crate) struct Blend {
    shown: Vec<Vec3>,
    steps: u32,
    active: bool,
    /// Set by the step for its deformation: only a step moves the shown mesh toward the
    /// simulated one (a replica's `apply_state` before and after the step does not).
    stepping: bool,
}

impl Blend {
    pub(crate) fn active(&self) -> bool {
        self.active
    }

    /// The most a shown vertex may move toward the simulated one this step: `BLEND_STEP_M`
    /// for `MAX_BLEND_STEPS` steps, then doubling every 30 steps (a body squeezed faster than
    /// the fade still converges).
    pub(crate) fn start_step(&mut self) {
        self.stepping = self.active;
    }

    fn limit_m(&self) -> f32 {
        let over = self.steps.saturating_sub(MAX_BLEND_STEPS) / 30;
        BLEND_STEP_M * (1u32 << over.min(16)) as f32
    }

    /// The shown position of vertex `v` (center-frame deformation `sim`), moved toward `sim`.
    pub(crate) fn follow(&mut self, v: usize, sim: Vec3) -> Vec3 {
        let limit = if self.stepping { self.limit_m() } else { 0.0 };
        match self.shown.get_mut(v) {
            Some(q) => {
                let d = sim - *q;
                let l = d.length();
                *q = if l > limit && l.is_finite() {
                    *q + d * (limit / l)
                } else {
                    sim
                };
                *q
            }
            None => sim,
        }
    }

    /// After a step's vertices: ends the blend once every shown vertex is at its simulated
    /// place (`converged`).
    pub(crate) fn finish_step(&mut self, converged: bool) {
        if !std::mem::take(&mut self.stepping) {
            return;
        }
        self.steps += 1;
        if converged {
            *self = Blend::default();
        }
    }

    /// The largest change a shown vertex may make in one step now, metres.
    pub fn max_step_m(&self) -> f32 {
        if self.active {
            self.limit_m()
        } else {
            0.0
        }
    }
}

/// A planned resolution change: the new body and, per new welded vertex, the old welded
/// vertex at the same rest position.
pub(crate) struct Reconfigure {
    pub(crate) plan: BodyPlan,
    pub(crate) spawn: Spawn,
    /// Per new welded vertex: its old welded index.
    old_of_new: Vec<u32>,
    /// The old body's deformed welded vertices, world space (as last shown).
    old_vertices: Vec<Vec3>,
}

impl SoftBody {
    /// Whether the center and every particle sleep (cheaper than [`activity`](Self::activity)).
    pub fn is_asleep(&self, world: &PhysicsWorld) -> bool {
        world
            .bodies
            .get(self.center)
            .is_some_and(|c| c.is_sleeping())
            && self
                .particles
                .iter()
                .all(|h| world.bodies.get(*h).is_none_or(|b| b.is_sleeping()))
    }

    /// What the body is doing now.
    pub fn activity(&self, world: &PhysicsWorld) -> Activity {
        let center = world.bodies.get(self.center);
        let asleep = self.is_asleep(world);
        let (c, vc, wc) = center.map_or((Vec3::ZERO, Vec3::ZERO, Vec3::ZERO), |b| {
            (b.translation(), b.linvel(), b.angvel())
        });
        let deformation_speed_mps = self
            .particles
            .iter()
            .filter_map(|h| world.bodies.get(*h))
            .map(|b| (b.linvel() - vc - wc.cross(b.translation() - c)).length())
            .filter(|v| v.is_finite())
            .fold(0.0f32, f32::max);
        Activity {
            deformation_speed_mps,
            driven: self.drives.iter().any(Option::is_some),
            max_displacement_m: self
                .displacement
                .iter()
                .map(|d| d.length())
                .fold(0.0f32, f32::max),
            speed_mps: center.map_or(0.0, |c| c.linvel().length()),
            asleep,
        }
    }

    /// True while a resolution change's correction is still fading.
    pub fn is_blending(&self) -> bool {
        self.blend.active()
    }

    /// The most a shown vertex may move toward the simulated body in one step while a
    /// resolution change blends, metres (0 if none).
    pub fn blend_step_m(&self) -> f32 {
        self.blend.max_step_m()
    }

    /// Puts every particle to sleep (a body at rest that should cost nothing until
    /// something touches it): while they sleep, nothing drives them and the center is still,
    /// the step skips the body. The center is left to rapier (it sleeps when it rests): put
    /// to sleep by hand on a body that rapier then wakes, its contacts could be lost.
    pub fn sleep(&mut self, world: &mut PhysicsWorld) {
        for &h in &self.particles {
            if let Some(b) = world.bodies.get_mut(h) {
                b.sleep();
            }
        }
    }

    /// Plans this body clustered with `config`, where it is now. A torn body is refused (its
    /// particle map follows its tears; a fresh clustering would bridge the slits).
    pub(crate) fn plan_reconfigure(
        &self,
        world: &PhysicsWorld,
        config: SoftBodyConfig,
    ) -> Result<Reconfigure, SoftBodyError> {
        if !self.tear_boxes.is_empty() {
            return Err(SoftBodyError::Config(
                "a torn body keeps its resolution".into(),
            ));
        }
        let center = world.bodies.get(self.center).ok_or_else(|| {
            SoftBodyError::Config("the body's center is not in this world".into())
        })?;
        let (c, r) = (center.translation(), *center.rotation());
        let (vc, wc) = (center.linvel(), center.angvel());
        if !(c.is_finite() && r.is_finite() && vc.is_finite() && wc.is_finite()) {
            return Err(SoftBodyError::Config(
                "the body's center state is not finite".into(),
            ));
        }
        // The rest mesh in the frame the body was built in, so a soft region still applies.
        let baked = crate::Mesh {
            positions: self
                .rest_mesh
                .positions
                .iter()
                .map(|p| *p + self.rest_center)
                .collect(),
            normals: self.rest_mesh.normals.clone(),
            triangles: self.rest_mesh.triangles.clone(),
        };
        let plan = BodyPlan::centred(&baked, config, Some(self.rest_center))?;
        // Same render vertices in the same order: each new welded vertex's old one.
        let mut old_of_new = vec![u32::MAX; plan.rest_vertices.len()];
        for (k, &w) in plan.welded.render_to_welded.iter().enumerate() {
            if let (Some(slot), Some(&old)) = (
                old_of_new.get_mut(w as usize),
                self.welded.render_to_welded.get(k),
            ) {
                *slot = old;
            }
        }
        if old_of_new
            .iter()
            .any(|&o| o as usize >= self.rest_vertices.len())
        {
            return Err(SoftBodyError::Config(
                "the new clustering's mesh does not match the body's".into(),
            ));
        }
        let displaced = |v: usize| {
            let d = self.vertices[v] - (c + r * self.rest_vertices[v]);
            if d.is_finite() {
                d
            } else {
                Vec3::ZERO
            }
        };
        let displacement = super::topology::mean_displacements(&plan.map, |v| {
            Some(displaced(old_of_new[v as usize] as usize))
        });
        let spawn = Spawn {
            origin: self.rest_center,
            translation: c,
            rotation: r,
            linvel: vc,
            angvel: wc,
            displacement,
            keep_center: Some((self.center, self.center_collider)),
        };
        Ok(Reconfigure {
            plan,
            spawn,
            old_of_new,
            old_vertices: self.vertices.clone(),
        })
    }

    /// After a [`plan_reconfigure`](Self::plan_reconfigure)'s body is instantiated: shows it
    /// where the old one was, then lets it follow the simulation at most `BLEND_STEP_M` per
    /// step.
    pub(crate) fn start_blend(
        &mut self,
        world: &PhysicsWorld,
        old_of_new: &[u32],
        old_vertices: &[Vec3],
    ) {
        let Some(center) = world.bodies.get(self.center) else {
            return;
        };
        let (c, inv) = (center.translation(), center.rotation().inverse());
        let shown = old_of_new
            .iter()
            .map(|&old| {
                let q = inv * (old_vertices[old as usize] - c);
                if q.is_finite() {
                    q
                } else {
                    Vec3::ZERO
                }
            })
            .collect();
        self.blend = Blend {
            shown,
            steps: 0,
            active: true,
            stepping: false,
        };
        self.deform(world);
    }
}

impl Reconfigure {
    /// Builds the new body into `world` around the old body's center, which stays (its
    /// particles use collision bits `bit`, the center's pair).
    pub(crate) fn instantiate(self, world: &mut PhysicsWorld, bit: u32) -> SoftBody {
        let Reconfigure {
            plan,
            spawn,
            old_of_new,
            old_vertices,
        } = self;
        let mut body = plan.instantiate(world, bit, &spawn);
        body.start_blend(world, &old_of_new, &old_vertices);
        body
    }
}
