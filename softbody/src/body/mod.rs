//! The thesis's particle soft body on rapier3d (chapter 3, Appendix A.6–A.12), made sound:
//! an exact per-step restoring fraction instead of the `dt / (1/90)` scaling, neighbour
//! coupling that cannot feed back on itself, the center's rigid velocity fed forward, and a
//! closed-form (drift-free) deformation.
//!
//! This module is the body itself; `set` holds the bodies of a world (it depends on this
//! module, not the other way round) and `handle` names one of them; `topology` tears a body's
//! rest mesh and updates its particle map (tear paper Algorithm 4), and plans the bodies a
//! cut makes of it. Tears and cuts are given in the *rest frame*: relative to the rest center,
//! in the center body's local frame (see [`SoftBody::rest_vertices`]).
//!
//! The struct's fields, its build (`BodyPlan`) and its per-step work (restoring, wake,
//! deformation) read each other's invariants and are one owned part; the parts that stand
//! alone live in `set`, `handle`, `topology`, `access` (getters, `apply_state`), `level`
//! (a resolution change while running, and the blend that hides it), `center` (rolling
//! resistance, and the orientation hands hold), `volume` (the volume term, a global
//! pressure) and `build` (a body's history replayed off the frame).

mod access;
pub(crate) mod build;
mod center;
pub(crate) mod handle;
mod level;
pub(crate) mod set;
mod topology;
mod volume;

pub use level::{Activity, BodyWork};
pub use topology::{StageClock, TearTimings};

use glam::{Quat, Vec3};
use rapier3d::prelude::{
    Aabb, ColliderBuilder, ColliderHandle, Group, InteractionGroups, InteractionTestMode,
    PhysicsWorld, Pose, QueryFilter, RigidBodyBuilder, RigidBodyHandle,
};

use crate::cluster::{build_particle_map, ParticleMap};
use crate::config::{
    CenterCollider, ContinuousCollision, ParticleCollider, RestoringScheme, SimulationSpace,
    SoftBodyConfig,
};
use crate::cut::particles::ParticleUpdateStats;
use crate::cut::{TearBoxPlanes, TearMesh};
use crate::mesh::{enclosed_volume, Mesh, WeldedMesh};
use crate::SoftBodyError;

