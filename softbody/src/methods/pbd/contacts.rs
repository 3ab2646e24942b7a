//! Contacts with the rapier world: the colliders near a body for one step, the points that
//! collide (surface points, and an embedded surface's tet nodes), and pushing them out of the
//! colliders with a swept ray (no wall is crossed within a substep) and Coulomb friction.

use glam::{Mat3, Quat, Vec3};
use parry3d::math::Pose;
use parry3d::query::Ray;
use parry3d::shape::Shape;
use rapier3d::prelude::{Aabb, ColliderHandle, PhysicsWorld, QueryFilter, RigidBodyHandle};

use super::surface::SurfaceMap;

/// A collider near the body for this step.
pub(super) struct NearCollider<'a> {
    /// The collider.
    pub(super) handle: ColliderHandle,
    /// Its rigid body if that is dynamic: the contacts push it back (two-way coupling).
    pub(super) dynamic_body: Option<RigidBodyHandle>,
    /// Its inverse mass in the contacts (0: immovable).
    pub(super) inv_mass: f32,
    /// Its world inverse inertia in the contacts (zero: it does not turn).
    pub(super) inv_inertia: Mat3,
    /// Its centre of mass now, world.
    pub(super) com: Vec3,
    pose: Pose,
    /// How far a moving (dynamic or kinematic) body's collider moved in the rapier step just taken: the substeps
    /// see it move there gradually (at the start of the step it was `lag` behind), so a body
    /// it runs into is pushed at its speed, not at its travel over one substep.
    lag: Vec3,
    shape: &'a dyn Shape,
    aabb_lo: Vec3,
    aabb_hi: Vec3,
    friction: f32,
    velocity: Vec3,
}

/// The colliders (sensors aside) whose bounds meet the box `[lo, hi]`, as they are now; with
/// `sweep_dynamic`, dynamic bodies' colliders are swept over the step of `dt_s` just taken.
pub(super) fn near_colliders(
    world: &PhysicsWorld,
    lo: Vec3,
    hi: Vec3,
    sweep_dynamic: bool,
    dt_s: f32,
) -> Vec<NearCollider<'_>> {
    world
        .intersect_aabb_conservative(Aabb::new(lo, hi), QueryFilter::default())
        .filter(|(_, co)| !co.is_sensor())
        .map(|(handle, co)| {
            let aabb = co.compute_aabb();
            let parent = co
                .parent()
                .and_then(|p| world.bodies.get(p).map(|b| (p, b)));
            let velocity = parent.map_or(Vec3::ZERO, |(_, b)| b.linvel());
            let dynamic = parent.filter(|(_, b)| b.is_dynamic());
            let dynamic_body = dynamic.map(|(h, _)| h);
            let inv_mass = match dynamic {
                Some((_, b)) if sweep_dynamic && b.mass() > 0.0 => 1.0 / b.mass(),
                _ => 0.0,
            };
            // A coupled body turns under the contacts as it moves under them: its world
            // inverse inertia (zero for a body that may not rotate, or is not coupled).
            let inv_inertia = match dynamic {
                Some((_, b)) if inv_mass > 0.0 && !b.is_rotation_locked().iter().any(|l| *l) => {
                    let mp = &b.mass_properties().local_mprops;
                    let r = Mat3::from_quat(*b.rotation());
                    let m = r * mp.reconstruct_inverse_inertia_matrix() * r.transpose();
                    if m.is_finite() {
                        m
                    } else {
                        Mat3::ZERO
                    }
                }
                _ => Mat3::ZERO,
            };
            let com = parent.map_or(co.position().translation, |(_, b)| b.center_of_mass());
            // A moving prop (kinematic) is swept too: seen at its end-of-step pose by every
            // substep it would jump its whole step's travel at the first one and the body
            // would take that jump as a velocity of travel / h — energy that grew with the
            // square of the substep count and kept the squeeze and poke from converging.
            let kinematic = parent.is_some_and(|(_, b)| b.is_kinematic());
            let lag = if kinematic || (sweep_dynamic && dynamic_body.is_some()) {
                velocity * dt_s
            } else {
                Vec3::ZERO
            };
            NearCollider {
                handle,
                dynamic_body,
                inv_mass,
                inv_inertia,
                com,
                lag,
                pose: *co.position(),
                shape: co.shape(),
                aabb_lo: aabb.mins,
                aabb_hi: aabb.maxs,
                friction: co.friction(),
                velocity,
            }
        })
        .collect()
}

/// A contact half-space of one substep.
#[derive(Clone, Copy, Debug)]
pub(super) struct Contact {
    /// The contact point (see [`ContactPoints`]).
    point: u32,
    /// The near collider that pushed it most.
    collider: u32,
    /// Where that collider had moved the plane's point by the contacts when the half-space
    /// was made: the half-space moves on with it.
    moved_at: Vec3,
    /// Outward normal of the half-space.
    normal: Vec3,
    /// A point on its plane.
    on_plane: Vec3,
}

