//! How a body's surface follows its particles: a surface vertex is a particle, or a point
//! embedded in a tet over the particles (barycentric weights).

use glam::Vec3;

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

impl SurfaceMap {
    /// Number of surface vertices over `particles` particles.
    pub(super) fn vertex_count(&self, particles: usize) -> usize {
        match self {
            SurfaceMap::Direct => particles,
            SurfaceMap::Embedded(e) => e.nodes.len(),
        }
    }

    /// Writes the surface of the particle positions `x` into `surface`.
    pub(super) fn update(&self, x: &[Vec3], surface: &mut Vec<Vec3>) {
        match self {
            SurfaceMap::Direct => {
                surface.clear();
                surface.extend_from_slice(x);
            }
            SurfaceMap::Embedded(e) => {
                surface.resize(e.nodes.len(), Vec3::ZERO);
                for (s, (n, w)) in surface.iter_mut().zip(e.nodes.iter().zip(&e.weights)) {
                    *s = (0..4).map(|k| x[n[k] as usize] * w[k]).sum();
                }
            }
        }
    }

    /// Surface point `s` over the positions `x` and over the previous positions `prev`.
    pub(super) fn point(&self, x: &[Vec3], prev: &[Vec3], s: usize) -> (Vec3, Vec3) {
        match self {
            SurfaceMap::Direct => (x[s], prev[s]),
            SurfaceMap::Embedded(e) => {
                let (nodes, w) = (e.nodes[s], e.weights[s]);
                (
                    (0..4).map(|k| x[nodes[k] as usize] * w[k]).sum(),
                    (0..4).map(|k| prev[nodes[k] as usize] * w[k]).sum(),
                )
            }
        }
    }

    /// The inverse of the mass a push on surface point `s` moves (see [`Self::move_point`]):
    /// the particle's, or `Σ w_k² / m_k` over an embedded point's tet nodes.
    pub(super) fn point_inverse_mass(&self, inv_mass: &[f32], s: usize) -> f32 {
        match self {
            SurfaceMap::Direct => inv_mass[s],
            SurfaceMap::Embedded(e) => {
                let (nodes, w) = (e.nodes[s], e.weights[s]);
                (0..4)
                    .map(|k| inv_mass[nodes[k] as usize] * w[k] * w[k])
                    .sum()
            }
        }
    }

    /// Moves surface point `s` by `delta` (an embedded point through its tet's nodes, each in
    /// proportion to its weight and inverse mass, so the point moves by exactly `delta`).
    pub(super) fn move_point(&self, x: &mut [Vec3], inv_mass: &[f32], s: usize, delta: Vec3) {
        match self {
            SurfaceMap::Direct => {
                if inv_mass[s] > 0.0 {
                    x[s] += delta;
                }
            }
            SurfaceMap::Embedded(e) => {
                let (nodes, w) = (e.nodes[s], e.weights[s]);
                let denom: f32 = (0..4)
                    .map(|k| inv_mass[nodes[k] as usize] * w[k] * w[k])
                    .sum();
                if denom < 1e-12 {
                    return;
                }
                for k in 0..4 {
                    let n = nodes[k] as usize;
                    x[n] += delta * (inv_mass[n] * w[k] / denom);
                }
            }
        }
    }
}
