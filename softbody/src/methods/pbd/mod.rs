//! The position-based solver shared by the surface, ISPC, tetrahedral and shape-matching
//! models (ISPC paper Algorithm 1; Müller et al. 2007; XPBD, Macklin et al. 2016).
//!
//! Per step: gather the rapier colliders near the body once, then per substep: predict
//! (gravity, damping), project the constraints Gauss–Seidel, match shapes, resolve contacts
//! (with a swept ray so a thin wall is never crossed), and derive velocities from positions.
//! With [`SolverKind::Xpbd`] every constraint has a compliance and a multiplier reset per
//! substep, so the stiffness does not depend on the iteration count or the substep size; with
//! [`SolverKind::Pbd`] each projection is scaled by a per-iteration stiffness in (0, 1], the
//! original (iteration-dependent) form, kept to show the difference.
//!
//! The constraint groups (`constraints`), the surface map (`surface`) and the contacts with
//! the world (`contacts`) are children that know nothing of the body: [`PbdBody`] owns them
//! and orders the work.

mod constraints;
mod contacts;
mod neohookean;
mod strain;
mod surface;

use glam::{Quat, Vec3};
use rapier3d::prelude::{Aabb, ColliderHandle, PhysicsWorld, QueryFilter, RigidBodyHandle};

use crate::methods::model::DeformableModel;
use constraints::{inverse_or_zero, Sweep};
pub use constraints::{tet_volume, BendingGroup, DistanceGroup, ShapeClusters, VolumeGroup};
use contacts::ColliderInertia;
pub use contacts::Reaction;
use contacts::{near_colliders, Contact, ContactPoints};
pub use neohookean::NeoHookeanGroup;
pub use strain::StrainGroup;
pub use surface::{Embedding, SurfaceMap};

/// Which projection the solver uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverKind {
    /// Extended PBD: compliance per constraint, stiffness independent of iterations and substeps.
    Xpbd,
    /// Plain PBD: every correction scaled by a per-iteration stiffness; the effective stiffness
    /// grows with the iteration count and the step rate.
    Pbd,
}

/// Solver settings shared by every constraint group of a body.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PbdParams {
    /// XPBD or plain PBD.
    pub solver: SolverKind,
    /// Substeps per step (≥ 1).
    pub substeps: u32,
    /// Gauss–Seidel iterations per substep (≥ 1).
    pub iterations: u32,
    /// Velocity damping rate, 1/s (ISPC paper Algorithm 1 line 9): `v *= exp(−d·h)`.
    pub damping_per_s: f32,
    /// Contact thickness of each surface point, metres.
    pub contact_radius_m: f32,
    /// Coulomb friction against colliders.
    pub friction: f32,
    /// Below this RMS particle speed for [`Self::sleep_after_s`] (and with nothing moving near)
    /// the body sleeps.
    pub sleep_speed_mps: f32,
    /// Seconds of stillness before sleeping; 0 disables sleeping.
    pub sleep_after_s: f32,
    /// Two-way coupling: the momentum the body's contacts take from a dynamic rapier body's
    /// collider is given back to that body after the step (a box dropped on the body rests on
    /// it, a lever it falls on turns; its momentum and angular momentum, see
    /// [`PbdBody::push_back`]). Fixed and kinematic colliders are not moved either way. Default on; the
    /// scenarios' props are all fixed or kinematic, so no figure changes with it.
    #[serde(default = "two_way_default")]
    pub two_way: bool,
    /// The Neo-Hookean tets' hard volume floor: no tet is squeezed below this fraction of its
    /// rest volume (`det F ≥ volume_floor`, `MIN_VOLUME_RATIO`, 0.2, by default; 0
    /// turns it off, to measure what the floor holds up). The other methods ignore it.
    #[serde(default = "volume_floor_default")]
    pub volume_floor: f32,
}

fn two_way_default() -> bool {
    true
}

fn volume_floor_default() -> f32 {
    neohookean::MIN_VOLUME_RATIO
}

impl Default for PbdParams {
    fn default() -> Self {
        Self {
            solver: SolverKind::Xpbd,
            substeps: 4,
            iterations: 4,
            damping_per_s: 1.0,
            contact_radius_m: 0.002,
            friction: 0.5,
            sleep_speed_mps: 0.02,
            sleep_after_s: 0.5,
            two_way: true,
            volume_floor: volume_floor_default(),
        }
    }
}