/// The points of a body that collide, over its particles: the surface points, and for an
/// embedded surface also the tet nodes (thickness 0): nodes of the cover outside the surface
/// would otherwise run into a wall the surface stopped at, and crush their tets inside out.
pub(super) struct ContactPoints<'a> {
    /// How the surface follows the particles.
    pub(super) map: &'a SurfaceMap,
    /// Particle positions.
    pub(super) x: &'a mut [Vec3],
    /// Particle positions at the start of the substep.
    pub(super) prev: &'a [Vec3],
    /// Inverse masses (0 = pinned).
    pub(super) inv_mass: &'a [f32],
    /// Contact thickness of the surface points, metres.
    pub(super) radius_m: f32,
    /// Which tet nodes of an embedded surface collide too (`None`: all).
    pub(super) nodes: Option<&'a [u32]>,
    /// What the contacts did to each near collider this step.
    pub(super) reactions: &'a mut [Reaction],
    /// Each near collider's inertia in the contacts (a dynamic body's when coupled, else
    /// zero: immovable).
    pub(super) collider_inertia: &'a [ColliderInertia],
}

/// A near collider's inertia in the contacts: its inverse mass and world inverse inertia
/// (zero: immovable, or it does not turn) and its centre of mass at the end of the rapier
/// step, world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ColliderInertia {
    pub(super) inv_mass: f32,
    pub(super) inv_inertia: Mat3,
    pub(super) com: Vec3,
}

impl ColliderInertia {
    pub(super) fn of(c: &NearCollider<'_>) -> Self {
        ColliderInertia {
            inv_mass: c.inv_mass,
            inv_inertia: c.inv_inertia,
            com: c.com,
        }
    }
}

/// What the body's contacts did to one near collider over a step: the impulse they gave it
/// (the opposite of what it gave the body's points) and that impulse's moment about the
/// origin, N·s and N·m·s.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Reaction {
    /// Linear impulse on the collider.
    pub impulse: Vec3,
    /// Moment of the impulse about the world origin.
    pub moment: Vec3,
    /// How far the contacts moved a coupled collider during the step (its share of every
    /// push, by inverse mass).
    pub shift: Vec3,
    /// How far it travelled within the step at the velocity those pushes gave it.
    pub drift: Vec3,
    /// How far the contacts turned a coupled collider during the step (a rotation vector,
    /// about its centre of mass), and how far it turned within the step at the spin they gave
    /// it: `shift` and `drift`'s angular twins.
    pub turn: Vec3,
    /// See `turn`.
    pub turn_drift: Vec3,
    /// Its velocity change so far (the pushes of earlier substeps over their substep).
    dv: Vec3,
    /// Its angular velocity change so far.
    dw: Vec3,
    /// `shift` at the start of the substep.
    shift_before: Vec3,
    /// `turn` at the start of the substep.
    turn_before: Vec3,
}

impl Reaction {
    /// Start of a substep of `h`: the collider moves on at its changed velocity.
    pub(super) fn advance(&mut self, h: f32) {
        self.drift += self.dv * h;
        self.turn_drift += self.dw * h;
        self.shift_before = self.shift;
        self.turn_before = self.turn;
    }

    /// End of a substep of `h`: this substep's pushes become velocity (XPBD's `v = Δx / h`).
    pub(super) fn close_substep(&mut self, h: f32) {
        self.dv += (self.shift - self.shift_before) / h;
        self.dw += (self.turn - self.turn_before) / h;
    }

    /// The whole rotation the contacts gave the collider so far this step.
    pub fn rotation(&self) -> Quat {
        Quat::from_scaled_axis(self.turn + self.turn_drift)
    }

    /// How far the contacts moved the collider's point that was at `p` (world, as the collider
    /// is at the end of the rapier step; `com` its centre of mass there): its shift and drift,
    /// and its turn about its centre of mass.
    pub(super) fn moved(&self, p: Vec3, com: Vec3) -> Vec3 {
        let c = com + self.shift + self.drift;
        let arm = p + self.shift + self.drift - c;
        self.shift + self.drift + (self.rotation() * arm - arm)
    }
}

