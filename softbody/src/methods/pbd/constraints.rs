//! The constraint groups of a position-based body. Each group owns its XPBD multipliers and
//! projects itself onto the particles it is given: distances (ISPC paper eq. 1–3), dihedral
//! bending (eq. 4), tet volumes, and shape-matching clusters (Müller et al. 2005).

use glam::{Quat, Vec3};

use crate::metrics::extract_rotation;

/// `1 / k` for a positive finite `k`, else 0: a compliance from a stiffness (0 = rigid), an
/// inverse mass from a mass (0 = pinned).
pub(super) fn inverse_or_zero(k: f32) -> f32 {
    if k > 0.0 && k.is_finite() {
        1.0 / k
    } else {
        0.0
    }
}

/// One Gauss–Seidel sweep's settings: XPBD or plain PBD, `1 / h²` of the substep, and the
/// direction (odd iterations sweep backwards).
#[derive(Clone, Copy, Debug)]
pub(super) struct Sweep {
    xpbd: bool,
    inv_h2: f32,
    reverse: bool,
}

impl Sweep {
    /// A sweep of substep `h`.
    pub(super) fn new(xpbd: bool, h: f32, reverse: bool) -> Self {
        Self {
            xpbd,
            inv_h2: 1.0 / (h * h),
            reverse,
        }
    }

    /// The same sweep in the XPBD form whatever the body's solver (a material energy has no
    /// plain-PBD form).
    pub(super) fn xpbd(self) -> Self {
        Self { xpbd: true, ..self }
    }

    /// `α̃ = α / h²`: a compliance scaled to this sweep's substep.
    pub(super) fn scaled_compliance(&self, compliance: f32) -> f32 {
        compliance * self.inv_h2
    }

    /// The constraint visited `kk`-th of `n` in this sweep's direction.
    pub(super) fn index(&self, kk: usize, n: usize) -> usize {
        if self.reverse {
            n - 1 - kk
        } else {
            kk
        }
    }