/// A body's energy split by kind, J.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Energy {
    /// ½ m v² over the free particles.
    pub kinetic_j: f32,
    /// −m g·x over the free particles (zero at the origin's height).
    pub potential_j: f32,
    /// Stored elastic energy.
    pub elastic_j: f32,
}

impl Energy {
    /// The sum.
    pub fn total_j(&self) -> f32 {
        self.kinetic_j + self.potential_j + self.elastic_j
    }
}

/// A particle held on a frictionless plane normal to a coordinate axis: its coordinate `axis`
/// (0 = x, 1 = y, 2 = z) is `at_m`, the other two are free. A plate it slides on, or a
/// symmetry plane; move `at_m` to move the plate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slide {
    /// The particle.
    pub node: u32,
    /// The axis the plane is normal to: 0, 1 or 2.
    pub axis: u8,
    /// Where the plane is along that axis, metres.
    pub at_m: f32,
}

/// A rigid frictionless sphere no particle may enter: each one inside is moved out along the
/// radius, projected with the other constraints at every iteration. An indenter; move
/// `center_m` to move it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereObstacle {
    /// Its centre, metres.
    pub center_m: Vec3,
    /// Its radius, metres.
    pub radius_m: f32,
}

/// A position-based body: particles, constraint groups, a surface, contacts with the world.
#[derive(Clone, Debug)]
pub struct PbdBody {
    name: String,
    /// Solver settings.
    pub params: PbdParams,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    prev: Vec<Vec3>,
    /// What the f32 positions lost when the prediction moved them (the true position is
    /// `x + carry`): compensated (Kahan–Babuška) integration. A substep's move `v·h` is
    /// hundreds of times smaller than a coordinate, so without it the velocity read back from
    /// the positions is quantised to `ulp(x) / h`: at 160 substeps a body at 0.6 m height
    /// falls at a wrong rate, at 320 it cannot start falling at all.
    carry: Vec<Vec3>,
    /// `carry` at the start of the substep.
    carry0: Vec<Vec3>,
    inv_mass: Vec<f32>,
    /// Distance constraint groups (edges, links, tet edges).
    pub distance: Vec<DistanceGroup>,
    /// Bending constraints, if any.
    pub bending: Option<BendingGroup>,
    /// Tet volume constraints, if any.
    pub volume: Option<VolumeGroup>,
    /// Shape-matching clusters, if any.
    pub clusters: Option<ShapeClusters>,
    /// Stable Neo-Hookean tets, if any (the accuracy reference).
    pub neo_hookean: Option<NeoHookeanGroup>,
    /// Strain constraints on tets, if any (the ISPC paper's tetrahedral baseline).
    pub strain: Option<StrainGroup>,
    /// Which tet nodes of an embedded surface collide besides the surface (`None`, the
    /// default: all). A cover's nodes outside the surface would otherwise pass into a wall the
    /// surface stopped at and crush their tets. A lattice weighted by inside fraction leaves
    /// the fringe fictitious material: only its surface and the nodes deep in the material
    /// collide, so its contact envelope is the surface at every resolution and a small prop
    /// that slips between surface points is still stopped inside.
    pub colliding_nodes: Option<Vec<u32>>,
    /// [`Self::pin_box`] holds the surface vertices in the box (the same material at every
    /// resolution of an embedding) instead of pinning the particles in it (default false).
    pub pin_surface: bool,
    /// Surface vertices held at a position: (vertex, position).
    held: Vec<(u32, Vec3)>,
    /// Particles held on frictionless planes (a plate, a symmetry plane), projected with the
    /// other constraints at every iteration.
    pub slides: Vec<Slide>,
    /// Rigid frictionless spheres the particles stay out of, projected with the other
    /// constraints at every iteration (an indenter).
    pub spheres: Vec<SphereObstacle>,
    /// What the last step's contacts did to each near collider, and which they were.
    reactions: Vec<Reaction>,
    reaction_targets: Vec<(ColliderHandle, Option<RigidBodyHandle>)>,
    collider_inertia: Vec<ColliderInertia>,
    last_dt_s: f32,
    surface_map: SurfaceMap,
    surface: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    sleeping: bool,
    still_s: f32,
    max_speed: f32,
    /// Contact half-spaces of this substep.
    contacts: Vec<Contact>,
    non_finite_resets: u64,
    constraint_solves: u64,
}