impl ContactPoints<'_> {
    fn surface_len(&self) -> usize {
        self.map.vertex_count(self.x.len())
    }

    fn len(&self) -> usize {
        match self.map {
            SurfaceMap::Direct => self.x.len(),
            SurfaceMap::Embedded(e) => {
                e.nodes.len() + self.nodes.map_or(self.x.len(), <[u32]>::len)
            }
        }
    }

    /// Contact point `c`: (position, previous position, thickness).
    fn point(&self, c: usize) -> (Vec3, Vec3, f32) {
        let s = self.surface_len();
        if c < s {
            let (p, p0) = self.map.point(self.x, self.prev, c);
            (p, p0, self.radius_m)
        } else {
            let i = self.node(c - s);
            (self.x[i], self.prev[i], 0.0)
        }
    }

    /// The particle of the `k`-th colliding node.
    fn node(&self, k: usize) -> usize {
        self.nodes.map_or(k, |l| l[k] as usize)
    }

    fn move_point(&mut self, c: usize, delta: Vec3) {
        let s = self.surface_len();
        if c < s {
            self.map.move_point(self.x, self.inv_mass, c, delta);
        } else {
            let i = self.node(c - s);
            if self.inv_mass[i] > 0.0 {
                self.x[i] += delta;
            }
        }
    }

    /// The inverse of the mass a push on contact point `c` moves: a particle's, or for an
    /// embedded point `Σ w_k² / m_k` over its tet's nodes (what [`SurfaceMap::move_point`]
    /// moves).
    fn inverse_mass(&self, c: usize) -> f32 {
        let s = self.surface_len();
        if c < s {
            self.map.point_inverse_mass(self.inv_mass, c)
        } else {
            self.inv_mass[self.node(c - s)]
        }
    }

    /// How far the contacts have moved near collider `k`'s point at `p` so far this step.
    fn collider_moved(&self, k: usize, p: Vec3) -> Vec3 {
        let com = self.collider_inertia.get(k).map_or(p, |i| i.com);
        self.reactions
            .get(k)
            .map_or(Vec3::ZERO, |r| r.moved(p, com))
    }

    /// Splits a push `d` of contact point `c` (at `at`) out of near collider `k` by inverse
    /// mass: a coupled dynamic collider takes its share as a shift, the point the rest;
    /// books the momentum the point gained (over a substep of `h`) as the collider's reaction.
    /// Returns the point's move.
    fn split(&mut self, k: usize, c: usize, at: Vec3, d: Vec3, h: f32) -> Vec3 {
        let wp = self.inverse_mass(c);
        let inertia = self.collider_inertia.get(k).copied();
        let Some(r) = self.reactions.get_mut(k) else {
            return d;
        };
        // The collider's inverse mass at `at` along the push: translation and turn (its arm
        // from the centre of mass as the contacts have moved it so far).
        let n = d.normalize_or_zero();
        let (wb, arm, inv_inertia, inv_mass) = match inertia {
            Some(i) if i.inv_mass > 0.0 => {
                let arm = at - (i.com + r.shift + r.drift);
                let rn = arm.cross(n);
                (
                    i.inv_mass + rn.dot(i.inv_inertia * rn),
                    arm,
                    i.inv_inertia,
                    i.inv_mass,
                )
            }
            _ => (0.0, Vec3::ZERO, Mat3::ZERO, 0.0),
        };
        let share = if wb > 0.0 && wp > 0.0 {
            wp / (wp + wb)
        } else {
            1.0
        };
        let moved = d * share;
        if wb > 0.0 {
            // The positional impulse that moves the collider's point by `−(d − moved)`.
            let p = -(d - moved) / wb;
            r.shift += p * inv_mass;
            r.turn += inv_inertia * arm.cross(p);
        }
        if wp > 0.0 {
            let j = -moved / (wp * h);
            r.impulse += j;
            r.moment += at.cross(j);
        }
        moved
    }

    /// This substep's contact half-spaces against `near`, into `contacts`.
    /// `at`: the fraction of the step done at the end of this substep.
    pub(super) fn generate(
        &self,
        near: &[NearCollider],
        h: f32,
        at: f32,
        contacts: &mut Vec<Contact>,
    ) {
        contacts.clear();
        if near.is_empty() {
            return;
        }
        let mut pushes = Vec::new();
        for c in 0..self.len() {
            let (p, p0, r) = self.point(c);
            pushes.clear();
            if let Some(target) = resolve_point(near, self.reactions, p0, p, r, h, at, &mut pushes)
            {
                let n = (target - p).normalize_or_zero();
                let collider = pushes
                    .iter()
                    .max_by(|a, b| a.1.length_squared().total_cmp(&b.1.length_squared()))
                    .map_or(0, |&(k, _)| k);
                if n != Vec3::ZERO {
                    contacts.push(Contact {
                        point: c as u32,
                        collider,
                        moved_at: self.collider_moved(collider as usize, target),
                        normal: n,
                        on_plane: target,
                    });
                }
            }
        }
    }

    /// Pushes every contact point back onto its half-space.
    pub(super) fn project(&mut self, contacts: &[Contact], h: f32) {
        for &Contact {
            point: i,
            collider,
            moved_at,
            normal: n,
            on_plane: q,
        } in contacts
        {
            let q = q + self.collider_moved(collider as usize, q) - moved_at;
            let (p, _, _) = self.point(i as usize);
            let c = n.dot(p - q);
            if c < 0.0 {
                let moved = self.split(collider as usize, i as usize, p, -n * c, h);
                self.move_point(i as usize, moved);
            }
        }
    }

    /// Each contact point is swept from its previous position (a ray, so no wall is crossed
    /// within a substep) and pushed out of every collider to its contact thickness, with
    /// Coulomb friction relative to the collider's motion.
    pub(super) fn collide(&mut self, near: &[NearCollider], h: f32, at: f32) {
        if near.is_empty() {
            return;
        }
        let mut pushes = Vec::new();
        for c in 0..self.len() {
            let (p, p0, r) = self.point(c);
            pushes.clear();
            if resolve_point(near, self.reactions, p0, p, r, h, at, &mut pushes).is_some() {
                let mut moved = Vec3::ZERO;
                for &(k, d) in &pushes {
                    moved += self.split(k as usize, c, p, d, h);
                }
                self.move_point(c, moved);
            }
        }
    }
}