    /// The multiplier step for a constraint of value `c` and weighted gradient norm `wsum`:
    /// XPBD with `compliance` (accumulating into `lambda`), or plain PBD scaled by
    /// `pbd_stiffness`.
    pub(super) fn correction(
        &self,
        c: f32,
        wsum: f32,
        compliance: f32,
        lambda: &mut f32,
        pbd_stiffness: f32,
    ) -> f32 {
        if self.xpbd {
            let alpha = compliance * self.inv_h2;
            let dl = (-c - alpha * *lambda) / (wsum + alpha);
            *lambda += dl;
            dl
        } else {
            -c / wsum * pbd_stiffness
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
                inverse_or_zero(k)
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

    /// Zeroes the multipliers (every substep).
    pub(super) fn reset(&mut self) {
        self.lambda.iter_mut().for_each(|l| *l = 0.0);
    }

    /// ISPC paper eq. 1–3 (XPBD form when the sweep is XPBD).
    pub(super) fn project(&mut self, x: &mut [Vec3], inv_mass: &[f32], sweep: Sweep) {
        let n = self.pairs.len();
        for kk in 0..n {
            let k = sweep.index(kk, n);
            let [a, b] = self.pairs[k];
            let (a, b) = (a as usize, b as usize);
            let (wa, wb) = (inv_mass[a], inv_mass[b]);
            let wsum = wa + wb;
            if wsum == 0.0 {
                continue;
            }
            let d = x[a] - x[b];
            let len = d.length();
            if len < 1e-9 {
                continue;
            }
            let n = d / len;
            let c = len - self.rest_m[k];
            let dl = sweep.correction(
                c,
                wsum,
                self.compliance[k],
                &mut self.lambda[k],
                self.pbd_stiffness,
            );
            x[a] += n * (wa * dl);
            x[b] -= n * (wb * dl);
        }
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
            g.compliance.push(inverse_or_zero(k));
        }
        g.lambda = vec![0.0; g.quads.len()];
        g
    }

    /// Zeroes the multipliers (every substep).
    pub(super) fn reset(&mut self) {
        self.lambda.iter_mut().for_each(|l| *l = 0.0);
    }

    /// ISPC paper eq. 4: dihedral angle of adjacent triangles (gradients after Bridson et al.
    /// 2003, as in Müller et al. 2007 Appendix A).
    pub(super) fn project(&mut self, x: &mut [Vec3], inv_mass: &[f32], sweep: Sweep) {
        let n = self.quads.len();
        for kk in 0..n {
            let k = sweep.index(kk, n);
            let q = &self.quads[k];
            let w = q.map(|i| inv_mass[i as usize]);
            let p = q.map(|i| x[i as usize]);
            let Some((phi, grads, wsum)) = dihedral(p, w) else {
                continue;
            };
            let c = phi - self.rest_rad[k];
            let dl = sweep.correction(
                c,
                wsum,
                self.compliance[k],
                &mut self.lambda[k],
                self.pbd_stiffness,
            );
            for j in 0..4 {
                x[q[j] as usize] += grads[j] * (w[j] * dl);
            }
        }
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
                inverse_or_zero(k)
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

    /// Zeroes the multipliers (every substep).
    pub(super) fn reset(&mut self) {
        self.lambda.iter_mut().for_each(|l| *l = 0.0);
    }

    /// `C = V − V₀` per tet, with a hard floor at `min_fraction` of the rest volume.
    pub(super) fn project(&mut self, x: &mut [Vec3], inv_mass: &[f32], sweep: Sweep) {
        let n = self.tets.len();
        for kk in 0..n {
            let k = sweep.index(kk, n);
            let t = &self.tets[k];
            let p = t.map(|i| x[i as usize]);
            let w = t.map(|i| inv_mass[i as usize]);
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
            let c = v - self.rest_m3[k];
            let floor = self.min_fraction * self.rest_m3[k];
            let dl = if v < floor {
                // Below the floor the constraint is hard (an inequality): a tet crushed by a
                // contact is pushed back before it can turn inside out.
                (floor - v) / wsum
            } else {
                sweep.correction(
                    c,
                    wsum,
                    self.compliance[k],
                    &mut self.lambda[k],
                    self.pbd_stiffness,
                )
            };
            for j in 0..4 {
                x[t[j] as usize] += grads[j] * (w[j] * dl);
            }
        }
    }

    /// Number of tets of non-positive volume over the positions `x`.
    pub(super) fn count_inverted(&self, x: &[Vec3]) -> usize {
        self.tets
            .iter()
            .filter(|t| tet_volume(t.map(|i| x[i as usize])) <= 0.0)
            .count()
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
    /// Scratch of [`Self::match_shapes`]: summed goal offsets and cluster counts per particle.
    accum: Vec<Vec3>,
    counts: Vec<f32>,
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

    /// Müller et al. 2005: goals `g = c + R q` from the polar rotation of `A_pq`; each particle
    /// moves by `α` of its mean goal offset over the clusters it is in.
    pub(super) fn match_shapes(&mut self, x: &mut [Vec3], inv_mass: &[f32], h: f32) {
        let alpha = 1.0 - (-self.rate_per_s.max(0.0) * h).exp();
        self.accum.clear();
        self.accum.resize(x.len(), Vec3::ZERO);
        self.counts.clear();
        self.counts.resize(x.len(), 0.0);
        for c in 0..self.offsets.len() - 1 {
            let (s, e) = (self.offsets[c] as usize, self.offsets[c + 1] as usize);
            let members = &self.members[s..e];
            let rest = &self.rest_rel[s..e];
            let cm = members.iter().map(|&i| x[i as usize]).sum::<Vec3>() / members.len() as f32;
            let mut a = glam::Mat3::ZERO;
            for (&i, q) in members.iter().zip(rest) {
                let p = x[i as usize] - cm;
                a += glam::Mat3::from_cols(p * q.x, p * q.y, p * q.z);
            }
            let r = extract_rotation(a, self.rotations[c]);
            self.rotations[c] = r;
            for (&i, q) in members.iter().zip(rest) {
                let goal = cm + r * *q;
                self.accum[i as usize] += goal - x[i as usize];
                self.counts[i as usize] += 1.0;
            }
        }
        for i in 0..x.len() {
            if self.counts[i] > 0.0 && inv_mass[i] > 0.0 {
                x[i] += self.accum[i] * (alpha / self.counts[i]);
            }
        }
    }
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
