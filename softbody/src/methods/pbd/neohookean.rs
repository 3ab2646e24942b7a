//! Stable Neo-Hookean tets as XPBD constraints (Macklin & Müller 2021, "A Constraint-based
//! Formulation of Stable Neo-Hookean Materials"): per tet a deviatoric constraint
//! `C_D = ‖F‖_F` with compliance `1 / (μ V₀)` and a hydrostatic one `C_H = det F − γ`,
//! `γ = 1 + μ / λ`, with compliance `1 / (λ V₀)`. Their energies sum to the stable Neo-Hookean
//! energy `μ/2 (I_C − 3) + λ/2 (J − γ)²` (Smith et al. 2018), whose minimum is the rest shape
//! and whose volume term is defined and restoring for an inverted tet (`det F < 0`), unlike a
//! log barrier: a crushed tet is pushed back out instead of blowing up.
//!
//! Linearised at rest this energy is `μ tr(ε²) + (λ − μ)/2 (tr ε)²`, so the constructor takes
//! the Lamé parameters of the small-strain material and uses `λ + μ` for the hydrostatic term:
//! small deformations then match Young's modulus and Poisson's ratio exactly.

use glam::{Mat3, Vec3};

use super::constraints::{inverse_or_zero, Sweep};

/// Smallest volume ratio `det F` a tet may reach: below it a hard (inequality) constraint
/// pushes it back, so no tet turns inside out whatever a kinematic prop forces on it. Far
/// below any compression the material reaches by itself (its bulk modulus keeps `det F` near 1).
pub const MIN_VOLUME_RATIO: f32 = 0.2;
/// Most sweeps of the floor per call.
const FLOOR_SWEEPS: usize = 16;

/// Stable Neo-Hookean constraints on a set of tets, each weighted (stiffness and, in the
/// builder, mass) by the fraction of it that is material.
#[derive(Clone, Debug, Default)]
pub struct NeoHookeanGroup {
    /// Positively oriented tets.
    pub tets: Vec<[u32; 4]>,
    /// Rest volumes, m³.
    pub rest_m3: Vec<f32>,
    /// Material fraction of each tet, (0, 1].
    pub weight: Vec<f32>,
    /// Shear modulus μ, Pa.
    pub mu_pa: f32,
    /// Lamé's first parameter of the small-strain material, Pa.
    pub lambda_pa: f32,
    /// The hard floor: no tet below this fraction of its rest volume (`det F`);
    /// `MIN_VOLUME_RATIO` from [`new`](Self::new), 0 turns it off.
    pub min_volume_ratio: f32,
    inv_rest: Vec<Mat3>,
    lambda_dev: Vec<f32>,
    lambda_vol: Vec<f32>,
    floor_hits: u64,
    floor_hits_material: u64,
}

/// Elastic energy of one tet, J per m³ of rest volume, zero at rest.
fn energy_density(f: Mat3, mu: f32, lambda_snh: f32) -> f32 {
    let gamma = 1.0 + mu / lambda_snh;
    let ic = f.x_axis.length_squared() + f.y_axis.length_squared() + f.z_axis.length_squared();
    let j = f.determinant();
    0.5 * mu * (ic - 3.0) + 0.5 * lambda_snh * ((j - gamma).powi(2) - (1.0 - gamma).powi(2))
}

/// `∂ det F / ∂F`: the cofactor matrix, columns `f₁×f₂, f₂×f₀, f₀×f₁`.
fn det_gradient(f: Mat3) -> Mat3 {
    Mat3::from_cols(
        f.y_axis.cross(f.z_axis),
        f.z_axis.cross(f.x_axis),
        f.x_axis.cross(f.y_axis),
    )
}