/// One particle soft body: its rapier bodies, its particle map and its deformed mesh.
#[derive(Clone, Debug)]
pub struct SoftBody {
    config: SoftBodyConfig,
    welded: WeldedMesh,
    render_triangles: Vec<[u32; 3]>,
    /// Welded rest vertices relative to the rest center: the *rest frame*, the center body's
    /// local frame, in which tears and cuts are given.
    rest_vertices: Vec<Vec3>,
    /// Each rest vertex's index by its exact position, kept from one tear to the next (made
    /// at the first).
    rest_index: Option<rustc_hash::FxHashMap<[u32; 3], u32>>,
    /// The rest center in the frame the mesh was built in (the world at insertion).
    rest_center: Vec3,
    /// The render mesh at rest, in the rest frame: what tears and cuts act on.
    rest_mesh: Mesh,
    /// The rest mesh being torn, made at the first tear.
    tear: Option<TearMesh>,
    /// Every tear box applied so far, in the rest frame.
    tear_boxes: Vec<TearBoxPlanes>,
    last_particle_update: ParticleUpdateStats,
    last_tear_timings: TearTimings,
    map: ParticleMap,
    /// Particle rest positions relative to the rest center.
    rest_offsets: Vec<Vec3>,
    /// Per particle: how far its anchor (the restoring target) sits from its rest position,
    /// rest frame — a wound's opening (`slit_open_m`, tear paper §3.3.4). The vertices'
    /// skinning measures from the rest position, so they follow.
    anchor_shift: Vec<Vec3>,
    /// Per particle: `neighbour_share / Σ w`, so the shares of its neighbours sum to the share.
    neighbour_scale: Vec<f32>,
    center: RigidBodyHandle,
    center_collider: Option<ColliderHandle>,
    particles: Vec<RigidBodyHandle>,
    particle_colliders: Vec<Option<ColliderHandle>>,
    particle_radius_m: Vec<f32>,
    /// Per particle: a position it is driven to (a grab), if any.
    drives: Vec<Option<Vec3>>,
    /// The center's orientation when the current grabs began (see `turn_center_by_hands`).
    held_rotation: Option<Quat>,
    /// Per particle: displacement from its rigid rest target after the last step.
    displacement: Vec<Vec3>,
    scratch: Vec<Vec3>,
    /// Per particle: the velocity this step's restoring gives it (`None`: left alone).
    planned_v: Vec<Option<Vec3>>,
    /// The volume term's scratch: ∂V/∂x per welded vertex, and per particle.
    vertex_grad: Vec<Vec3>,
    particle_grad: Vec<Vec3>,
    /// The volume term's scratch: the welded vertices where the particles are now, relative
    /// to the center (not `vertices`, which may be blending or stale).
    sim_vertices: Vec<Vec3>,
    /// Deformed welded vertices, world space.
    vertices: Vec<Vec3>,
    render_positions: Vec<Vec3>,
    render_normals: Vec<Vec3>,
    slot_normals: Vec<Vec3>,
    rest_volume_m3: f32,
    size_m: f32,
    /// Rolling resistance's lever: mean rest vertex distance × `center_scale`.
    roll_radius_m: f32,
    non_finite_recoveries: u64,
    /// A resolution change's correction still shown (see `level`).
    blend: level::Blend,
    /// All asleep at the last step, nothing driven: the step skipped it (one bounds query).
    dormant: bool,
    /// Shows a state simulated elsewhere ([`SoftBody::set_replica`]; `update_mesh` deforms).
    replica: bool,
    /// A replica's last placed state and the state its mesh was deformed for (fingerprints).
    replica_mesh: (Option<u64>, Option<u64>),
    /// How much work the steps did on it ([`SoftBody::work`]).
    work: BodyWork,
    /// How long its particles have been still with its center asleep, seconds.
    still_s: f32,
}

/// A particle that moved less than this (m/s) through the last step is still (see
/// `STILL_BEFORE_SLEEP_S`).
const STILL_MPS: f32 = 1e-3;

/// How long a body's particles must be still, its center asleep, before the whole body is put
/// to sleep (rapier's own wait, `time_until_sleep`).
const STILL_BEFORE_SLEEP_S: f32 = 0.5;

fn groups(bit: u32, self_collisions: bool) -> (InteractionGroups, InteractionGroups) {
    // Two bits per body: particles P, center C. Particles never touch their own center
    // (Appendix A.10) and touch each other only with self-collisions on (thesis 3.5.3).
    let p = Group::from_bits_truncate(1 << bit);
    let c = Group::from_bits_truncate(1 << (bit + 1));
    let particle_filter = if self_collisions {
        Group::ALL - c
    } else {
        Group::ALL - c - p
    };
    (
        InteractionGroups::new(p, particle_filter, InteractionTestMode::And),
        InteractionGroups::new(c, Group::ALL - p, InteractionTestMode::And),
    )
}

/// A soft body planned — welded, clustered, its center's collider shape made — and in no
/// world yet: the costly part of [`SoftBodySet::insert`](crate::SoftBodySet::insert)
/// (clustering the thesis's bunny takes ~8 ms), done once.
/// [`SoftBodySet::insert_plan`](crate::SoftBodySet::insert_plan) puts a copy in a world, the
/// same body `insert` would build, in a fraction of that: a room builds every object of a
/// class (its spawns, a late joiner's snapshot, a cut's pieces, a rebuild) from one plan.
/// Cloning a plan shares it (it is immutable): handing one to a worker thread costs nothing.
#[derive(Clone)]
pub struct SoftBodyPlan(pub(crate) std::sync::Arc<BodyPlan>);