impl PbdBody {
    /// A body of particles `x` (masses `mass_kg`, 0 = pinned) whose surface is `surface_map`
    /// over them with `triangles`.
    pub fn new(
        name: impl Into<String>,
        params: PbdParams,
        x: Vec<Vec3>,
        mass_kg: &[f32],
        surface_map: SurfaceMap,
        triangles: Vec<[u32; 3]>,
    ) -> Self {
        let n = x.len();
        let inv_mass = (0..n)
            .map(|i| inverse_or_zero(mass_kg.get(i).copied().unwrap_or(0.0)))
            .collect();
        let mut b = PbdBody {
            name: name.into(),
            params,
            v: vec![Vec3::ZERO; n],
            prev: x.clone(),
            carry: vec![Vec3::ZERO; n],
            carry0: vec![Vec3::ZERO; n],
            x,
            inv_mass,
            distance: Vec::new(),
            bending: None,
            volume: None,
            clusters: None,
            neo_hookean: None,
            strain: None,
            colliding_nodes: None,
            pin_surface: false,
            held: Vec::new(),
            slides: Vec::new(),
            spheres: Vec::new(),
            reactions: Vec::new(),
            reaction_targets: Vec::new(),
            collider_inertia: Vec::new(),
            last_dt_s: 0.0,
            surface_map,
            surface: Vec::new(),
            triangles,
            sleeping: false,
            still_s: 0.0,
            max_speed: 0.0,
            contacts: Vec::new(),
            non_finite_resets: 0,
            constraint_solves: 0,
        };
        b.update_surface();
        b
    }

    /// Particle positions, world space.
    pub fn positions(&self) -> &[Vec3] {
        &self.x
    }

    /// Inverse masses (0 = pinned).
    pub fn inverse_masses(&self) -> &[f32] {
        &self.inv_mass
    }

    /// Renames the body (for tables).
    pub fn set_name(&mut self, name: impl Into<String>) {
        self.name = name.into();
    }

    /// Constraint projections done so far (a machine-independent cost measure).
    pub fn constraint_solves(&self) -> u64 {
        self.constraint_solves
    }

    /// Constraint projections per step at the current settings.
    pub fn solves_per_step(&self) -> u64 {
        let per_iter = self.distance.iter().map(|g| g.len()).sum::<usize>()
            + self.bending.as_ref().map_or(0, |b| b.quads.len())
            + self.volume.as_ref().map_or(0, |v| v.tets.len())
            + 2 * self.neo_hookean.as_ref().map_or(0, |g| g.len())
            + 6 * self.strain.as_ref().map_or(0, |g| g.len());
        let sm = self.clusters.as_ref().map_or(0, |c| c.members.len());
        let contacts = self.surface.len();
        (self.params.substeps as u64)
            * (self.params.iterations as u64 * per_iter as u64 + sm as u64 + contacts as u64)
    }

    /// How often a non-finite particle was reset (should stay 0).
    pub fn non_finite_resets(&self) -> u64 {
        self.non_finite_resets
    }

    fn update_surface(&mut self) {
        self.surface_map.update(&self.x, &mut self.surface);
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        crate::mesh::bounds(&self.x)
    }

    /// True if a collider of a moving (or awake dynamic) body is within the body's bounds.
    fn intruder(&self, world: &PhysicsWorld) -> bool {
        let (lo, hi) = self.bounds();
        let m = Vec3::splat(self.params.contact_radius_m + 0.01);
        let aabb = Aabb::new(lo - m, hi + m);
        world
            .intersect_aabb_conservative(aabb, QueryFilter::default())
            .any(|(_, co)| {
                let Some(parent) = co.parent().and_then(|p| world.bodies.get(p)) else {
                    return false;
                };
                crate::body::is_moving(parent)
            })
    }

