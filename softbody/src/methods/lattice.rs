//! A well-shaped tet mesh for the accuracy reference: a cubic lattice over a closed surface,
//! each cube split into the six congruent tets of the Kuhn (Freudenthal) subdivision — edges
//! 1, √2 and √3 cells, dihedral angles 45°–90°, no slivers, conforming across cubes — with
//! each tet weighted by the fraction of its volume inside the surface. The surface is embedded
//! in the tets as in [`crate::methods::tets`].
//!
//! Why weights: a plain cover is larger than the body by up to a cell all round, so its
//! stiffness and contact envelope converge only as fast as the cells shrink; weighting each
//! tet's mass and stiffness by its inside fraction (a fictitious-domain discretisation) makes
//! a coarse lattice model the body's own volume, and refinement converges faster.

use std::collections::{HashMap, HashSet};

use glam::Vec3;

use crate::methods::tets::{embed, TetMesh};
use crate::SoftBodyError;

/// Sub-samples per cell and axis for the inside fractions.
const SUBSAMPLES: usize = 4;
/// Smallest weight of a kept tet: a tet holding a surface vertex but (by the samples) nothing
/// of the inside still carries that vertex.
pub const MIN_WEIGHT: f32 = 0.02;
/// Largest lattice, in cells: a bound on memory for a hostile size.
const MAX_CELLS: usize = 4_000_000;
/// Where the sample columns sit in a sub-cell, per axis (x, y, z): off the centre by
/// different amounts, so no column runs exactly through a vertex or an edge of a regular mesh
/// and no sample lies on a face between two Kuhn tets (`u_a = u_b`).
const SAMPLE_AT: [f32; 3] = [0.513, 0.71, 0.529];

/// A Kuhn lattice over a closed surface and the inside fraction of each of its tets.
#[derive(Clone, Debug)]
pub struct LatticeTets {
    /// Nodes, tets (positively oriented) and the surface's embedding.
    pub mesh: TetMesh,
    /// Fraction of each tet's volume inside the surface, in [`MIN_WEIGHT`], 1].
    pub inside_fraction: Vec<f32>,
}

impl LatticeTets {
    /// The nodes deep in the material: every tet around them is (by the samples) inside.
    pub fn material_nodes(&self) -> Vec<u32> {
        let mut full = vec![true; self.mesh.nodes.len()];
        for (t, w) in self.mesh.tets.iter().zip(&self.inside_fraction) {
            if *w < 0.99 {
                t.iter().for_each(|&i| full[i as usize] = false);
            }
        }
        (0..full.len() as u32)
            .filter(|&i| full[i as usize])
            .collect()
    }
}

/// The six Kuhn tets of the unit cube as corner indices (bit 0 = x, 1 = y, 2 = z): the tet of
/// the axis order `(a, b, c)` holds the points with `u_a ≥ u_b ≥ u_c`.
const KUHN: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

fn kuhn_corners(order: [usize; 3]) -> [usize; 4] {
    let c1 = 1 << order[0];
    let c2 = c1 | (1 << order[1]);
    [0, c1, c2, 7]
}

/// Which Kuhn tet of [`KUHN`] holds the local point `u` of a cube.
fn kuhn_index(u: [f32; 3]) -> usize {
    KUHN.iter()
        .position(|o| u[o[0]] >= u[o[1]] && u[o[1]] >= u[o[2]])
        .unwrap_or(0)
}

/// The surface's crossings of vertical lines (along y) through a grid of `(x, z)` columns: the
/// inside of the closed surface is between consecutive crossings (even-odd rule).
struct Columns {
    nx: usize,
    nz: usize,
    /// Sorted crossing heights per column.
    crossings: Vec<Vec<f32>>,
}

