//! The volume term (`SoftBodyConfig::volume_stiffness`): a global pressure that keeps a
//! squeezed body's volume by bulging its free surface. Part of the restoring step
//! (`SoftBody::apply_restoring_velocities` calls it after planning the restoring
//! velocities); it reads only the current shape, so nothing more travels in a room.

use glam::{Quat, Vec3};

use super::SoftBody;

/// The volume term leaves a volume error smaller than this fraction of the rest volume alone.
const VOLUME_TOLERANCE: f32 = 2e-3;

impl SoftBody {
    /// How freely the volume term moves particle `j`, in [0, 1]: 0 if grabbed or pressed in
    /// (its displacement from its target, `self.scratch`, is inward along the volume gradient
    /// by half its radius or more), 1 if not pressed in at all, linear between (no switch
    /// that flips from one step to the next). A particle a plate or a hand presses in cannot
    /// move out: what it was given would be taken back by the contact, and the volume never
    /// restored. The free particles take it all and the body bulges.
    fn freedom(&self, j: usize) -> f32 {
        if self.drives[j].is_some() {
            return 0.0;
        }
        let g = self.particle_grad[j];
        let len = g.length();
        if len <= 0.0 {
            return 0.0;
        }
        let r = self.particle_radius_m[j].max(1e-6);
        let inward = -self.scratch[j].dot(g) / len;
        let pressed = (1.0 - inward / (0.5 * r)).clamp(0.0, 1.0);
        let out = ((4.0 * r + inward) / (2.0 * r)).clamp(0.0, 1.0);
        pressed * out
    }

