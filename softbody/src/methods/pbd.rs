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

use glam::{Quat, Vec3};
use parry3d::math::Pose;
use parry3d::query::Ray;
use parry3d::shape::Shape;
use rapier3d::prelude::{Aabb, PhysicsWorld, QueryFilter};

use crate::methods::model::DeformableModel;
use crate::metrics::extract_rotation;

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
        }
    }
}

/// Distance constraints of one material (ISPC paper eq. 1–3).
#[derive(Clone, Debug, Default)]
pub struct DistanceGroup {
    /// What the group is (edges, ISPC links, tet edges).
    pub label: &'static str,
    /// Particle pairs.
    pub pairs: Vec<[u32; 2]>,
    /// Rest lengths, metres.
    pub rest_m: Vec<f32>,
    /// XPBD compliance per constraint, m/N.
    pub compliance: Vec<f32>,
    /// Plain-PBD stiffness per iteration, (0, 1].
    pub pbd_stiffness: f32,
    lambda: Vec<f32>,
}

impl DistanceGroup {
    /// A group over `pairs` with rest lengths from `x`; the compliance of each constraint is
    /// `1 / (E · V_share / L²)`: a spring of a continuum of Young's modulus `young_pa` whose
    /// volume `volume_m3` is shared evenly by the constraints.
    pub fn new(
        label: &'static str,
        pairs: Vec<[u32; 2]>,
        x: &[Vec3],
        young_pa: f32,
        volume_m3: f32,
        pbd_stiffness: f32,
    ) -> Self {
        let rest_m: Vec<f32> = pairs
            .iter()
            .map(|[a, b]| x[*a as usize].distance(x[*b as usize]))
            .collect();
        let share = volume_m3.abs() / pairs.len().max(1) as f32;
        let compliance = rest_m
            .iter()
            .map(|l| {
                let k = young_pa * share / (l * l).max(1e-12);
                if k > 0.0 && k.is_finite() {
                    1.0 / k
                } else {
                    0.0
                }
            })
            .collect();
        let n = pairs.len();
        Self {
            label,
            pairs,
            rest_m,
            compliance,
            pbd_stiffness,
            lambda: vec![0.0; n],
        }
    }

    /// Number of constraints.
    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    /// True if there are none.
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }
}

/// Dihedral bending constraints on pairs of adjacent triangles (ISPC paper eq. 4).
#[derive(Clone, Debug, Default)]
pub struct BendingGroup {
    /// `[p0, p1, p2, p3]`: p0, p1 the opposite vertices, p2–p3 the shared edge.
    pub quads: Vec<[u32; 4]>,
    /// Rest dihedral angles, radians.
    pub rest_rad: Vec<f32>,
    /// XPBD compliance per constraint, 1/(N·m).
    pub compliance: Vec<f32>,
    /// Plain-PBD stiffness per iteration.
    pub pbd_stiffness: f32,
    lambda: Vec<f32>,
}

impl BendingGroup {
    /// Every interior edge of `triangles` (shared by exactly two faces) with bending stiffness
    /// `young_pa · ratio · L³` (L the shared edge).
    pub fn from_triangles(
        triangles: &[[u32; 3]],
        x: &[Vec3],
        young_pa: f32,
        ratio: f32,
        pbd_stiffness: f32,
    ) -> Self {
        let mut edges: std::collections::HashMap<(u32, u32), Vec<u32>> = Default::default();
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                edges
                    .entry((a.min(b), a.max(b)))
                    .or_default()
                    .push(t as u32);
            }
        }
        let mut keys: Vec<_> = edges.into_iter().filter(|(_, f)| f.len() == 2).collect();
        keys.sort_unstable_by_key(|(k, _)| *k);
        let mut g = BendingGroup {
            pbd_stiffness,
            ..Default::default()
        };
        for ((a, b), faces) in keys {
            let opp = |t: u32| {
                triangles[t as usize]
                    .iter()
                    .copied()
                    .find(|&v| v != a && v != b)
            };
            let (Some(c), Some(d)) = (opp(faces[0]), opp(faces[1])) else {
                continue;
            };
            if c == d {
                continue;
            }
            let q = [c, d, a, b];
            let Some((phi, _, _)) = dihedral(q.map(|i| x[i as usize]), [1.0; 4]) else {
                continue;
            };
            let l = x[a as usize].distance(x[b as usize]);
            let k = young_pa * ratio * l * l * l;
            g.quads.push(q);
            g.rest_rad.push(phi);
            g.compliance.push(if k > 0.0 && k.is_finite() {
                1.0 / k
            } else {
                0.0
            });
        }
        g.lambda = vec![0.0; g.quads.len()];
        g
    }
}