impl NeoHookeanGroup {
    /// Constraints on `tets` over rest positions `x`, for Young's modulus `young_pa` and bulk
    /// modulus `bulk_pa` (Poisson's ratio follows), each tet weighted by `weight` (1 if absent).
    pub fn new(
        tets: Vec<[u32; 4]>,
        x: &[Vec3],
        weight: &[f32],
        young_pa: f32,
        bulk_pa: f32,
    ) -> Self {
        // E and K give ν = (3K − E) / 6K, μ = E / 2(1 + ν), λ = K − 2μ/3.
        let nu = ((3.0 * bulk_pa - young_pa) / (6.0 * bulk_pa)).clamp(0.0, 0.49);
        let mu_pa = young_pa / (2.0 * (1.0 + nu));
        let lambda_pa = (bulk_pa - 2.0 * mu_pa / 3.0).max(0.0);
        let mut rest_m3 = Vec::with_capacity(tets.len());
        let mut inv_rest = Vec::with_capacity(tets.len());
        for t in &tets {
            let p = t.map(|i| x[i as usize]);
            let dm = Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
            rest_m3.push(dm.determinant() / 6.0);
            inv_rest.push(if dm.determinant().abs() > 1e-18 {
                dm.inverse()
            } else {
                Mat3::ZERO
            });
        }
        let n = tets.len();
        Self {
            tets,
            rest_m3,
            weight: (0..n)
                .map(|i| weight.get(i).copied().unwrap_or(1.0))
                .collect(),
            mu_pa,
            lambda_pa,
            min_volume_ratio: MIN_VOLUME_RATIO,
            inv_rest,
            lambda_dev: vec![0.0; n],
            lambda_vol: vec![0.0; n],
            floor_hits: 0,
            floor_hits_material: 0,
        }
    }

    /// How often a tet was pushed back up to `MIN_VOLUME_RATIO` (the floor engaged), in
    /// all tets and in tets at least half inside the surface (the rest is the fringe of
    /// fictitious material around it, soft in proportion, which contacts crush most).
    pub fn floor_hits(&self) -> (u64, u64) {
        (self.floor_hits, self.floor_hits_material)
    }

    /// The hydrostatic stiffness of the stable Neo-Hookean energy (see the module doc).
    fn lambda_snh(&self) -> f32 {
        self.lambda_pa + self.mu_pa
    }

    /// Number of tets.
    pub fn len(&self) -> usize {
        self.tets.len()
    }

    /// True if there are none.
    pub fn is_empty(&self) -> bool {
        self.tets.is_empty()
    }

    /// Zeroes the multipliers (every substep).
    pub(super) fn reset(&mut self) {
        self.lambda_dev.iter_mut().for_each(|l| *l = 0.0);
        self.lambda_vol.iter_mut().for_each(|l| *l = 0.0);
    }

    fn deformation(&self, k: usize, x: &[Vec3]) -> Mat3 {
        let p = self.tets[k].map(|i| x[i as usize]);
        Mat3::from_cols(p[1] - p[0], p[2] - p[0], p[3] - p[0]) * self.inv_rest[k]
    }

    /// `∂C/∂x` of the four nodes of tet `k` for a constraint whose gradient in F is `dc_df`:
    /// nodes 1–3 are the columns of `∂C/∂F · D_m⁻ᵀ`, node 0 minus their sum.
    fn node_gradients(&self, k: usize, dc_df: Mat3) -> [Vec3; 4] {
        let g = dc_df * self.inv_rest[k].transpose();
        [
            -(g.x_axis + g.y_axis + g.z_axis),
            g.x_axis,
            g.y_axis,
            g.z_axis,
        ]
    }