impl SoftBodyPlan {
    /// Plans a body of `mesh` (baked into world space, as for `insert`) with `config`;
    /// refuses what `insert` refuses.
    pub fn new(mesh: &Mesh, config: SoftBodyConfig) -> Result<Self, SoftBodyError> {
        config.validate()?;
        mesh.validate("<soft body mesh>")?;
        Ok(SoftBodyPlan(std::sync::Arc::new(BodyPlan::new(
            mesh, config,
        )?)))
    }

    /// Its number of particles.
    pub fn num_particles(&self) -> usize {
        self.0.map.len()
    }

    /// The configuration it was planned with.
    pub fn config(&self) -> &SoftBodyConfig {
        &self.0.config
    }
}

impl std::fmt::Debug for SoftBodyPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SoftBodyPlan")
            .field("particles", &self.0.map.len())
            .field("vertices", &self.0.rest_vertices.len())
            .finish()
    }
}

/// Where a new body's bodies go: the point `origin` of the mesh's (baked) frame goes to
/// `translation`, turned by `rotation`, and everything moves with the rigid velocity
/// `linvel + angvel × (x − translation)`. Particles may start displaced from their targets.
#[derive(Clone, Debug)]
pub(crate) struct Spawn {
    pub(crate) origin: Vec3,
    pub(crate) translation: Vec3,
    pub(crate) rotation: Quat,
    pub(crate) linvel: Vec3,
    pub(crate) angvel: Vec3,
    /// Per particle, world space; empty for none.
    pub(crate) displacement: Vec<Vec3>,
    /// A center body (and its collider) already in the world to keep, instead of a new one:
    /// a resolution change keeps its body's center, contacts and all.
    pub(crate) keep_center: Option<(RigidBodyHandle, Option<ColliderHandle>)>,
}

impl Spawn {
    /// The mesh's frame is the world, at rest.
    const AT_REST: Spawn = Spawn {
        origin: Vec3::ZERO,
        translation: Vec3::ZERO,
        rotation: Quat::IDENTITY,
        linvel: Vec3::ZERO,
        angvel: Vec3::ZERO,
        displacement: Vec::new(),
        keep_center: None,
    };

    fn place(&self, p: Vec3) -> Vec3 {
        self.translation + self.rotation * (p - self.origin)
    }

    fn velocity_at(&self, x: Vec3) -> Vec3 {
        self.linvel + self.angvel.cross(x - self.translation)
    }
}

/// Everything a body needs that can fail, computed before anything enters the world: a cut
/// plans all its pieces first, so a refused piece leaves the world untouched.
#[derive(Clone)]
pub(crate) struct BodyPlan {
    pub(crate) config: SoftBodyConfig,
    welded: WeldedMesh,
    render_triangles: Vec<[u32; 3]>,
    pub(crate) rest_mesh: Mesh,
    pub(crate) rest_center: Vec3,
    pub(crate) rest_vertices: Vec<Vec3>,
    pub(crate) map: ParticleMap,
    rest_offsets: Vec<Vec3>,
    neighbour_scale: Vec<f32>,
    center_shape: Option<ColliderBuilder>,
    rest_volume_m3: f32,
    size_m: f32,
    roll_radius_m: f32,
}

impl BodyPlan {
    /// Welds and clusters `mesh` (baked: the body's local frame is the world's at rest) and
    /// builds the center's collider shape.
    pub(crate) fn new(mesh: &Mesh, config: SoftBodyConfig) -> Result<Self, SoftBodyError> {
        Self::centred(mesh, config, None)
    }

