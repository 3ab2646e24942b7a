//! Strain constraints on tets, the ISPC paper's tetrahedral baseline (its eqs. 5–11, after
//! Müller et al. 2014, "Strain based dynamics"): with `P = [p₁−p₀, p₂−p₀, p₃−p₀]` and the rest
//! `Q` likewise, `F = P Q⁻¹`, `S = FᵀF`; stretch constraints `S_ii − 1` (eq. 10, the rest
//! stretch `s_i = 1`) and shear constraints `S_ij`, i < j (eq. 11), each projected on its own.

use glam::{Mat3, Vec3};

use super::constraints::{inverse_or_zero, Sweep};

/// Stretch and shear constraints on a set of tets.
#[derive(Clone, Debug, Default)]
pub struct StrainGroup {
    /// Positively oriented tets.
    pub tets: Vec<[u32; 4]>,
    /// `Q⁻¹` per tet.
    inv_rest: Vec<Mat3>,
    /// XPBD compliance of a stretch constraint per tet, `1 / (E V₀)`.
    stretch_compliance: Vec<f32>,
    /// XPBD compliance of a shear constraint per tet, `1 / (μ V₀)`.
    shear_compliance: Vec<f32>,
    /// Plain-PBD stiffness per iteration.
    pub pbd_stiffness: f32,
    lambda: Vec<[f32; 6]>,
}

/// The six strain components, stretch first: (i, j).
const COMPONENTS: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

impl StrainGroup {
    /// Strain constraints on `tets` over rest positions `x` for Young's modulus `young_pa`
    /// and shear modulus `shear_pa`.
    pub fn new(
        tets: Vec<[u32; 4]>,
        x: &[Vec3],
        young_pa: f32,
        shear_pa: f32,
        pbd_stiffness: f32,
    ) -> Self {
        let mut g = StrainGroup {
            pbd_stiffness,
            ..Default::default()
        };
        for t in &tets {
            let p = t.map(|i| x[i as usize]);
            let q = Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
            let v0 = (q.determinant() / 6.0).abs();
            g.inv_rest.push(if q.determinant().abs() > 1e-18 {
                q.inverse()
            } else {
                Mat3::ZERO
            });
            g.stretch_compliance.push(inverse_or_zero(young_pa * v0));
            g.shear_compliance.push(inverse_or_zero(shear_pa * v0));
        }
        g.lambda = vec![[0.0; 6]; tets.len()];
        g.tets = tets;
        g
    }

    /// Number of tets.
    pub fn len(&self) -> usize {
        self.tets.len()
    }

    /// True if there are none.
    pub fn is_empty(&self) -> bool {
        self.tets.is_empty()
    }

    /// Number of tets of non-positive volume over the positions `x`.
    pub fn count_inverted(&self, x: &[Vec3]) -> usize {
        self.tets
            .iter()
            .filter(|t| super::tet_volume(t.map(|i| x[i as usize])) <= 0.0)
            .count()
    }

    /// Zeroes the multipliers (every substep).
    pub(super) fn reset(&mut self) {
        self.lambda.iter_mut().for_each(|l| *l = [0.0; 6]);
    }

    /// Eqs. 10–11, every component of every tet, Gauss–Seidel.
    pub(super) fn project(&mut self, x: &mut [Vec3], inv_mass: &[f32], sweep: Sweep) {
        let n = self.tets.len();
        for kk in 0..n {
            let k = sweep.index(kk, n);
            let t = self.tets[k];
            let qi = self.inv_rest[k];
            let w = t.map(|i| inv_mass[i as usize]);
            for (c, &(i, j)) in COMPONENTS.iter().enumerate() {
                let p = t.map(|v| x[v as usize]);
                let f = Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]) * qi;
                let (fi, fj) = (f.col(i), f.col(j));
                let value = fi.dot(fj) - if i == j { 1.0 } else { 0.0 };
                // ∂(fᵢ·fⱼ)/∂(p_{k+1} − p₀) = Q⁻¹[k][i] fⱼ + Q⁻¹[k][j] fᵢ (row k of Q⁻¹).
                let mut grads = [Vec3::ZERO; 4];
                for r in 0..3 {
                    let row = qi.row(r);
                    grads[r + 1] = fj * row[i] + fi * row[j];
                }
                grads[0] = -(grads[1] + grads[2] + grads[3]);
                let wsum: f32 = (0..4).map(|v| w[v] * grads[v].length_squared()).sum();
                if wsum < 1e-30 {
                    continue;
                }
                let compliance = if i == j {
                    self.stretch_compliance[k]
                } else {
                    self.shear_compliance[k]
                };
                let dl = sweep.correction(
                    value,
                    wsum,
                    compliance,
                    &mut self.lambda[k][c],
                    self.pbd_stiffness,
                );
                for v in 0..4 {
                    x[t[v] as usize] += grads[v] * (w[v] * dl);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The gradients are those of `S_ij`: a finite-difference check on a sheared tet.
    #[test]
    fn strain_gradients_match_finite_differences() {
        let rest = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let g = StrainGroup::new(vec![[0, 1, 2, 3]], &rest, 1.0, 1.0, 1.0);
        let x = [
            Vec3::new(0.01, -0.02, 0.0),
            Vec3::new(1.1, 0.1, 0.0),
            Vec3::new(0.2, 0.9, 0.1),
            Vec3::new(0.0, 0.1, 1.2),
        ];
        let s = |x: &[Vec3; 4], i: usize, j: usize| {
            let f = Mat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]) * g.inv_rest[0];
            f.col(i).dot(f.col(j))
        };
        for &(i, j) in &COMPONENTS {
            let f = Mat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]) * g.inv_rest[0];
            let (fi, fj) = (f.col(i), f.col(j));
            let mut grads = [Vec3::ZERO; 4];
            for r in 0..3 {
                let row = g.inv_rest[0].row(r);
                grads[r + 1] = fj * row[i] + fi * row[j];
            }
            grads[0] = -(grads[1] + grads[2] + grads[3]);
            for v in 0..4 {
                for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                    let mut y = x;
                    y[v] += axis * 1e-3;
                    let fd = (s(&y, i, j) - s(&x, i, j)) / 1e-3;
                    let an = grads[v].dot(axis);
                    assert!((fd - an).abs() < 5e-3, "S{i}{j} node {v}: {fd} vs {an}");
                }
            }
        }
    }
}
