//! Capping a cut: triangulating the cross-section a plane leaves in a closed mesh.
//!
//! The crossing triangles' segments form the section's outlines (closed loops when the mesh
//! is closed). They go into a constrained Delaunay triangulation (spade, exact predicates)
//! as constraint edges, with no points added, so the cap uses exactly the cut's vertices and
//! closes the pieces without cracks. Which triangles are inside follows the even–odd rule: a
//! flood from the convex hull flips parity at every outline it crosses. That handles several
//! outlines (a bunny cut through its ears), holes (a torus cut across) and outlines nested in
//! holes, with no loop chaining and no orientation guessing.

use std::collections::VecDeque;

use glam::{DVec3, Vec3};
use spade::handles::{DirectedEdgeHandle, FixedFaceHandle, InnerTag};
use spade::{CdtEdge, ConstrainedDelaunayTriangulation, Point2, Triangulation};

use super::plane::IdMap;

/// A triangulated section.
pub(super) struct Section {
    /// Triangles over the cut points, counter-clockwise seen from the plane normal's side
    /// (their geometric normal is `+normal`).
    pub triangles: Vec<[u32; 3]>,
    /// Outline segments left out because they crossed another one (self-intersecting input).
    pub conflicts: usize,
}

/// Triangulates the outline `segments` over `points` (which lie in the plane with unit
/// `normal`).
pub(super) fn triangulate_section(points: &[Vec3], segments: &[[u32; 2]], normal: Vec3) -> Section {
    let empty = Section {
        triangles: Vec::new(),
        conflicts: 0,
    };
    if points.len() < 3 || segments.len() < 3 {
        return empty;
    }
    // A basis of the plane with u × v = normal, in f64 so the 2D points keep the f32 digits.
    let n = normal.as_dvec3();
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    // Only the outline's points go in (a point merged away by the cut is in no segment).
    // Exact duplicates collapse onto the first: spade would drop them and shift indices.
    let mut first_of: IdMap<[u64; 2], u32> = IdMap::default();
    let mut cdt_of_point: IdMap<u32, u32> = IdMap::default();
    let mut point_of_cdt: Vec<u32> = Vec::with_capacity(segments.len());
    let mut verts = Vec::with_capacity(segments.len());
    let mut edges: Vec<[usize; 2]> = Vec::with_capacity(segments.len());
    for s in segments {
        let [a, b] = s.map(|i| {
            *cdt_of_point.entry(i).or_insert_with(|| {
                let p: DVec3 = points[i as usize].as_dvec3();
                let q = Point2::new(p.dot(u), p.dot(v));
                *first_of
                    .entry([q.x.to_bits(), q.y.to_bits()])
                    .or_insert_with(|| {
                        verts.push(q);
                        point_of_cdt.push(i);
                        (verts.len() - 1) as u32
                    })
            })
        });
        if a != b {
            edges.push([a as usize, b as usize]);
        }
    }
    let mut conflicts = 0usize;
    let cdt = match ConstrainedDelaunayTriangulation::<Point2<f64>>::try_bulk_load_cdt(
        verts,
        edges,
        |_| conflicts += 1,
    ) {
        Ok(cdt) => cdt,
        // Only non-finite or absurdly large coordinates fail; the cut validated both.
        Err(_) => return empty,
    };

    let inside = even_odd(&cdt, |e| cdt.is_constraint_edge(e.fix().as_undirected()));
    let mut triangles = Vec::new();
    for face in cdt.inner_faces() {
        if inside[face.fix().index()] {
            // spade's faces are counter-clockwise in (u, v), so their normal is u × v = +n.
            triangles.push(face.vertices().map(|vh| point_of_cdt[vh.fix().index()]));
        }
    }
    Section {
        triangles,
        conflicts,
    }
}