/// Tetrahedron volume constraints `C = V − V₀` (the tetrahedral reference's second set).
#[derive(Clone, Debug, Default)]
pub struct VolumeGroup {
    /// Positively oriented tets.
    pub tets: Vec<[u32; 4]>,
    /// Rest volumes, m³.
    pub rest_m3: Vec<f32>,
    /// XPBD compliance per tet, 1/(K·V₀) for bulk modulus K.
    pub compliance: Vec<f32>,
    /// Plain-PBD stiffness per iteration.
    pub pbd_stiffness: f32,
    /// Volume fraction below which a tet is pushed back hard (0 disables the floor).
    pub min_fraction: f32,
    lambda: Vec<f32>,
}

impl VolumeGroup {
    /// Volume constraints on `tets` with bulk modulus `bulk_pa`.
    pub fn new(tets: Vec<[u32; 4]>, x: &[Vec3], bulk_pa: f32, pbd_stiffness: f32) -> Self {
        let rest_m3: Vec<f32> = tets
            .iter()
            .map(|t| tet_volume(t.map(|i| x[i as usize])))
            .collect();
        let compliance = rest_m3
            .iter()
            .map(|v| {
                let k = bulk_pa / v.abs().max(1e-15);
                if k.is_finite() && k > 0.0 {
                    1.0 / k
                } else {
                    0.0
                }
            })
            .collect();
        let n = tets.len();
        Self {
            tets,
            rest_m3,
            compliance,
            pbd_stiffness,
            min_fraction: 0.25,
            lambda: vec![0.0; n],
        }
    }
}

/// Shape-matching clusters (Müller et al. 2005, "Meshless deformations based on shape
/// matching"): each cluster pulls its members towards its best rigid fit of the rest shape.
#[derive(Clone, Debug, Default)]
pub struct ShapeClusters {
    /// Row starts into `members`, one more than the number of clusters.
    pub offsets: Vec<u32>,
    /// Member particles.
    pub members: Vec<u32>,
    /// Rest positions of the members relative to their cluster's rest centroid.
    pub rest_rel: Vec<Vec3>,
    /// Rate at which members reach their goals, 1/s: per substep `α = 1 − exp(−rate·h)`.
    pub rate_per_s: f32,
    rotations: Vec<Quat>,
}

impl ShapeClusters {
    /// Clusters from member lists over rest positions `x`.
    pub fn new(clusters: &[Vec<u32>], x: &[Vec3], rate_per_s: f32) -> Self {
        let mut s = ShapeClusters {
            offsets: vec![0],
            rate_per_s,
            ..Default::default()
        };
        for c in clusters.iter().filter(|c| c.len() >= 2) {
            let cm = c.iter().map(|&i| x[i as usize]).sum::<Vec3>() / c.len() as f32;
            for &i in c {
                s.members.push(i);
                s.rest_rel.push(x[i as usize] - cm);
            }
            s.offsets.push(s.members.len() as u32);
        }
        s.rotations = vec![Quat::IDENTITY; s.offsets.len() - 1];
        s
    }