    /// Both constraints of every tet, solved together per tet (Macklin & Müller 2021 §4: solved
    /// one after the other, the deviatoric constraint pulls `‖F‖` towards 0 and the
    /// hydrostatic one pushes back, and the rest shape is a fixed point only once Gauss–Seidel
    /// has converged; solved as one 2 × 2 system it is one at every iteration). Always the XPBD
    /// form: the energy is the material.
    pub(super) fn project(&mut self, x: &mut [Vec3], inv_mass: &[f32], sweep: Sweep) {
        let sweep = sweep.xpbd();
        let n = self.tets.len();
        let (mu, lambda_snh) = (self.mu_pa, self.lambda_snh());
        let gamma = 1.0 + mu / lambda_snh;
        for kk in 0..n {
            let k = sweep.index(kk, n);
            let t = self.tets[k];
            let v0 = self.rest_m3[k] * self.weight[k];
            let f = self.deformation(k, x);
            let r =
                (f.x_axis.length_squared() + f.y_axis.length_squared() + f.z_axis.length_squared())
                    .sqrt();
            if r < 1e-9 {
                continue;
            }
            let gd = self.node_gradients(k, f * (1.0 / r));
            let gh = self.node_gradients(k, det_gradient(f));
            let w = t.map(|i| inv_mass[i as usize]);
            // The 2 × 2 system in f64: at rest the two gradients are parallel and its
            // determinant is a small difference of large products.
            let (mut a11, mut a12, mut a22) = (0.0f64, 0.0f64, 0.0f64);
            for j in 0..4 {
                let wj = w[j] as f64;
                a11 += wj * gd[j].length_squared() as f64;
                a12 += wj * gd[j].dot(gh[j]) as f64;
                a22 += wj * gh[j].length_squared() as f64;
            }
            let ad = sweep.scaled_compliance(inverse_or_zero(mu * v0)) as f64;
            let ah = sweep.scaled_compliance(inverse_or_zero(lambda_snh * v0)) as f64;
            a11 += ad;
            a22 += ah;
            let det = a11 * a22 - a12 * a12;
            if det.is_nan() || det.abs() <= 1e-300 {
                continue;
            }
            let b1 = -(r as f64) - ad * self.lambda_dev[k] as f64;
            let b2 = -((f.determinant() - gamma) as f64) - ah * self.lambda_vol[k] as f64;
            let dld = (b1 * a22 - a12 * b2) / det;
            let dlh = (a11 * b2 - a12 * b1) / det;
            if !(dld.is_finite() && dlh.is_finite()) {
                continue;
            }
            self.lambda_dev[k] += dld as f32;
            self.lambda_vol[k] += dlh as f32;
            for j in 0..4 {
                x[t[j] as usize] += (gd[j] * dld as f32 + gh[j] * dlh as f32) * w[j];
            }
        }
        self.enforce_floor(x, inv_mass);
    }

    /// The hard floor `det F ≥ min_volume_ratio` on every tet (a rigid constraint, projected
    /// fully: an inequality has no multiplier to carry).
    pub(super) fn enforce_floor(&mut self, x: &mut [Vec3], inv_mass: &[f32]) {
        let floor = self.min_volume_ratio;
        if floor <= 0.0 {
            return;
        }
        // Lifting one tet may push a neighbour under: sweep until none is (bounded).
        for sweep in 0..FLOOR_SWEEPS {
            let mut below = false;
            for k in 0..self.tets.len() {
                // det F is cubic in the positions: a linearised step may fall short, so a few.
                for pass in 0..4 {
                    let f = self.deformation(k, x);
                    let j = f.determinant();
                    if j >= floor {
                        break;
                    }
                    below = true;
                    if sweep == 0 && pass == 0 {
                        self.floor_hits += 1;
                        if self.weight[k] >= 0.5 {
                            self.floor_hits_material += 1;
                        }
                    }
                    let t = self.tets[k];
                    let g = self.node_gradients(k, det_gradient(f));
                    let w = t.map(|i| inv_mass[i as usize]);
                    let wsum: f32 = (0..4).map(|i| w[i] * g[i].length_squared()).sum();
                    if wsum < 1e-30 {
                        break;
                    }
                    let dl = (floor - j) / wsum;
                    for i in 0..4 {
                        x[t[i] as usize] += g[i] * (w[i] * dl);
                    }
                }
            }
            if !below {
                break;
            }
        }
    }

    /// Elastic energy over the positions `x`, J (zero at rest).
    pub fn energy_j(&self, x: &[Vec3]) -> f32 {
        let (mu, lambda_snh) = (self.mu_pa, self.lambda_snh());
        (0..self.tets.len())
            .map(|k| {
                energy_density(self.deformation(k, x), mu, lambda_snh)
                    * self.rest_m3[k]
                    * self.weight[k]
            })
            .sum()
    }