impl Columns {
    fn new(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        origin: Vec3,
        step_m: f32,
        n: [usize; 2],
    ) -> Self {
        let [nx, nz] = n;
        let mut crossings = vec![Vec::new(); nx * nz];
        let col = |i: usize, k: usize| {
            (
                origin.x + (i as f32 + SAMPLE_AT[0]) * step_m,
                origin.z + (k as f32 + SAMPLE_AT[2]) * step_m,
            )
        };
        for t in triangles {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            let lo = a.min(b).min(c);
            let hi = a.max(b).max(c);
            let i0 = (((lo.x - origin.x) / step_m - 0.5).floor().max(0.0)) as usize;
            let i1 = ((((hi.x - origin.x) / step_m - 0.5).ceil()).max(0.0) as usize).min(nx - 1);
            let k0 = (((lo.z - origin.z) / step_m - 0.5).floor().max(0.0)) as usize;
            let k1 = ((((hi.z - origin.z) / step_m - 0.5).ceil()).max(0.0) as usize).min(nz - 1);
            for i in i0..=i1 {
                for k in k0..=k1 {
                    let (x, z) = col(i, k);
                    // Barycentric coordinates of (x, z) in the triangle projected on xz.
                    let d = (b.x - a.x) * (c.z - a.z) - (c.x - a.x) * (b.z - a.z);
                    if d.abs() < 1e-20 {
                        continue;
                    }
                    let l1 = ((x - a.x) * (c.z - a.z) - (c.x - a.x) * (z - a.z)) / d;
                    let l2 = ((b.x - a.x) * (z - a.z) - (x - a.x) * (b.z - a.z)) / d;
                    let l0 = 1.0 - l1 - l2;
                    if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                        continue;
                    }
                    crossings[i * nz + k].push(a.y * l0 + b.y * l1 + c.y * l2);
                }
            }
        }
        for c in &mut crossings {
            c.sort_unstable_by(f32::total_cmp);
        }
        Self { nx, nz, crossings }
    }

    /// True if height `y` on column `(i, k)` is inside the surface.
    fn inside(&self, i: usize, k: usize, y: f32) -> bool {
        if i >= self.nx || k >= self.nz {
            return false;
        }
        let c = &self.crossings[i * self.nz + k];
        c.partition_point(|&h| h < y) % 2 == 1
    }
}