    /// Number of clusters.
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// True if there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A surface point carried by a tetrahedron (barycentric weights).
#[derive(Clone, Debug, Default)]
pub struct Embedding {
    /// Tet nodes per surface vertex.
    pub nodes: Vec<[u32; 4]>,
    /// Barycentric weights per surface vertex (sum 1; may be slightly outside [0, 1] when the
    /// vertex lies just outside every tet).
    pub weights: Vec<[f32; 4]>,
}

/// How the surface follows the particles.
#[derive(Clone, Debug)]
pub enum SurfaceMap {
    /// Surface vertex `i` is particle `i`.
    Direct,
    /// Surface vertices are embedded in tets over the particles.
    Embedded(Embedding),
}

/// A collider near the body for this step.
struct NearCollider<'a> {
    pose: Pose,
    shape: &'a dyn Shape,
    aabb_lo: Vec3,
    aabb_hi: Vec3,
    friction: f32,
    velocity: Vec3,
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
    inv_mass: Vec<f32>,
    /// Distance constraint groups (edges, links, tet edges).
    pub distance: Vec<DistanceGroup>,
    /// Bending constraints, if any.
    pub bending: Option<BendingGroup>,
    /// Tet volume constraints, if any.
    pub volume: Option<VolumeGroup>,
    /// Shape-matching clusters, if any.
    pub clusters: Option<ShapeClusters>,
    surface_map: SurfaceMap,
    surface: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    sleeping: bool,
    still_s: f32,
    max_speed: f32,
    accum: Vec<Vec3>,
    counts: Vec<f32>,
    /// Contact half-spaces of this substep: (surface point, normal, point on the plane).
    contacts: Vec<(u32, Vec3, Vec3)>,
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
            .map(|i| {
                let m = mass_kg.get(i).copied().unwrap_or(0.0);
                if m > 0.0 && m.is_finite() {
                    1.0 / m
                } else {
                    0.0
                }
            })
            .collect();
        let mut b = PbdBody {
            name: name.into(),
            params,
            v: vec![Vec3::ZERO; n],
            prev: x.clone(),
            x,
            inv_mass,
            distance: Vec::new(),
            bending: None,
            volume: None,
            clusters: None,
            surface_map,
            surface: Vec::new(),
            triangles,
            sleeping: false,
            still_s: 0.0,
            max_speed: 0.0,
            accum: vec![Vec3::ZERO; n],
            counts: vec![0.0; n],
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
            + self.volume.as_ref().map_or(0, |v| v.tets.len());
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
        match &self.surface_map {
            SurfaceMap::Direct => {
                self.surface.clear();
                self.surface.extend_from_slice(&self.x);
            }
            SurfaceMap::Embedded(e) => {
                self.surface.resize(e.nodes.len(), Vec3::ZERO);
                for (s, (n, w)) in self.surface.iter_mut().zip(e.nodes.iter().zip(&e.weights)) {
                    *s = (0..4).map(|k| self.x[n[k] as usize] * w[k]).sum();
                }
            }
        }
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
        let near: Vec<NearCollider> = world
            .intersect_aabb_conservative(Aabb::new(lo - grow, hi + grow), QueryFilter::default())
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
            .collect();
        let damp = (-self.params.damping_per_s.max(0.0) * h).exp();
        for _ in 0..substeps {
            // Algorithm 1 lines 8–10: external forces, damping, prediction.
            for i in 0..self.x.len() {
                self.prev[i] = self.x[i];
                if self.inv_mass[i] == 0.0 {
                    self.v[i] = Vec3::ZERO;
                    continue;
                }
                self.v[i] = (self.v[i] + gravity * h) * damp;
                self.x[i] += self.v[i] * h;
            }
            // Line 11: contact constraints (half-spaces) for this substep.
            self.generate_contacts(&near, h);
            // Lines 12–14: Gauss–Seidel projection, contacts with the other constraints.
            self.reset_multipliers();
            // Symmetric Gauss–Seidel: odd iterations sweep backwards, so a load travels the
            // whole body both ways within one substep instead of one element per iteration.
            for it in 0..self.params.iterations.max(1) {
                let rev = it % 2 == 1;
                self.project_distances(h, rev);
                self.project_bending(h, rev);
                self.project_volumes(h, rev);
                self.project_contacts();
            }
            self.match_shapes(h);
            // Contacts once more, last, so the final positions are collision-free.
            self.collide(&near, h);
            // Lines 16–17: velocities from positions.
            for i in 0..self.x.len() {
                if !self.x[i].is_finite() {
                    self.x[i] = self.prev[i];
                    self.v[i] = Vec3::ZERO;
                    self.non_finite_resets += 1;
                    continue;
                }
                self.v[i] = (self.x[i] - self.prev[i]) / h;
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
            g.lambda.iter_mut().for_each(|l| *l = 0.0);
        }
        if let Some(b) = &mut self.bending {
            b.lambda.iter_mut().for_each(|l| *l = 0.0);
        }
        if let Some(v) = &mut self.volume {
            v.lambda.iter_mut().for_each(|l| *l = 0.0);
        }
    }

    /// ISPC paper eq. 1–3 (XPBD form when `solver` is XPBD).
    fn project_distances(&mut self, h: f32, reverse: bool) {
        let xpbd = self.params.solver == SolverKind::Xpbd;
        let inv_h2 = 1.0 / (h * h);
        for g in &mut self.distance {
            let n = g.pairs.len();
            for kk in 0..n {
                let k = if reverse { n - 1 - kk } else { kk };
                let [a, b] = g.pairs[k];
                let (a, b) = (a as usize, b as usize);
                let (wa, wb) = (self.inv_mass[a], self.inv_mass[b]);
                let wsum = wa + wb;
                if wsum == 0.0 {
                    continue;
                }
                let d = self.x[a] - self.x[b];
                let len = d.length();
                if len < 1e-9 {
                    continue;
                }
                let n = d / len;
                let c = len - g.rest_m[k];
                let dl = if xpbd {
                    let alpha = g.compliance[k] * inv_h2;
                    let dl = (-c - alpha * g.lambda[k]) / (wsum + alpha);
                    g.lambda[k] += dl;
                    dl
                } else {
                    -c / wsum * g.pbd_stiffness
                };
                self.x[a] += n * (wa * dl);
                self.x[b] -= n * (wb * dl);
            }
        }
    }

    /// ISPC paper eq. 4: dihedral angle of adjacent triangles (gradients after Bridson et al.
    /// 2003, as in Müller et al. 2007 Appendix A).
    fn project_bending(&mut self, h: f32, reverse: bool) {
        let xpbd = self.params.solver == SolverKind::Xpbd;
        let inv_h2 = 1.0 / (h * h);
        let Some(g) = &mut self.bending else { return };
        let n = g.quads.len();
        for kk in 0..n {
            let k = if reverse { n - 1 - kk } else { kk };
            let q = &g.quads[k];
            let w = q.map(|i| self.inv_mass[i as usize]);
            let p = q.map(|i| self.x[i as usize]);
            let Some((phi, grads, wsum)) = dihedral(p, w) else {
                continue;
            };
            let c = phi - g.rest_rad[k];
            let dl = if xpbd {
                let alpha = g.compliance[k] * inv_h2;
                let dl = (-c - alpha * g.lambda[k]) / (wsum + alpha);
                g.lambda[k] += dl;
                dl
            } else {
                -c / wsum * g.pbd_stiffness
            };
            for j in 0..4 {
                self.x[q[j] as usize] += grads[j] * (w[j] * dl);
            }
        }
    }

    fn project_volumes(&mut self, h: f32, reverse: bool) {
        let xpbd = self.params.solver == SolverKind::Xpbd;
        let inv_h2 = 1.0 / (h * h);
        let Some(g) = &mut self.volume else { return };
        let n = g.tets.len();
        for kk in 0..n {
            let k = if reverse { n - 1 - kk } else { kk };
            let t = &g.tets[k];
            let p = t.map(|i| self.x[i as usize]);
            let w = t.map(|i| self.inv_mass[i as usize]);
            let (e1, e2, e3) = (p[1] - p[0], p[2] - p[0], p[3] - p[0]);
            let g1 = e2.cross(e3) / 6.0;
            let g2 = e3.cross(e1) / 6.0;
            let g3 = e1.cross(e2) / 6.0;
            let g0 = -(g1 + g2 + g3);
            let grads = [g0, g1, g2, g3];
            let wsum: f32 = (0..4).map(|j| w[j] * grads[j].length_squared()).sum();
            if wsum < 1e-30 {
                continue;
            }
            let v = e1.dot(e2.cross(e3)) / 6.0;
            let c = v - g.rest_m3[k];
            let floor = g.min_fraction * g.rest_m3[k];
            let dl = if v < floor {
                // Below the floor the constraint is hard (an inequality): a tet crushed by a
                // contact is pushed back before it can turn inside out.
                (floor - v) / wsum
            } else if xpbd {
                let alpha = g.compliance[k] * inv_h2;
                let dl = (-c - alpha * g.lambda[k]) / (wsum + alpha);
                g.lambda[k] += dl;
                dl
            } else {
                -c / wsum * g.pbd_stiffness
            };
            for j in 0..4 {
                self.x[t[j] as usize] += grads[j] * (w[j] * dl);
            }
        }
    }

    /// Müller et al. 2005: goals `g = c + R q` from the polar rotation of `A_pq`; each particle
    /// moves by `α` of its mean goal offset over the clusters it is in.
    fn match_shapes(&mut self, h: f32) {
        let Some(cl) = &mut self.clusters else { return };
        let alpha = 1.0 - (-cl.rate_per_s.max(0.0) * h).exp();
        self.accum.iter_mut().for_each(|a| *a = Vec3::ZERO);
        self.counts.iter_mut().for_each(|c| *c = 0.0);
        for c in 0..cl.offsets.len() - 1 {
            let (s, e) = (cl.offsets[c] as usize, cl.offsets[c + 1] as usize);
            let members = &cl.members[s..e];
            let rest = &cl.rest_rel[s..e];
            let cm =
                members.iter().map(|&i| self.x[i as usize]).sum::<Vec3>() / members.len() as f32;
            let mut a = glam::Mat3::ZERO;
            for (&i, q) in members.iter().zip(rest) {
                let p = self.x[i as usize] - cm;
                a += glam::Mat3::from_cols(p * q.x, p * q.y, p * q.z);
            }
            let r = extract_rotation(a, cl.rotations[c]);
            cl.rotations[c] = r;
            for (&i, q) in members.iter().zip(rest) {
                let goal = cm + r * *q;
                self.accum[i as usize] += goal - self.x[i as usize];
                self.counts[i as usize] += 1.0;
            }
        }
        for i in 0..self.x.len() {
            if self.counts[i] > 0.0 && self.inv_mass[i] > 0.0 {
                self.x[i] += self.accum[i] * (alpha / self.counts[i]);
            }
        }
    }

    fn surface_point(&self, s: usize) -> (Vec3, Vec3) {
        match &self.surface_map {
            SurfaceMap::Direct => (self.x[s], self.prev[s]),
            SurfaceMap::Embedded(e) => {
                let (nodes, w) = (e.nodes[s], e.weights[s]);
                (
                    (0..4).map(|k| self.x[nodes[k] as usize] * w[k]).sum(),
                    (0..4).map(|k| self.prev[nodes[k] as usize] * w[k]).sum(),
                )
            }
        }
    }

    /// Moves surface point `s` by `delta` (an embedded point through its tet's nodes, each in
    /// proportion to its weight and inverse mass, so the point moves by exactly `delta`).
    fn move_surface_point(&mut self, s: usize, delta: Vec3) {
        match &self.surface_map {
            SurfaceMap::Direct => {
                if self.inv_mass[s] > 0.0 {
                    self.x[s] += delta;
                }
            }
            SurfaceMap::Embedded(e) => {
                let (nodes, w) = (e.nodes[s], e.weights[s]);
                let denom: f32 = (0..4)
                    .map(|k| self.inv_mass[nodes[k] as usize] * w[k] * w[k])
                    .sum();
                if denom < 1e-12 {
                    return;
                }
                for k in 0..4 {
                    let n = nodes[k] as usize;
                    self.x[n] += delta * (self.inv_mass[n] * w[k] / denom);
                }
            }
        }
    }

    fn surface_len(&self) -> usize {
        match &self.surface_map {
            SurfaceMap::Direct => self.x.len(),
            SurfaceMap::Embedded(e) => e.nodes.len(),
        }
    }

    /// Points that collide: the surface points, and for an embedded surface also the tet
    /// nodes (thickness 0): nodes of the cover outside the surface would otherwise run into a
    /// wall the surface stopped at, and crush their tets inside out.
    fn contact_len(&self) -> usize {
        match &self.surface_map {
            SurfaceMap::Direct => self.x.len(),
            SurfaceMap::Embedded(e) => e.nodes.len() + self.x.len(),
        }
    }

    /// Contact point `c`: (position, previous position, thickness).
    fn contact_point(&self, c: usize) -> (Vec3, Vec3, f32) {
        let s = self.surface_len();
        if c < s {
            let (p, p0) = self.surface_point(c);
            (p, p0, self.params.contact_radius_m)
        } else {
            (self.x[c - s], self.prev[c - s], 0.0)
        }
    }

    fn move_contact_point(&mut self, c: usize, delta: Vec3) {
        let s = self.surface_len();
        if c < s {
            self.move_surface_point(c, delta);
        } else if self.inv_mass[c - s] > 0.0 {
            self.x[c - s] += delta;
        }
    }

    fn generate_contacts(&mut self, near: &[NearCollider], h: f32) {
        self.contacts.clear();
        if near.is_empty() {
            return;
        }
        for c in 0..self.contact_len() {
            let (p, p0, r) = self.contact_point(c);
            if let Some(target) = resolve_point(near, p0, p, r, h) {
                let n = (target - p).normalize_or_zero();
                if n != Vec3::ZERO {
                    self.contacts.push((c as u32, n, target));
                }
            }
        }
    }

    fn project_contacts(&mut self) {
        for k in 0..self.contacts.len() {
            let (i, n, q) = self.contacts[k];
            let (p, _, _) = self.contact_point(i as usize);
            let c = n.dot(p - q);
            if c < 0.0 {
                self.move_contact_point(i as usize, -n * c);
            }
        }
    }

    /// Contacts: each contact point is swept from its previous position (a ray, so no wall is
    /// crossed within a substep) and pushed out of every collider to its contact thickness,
    /// with Coulomb friction relative to the collider's motion.
    fn collide(&mut self, near: &[NearCollider], h: f32) {
        if near.is_empty() {
            return;
        }
        for c in 0..self.contact_len() {
            let (p, p0, r) = self.contact_point(c);
            if let Some(target) = resolve_point(near, p0, p, r, h) {
                self.move_contact_point(c, target - p);
            }
        }
    }

    /// Number of tets with non-positive volume.
    pub fn count_inverted(&self) -> usize {
        self.volume.as_ref().map_or(0, |g| {
            g.tets
                .iter()
                .filter(|t| tet_volume(t.map(|i| self.x[i as usize])) <= 0.0)
                .count()
        })
    }

    /// Pins particles inside a box; returns the count.
    pub fn pin_box(&mut self, lo: Vec3, hi: Vec3) -> usize {
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

/// Signed volume of a tet.
pub fn tet_volume(p: [Vec3; 4]) -> f32 {
    (p[1] - p[0]).dot((p[2] - p[0]).cross(p[3] - p[0])) / 6.0
}

/// Dihedral angle of `[p0, p1, p2, p3]` (p2–p3 the shared edge), its gradients, and
/// `Σ w |∇|²`; `None` when degenerate.
fn dihedral(p: [Vec3; 4], w: [f32; 4]) -> Option<(f32, [Vec3; 4], f32)> {
    let e = p[3] - p[2];
    let elen = e.length();
    if elen < 1e-9 {
        return None;
    }
    let inv_e = 1.0 / elen;
    let n1 = (p[2] - p[0]).cross(p[3] - p[0]);
    let n2 = (p[3] - p[1]).cross(p[2] - p[1]);
    let (l1, l2) = (n1.length_squared(), n2.length_squared());
    if l1 < 1e-20 || l2 < 1e-20 {
        return None;
    }
    let (n1s, n2s) = (n1 / l1, n2 / l2);
    let d0 = n1s * elen;
    let d1 = n2s * elen;
    let d2 = n1s * ((p[0] - p[3]).dot(e) * inv_e) + n2s * ((p[1] - p[3]).dot(e) * inv_e);
    let d3 = n1s * ((p[2] - p[0]).dot(e) * inv_e) + n2s * ((p[2] - p[1]).dot(e) * inv_e);
    let (u1, u2) = (n1.normalize(), n2.normalize());
    let phi = u1.dot(u2).clamp(-1.0, 1.0).acos();
    let sign = if u1.cross(u2).dot(e) > 0.0 { -1.0 } else { 1.0 };
    let grads = [d0 * sign, d1 * sign, d2 * sign, d3 * sign];
    let wsum: f32 = (0..4).map(|j| w[j] * grads[j].length_squared()).sum();
    if wsum < 1e-20 {
        return None;
    }
    Some((phi, grads, wsum))
}

impl DeformableModel for PbdBody {
    fn name(&self) -> &str {
        &self.name
    }

    fn post_physics(&mut self, world: &mut PhysicsWorld, dt_s: f32) {
        self.step(world, dt_s);
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
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bending gradients are those of the dihedral angle: a finite-difference check.
    #[test]
    fn dihedral_gradients_match_finite_differences() {
        let p = [
            Vec3::new(0.3, 1.0, 0.2),
            Vec3::new(-0.2, -0.9, 0.5),
            Vec3::new(-1.0, 0.1, 0.0),
            Vec3::new(1.0, -0.1, 0.1),
        ];
        let Some((phi, grads, _)) = dihedral(p, [1.0; 4]) else {
            panic!("degenerate test quad");
        };
        let eps = 1e-3;
        for j in 0..4 {
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                let mut q = p;
                q[j] += axis * eps;
                let Some((phi2, _, _)) = dihedral(q, [1.0; 4]) else {
                    panic!("degenerate");
                };
                let fd = (phi2 - phi) / eps;
                let an = grads[j].dot(axis);
                assert!((fd - an).abs() < 2e-2, "node {j} {axis:?}: fd {fd} vs {an}");
            }
        }
    }
}