    /// The volume term (`SoftBodyConfig::volume_stiffness`): a global pressure. With `V` the
    /// enclosed volume of the surface the particles make now, `gₚ = ∂V/∂xₚ`
    /// through the skinning (each vertex is its rest place plus the weighted displacement of
    /// its particles, so `gₚ = Σᵥ wᵥₚ ∂V/∂xᵥ`), and `V'` the volume the planned velocities
    /// of the free particles ([`freedom`](Self::freedom) `f`, weighting each) would give after the step
    /// (`V + dt Σ fₚ gₚ·(vₚ − rigid)`, first order: rigid motion changes no volume), the free
    /// particles' velocities change by `−β (V' − V₀) fₚ gₚ / (dt Σ fₚ|g|²)`, `β = 1 − exp(−rate·dt)`:
    /// the smallest change (least squares) that corrects the fraction β of the volume error.
    /// Grabbed and pressed-in particles keep their velocity and are not counted in `V'`:
    /// what presses them decides where they go, and the next step measures it.
    pub(super) fn keep_volume(&mut self, dt: f32, r: Quat, vc: Vec3, wc: Vec3) {
        let rate = self.config.volume_stiffness;
        if rate <= 0.0 || self.tear.is_some() || self.rest_volume_m3 <= 0.0 {
            return;
        }
        // The shape the particles make now, built here from this step's displacements
        // (`self.scratch`, measured from the world): `vertices` is what the last deformation
        // showed — blending towards a received state, or still at rest in a world rebuilt from
        // a snapshot — and a term that read it would make two peers with the same physics
        // state step differently.
        self.sim_vertices.clear();
        for (v, rest) in self.rest_vertices.iter().enumerate() {
            let mut p = r * *rest;
            if self.map.soft_vertex[v] {
                let (ids, ws) = self.map.vertex_particles.row(v);
                for (&pi, &w) in ids.iter().zip(ws) {
                    let i = pi as usize;
                    p += (self.scratch[i] + r * self.anchor_shift[i]) * w;
                }
            }
            self.sim_vertices.push(p);
        }
        let tris = &self.welded.triangles;
        let verts = &self.sim_vertices;
        let volume: f32 = tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| verts[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        if !volume.is_finite() || volume <= 0.0 {
            return;
        }
        // A body near its own volume (a flight, a rest, a light touch) costs this one pass:
        // the gradients are made only when there is volume to restore. What this step's
        // motion will change, the next step measures.
        if (volume - self.rest_volume_m3).abs() < 0.5 * VOLUME_TOLERANCE * self.rest_volume_m3 {
            return;
        }
        self.vertex_grad.clear();
        self.vertex_grad.resize(verts.len(), Vec3::ZERO);
        for t in tris {
            let [a, b, c] = t.map(|i| verts[i as usize]);
            self.vertex_grad[t[0] as usize] += b.cross(c) / 6.0;
            self.vertex_grad[t[1] as usize] += c.cross(a) / 6.0;
            self.vertex_grad[t[2] as usize] += a.cross(b) / 6.0;
        }
        self.particle_grad.clear();
        self.particle_grad.resize(self.particles.len(), Vec3::ZERO);
        for (v, g) in self.vertex_grad.iter().enumerate() {
            if !self.map.soft_vertex[v] {
                continue;
            }
            let (ids, ws) = self.map.vertex_particles.row(v);
            for (&p, &w) in ids.iter().zip(ws) {
                self.particle_grad[p as usize] += *g * w;
            }
        }
        // The push is an internal pressure: it must not move the body as a whole. The free
        // particles' push `fₚ gₚ` is made free of net force and torque (the rigid part of it,
        // weighted by the freedom, taken out about their weighted centroid); left in, it is a
        // steady force wherever the body is pressed or held on one side only — a hand holding
        // a stretched piece was pushed away, piece and center apart, a little more each step.
        let mut change = 0.0f32;
        let mut weight = 0.0f32;
        let mut push = Vec3::ZERO;
        let mut centroid = Vec3::ZERO;
        for (j, g) in self.particle_grad.iter().enumerate() {
            // Pressed in: its restoring pushes it out into what presses it, which takes that
            // back; counting it in full would promise volume that never comes.
            let free = self.freedom(j);
            if free <= 0.0 {
                continue;
            }
            if let Some(v) = self.planned_v[j] {
                let rigid = vc + wc.cross(r * (self.rest_offsets[j] + self.anchor_shift[j]));
                change += free * g.dot(v - rigid) * dt;
            }
            weight += free;
            push += free * *g;
            centroid += free * (r * (self.rest_offsets[j] + self.anchor_shift[j]));
        }
        if weight <= 0.0 {
            return;
        }
        let shift = push / weight;
        centroid /= weight;
        let mut torque = Vec3::ZERO;
        let mut inertia = glam::Mat3::ZERO;
        for (j, g) in self.particle_grad.iter().enumerate() {
            let free = self.freedom(j);
            if free <= 0.0 {
                continue;
            }
            let q = r * (self.rest_offsets[j] + self.anchor_shift[j]) - centroid;
            torque += free * q.cross(*g - shift);
            inertia += free
                * (glam::Mat3::from_diagonal(Vec3::splat(q.length_squared()))
                    - glam::Mat3::from_cols(q * q.x, q * q.y, q * q.z));
        }
        // Fewer than three particles free, or all on a line: no torque to take out that way.
        let spin =
            if inertia.determinant().abs() > 1e-12 * inertia.col(0).length().powi(3).max(1e-30) {
                inertia.inverse() * torque
            } else {
                Vec3::ZERO
            };
        let direction = |j: usize, g: Vec3, free: f32| {
            let q = r * (self.rest_offsets[j] + self.anchor_shift[j]) - centroid;
            free * (g - shift - spin.cross(q))
        };
        // The volume gained per unit of push: the push is no longer along the gradient alone.
        let mut norm = 0.0f32;
        for (j, g) in self.particle_grad.iter().enumerate() {
            let free = self.freedom(j);
            if free > 0.0 {
                norm += g.dot(direction(j, *g, free));
            }
        }
        let error = volume + change - self.rest_volume_m3;
        // Within the tolerance the term does nothing: a body at rest is a little deformed
        // (its own weight), and a push every step would keep its particles from sleeping
        // (an untouched resting body must cost one bounds query). A push that gains no
        // volume once its rigid part is out (a piece held all round) is not made.
        if norm <= 0.0
            || !norm.is_finite()
            || !error.is_finite()
            || error.abs() < VOLUME_TOLERANCE * self.rest_volume_m3
        {
            return;
        }
        let beta = 1.0 - (-rate * dt).exp();
        let scale = -beta * error / (dt * norm);
        let max_dv = self.config.max_velocity_change_mps;
        for j in 0..self.particle_grad.len() {
            let free = self.freedom(j);
            if free <= 0.0 {
                continue;
            }
            let mut dv = direction(j, self.particle_grad[j], free) * scale;
            let len = dv.length();
            if len > max_dv {
                dv *= max_dv / len;
            }
            if let Some(v) = &mut self.planned_v[j] {
                *v += dv;
            } else if len > 1e-6 {
                self.planned_v[j] = Some(dv);
            }
        }
    }
}