    /// The elastic force on every particle over the positions `x`, N: `f = −∂E/∂x` (the
    /// first Piola–Kirchhoff stress `P = μ F + λ' (J − γ) cof F` of each tet, `−V₀ P D_m⁻ᵀ` on
    /// its nodes). `out` is cleared and sized to `x`. At static equilibrium the forces on held
    /// particles are what holds them: a plate's reaction.
    pub fn elastic_forces(&self, x: &[Vec3], out: &mut Vec<Vec3>) {
        out.clear();
        out.resize(x.len(), Vec3::ZERO);
        let (mu, lambda_snh) = (self.mu_pa, self.lambda_snh());
        let gamma = 1.0 + mu / lambda_snh;
        for (k, t) in self.tets.iter().enumerate() {
            let f = self.deformation(k, x);
            let p = f * mu + det_gradient(f) * (lambda_snh * (f.determinant() - gamma));
            let g = self.node_gradients(k, p);
            let v0 = self.rest_m3[k] * self.weight[k];
            for (j, &node) in t.iter().enumerate() {
                out[node as usize] -= g[j] * v0;
            }
        }
    }

    /// Number of tets of non-positive volume over the positions `x`.
    pub fn count_inverted(&self, x: &[Vec3]) -> usize {
        (0..self.tets.len())
            .filter(|&k| self.deformation(k, x).determinant() <= 0.0)
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The energy is zero and stationary at rest (the rest shape is the minimum), invariant
    /// under rotation, and its small-strain stiffness is the material's: a uniaxial stretch of
    /// ε with free sides costs E ε² / 2 per m³ to first order, pure shear μ γ².
    #[test]
    fn energy_is_the_small_strain_material_at_rest() {
        let (e, k) = (2.0e5f32, 4.0e5f32);
        let x = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let g = NeoHookeanGroup::new(vec![[0, 1, 2, 3]], &x, &[1.0], e, k);
        let (mu, l) = (g.mu_pa, g.lambda_snh());
        assert!(energy_density(Mat3::IDENTITY, mu, l).abs() < 1e-3);
        let rot = Mat3::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        assert!(
            energy_density(rot, mu, l).abs() < 0.5,
            "{}",
            energy_density(rot, mu, l)
        );
        let eps = 1e-2f32;
        let shear = Mat3::from_cols(Vec3::X, Vec3::new(eps, 1.0, 0.0), Vec3::Z);
        // Engineering shear eps: μ eps² / 2 per m³.
        let want = 0.5 * mu * eps * eps;
        let got = energy_density(shear, mu, l);
        assert!((got - want).abs() < 0.05 * want, "shear {got} vs {want}");
        // Hydrostatic: F = (1 + e) I costs 9/2 K e² per m³.
        let vol = Mat3::IDENTITY * (1.0 + eps);
        let want = 4.5 * k * eps * eps;
        let got = energy_density(vol, mu, l);
        assert!((got - want).abs() < 0.05 * want, "volume {got} vs {want}");
    }

    /// The elastic forces are minus the energy's gradient (central differences).
    #[test]
    fn elastic_forces_are_minus_the_energy_gradient() {
        let x0 = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE];
        let tets = vec![[0, 1, 2, 3], [1, 4, 2, 3]];
        let g = NeoHookeanGroup::new(tets, &x0, &[1.0, 0.7], 1.0e4, 3.0e4);
        let x: Vec<Vec3> = x0
            .iter()
            .enumerate()
            .map(|(i, p)| *p * 1.1 + Vec3::new(0.05 * i as f32, -0.03, 0.02 * (i % 2) as f32))
            .collect();
        let mut f = Vec::new();
        g.elastic_forces(&x, &mut f);
        let h = 1e-3f32;
        for node in 0..x.len() {
            for axis in 0..3 {
                let mut a = x.clone();
                let mut b = x.clone();
                a[node][axis] += h;
                b[node][axis] -= h;
                let grad = (g.energy_j(&a) - g.energy_j(&b)) / (2.0 * h);
                let got = -f[node][axis];
                assert!(
                    (got - grad).abs() < 2e-3 * grad.abs().max(100.0),
                    "node {node} axis {axis}: force {got} vs gradient {grad}"
                );
            }
        }
    }
}