    /// As [`new`](Self::new), with the rest center at `rest_center` instead of the particles'
    /// mean (a resolution change keeps its body's center, so the center does not move).
    pub(crate) fn centred(
        mesh: &Mesh,
        config: SoftBodyConfig,
        rest_center: Option<Vec3>,
    ) -> Result<Self, SoftBodyError> {
        let welded = mesh.weld(config.weld_epsilon_m);
        let soft: Vec<bool> = match &config.soft_region {
            Some(r) => welded.positions.iter().map(|p| r.contains(*p)).collect(),
            None => vec![true; welded.positions.len()],
        };
        let (lo, hi) = crate::mesh::bounds(&welded.positions);
        let size_m = (hi - lo).max_element().max(1e-6);
        let mut affect = config.affect_range_m;
        let map0 = build_particle_map(
            &welded.positions,
            &welded.triangles,
            &soft,
            config.cluster,
            0.0,
        )?;
        if affect == 0.0 {
            affect = 2.5 * mean_spacing(&map0.rest_particles);
        }
        let map = if affect > 0.0 {
            build_particle_map(
                &welded.positions,
                &welded.triangles,
                &soft,
                config.cluster,
                affect,
            )?
        } else {
            map0
        };
        // Thesis 3.2.1 / Figure 3.8: the center is the mean of the particles.
        let rest_center = rest_center
            .unwrap_or_else(|| map.rest_particles.iter().copied().sum::<Vec3>() / map.len() as f32);
        let rest_offsets: Vec<Vec3> = map
            .rest_particles
            .iter()
            .map(|p| *p - rest_center)
            .collect();
        let rest_vertices: Vec<Vec3> = welded.positions.iter().map(|p| *p - rest_center).collect();
        let neighbour_scale = neighbour_scale(&map, config.neighbour_share);
        let roll_radius_m = (rest_vertices.iter().map(|v| v.length()).sum::<f32>()
            / rest_vertices.len().max(1) as f32
            * config.center_scale)
            .max(1e-4);
        let center_shape = match config.space {
            SimulationSpace::Local => None,
            SimulationSpace::World => {
                let builder = match config.center_collider {
                    CenterCollider::Ball => Some(ColliderBuilder::ball(roll_radius_m)),
                    CenterCollider::ConvexHull => {
                        let pts: Vec<Vec3> = rest_vertices
                            .iter()
                            .map(|v| *v * config.center_scale)
                            .collect();
                        ColliderBuilder::convex_hull(&pts)
                    }
                };
                Some(builder.ok_or_else(|| {
                    SoftBodyError::Config("the mesh has no convex hull (flat or degenerate)".into())
                })?)
            }
        };
        // The rest mesh as the tear and the cut see it: render vertices at their welded rest
        // positions, in the rest frame.
        let rest_mesh = Mesh {
            positions: welded
                .render_to_welded
                .iter()
                .map(|&w| rest_vertices[w as usize])
                .collect(),
            normals: mesh.normals.clone(),
            triangles: mesh.triangles.clone(),
        };
        let rest_volume_m3 = enclosed_volume(&welded.positions, &welded.triangles);
        Ok(BodyPlan {
            render_triangles: mesh.triangles.clone(),
            welded,
            rest_mesh,
            rest_center,
            rest_vertices,
            map,
            rest_offsets,
            neighbour_scale,
            center_shape,
            rest_volume_m3,
            size_m,
            roll_radius_m,
            config,
        })
    }

