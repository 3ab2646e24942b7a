//! Internal shape-preserving constraints (ISPC paper Algorithm 2): from every vertex a ray
//! along the inverted normal finds the triangle on the opposite side of the body; the vertex is
//! linked to the nearest corner of that triangle by a distance constraint; links are
//! deduplicated. Works on open meshes: a ray leaving through a hole is just a miss.

use std::collections::HashSet;

use glam::Vec3;
use parry3d::query::{Ray, RayCast};
use parry3d::shape::TriMesh;

use crate::SoftBodyError;

/// The links of Algorithm 2 and what happened to the rays.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IspcLinks {
    /// Deduplicated vertex pairs `(min, max)`.
    pub links: Vec<[u32; 2]>,
    /// Rays cast (one per vertex with a defined normal).
    pub rays: usize,
    /// Rays that hit nothing (left through a hole, or the vertex has no opposite side).
    pub misses: usize,
    /// Hits on a face of the start vertex itself that were stepped over (Algorithm 2 skips them).
    pub own_faces_skipped: usize,
    /// Links dropped as duplicates of another link or of a surface edge.
    pub duplicates: usize,
}

/// Area-weighted vertex normals (outward for outward triangles).
pub fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let f = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += f;
        }
    }
    n.into_iter().map(|v| v.normalize_or_zero()).collect()
}

/// Algorithm 2 on a welded mesh (open meshes allowed).
pub fn ispc_links(positions: &[Vec3], triangles: &[[u32; 3]]) -> Result<IspcLinks, SoftBodyError> {
    let mesh = TriMesh::new(positions.to_vec(), triangles.to_vec())
        .map_err(|e| SoftBodyError::Config(format!("ISPC: cannot build the ray mesh: {e:?}")))?;
    let (lo, hi) = crate::mesh::bounds(positions);
    let size = (hi - lo).max_element().max(1e-6);
    let normals = vertex_normals(positions, triangles);
    let mut edges: HashSet<(u32, u32)> = HashSet::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.insert((a.min(b), a.max(b)));
        }
    }
    let mut out = IspcLinks::default();
    let mut seen: HashSet<(u32, u32)> = HashSet::new();
    for (i, (&p, &n)) in positions.iter().zip(&normals).enumerate() {
        if n == Vec3::ZERO {
            continue;
        }
        out.rays += 1;
        let dir = -n;
        // Lines 4–9: cast along the inverted normal; a hit on one of the start vertex's own
        // faces (grazing, at distance ~0) is stepped over and the ray continues.
        let mut origin = p + dir * (1e-5 * size);
        let mut hit = None;
        for _ in 0..8 {
            let ray = Ray::new(origin, dir);
            let Some(h) = mesh.cast_local_ray_and_get_normal(&ray, 4.0 * size, false) else {
                break;
            };
            let tri = triangles.get(h.subshape as usize).copied();
            match tri {
                Some(t) if t.contains(&(i as u32)) => {
                    out.own_faces_skipped += 1;
                    origin += dir * (h.time_of_impact + 1e-5 * size);
                }
                Some(t) => {
                    hit = Some((t, origin + dir * h.time_of_impact));
                    break;
                }
                None => break,
            }
        }
        let Some((t, at)) = hit else {
            out.misses += 1;
            continue;
        };
        // Lines 10–13: link to the corner of the hit triangle nearest the hit point.
        let Some(j) = t
            .iter()
            .copied()
            .min_by(|a, b| {
                positions[*a as usize]
                    .distance_squared(at)
                    .total_cmp(&positions[*b as usize].distance_squared(at))
            })
            .filter(|&j| j != i as u32)
        else {
            out.misses += 1;
            continue;
        };
        // Lines 14–18: store each link once.
        let key = ((i as u32).min(j), (i as u32).max(j));
        if edges.contains(&key) || !seen.insert(key) {
            out.duplicates += 1;
            continue;
        }
        out.links.push([key.0, key.1]);
    }
    Ok(out)
}

/// The mesh with every triangle whose centroid lies within `radius_m` of a center removed and
/// unreferenced vertices dropped: a mesh with holes, as the ISPC paper's dragon.
pub fn punch_holes(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    centers_m: &[Vec3],
    radius_m: f32,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let kept: Vec<[u32; 3]> = triangles
        .iter()
        .copied()
        .filter(|t| {
            let c = t.iter().map(|&i| positions[i as usize]).sum::<Vec3>() / 3.0;
            centers_m.iter().all(|h| h.distance(c) > radius_m)
        })
        .collect();
    let mut remap = vec![u32::MAX; positions.len()];
    let mut out_pos = Vec::new();
    let tris = kept
        .iter()
        .map(|t| {
            t.map(|i| {
                let r = &mut remap[i as usize];
                if *r == u32::MAX {
                    *r = out_pos.len() as u32;
                    out_pos.push(positions[i as usize]);
                }
                *r
            })
        })
        .collect();
    (out_pos, tris)
}