/// Fills the closed, outward mesh `(positions, triangles)` with a Kuhn lattice of cells of
/// `cell_m`, keeps the tets that hold some of the inside or a surface vertex, weights them by
/// their inside fraction and embeds the surface. Errors on a bad size or an empty result.
pub fn lattice_tets(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    cell_m: f32,
) -> Result<LatticeTets, SoftBodyError> {
    if !(cell_m.is_finite() && cell_m > 0.0) || positions.is_empty() {
        return Err(SoftBodyError::Config(format!(
            "lattice cell size {cell_m} must be a positive length over a non-empty mesh"
        )));
    }
    let (lo, hi) = crate::mesh::bounds(positions);
    // One empty cell of margin all round, so every surface vertex is strictly inside the grid.
    let origin = lo - Vec3::splat(cell_m);
    let dims = ((hi - origin) / cell_m).ceil() + Vec3::ONE;
    let n = [dims.x as usize, dims.y as usize, dims.z as usize];
    if n.iter().product::<usize>() > MAX_CELLS {
        return Err(SoftBodyError::Config(format!(
            "lattice of {n:?} cells at {cell_m} m exceeds {MAX_CELLS} cells"
        )));
    }
    let s = SUBSAMPLES;
    let step = cell_m / s as f32;
    let columns = Columns::new(positions, triangles, origin, step, [n[0] * s, n[2] * s]);
    let off = SAMPLE_AT;
    let mut counts: HashMap<[usize; 3], [u16; 6]> = HashMap::new();
    for cx in 0..n[0] {
        for cz in 0..n[2] {
            for si in 0..s {
                for sk in 0..s {
                    let (ci, ck) = (cx * s + si, cz * s + sk);
                    if columns.crossings[ci * columns.nz + ck].is_empty() {
                        continue;
                    }
                    for cy in 0..n[1] {
                        for sj in 0..s {
                            let v = (sj as f32 + off[1]) / s as f32;
                            let y = origin.y + (cy as f32 + v) * cell_m;
                            if !columns.inside(ci, ck, y) {
                                continue;
                            }
                            let u = (si as f32 + off[0]) / s as f32;
                            let w = (sk as f32 + off[2]) / s as f32;
                            counts.entry([cx, cy, cz]).or_insert([0; 6])[kuhn_index([u, v, w])] +=
                                1;
                        }
                    }
                }
            }
        }
    }
    // How many of a full cube's samples fall in each Kuhn tet: the grid does not split them
    // evenly, and a fraction is of the tet's own samples.
    let mut per_tet = [0u16; 6];
    for si in 0..s {
        for sj in 0..s {
            for sk in 0..s {
                let u = [si, sj, sk]
                    .iter()
                    .zip(off)
                    .map(|(&i, o)| (i as f32 + o) / s as f32)
                    .collect::<Vec<f32>>();
                per_tet[kuhn_index([u[0], u[1], u[2]])] += 1;
            }
        }
    }
    let cell_of = |p: Vec3| {
        let q = ((p - origin) / cell_m).floor();
        [q.x as usize, q.y as usize, q.z as usize]
    };
    // Tets holding a surface vertex are kept whatever their samples say.
    let mut holds_vertex: HashSet<([usize; 3], usize)> = HashSet::new();
    for &p in positions {
        let c = cell_of(p);
        let base = origin + Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) * cell_m;
        let u = (p - base) / cell_m;
        holds_vertex.insert((c, kuhn_index([u.x, u.y, u.z])));
    }
    let mut keys: Vec<([usize; 3], usize, f32)> = Vec::new();
    for (&c, cnt) in &counts {
        for (t, &k) in cnt.iter().enumerate() {
            if k > 0 || holds_vertex.contains(&(c, t)) {
                let fraction = k as f32 / per_tet[t].max(1) as f32;
                keys.push((c, t, fraction.clamp(MIN_WEIGHT, 1.0)));
            }
        }
    }
    for &(c, t) in &holds_vertex {
        if !counts.contains_key(&c) {
            keys.push((c, t, MIN_WEIGHT));
        }
    }
    // A fixed order (the hash map's is not): by cell, then tet.
    keys.sort_unstable_by_key(|&(c, t, _)| (c[0], c[1], c[2], t));
    keys.dedup_by_key(|k| (k.0, k.1));
    let mut node_of: HashMap<[usize; 3], u32> = HashMap::new();
    let mut nodes: Vec<Vec3> = Vec::new();
    let mut tets = Vec::with_capacity(keys.len());
    let mut inside_fraction = Vec::with_capacity(keys.len());
    for (c, t, w) in keys {
        let corners = kuhn_corners(KUHN[t]).map(|bits| {
            let g = [
                c[0] + (bits & 1),
                c[1] + ((bits >> 1) & 1),
                c[2] + ((bits >> 2) & 1),
            ];
            *node_of.entry(g).or_insert_with(|| {
                nodes.push(origin + Vec3::new(g[0] as f32, g[1] as f32, g[2] as f32) * cell_m);
                (nodes.len() - 1) as u32
            })
        });
        let mut tet = corners;
        if crate::methods::pbd::tet_volume(tet.map(|i| nodes[i as usize])) < 0.0 {
            tet.swap(2, 3);
        }
        tets.push(tet);
        inside_fraction.push(w);
    }
    if tets.is_empty() {
        return Err(SoftBodyError::Config(format!(
            "lattice: the surface encloses nothing at cell size {cell_m} (open mesh?)"
        )));
    }
    let embedding = embed(&nodes, &tets, positions, cell_m);
    Ok(LatticeTets {
        mesh: TetMesh {
            nodes,
            tets,
            embedding,
        },
        inside_fraction,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The six Kuhn tets fill the cube: their volumes sum to one cell, none is degenerate.
    #[test]
    fn kuhn_tets_fill_the_cube() {
        let corner =
            |b: usize| Vec3::new((b & 1) as f32, ((b >> 1) & 1) as f32, ((b >> 2) & 1) as f32);
        let vols: Vec<f32> = KUHN
            .iter()
            .map(|&o| crate::methods::pbd::tet_volume(kuhn_corners(o).map(corner)).abs())
            .collect();
        assert!(
            vols.iter().all(|v| (v - 1.0 / 6.0).abs() < 1e-6),
            "{vols:?}"
        );
    }
}