    /// Inserts the body's rigid bodies and colliders into `world`, placed by `spawn`.
    pub(crate) fn instantiate(self, world: &mut PhysicsWorld, bit: u32, spawn: &Spawn) -> SoftBody {
        let BodyPlan {
            config,
            welded,
            render_triangles,
            rest_mesh,
            rest_center,
            rest_vertices,
            map,
            rest_offsets,
            neighbour_scale,
            center_shape,
            rest_volume_m3,
            size_m,
            roll_radius_m,
        } = self;
        let (pg, cg) = groups(bit, config.self_collisions);
        let center_at = spawn.place(rest_center);
        let center_builder = match config.space {
            SimulationSpace::Local => RigidBodyBuilder::fixed(),
            SimulationSpace::World => RigidBodyBuilder::dynamic()
                .can_sleep(true)
                .linvel(spawn.velocity_at(center_at))
                .angvel(spawn.angvel),
        }
        .pose(Pose::from_parts(center_at, spawn.rotation));
        let (center, center_collider) = match spawn.keep_center {
            Some(kept) => kept,
            None => {
                let center = world.insert_body(center_builder);
                let collider = center_shape.map(|builder| {
                    world.insert_collider(
                        builder
                            .mass(config.center_mass_kg)
                            .friction(config.friction)
                            .collision_groups(cg),
                        Some(center),
                    )
                });
                (center, collider)
            }
        };

        let mut particles = Vec::with_capacity(map.len());
        let mut particle_colliders = Vec::with_capacity(map.len());
        let mut particle_radius_m = Vec::with_capacity(map.len());
        for (i, p) in map.rest_particles.iter().enumerate() {
            let (soft_ccd, full_ccd) = match config.continuous_collision {
                ContinuousCollision::Off => (0.0, false),
                ContinuousCollision::Soft { prediction_m } => (prediction_m.max(0.0), false),
                ContinuousCollision::Full => (0.0, true),
            };
            let at = spawn.place(*p) + spawn.displacement.get(i).copied().unwrap_or(Vec3::ZERO);
            let h = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .soft_ccd_prediction(soft_ccd)
                    .ccd_enabled(full_ccd)
                    .translation(at)
                    .linvel(spawn.velocity_at(at))
                    .gravity_scale(0.0)
                    .can_sleep(config.particles_can_sleep)
                    .angular_damping(config.angular_damping)
                    .additional_mass(if config.collider == ParticleCollider::None {
                        config.particle_mass_kg
                    } else {
                        0.0
                    }),
            );
            let r = (map.particle_extent_m[i] * config.particle_scale).max(1e-4);
            let shape = match config.collider {
                ParticleCollider::Sphere => Some(ColliderBuilder::ball(r)),
                ParticleCollider::Box => Some(ColliderBuilder::cuboid(r, r, r)),
                ParticleCollider::None => None,
            };
            let ch = shape.map(|s| {
                world.insert_collider(
                    s.mass(config.particle_mass_kg)
                        .friction(config.friction)
                        .collision_groups(pg),
                    Some(h),
                )
            });
            particles.push(h);
            particle_colliders.push(ch);
            particle_radius_m.push(r);
        }
        let n = map.len();
        let mut body = SoftBody {
            render_triangles,
            vertices: welded.positions.clone(),
            render_positions: vec![Vec3::ZERO; welded.render_to_welded.len()],
            render_normals: vec![Vec3::ZERO; welded.render_to_welded.len()],
            slot_normals: vec![Vec3::ZERO; welded.normal_slots],
            welded,
            rest_vertices,
            rest_index: None,
            rest_center,
            rest_mesh,
            tear: None,
            tear_boxes: Vec::new(),
            last_particle_update: ParticleUpdateStats::default(),
            last_tear_timings: TearTimings::default(),
            map,
            rest_offsets,
            neighbour_scale,
            center,
            center_collider,
            particles,
            particle_colliders,
            particle_radius_m,
            drives: vec![None; n],
            held_rotation: None,
            anchor_shift: vec![Vec3::ZERO; n],
            displacement: vec![Vec3::ZERO; n],
            scratch: vec![Vec3::ZERO; n],
            planned_v: Vec::with_capacity(n),
            vertex_grad: Vec::new(),
            particle_grad: Vec::new(),
            sim_vertices: Vec::new(),
            rest_volume_m3,
            size_m,
            roll_radius_m,
            config,
            non_finite_recoveries: 0,
            blend: level::Blend::default(),
            dormant: false,
            replica: false,
            replica_mesh: (None, None),
            work: BodyWork::default(),
            still_s: 0.0,
        };
        body.deform(world);
        body
    }
}

/// Per particle: `neighbour_share / Σ w` over its neighbour weights (0 without neighbours).
pub(crate) fn neighbour_scale(map: &ParticleMap, share: f32) -> Vec<f32> {
    (0..map.len())
        .map(|i| {
            let (_, w) = map.neighbours.row(i);
            let s: f32 = w.iter().sum();
            if s > 0.0 {
                share / s
            } else {
                0.0
            }
        })
        .collect()
}

