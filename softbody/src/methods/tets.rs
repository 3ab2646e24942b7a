//! The tetrahedral reference: parry's `volume_mesh` (a lattice cover containing the closed
//! surface, Apache-2.0 like the rest of parry; no TetGen, so the build stays permissive), and
//! the barycentric embedding of the surface in it.

use std::collections::HashMap;

use glam::{Mat3, Vec3};
use parry3d::transformation::{volume_mesh, VolumeMeshParameters};

use crate::methods::pbd::{tet_volume, Embedding};
use crate::SoftBodyError;

/// Tets filling a closed surface, and where the surface's vertices sit in them.
#[derive(Clone, Debug)]
pub struct TetMesh {
    /// Tet nodes, metres.
    pub nodes: Vec<Vec3>,
    /// Positively oriented tets.
    pub tets: Vec<[u32; 4]>,
    /// Each surface vertex's tet and barycentric weights.
    pub embedding: Embedding,
}

/// Fills the closed, outward mesh `(positions, triangles)` with tets of about `cell_m` and
/// embeds its vertices. Errors if the mesh encloses nothing at that size.
pub fn tetrahedralize(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    cell_m: f32,
) -> Result<TetMesh, SoftBodyError> {
    if !(cell_m.is_finite() && cell_m > 0.0) {
        return Err(SoftBodyError::Config(format!(
            "tet cell size {cell_m} must be a positive length"
        )));
    }
    let mut params = VolumeMeshParameters::new(cell_m);
    // Shrink-wrap the staircase towards the surface: the embedded surface then sits near
    // the cover's boundary instead of up to a cell inside it.
    params.cover_smoothing = 4;
    let vm = volume_mesh(positions, triangles, &params).ok_or_else(|| {
        SoftBodyError::Config(format!(
            "volume_mesh: the surface encloses nothing at cell size {cell_m} (open mesh?)"
        ))
    })?;
    let mut tets = vm.cells;
    if tets.is_empty() {
        return Err(SoftBodyError::Config(format!(
            "volume_mesh: no tets at cell size {cell_m}"
        )));
    }
    for t in &mut tets {
        if tet_volume(t.map(|i| vm.vertices[i as usize])) < 0.0 {
            t.swap(2, 3);
        }
    }
    let embedding = embed(&vm.vertices, &tets, positions, cell_m);
    Ok(TetMesh {
        nodes: vm.vertices,
        tets,
        embedding,
    })
}

/// Barycentric weights of `p` in tet `t`, or `None` if degenerate.
pub fn barycentric(nodes: &[Vec3], t: [u32; 4], p: Vec3) -> Option<[f32; 4]> {
    let [a, b, c, d] = t.map(|i| nodes[i as usize]);
    let m = Mat3::from_cols(b - a, c - a, d - a);
    if m.determinant().abs() < 1e-18 {
        return None;
    }
    let l = m.inverse() * (p - a);
    Some([1.0 - l.x - l.y - l.z, l.x, l.y, l.z])
}

/// Embeds `points` in the tets: the tet containing each point (or, if none does, the one it is
/// least outside of among those near it).
pub fn embed(nodes: &[Vec3], tets: &[[u32; 4]], points: &[Vec3], cell_m: f32) -> Embedding {
    let inv = 1.0 / cell_m.max(1e-6);
    let key = |p: Vec3| {
        let q = (p * inv).floor();
        [q.x as i32, q.y as i32, q.z as i32]
    };
    let mut grid: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    for (ti, t) in tets.iter().enumerate() {
        let ps = t.map(|i| nodes[i as usize]);
        let lo = ps.iter().fold(Vec3::splat(f32::MAX), |a, p| a.min(*p));
        let hi = ps.iter().fold(Vec3::splat(f32::MIN), |a, p| a.max(*p));
        let (kl, kh) = (key(lo), key(hi));
        for x in kl[0]..=kh[0] {
            for y in kl[1]..=kh[1] {
                for z in kl[2]..=kh[2] {
                    grid.entry([x, y, z]).or_default().push(ti as u32);
                }
            }
        }
    }
    let mut out = Embedding::default();
    for &p in points {
        let k = key(p);
        let mut best: Option<([u32; 4], [f32; 4], f32)> = None;
        let consider = |ti: u32, best: &mut Option<([u32; 4], [f32; 4], f32)>| {
            let t = tets[ti as usize];
            if let Some(w) = barycentric(nodes, t, p) {
                let m = w.iter().copied().fold(f32::MAX, f32::min);
                if best.is_none_or(|b| m > b.2) {
                    *best = Some((t, w, m));
                }
            }
        };
        for r in 0i32..3 {
            for x in -r..=r {
                for y in -r..=r {
                    for z in -r..=r {
                        if x.abs().max(y.abs()).max(z.abs()) != r {
                            continue;
                        }
                        if let Some(list) = grid.get(&[k[0] + x, k[1] + y, k[2] + z]) {
                            list.iter().for_each(|&ti| consider(ti, &mut best));
                        }
                    }
                }
            }
            if best.is_some_and(|b| b.2 >= -1e-4) {
                break;
            }
        }
        if best.is_none() {
            (0..tets.len() as u32).for_each(|ti| consider(ti, &mut best));
        }
        let (t, w) = match best {
            Some((t, w, _)) => (t, w),
            None => ([0; 4], [0.25; 4]),
        };
        out.nodes.push(t);
        out.weights.push(w);
    }
    out
}

/// The unique edges of `tets`.
pub fn tet_edges(tets: &[[u32; 4]]) -> Vec<[u32; 2]> {
    let mut set: Vec<[u32; 2]> = Vec::with_capacity(tets.len() * 6);
    for t in tets {
        for (a, b) in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
            let (x, y) = (t[a], t[b]);
            set.push([x.min(y), x.max(y)]);
        }
    }
    set.sort_unstable();
    set.dedup();
    set
}