    /// One step of Algorithm 1 (ISPC paper), `params.substeps` substeps, against `world`'s
    /// colliders at their current poses.
    pub fn step(&mut self, world: &PhysicsWorld, dt_s: f32) {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            return;
        };
        self.reactions.clear();
        self.reaction_targets.clear();
        self.collider_inertia.clear();
        self.last_dt_s = dt;
        if self.sleeping {
            if self.intruder(world) {
                self.sleeping = false;
                self.still_s = 0.0;
            } else {
                return;
            }
        }
        let substeps = self.params.substeps.max(1);
        let h = dt / substeps as f32;
        let gravity = world.gravity;
        // Colliders near the body for the whole step: its bounds grown by its travel.
        let (lo, hi) = self.bounds();
        let travel = (self.max_speed + gravity.length() * dt) * dt;
        let grow = Vec3::splat(travel + self.params.contact_radius_m + 0.02);
        let near = near_colliders(world, lo - grow, hi + grow, self.params.two_way, dt);
        self.reactions.resize(near.len(), Reaction::default());
        self.reaction_targets
            .extend(near.iter().map(|c| (c.handle, c.dynamic_body)));
        self.collider_inertia
            .extend(near.iter().map(ColliderInertia::of));
        let damp = (-self.params.damping_per_s.max(0.0) * h).exp();
        for sub in 0..substeps {
            let at = (sub + 1) as f32 / substeps as f32;
            // A coupled body keeps moving at the velocity the earlier substeps' pushes gave it.
            for r in &mut self.reactions {
                r.advance(h);
            }
            // Algorithm 1 lines 8–10: external forces, damping, prediction.
            for i in 0..self.x.len() {
                self.prev[i] = self.x[i];
                self.carry0[i] = self.carry[i];
                if self.inv_mass[i] == 0.0 {
                    self.v[i] = Vec3::ZERO;
                    self.carry[i] = Vec3::ZERO;
                    self.carry0[i] = Vec3::ZERO;
                    continue;
                }
                self.v[i] = (self.v[i] + gravity * h) * damp;
                // Fast2Sum: `x` is far larger than the move, so `(moved − x)` is exact and
                // `y − (moved − x)` is exactly what rounding dropped.
                let y = self.carry[i] + self.v[i] * h;
                let moved = self.x[i] + y;
                self.carry[i] = y - (moved - self.x[i]);
                self.x[i] = moved;
            }
            // Line 11: contact constraints (half-spaces) for this substep.
            let (points, contacts) = self.contact_points();
            points.generate(&near, h, at, contacts);
            // Lines 12–14: Gauss–Seidel projection, contacts with the other constraints.
            self.reset_multipliers();
            // Symmetric Gauss–Seidel: odd iterations sweep backwards, so a load travels the
            // whole body both ways within one substep instead of one element per iteration.
            for it in 0..self.params.iterations.max(1) {
                self.project_constraints(h, it % 2 == 1);
                let (mut points, contacts) = self.contact_points();
                points.project(contacts, h);
            }
            if let Some(clusters) = &mut self.clusters {
                clusters.match_shapes(&mut self.x, &self.inv_mass, h);
            }
            // Contacts once more, last, so the final positions are collision-free.
            self.contact_points().0.collide(&near, h, at);
            // A contact may have crushed a tet of the reference: its floor has the last word.
            if let Some(g) = &mut self.neo_hookean {
                g.enforce_floor(&mut self.x, &self.inv_mass);
            }
            for r in &mut self.reactions {
                r.close_substep(h);
            }
            // Lines 16–17: velocities from positions.
            for i in 0..self.x.len() {
                if !(self.x[i].is_finite() && self.carry[i].is_finite()) {
                    self.x[i] = self.prev[i];
                    self.v[i] = Vec3::ZERO;
                    self.carry[i] = Vec3::ZERO;
                    self.non_finite_resets += 1;
                    continue;
                }
                self.v[i] = ((self.x[i] - self.prev[i]) + (self.carry[i] - self.carry0[i])) / h;
            }
        }
        self.constraint_solves += self.solves_per_step();
        self.update_surface();
        self.max_speed = self.v.iter().map(|v| v.length()).fold(0.0, f32::max);
        // Sleep on the RMS speed: a resting body's contact jitter moves a few particles a little
        // every substep, which a maximum would never forgive.
        let rms_speed = (self.v.iter().map(|v| v.length_squared()).sum::<f32>()
            / self.v.len().max(1) as f32)
            .sqrt();
        // A resting body under gravity is re-accelerated by g·dt every step and stopped again
        // by its contacts: that much residual speed is rest, not motion.
        let threshold = self.params.sleep_speed_mps + gravity.length() * dt;
        if self.params.sleep_after_s > 0.0 && rms_speed < threshold {
            self.still_s += dt;
            if self.still_s >= self.params.sleep_after_s && !self.intruder(world) {
                self.sleeping = true;
                self.v.iter_mut().for_each(|v| *v = Vec3::ZERO);
                self.max_speed = 0.0;
            }
        } else {
            self.still_s = 0.0;
        }
    }

    fn reset_multipliers(&mut self) {
        for g in &mut self.distance {
            g.reset();
        }
        if let Some(b) = &mut self.bending {
            b.reset();
        }
        if let Some(v) = &mut self.volume {
            v.reset();
        }
        if let Some(g) = &mut self.neo_hookean {
            g.reset();
        }
        if let Some(g) = &mut self.strain {
            g.reset();
        }
    }

    /// One Gauss–Seidel sweep over the distance, bending and volume constraints, in that
    /// order (`reverse`: each group backwards).
    fn project_constraints(&mut self, h: f32, reverse: bool) {
        let sweep = Sweep::new(self.params.solver == SolverKind::Xpbd, h, reverse);
        for g in &mut self.distance {
            g.project(&mut self.x, &self.inv_mass, sweep);
        }
        if let Some(g) = &mut self.bending {
            g.project(&mut self.x, &self.inv_mass, sweep);
        }
        if let Some(g) = &mut self.volume {
            g.project(&mut self.x, &self.inv_mass, sweep);
        }
        if let Some(g) = &mut self.neo_hookean {
            g.project(&mut self.x, &self.inv_mass, sweep);
        }
        if let Some(g) = &mut self.strain {
            g.project(&mut self.x, &self.inv_mass, sweep);
        }
        for &(s, at) in &self.held {
            let (p, _) = self.surface_map.point(&self.x, &self.prev, s as usize);
            self.surface_map
                .move_point(&mut self.x, &self.inv_mass, s as usize, at - p);
        }
        for s in &self.slides {
            let i = s.node as usize;
            if self.inv_mass.get(i).is_some_and(|w| *w > 0.0) && s.at_m.is_finite() {
                self.x[i][usize::from(s.axis.min(2))] = s.at_m;
            }
        }
        for o in &self.spheres {
            if !(o.center_m.is_finite() && o.radius_m.is_finite() && o.radius_m > 0.0) {
                continue;
            }
            for (x, w) in self.x.iter_mut().zip(&self.inv_mass) {
                let d = *x - o.center_m;
                let len = d.length();
                if *w > 0.0 && len < o.radius_m && len > 0.0 {
                    *x = o.center_m + d * (o.radius_m / len);
                }
            }
        }
    }

    /// The points that collide, over the particles as they are, and this substep's contacts.
    fn contact_points(&mut self) -> (ContactPoints<'_>, &mut Vec<Contact>) {
        (
            ContactPoints {
                map: &self.surface_map,
                x: &mut self.x,
                prev: &self.prev,
                inv_mass: &self.inv_mass,
                radius_m: self.params.contact_radius_m,
                nodes: self.colliding_nodes.as_deref(),
                reactions: &mut self.reactions,
                collider_inertia: &self.collider_inertia,
            },
            &mut self.contacts,
        )
    }

    /// The force each collider the body touched took from its contacts over the last step
    /// (impulse / dt), N: what a hand holding or lifting the body feels.
    pub fn contact_forces(&self) -> impl Iterator<Item = (ColliderHandle, Vec3)> + '_ {
        let dt = self.last_dt_s.max(1e-9);
        self.reaction_targets
            .iter()
            .zip(&self.reactions)
            .filter(|(_, r)| r.impulse != Vec3::ZERO)
            .map(move |((h, _), r)| (*h, r.impulse / dt))
    }

    /// Gives the last step's contact momentum back to the dynamic bodies it came from (the
    /// other half of two-way coupling; see [`PbdParams::two_way`]): its impulse and the
    /// impulse's moment about the body's centre of mass, and the motion and turn the contacts
    /// gave it within the step, so it ends the step where they left it. The turn is followed
    /// within the step as the motion is (each push moves and turns the collider by its
    /// inverse mass and inertia at the contact point): given back only after the step, it
    /// gained energy with every substep and threw a resting box off (measured, before).
    pub fn push_back(&self, world: &mut PhysicsWorld) {
        if !self.params.two_way {
            return;
        }
        for ((_, body), r) in self.reaction_targets.iter().zip(&self.reactions) {
            let Some(b) = body.and_then(|h| world.bodies.get_mut(h)) else {
                continue;
            };
            if r.impulse == Vec3::ZERO || !r.impulse.is_finite() || !r.moment.is_finite() {
                continue;
            }
            let com = b.center_of_mass();
            b.apply_impulse(r.impulse, true);
            let torque = r.moment - com.cross(r.impulse);
            if torque.is_finite() && !b.is_rotation_locked().iter().any(|l| *l) {
                b.apply_torque_impulse(torque, true);
            }
            // Its share of the pushes and the motion they gave it within the step, so it ends
            // the step where the contacts left it: moved, and turned about its centre of mass.
            let moved = r.shift + r.drift;
            let turn = r.rotation();
            if moved.is_finite()
                && turn.is_finite()
                && (moved != Vec3::ZERO || turn != Quat::IDENTITY)
            {
                let mut pose = *b.position();
                let c = com + moved;
                pose.translation = c + turn * (pose.translation + moved - c);
                pose.rotation = (turn * pose.rotation).normalize();
                b.set_position(pose, true);
            }
        }
    }

    /// Number of tets with non-positive volume.
    pub fn count_inverted(&self) -> usize {
        self.volume
            .as_ref()
            .map_or(0, |g| g.count_inverted(&self.x))
            + self
                .neo_hookean
                .as_ref()
                .map_or(0, |g| g.count_inverted(&self.x))
            + self
                .strain
                .as_ref()
                .map_or(0, |g| g.count_inverted(&self.x))
    }

    /// Pins the particles `nodes` where they are (inverse mass 0, at rest); unknown indices
    /// are ignored.
    pub fn pin_nodes(&mut self, nodes: &[u32]) {
        for &i in nodes {
            if let Some(w) = self.inv_mass.get_mut(i as usize) {
                *w = 0.0;
                self.v[i as usize] = Vec3::ZERO;
            }
        }
    }

    /// Kinetic, gravitational (height above y = 0 under `gravity`) and elastic energy of
    /// the body now, J. The elastic part is the stable Neo-Hookean energy (0 for bodies
    /// without those tets: their constraints are not an energy of a material).
    pub fn energy_j(&self, gravity: Vec3) -> Energy {
        let mut e = Energy::default();
        for ((x, v), w) in self.x.iter().zip(&self.v).zip(&self.inv_mass) {
            if *w > 0.0 {
                let m = 1.0 / w;
                e.kinetic_j += 0.5 * m * v.length_squared();
                e.potential_j -= m * gravity.dot(*x);
            }
        }
        e.elastic_j = self
            .neo_hookean
            .as_ref()
            .map_or(0.0, |g| g.energy_j(&self.x));
        e
    }
    /// Pins particles inside a box; returns the count.
    pub fn pin_box(&mut self, lo: Vec3, hi: Vec3) -> usize {
        if self.pin_surface {
            let before = self.held.len();
            for (i, p) in self.surface.iter().enumerate() {
                if p.cmpge(lo).all() && p.cmple(hi).all() {
                    self.held.push((i as u32, *p));
                }
            }
            return self.held.len() - before;
        }
        let mut n = 0;
        for (i, p) in self.x.iter().enumerate() {
            if p.cmpge(lo).all() && p.cmple(hi).all() {
                self.inv_mass[i] = 0.0;
                self.v[i] = Vec3::ZERO;
                n += 1;
            }
        }
        n
    }

    /// Sets every free particle's velocity.
    pub fn set_all_velocities(&mut self, v: Vec3) {
        for (vi, w) in self.v.iter_mut().zip(&self.inv_mass) {
            if *w > 0.0 {
                *vi = v;
            }
        }
        self.max_speed = v.length();
        self.sleeping = false;
        self.still_s = 0.0;
    }
}