/// Which faces of `cdt` are inside by the even–odd rule over the edges `wall` accepts: a flood
/// from the convex hull that flips parity at every wall it crosses. Indexed by face index.
pub(super) fn even_odd(
    cdt: &ConstrainedDelaunayTriangulation<Point2<f64>>,
    wall: impl Fn(DirectedEdgeHandle<'_, Point2<f64>, (), CdtEdge<()>, ()>) -> bool,
) -> Vec<bool> {
    let mut inside: Vec<Option<bool>> = vec![None; cdt.num_all_faces()];
    let mut queue: VecDeque<FixedFaceHandle<InnerTag>> = VecDeque::new();
    for face in cdt.inner_faces() {
        for e in face.adjacent_edges() {
            if e.rev().face().is_outer() && inside[face.fix().index()].is_none() {
                inside[face.fix().index()] = Some(wall(e));
                queue.push_back(face.fix());
            }
        }
    }
    while let Some(f) = queue.pop_front() {
        let here = inside[f.index()].unwrap_or(false);
        for e in cdt.face(f).adjacent_edges() {
            if let Some(next) = e.rev().face().as_inner() {
                if inside[next.fix().index()].is_none() {
                    inside[next.fix().index()] = Some(here ^ wall(e));
                    queue.push_back(next.fix());
                }
            }
        }
    }
    inside.into_iter().map(|i| i == Some(true)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(points: &mut Vec<Vec3>, segs: &mut Vec<[u32; 2]>, half: f32) {
        let base = points.len() as u32;
        for (x, y) in [(-half, -half), (half, -half), (half, half), (-half, half)] {
            points.push(Vec3::new(x, y, 0.0));
        }
        for k in 0..4 {
            segs.push([base + k, base + (k + 1) % 4]);
        }
    }

    fn area(points: &[Vec3], tris: &[[u32; 3]]) -> f32 {
        tris.iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| points[i as usize]);
                (b - a).cross(c - a).z * 0.5
            })
            .sum()
    }

    #[test]
    fn a_square_with_a_hole_is_capped_around_the_hole() {
        let (mut p, mut s) = (Vec::new(), Vec::new());
        square(&mut p, &mut s, 1.0);
        square(&mut p, &mut s, 0.5);
        let sec = triangulate_section(&p, &s, Vec3::Z);
        assert_eq!(sec.conflicts, 0);
        // 4 − 1 = 3, every triangle counter-clockwise seen from +z.
        assert!((area(&p, &sec.triangles) - 3.0).abs() < 1e-5);
        assert!(sec.triangles.iter().all(|t| {
            let [a, b, c] = t.map(|i| p[i as usize]);
            (b - a).cross(c - a).z > 0.0
        }));
    }

    #[test]
    fn an_island_in_a_hole_is_inside_again() {
        let (mut p, mut s) = (Vec::new(), Vec::new());
        square(&mut p, &mut s, 1.0);
        square(&mut p, &mut s, 0.6);
        square(&mut p, &mut s, 0.3);
        let sec = triangulate_section(&p, &s, Vec3::Z);
        let want = 4.0 - 1.44 + 0.36;
        assert!((area(&p, &sec.triangles) - want).abs() < 1e-5);
    }

    #[test]
    fn the_normal_decides_the_winding() {
        let (mut p, mut s) = (Vec::new(), Vec::new());
        square(&mut p, &mut s, 1.0);
        let sec = triangulate_section(&p, &s, -Vec3::Z);
        // Seen from −z they are counter-clockwise, so from +z clockwise: negative area.
        assert!((area(&p, &sec.triangles) + 4.0).abs() < 1e-5);
    }

    #[test]
    fn crossing_outlines_are_counted_not_a_panic() {
        let p = vec![
            Vec3::new(-1.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, -1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(2.0, 2.0, 0.0),
        ];
        let s = vec![[0, 1], [2, 3], [1, 4], [4, 0]];
        let sec = triangulate_section(&p, &s, Vec3::Z);
        assert_eq!(sec.conflicts, 1);
    }
}