impl SoftBody {
    /// The restoring step of thesis 3.2.2 / Appendix A.6–A.7, made sound.
    ///
    /// Thesis: `v = MoveTowards(v, (dest − x − Σ w·(dest_j − x_j)) · k · dt/(1/90), 10)`. Its
    /// per-step displacement fraction is `α = k·dt²·90`: it grows with the step size and passes
    /// 1 (overshoot) at k·dt > 1/(90·dt), i.e. k > 90 at 90 Hz and k > 40 at 60 Hz, and diverges
    /// at twice that. Worse, its raw neighbour term amplifies a uniform displacement by
    /// `1 + α(Σw − 1)` per step: where the weights sum past 1 (the default range) it diverges at
    /// every k and dt. Here the fraction is `α = 1 − exp(−k·dt)`, which matches the thesis for small
    /// k·dt and never reaches 1. The neighbour term follows neighbours' displacement *relative*
    /// to the particle's own, with shares summing to `neighbour_share ≤ 0.5`; by Gershgorin the
    /// update `u ← u − α(I + L)u` then contracts for every α < 1 — no stiffness or step rate
    /// can destabilise it. A uniform displacement (the whole body lagging its center) decays at
    /// the full rate instead of being amplified as in the thesis's form.
    fn apply_restoring_velocities(&mut self, world: &mut PhysicsWorld, dt_s: f32) {
        if self.replica {
            return; // kinematic: its owner's state moves it
        }
        self.apply_rolling_resistance(world);
        self.turn_center_by_hands(world, dt_s);
        let Some(center) = world.bodies.get(self.center) else {
            return;
        };
        let c = center.translation();
        let r = *center.rotation();
        let vc = center.linvel();
        let wc = center.angvel();
        let dt = dt_s.max(1e-6);
        let alpha = 1.0 - (-self.config.stiffness * dt).exp();
        // u_i = x_i − dest_i (Appendix A.6: dest = center + rotation · rest offset).
        let mut sleeping = 0usize;
        let mut most_displaced = 0.0f32;
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for (i, &h) in self.particles.iter().enumerate() {
            let (x, asleep) = world
                .bodies
                .get(h)
                .map(|b| (b.translation(), b.is_sleeping()))
                .unwrap_or((Vec3::NAN, false));
            sleeping += asleep as usize;
            let dest = c + r * (self.rest_offsets[i] + self.anchor_shift[i]);
            let u = x - dest;
            self.scratch[i] = if u.is_finite() { u } else { Vec3::ZERO };
            most_displaced = most_displaced.max(self.scratch[i].length_squared());
            if x.is_finite() {
                lo = lo.min(x);
                hi = hi.max(x);
            }
        }
        let woke = sleeping > 0 && self.wake_if_approached(world, lo, hi);
        self.dormant = !woke
            && sleeping == self.particles.len()
            && self.drives.iter().all(Option::is_none)
            && world
                .bodies
                .get(self.center)
                .is_some_and(|b| b.is_sleeping());
        if self.dormant {
            return;
        }
        self.work.restorings += 1;
        let center_still = world
            .bodies
            .get(self.center)
            .is_some_and(|b| b.is_sleeping());
        let mut still = center_still;
        let max_dv = self.config.max_velocity_change_mps;
        let thesis = self.config.restoring == RestoringScheme::Thesis;
        // Thesis: expectedDelta = fixedDeltaTime / 0.0111112 (Appendix A.7).
        let thesis_gain = self.config.stiffness * dt / 0.011_111_2;
        self.planned_v.clear();
        self.planned_v.resize(self.particles.len(), None);
        for (j, &h) in self.particles.iter().enumerate() {
            let uj = self.scratch[j];
            let (ids, ws) = self.map.neighbours.row(j);
            let mut pull = Vec3::ZERO;
            for (&i, &w) in ids.iter().zip(ws) {
                pull += (self.scratch[i as usize] - uj) * w;
            }
            let correction = -uj + pull * self.neighbour_scale[j];
            let dest = c + r * (self.rest_offsets[j] + self.anchor_shift[j]);
            let Some(body) = world.bodies.get_mut(h) else {
                continue;
            };
            if !body.translation().is_finite() {
                // Never let a non-finite state live on: put the particle back at its target.
                body.set_translation(dest, true);
                body.set_linvel(vc, true);
                self.non_finite_recoveries += 1;
                continue;
            }
            let target = match self.drives[j] {
                Some(goal) => (goal - body.translation()) / dt,
                None if thesis => {
                    // dir_j − Σ_i w_ij · dir_i with dir = −u (Appendix A.6–A.7).
                    let mut from_others = Vec3::ZERO;
                    for (&i, &w) in ids.iter().zip(ws) {
                        from_others += -self.scratch[i as usize] * w;
                    }
                    (-uj - from_others) * thesis_gain
                }
                // Feed the center's rigid motion forward so a rigidly moving body has no lag.
                None => vc + wc.cross(dest - c) + correction * (alpha / dt),
            };
            let v = body.linvel();
            let dv = target - v;
            let len = dv.length();
            let new_v = if len > max_dv && self.drives[j].is_none() {
                v + dv * (max_dv / len)
            } else {
                target
            };
            if body.is_sleeping()
                && (new_v - v).length_squared() < 1e-10
                && uj.length_squared() < 1e-12
            {
                continue;
            }
            // still: it moved less than 1 mm/s through the last step, whatever the restoring
            // asks of it (a particle it presses into what carries the body never gets there)
            still &= self.drives[j].is_none() && v.length_squared() < STILL_MPS * STILL_MPS;
            self.planned_v[j] = Some(new_v);
        }
        // Every particle within 0.1 % of the body's size of its place: its shape, and so its
        // volume, is its own (a flight, a rest) — not even the volume pass.
        if most_displaced.sqrt() > 1e-3 * self.size_m {
            self.keep_volume(dt, r, vc, wc);
        }
        // Center asleep, every particle asleep or still for 0.5 s: the whole body sleeps (the
        // solver moves particles pressed into a table by µm a step, which rapier counts as motion).
        self.still_s = if still { self.still_s + dt } else { 0.0 };
        if self.still_s >= STILL_BEFORE_SLEEP_S {
            self.still_s = 0.0;
            self.sleep(world);
            return;
        }
        let held = self.drives.iter().any(Option::is_some);
        for (j, &h) in self.particles.iter().enumerate() {
            if let (Some(v), Some(body)) = (self.planned_v[j], world.bodies.get_mut(h)) {
                // An awake particle of a body nobody holds is not woken again: rapier's wake-up
                // restarts the countdown to sleep, and resting bodies never slept.
                let wake = held || body.is_sleeping();
                body.set_linvel(v, wake);
            }
        }
    }