impl DeformableModel for PbdBody {
    fn name(&self) -> &str {
        &self.name
    }

    fn post_physics(&mut self, world: &mut PhysicsWorld, dt_s: f32) {
        self.step(world, dt_s);
        self.push_back(world);
    }

    fn surface(&self) -> &[Vec3] {
        &self.surface
    }

    fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    fn is_sleeping(&self) -> bool {
        self.sleeping
    }

    fn num_particles(&self) -> usize {
        self.x.len()
    }

    fn inverted_elements(&self) -> usize {
        self.count_inverted()
    }

    fn max_speed_mps(&self) -> f32 {
        self.max_speed
    }

    fn contact_thickness_m(&self) -> f32 {
        self.params.contact_radius_m
    }

    fn pin_region(&mut self, _world: &mut PhysicsWorld, min_m: Vec3, max_m: Vec3) -> usize {
        self.pin_box(min_m, max_m)
    }

    fn set_velocity(&mut self, _world: &mut PhysicsWorld, v_mps: Vec3) {
        self.set_all_velocities(v_mps);
    }

    fn energy(&self, gravity: Vec3) -> Option<Energy> {
        Some(self.energy_j(gravity))
    }

    fn volume_floor_hits(&self) -> (u64, u64) {
        self.neo_hookean.as_ref().map_or((0, 0), |g| g.floor_hits())
    }
}