/// Where `p` (coming from `p0`) must go to be outside every collider by `r`, or `None` if
/// it already is; `pushes` gets each collider's share of the move (near index, displacement).
/// A collider is where it was `1 − at` of the step ago (see `lag`), plus the shift the
/// contacts gave it so far (`reactions`).
#[allow(clippy::too_many_arguments)]
fn resolve_point(
    near: &[NearCollider],
    reactions: &[Reaction],
    p0: Vec3,
    p: Vec3,
    r: f32,
    h: f32,
    at: f32,
    pushes: &mut Vec<(u32, Vec3)>,
) -> Option<Vec3> {
    let mut q = p;
    let mut moved = false;
    for (k, c) in near.iter().enumerate() {
        let back = c.lag * (1.0 - at) - reactions.get(k).map_or(Vec3::ZERO, |r| r.shift + r.drift);
        // A turned collider sweeps further than its bounds: grow them by its turn's reach.
        let reach = reactions.get(k).map_or(0.0, |r| {
            (r.turn + r.turn_drift).length()
                * ((c.aabb_hi - c.aabb_lo).length() + c.com.distance(c.pose.translation))
        });
        let lo = q.min(p0) - Vec3::splat(r + reach);
        let hi = q.max(p0) + Vec3::splat(r + reach);
        if lo.cmpgt(c.aabb_hi - back.min(Vec3::ZERO)).any()
            || hi.cmplt(c.aabb_lo - back.max(Vec3::ZERO)).any()
        {
            continue;
        }
        let mut pose = c.pose;
        pose.translation -= back;
        if let Some(r) = reactions.get(k) {
            let turn = r.rotation();
            if turn != Quat::IDENTITY {
                // Turned about its centre of mass, moved as the pose is.
                let com = c.com - back;
                pose.rotation = turn * pose.rotation;
                pose.translation = com + turn * (pose.translation - com);
            }
        }
        let c = NearCollider { pose, ..*c };
        let before = q;
        // Sweep: a point that was outside and is now past the surface stops at the entry.
        let d = q - p0;
        if d.length_squared() > 1e-14 && !c.shape.contains_point(&c.pose, p0) {
            let ray = Ray::new(p0, d);
            if let Some(t) = c.shape.cast_ray(&c.pose, &ray, 1.0, true) {
                if t < 1.0 {
                    q = p0 + d * t;
                }
            }
        }
        let proj = c.shape.project_point(&c.pose, q, false);
        let off = q - proj.point;
        let dist = off.length();
        let normal = if proj.is_inside {
            if dist > 1e-9 {
                -off / dist
            } else {
                continue;
            }
        } else if dist < r && dist > 1e-9 {
            off / dist
        } else if dist <= 1e-9 {
            // Exactly on the surface: push along the travel, backwards.
            let back = -(p - p0).normalize_or_zero();
            if back == Vec3::ZERO {
                continue;
            }
            back
        } else {
            if q != before {
                moved = true;
                pushes.push((k as u32, q - before));
            }
            continue;
        };
        let pushed = proj.point + normal * r;
        // Coulomb friction on the tangential travel relative to the collider.
        let depth = (pushed - q).length();
        let rel = pushed - p0 - c.velocity * h;
        let tangential = rel - normal * rel.dot(normal);
        let t_len = tangential.length();
        let limit = c.friction * depth;
        let fric = if t_len <= limit {
            tangential
        } else {
            tangential * (limit / t_len)
        };
        q = pushed - fric;
        moved = true;
        pushes.push((k as u32, q - before));
    }
    moved.then_some(q)
}