    /// Rapier does not wake a sleeping particle when a kinematic body (a plate, a hand) moves
    /// into it, and a particle that sleeps through the contact ends up on the wrong side. So a
    /// body with sleeping particles checks each step for a moving collider, not its own, in
    /// its bounds (expanded by the largest particle radius plus 1 cm) and wakes all its
    /// particles if there is one. Soft CCD on the particles covers faster approaches.
    fn wake_if_approached(&mut self, world: &mut PhysicsWorld, lo: Vec3, hi: Vec3) -> bool {
        let margin = self
            .particle_radius_m
            .iter()
            .copied()
            .fold(0.0f32, f32::max)
            + 0.01;
        let own = self
            .particle_colliders
            .first()
            .copied()
            .flatten()
            .and_then(|h| world.colliders.get(h))
            .map(|c| c.collision_groups().memberships);
        let aabb = Aabb::new(lo - Vec3::splat(margin), hi + Vec3::splat(margin));
        let mut intruder = false;
        for (_, co) in world.intersect_aabb_conservative(aabb, QueryFilter::default()) {
            if Some(co.collision_groups().memberships) == own
                || Some(co.parent()) == Some(Some(self.center))
            {
                continue;
            }
            let Some(parent) = co.parent().and_then(|p| world.bodies.get(p)) else {
                continue;
            };
            let moving = is_moving(parent);
            if moving {
                intruder = true;
                break;
            }
        }
        if intruder {
            for &h in &self.particles {
                if let Some(b) = world.bodies.get_mut(h) {
                    b.wake_up(true);
                }
            }
        }
        intruder
    }

