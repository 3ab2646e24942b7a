//! Contacts with the rapier world: the colliders near a body for one step, the points that
//! collide (surface points, and an embedded surface's tet nodes), and pushing them out of the
//! colliders with a swept ray (no wall is crossed within a substep) and Coulomb friction.

use glam::Vec3;
use parry3d::math::Pose;
use parry3d::query::Ray;
use parry3d::shape::Shape;
use rapier3d::prelude::{Aabb, PhysicsWorld, QueryFilter};

use super::surface::SurfaceMap;

/// A collider near the body for this step.
pub(super) struct NearCollider<'a> {
    pose: Pose,
    shape: &'a dyn Shape,
    aabb_lo: Vec3,
    aabb_hi: Vec3,
    friction: f32,
    velocity: Vec3,
}

/// The colliders (sensors aside) whose bounds meet the box `[lo, hi]`, as they are now.
pub(super) fn near_colliders(world: &PhysicsWorld, lo: Vec3, hi: Vec3) -> Vec<NearCollider<'_>> {
    world
        .intersect_aabb_conservative(Aabb::new(lo, hi), QueryFilter::default())
        .filter(|(_, co)| !co.is_sensor())
        .map(|(_, co)| {
            let aabb = co.compute_aabb();
            let velocity = co
                .parent()
                .and_then(|p| world.bodies.get(p))
                .map(|b| b.linvel())
                .unwrap_or(Vec3::ZERO);
            NearCollider {
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

    /// This substep's contact half-spaces against `near`, into `contacts`.
    pub(super) fn generate(&self, near: &[NearCollider], h: f32, contacts: &mut Vec<Contact>) {
        contacts.clear();
        if near.is_empty() {
            return;
        }
        for c in 0..self.len() {
            let (p, p0, r) = self.point(c);
            if let Some(target) = resolve_point(near, p0, p, r, h) {
                let n = (target - p).normalize_or_zero();
                if n != Vec3::ZERO {
                    contacts.push(Contact {
                        point: c as u32,
                        normal: n,
                        on_plane: target,
                    });
                }
            }
        }
    }

    /// Pushes every contact point back onto its half-space.
    pub(super) fn project(&mut self, contacts: &[Contact]) {
        for &Contact {
            point: i,
            normal: n,
            on_plane: q,
        } in contacts
        {
            let (p, _, _) = self.point(i as usize);
            let c = n.dot(p - q);
            if c < 0.0 {
                self.move_point(i as usize, -n * c);
            }
        }
    }

    /// Each contact point is swept from its previous position (a ray, so no wall is crossed
    /// within a substep) and pushed out of every collider to its contact thickness, with
    /// Coulomb friction relative to the collider's motion.
    pub(super) fn collide(&mut self, near: &[NearCollider], h: f32) {
        if near.is_empty() {
            return;
        }
        for c in 0..self.len() {
            let (p, p0, r) = self.point(c);
            if let Some(target) = resolve_point(near, p0, p, r, h) {
                self.move_point(c, target - p);
            }
        }
    }
}

/// Where `p` (coming from `p0`) must go to be outside every collider by `r`, or `None` if
/// it already is.
fn resolve_point(near: &[NearCollider], p0: Vec3, p: Vec3, r: f32, h: f32) -> Option<Vec3> {
    let mut q = p;
    let mut moved = false;
    for c in near {
        let lo = q.min(p0) - Vec3::splat(r);
        let hi = q.max(p0) + Vec3::splat(r);
        if lo.cmpgt(c.aabb_hi).any() || hi.cmplt(c.aabb_lo).any() {
            continue;
        }
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
    }
    moved.then_some(q)
}