    /// Thesis 3.3 and Appendix A.11–A.12 in closed form: each vertex is its rest position moved
    /// rigidly with the center, plus the weighted displacement of its particles. This equals
    /// "translate by the particles' movement, then rotate about the weighted particle pivot"
    /// applied incrementally, without the accumulation drift of the incremental form.
    fn deform(&mut self, world: &PhysicsWorld) {
        self.work.deformations += 1;
        self.replica_mesh.1 = None;
        let Some(center) = world.bodies.get(self.center) else {
            return;
        };
        let c = center.translation();
        let r = *center.rotation();
        for (i, &h) in self.particles.iter().enumerate() {
            let x = world
                .bodies
                .get(h)
                .map(|b| b.translation())
                .unwrap_or(Vec3::NAN);
            let u = x - (c + r * self.rest_offsets[i]);
            self.displacement[i] = if u.is_finite() { u } else { Vec3::ZERO };
        }
        let blending = self.blend.active();
        let r_inv = r.inverse();
        let mut converged = true;
        for (v, out) in self.vertices.iter_mut().enumerate() {
            let mut p = c + r * self.rest_vertices[v];
            if self.map.soft_vertex[v] {
                let (ids, ws) = self.map.vertex_particles.row(v);
                for (&pi, &w) in ids.iter().zip(ws) {
                    p += self.displacement[pi as usize] * w;
                }
            }
            if blending {
                let sim = r_inv * (p - c);
                let shown = self.blend.follow(v, sim);
                converged &= shown.distance_squared(sim) < 2.5e-9;
                p = c + r * shown;
            }
            *out = p;
        }
        if blending {
            self.blend.finish_step(converged);
        }
        // Normals: area-weighted face normals accumulated into normal slots.
        self.slot_normals.iter_mut().for_each(|n| *n = Vec3::ZERO);
        for t in &self.render_triangles {
            let w = [
                self.welded.render_to_welded[t[0] as usize],
                self.welded.render_to_welded[t[1] as usize],
                self.welded.render_to_welded[t[2] as usize],
            ];
            let (a, b, cc) = (
                self.vertices[w[0] as usize],
                self.vertices[w[1] as usize],
                self.vertices[w[2] as usize],
            );
            let n = (b - a).cross(cc - a);
            for &k in t {
                self.slot_normals[self.welded.render_to_normal_slot[k as usize] as usize] += n;
            }
        }
        for (k, (pos, nrm)) in self
            .render_positions
            .iter_mut()
            .zip(self.render_normals.iter_mut())
            .enumerate()
        {
            *pos = self.vertices[self.welded.render_to_welded[k] as usize];
            *nrm = self.slot_normals[self.welded.render_to_normal_slot[k] as usize]
                .normalize_or_zero();
        }
    }
}

/// True for a kinematic body that moves this step or a dynamic body that is awake: what can
/// push into a sleeping soft body.
pub(crate) fn is_moving(body: &rapier3d::prelude::RigidBody) -> bool {
    if body.is_kinematic() {
        let next = body.next_position();
        next.translation != body.translation()
            || next.rotation != *body.rotation()
            || body.linvel() != Vec3::ZERO
            || body.angvel() != Vec3::ZERO
    } else {
        body.is_dynamic() && !body.is_sleeping()
    }
}

fn mean_spacing(points: &[Vec3]) -> f32 {
    // Mean nearest-neighbour distance, by brute force on a sample of at most 256 points.
    if points.len() < 2 {
        return 0.0;
    }
    let step = (points.len() / 256).max(1);
    let mut sum = 0.0;
    let mut n = 0;
    for i in (0..points.len()).step_by(step) {
        let mut best = f32::MAX;
        for (j, q) in points.iter().enumerate() {
            if j != i {
                best = best.min(points[i].distance(*q));
            }
        }
        sum += best;
        n += 1;
    }
    sum / n as f32
}
