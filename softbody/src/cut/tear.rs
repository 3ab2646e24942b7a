//! Progressive tearing (tear paper Algorithm 1, §3.1): a scalpel's sampled positions make
//! consecutive tear segments; each segment's box (as wide as the tear, from the blade's tip to
//! its back end, from the previous sample to this one) clips the faces inside it.
//!
//! How this differs from the paper, and why:
//! - **Conforming by construction.** The paper splits faces plane by plane and then runs a
//!   second pass over neighbours so no vertex sits on an edge (its Figure 6). Here a face's
//!   new points on its edges are where that edge crosses the box's surface, computed once per
//!   welded edge and shared by both faces of the edge; every face an edge point lies on also
//!   meets the box, so it is re-triangulated in the same pass with the same point. No
//!   T-junction can arise and no second pass is needed.
//! - **Any convex region, clipped exactly.** A face meeting the box is re-triangulated as a
//!   constrained Delaunay triangulation (spade) of its corners, its edge points and the points
//!   where the box's edges pierce it, with the outline of face ∩ box as constraints; the
//!   triangles whose centroid lies in the box are dropped. That handles a box wholly inside a
//!   face (a hole), a face wholly inside the box, and everything between, with one code path.
//! - **Touching boxes.** Consecutive boxes share a plane (Figure 5): a segment's box starts at
//!   the plane the previous one ended at, so consecutive boxes neither overlap nor leave a gap
//!   along the cut.
//! - **Mesh sections** (`sections`): faces grouped by a median split into boxes of at most
//!   [`SECTION_FACES`] faces; a segment searches only the sections its box overlaps. New faces
//!   join their parent's section.

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

use super::plane::PieceBuilder;
use super::sections::{Aabb, Sections};
use super::CutError;
use crate::mesh::{bounds, Mesh};

/// Faces per mesh section at most.
pub const SECTION_FACES: usize = 64;

/// Widest tear accepted, metres.
pub const MAX_TEAR_WIDTH_M: f32 = 0.05;

/// Longest tear segment (or blade) accepted, metres.
pub const MAX_SEGMENT_M: f32 = 1.0;

/// Least distance between a new vertex and an old one, or between two new ones, metres:
/// well above the 1 µm at which the simulation welds vertices.
const CLEARANCE_M: f32 = 2e-5;

/// The hexahedron's edges, as pairs of corner indices (see [`TearBox::corners`]).
const BOX_EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

/// New points of one face closer than this become one, metres.
const MERGE_M: f32 = 5e-6;

/// A face the box meets, with what the clip found on it.
#[derive(Clone, Debug)]
struct FaceWork {
    face: u32,
    /// Which corners lie in the box.
    inside: [bool; 3],
    /// Per edge (corner k → k+1), its points in order: (t from corner k, vertex id).
    on_edges: [Vec<(f32, u32)>; 3],
    /// Box edges piercing the face: (vertex id, barycentric coordinates).
    pierce: Vec<(u32, [f32; 3])>,
}

/// One sampled step of the scalpel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TearSegment {
    /// Where the blade's tip was at the previous sample (in the mesh's frame).
    pub from: Vec3,
    /// Where the blade's tip is now.
    pub to: Vec3,
    /// From the tip to the blade's back end: the box reaches this far above the tip.
    pub blade: Vec3,
}

/// A closed half-space `normal · x <= offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct HalfSpace {
    normal: Vec3,
    offset: f32,
}

impl HalfSpace {
    fn distance(&self, p: Vec3) -> f32 {
        self.normal.dot(p) - self.offset
    }
}

/// The region a segment removes: six half-spaces in the order start, end, left, right,
/// bottom, top (opposite faces are `2k` and `2k + 1`).
#[derive(Clone, Copy, Debug)]
struct TearBox {
    planes: [HalfSpace; 6],
}

impl TearBox {
    fn contains(&self, p: Vec3) -> bool {
        self.planes.iter().all(|h| h.distance(p) <= 0.0)
    }

    /// The 8 corners (index bits: end?, right?, top?) of the hexahedron.
    fn corners(&self) -> Option<[Vec3; 8]> {
        let mut out = [Vec3::ZERO; 8];
        for (i, c) in out.iter_mut().enumerate() {
            let [a, b, d] = [
                self.planes[i & 1],
                self.planes[2 + ((i >> 1) & 1)],
                self.planes[4 + ((i >> 2) & 1)],
            ];
            let det = a.normal.dot(b.normal.cross(d.normal));
            if det.abs() < 1e-6 {
                return None;
            }
            *c = (b.normal.cross(d.normal) * a.offset
                + d.normal.cross(a.normal) * b.offset
                + a.normal.cross(b.normal) * d.offset)
                / det;
        }
        out.iter().all(|c| c.is_finite()).then_some(out)
    }

    /// The part `[t0, t1]` of the segment `p + t (q − p)`, `t ∈ [0, 1]`, inside the box.
    fn clip_segment(&self, p: Vec3, q: Vec3) -> Option<(f32, f32)> {
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        let d = q - p;
        for h in &self.planes {
            let (num, den) = (-h.distance(p), h.normal.dot(d));
            if den == 0.0 {
                if num < 0.0 {
                    return None;
                }
            } else {
                let t = num / den;
                if den < 0.0 {
                    t0 = t0.max(t);
                } else {
                    t1 = t1.min(t);
                }
                if t0 > t1 {
                    return None;
                }
            }
        }
        Some((t0, t1))
    }
}

/// What one tear segment did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TearStats {
    /// Faces the box met and re-triangulated or removed.
    pub faces_clipped: usize,
    /// Faces made by the re-triangulation (kept, outside the box).
    pub faces_added: usize,
    /// Vertices added (edge points and box-edge points).
    pub vertices_added: usize,
    /// Faces tested exactly (those in the sections the box overlaps).
    pub faces_searched: usize,
}

/// A mesh being torn: welded vertices, faces with a normal per corner, and the sections.
#[derive(Clone, Debug)]
pub struct TearMesh {
    positions: Vec<Vec3>,
    faces: Vec<[u32; 3]>,
    corner_normals: Vec<[Vec3; 3]>,
    alive: Vec<bool>,
    sections: Sections,
    /// The plane the last segment's box ended at, if the scalpel is still in the cut.
    last_end: Option<HalfSpace>,
    /// The tear width, metres.
    width_m: f32,
}

impl TearMesh {
    /// Prepares `mesh` for tearing with tears `width_m` wide.
    pub fn new(mesh: &Mesh, width_m: f32) -> Result<Self, CutError> {
        if !width_m.is_finite() {
            return Err(CutError::NonFinite("tear width"));
        }
        if width_m <= 0.0 || width_m > MAX_TEAR_WIDTH_M {
            return Err(CutError::Degenerate("tear width outside (0, 5 cm]"));
        }
        if mesh.triangles.len() > super::MAX_CUT_TRIANGLES {
            return Err(CutError::Mesh(format!(
                "{} triangles, more than the {} a tear accepts",
                mesh.triangles.len(),
                super::MAX_CUT_TRIANGLES
            )));
        }
        mesh.validate("tear input")
            .map_err(|e| CutError::Mesh(e.to_string()))?;
        let welded = mesh.weld(1e-6);
        let corner_normals =
            super::plane::corner_normals(mesh, &welded.positions, &welded.triangles);
        let sections = Sections::build(&welded.positions, &welded.triangles, SECTION_FACES);
        Ok(Self {
            alive: vec![true; welded.triangles.len()],
            positions: welded.positions,
            faces: welded.triangles,
            corner_normals,
            sections,
            last_end: None,
            width_m,
        })
    }

    /// Ends the current stroke: the next segment starts a new tear (its box starts square).
    pub fn lift(&mut self) {
        self.last_end = None;
    }

    /// Number of live faces.
    pub fn face_count(&self) -> usize {
        self.alive.iter().filter(|&&a| a).count()
    }

    /// Number of vertices (some may no longer be used).
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Tears along one segment. Refused (changing nothing) for non-finite input, a segment or
    /// blade shorter than 10 µm or longer than [`MAX_SEGMENT_M`], or a blade along the
    /// segment.
    pub fn tear(&mut self, seg: &TearSegment) -> Result<TearStats, CutError> {
        let tear_box = self.make_box(seg)?;
        let stats = self.clip(&tear_box);
        self.last_end = Some(tear_box.planes[1]);
        Ok(stats)
    }

    /// The box that [`tear`](Self::tear)ing `seg` now would clip (before the planes move out
    /// by the clearance of at most a fraction of a millimetre), for the particle update of
    /// Algorithm 4. Refused like `tear`; changes nothing.
    pub fn box_for(&self, seg: &TearSegment) -> Result<super::particles::TearBoxPlanes, CutError> {
        let b = self.make_box(seg)?;
        Ok(super::particles::TearBoxPlanes {
            normals: b.planes.map(|h| h.normal),
            offsets_m: b.planes.map(|h| h.offset),
        })
    }

    fn make_box(&self, seg: &TearSegment) -> Result<TearBox, CutError> {
        if !(seg.from.is_finite() && seg.to.is_finite() && seg.blade.is_finite()) {
            return Err(CutError::NonFinite("tear segment"));
        }
        let along = seg.to - seg.from;
        let (len, blade_len) = (along.length(), seg.blade.length());
        for l in [len, blade_len] {
            if !(1e-5..=MAX_SEGMENT_M).contains(&l) {
                return Err(CutError::Degenerate(
                    "tear segment or blade shorter than 10 µm or longer than 1 m",
                ));
            }
        }
        let along = along / len;
        let up = seg.blade - along * seg.blade.dot(along);
        if up.length() < 0.05 * blade_len {
            return Err(CutError::Degenerate("blade along the tear direction"));
        }
        let up = up.normalize();
        let side = along.cross(up);
        let half = 0.5 * self.width_m;
        let h = |normal: Vec3, offset: f32| HalfSpace { normal, offset };
        let start = match self.last_end {
            // The previous box's end plane, facing the other way: the boxes touch.
            Some(e) if e.distance(seg.from).abs() < 1e-4 && e.normal.dot(along) > 0.2 => {
                h(-e.normal, -e.offset)
            }
            _ => h(-along, -along.dot(seg.from)),
        };
        let tips = [seg.from, seg.to];
        let backs = [seg.from + seg.blade, seg.to + seg.blade];
        let planes = [
            start,
            h(along, along.dot(seg.to)),
            h(-side, half - side.dot(seg.from)),
            h(side, half + side.dot(seg.from)),
            h(
                -up,
                tips.iter().map(|p| -up.dot(*p)).fold(f32::MIN, f32::max),
            ),
            h(
                up,
                backs.iter().map(|p| up.dot(*p)).fold(f32::MIN, f32::max),
            ),
        ];
        Ok(TearBox { planes })
    }

    /// Clips every face the box meets. Vertices within `eps` of a box plane push that plane
    /// out a little first, so no edge is cut at its very end.
    fn clip(&mut self, tear_box: &TearBox) -> TearStats {
        let mut b = *tear_box;
        let mut stats = TearStats::default();
        let Some(corners) = b.corners() else {
            return stats;
        };
        let (lo, hi) = bounds(&corners);
        let reach = Aabb {
            lo: lo - Vec3::splat(1e-4),
            hi: hi + Vec3::splat(1e-4),
        };
        let candidates: Vec<u32> = self
            .sections
            .faces_near(&reach)
            .filter(|&f| self.alive[f as usize])
            .collect();
        stats.faces_searched = candidates.len();
        // Clearance: no vertex within `eps` of a box plane, no edge grazing the box (its two
        // points closer than `eps`), no box edge grazing a face's edge. Otherwise the planes
        // move out a little (each by its own amount) and the checks run again.
        let original = b;
        for attempt in 1..=8u8 {
            if !self.grazes(&b, &candidates) {
                break;
            }
            for (i, (plane, orig)) in b.planes.iter_mut().zip(&original.planes).enumerate() {
                plane.offset =
                    orig.offset + CLEARANCE_M * f32::from(attempt) * (1.0 + 0.37 * i as f32);
            }
        }
        let Some(box_corners) = b.corners() else {
            return stats;
        };

        // Edge points, once per welded edge: (t along low→high, vertex id).
        let first_new = self.positions.len();
        let mut work: Vec<FaceWork> = Vec::new();
        let mut edge_points: HashMap<(u32, u32), Vec<(f32, u32)>> = HashMap::new();
        for &f in &candidates {
            let tri = self.faces[f as usize];
            let [p0, p1, p2] = tri.map(|v| self.positions[v as usize]);
            // Quick reject: the face's bounds against the box's.
            let (flo, fhi) = (p0.min(p1).min(p2), p0.max(p1).max(p2));
            if flo.cmpgt(reach.hi).any() || fhi.cmplt(reach.lo).any() {
                continue;
            }
            let inside = [p0, p1, p2].map(|p| b.contains(p));
            // Edge points.
            let mut on_edges: [Vec<(f32, u32)>; 3] = Default::default();
            for k in 0..3 {
                let (u, v) = (tri[k], tri[(k + 1) % 3]);
                let (e0, e1) = (u.min(v), u.max(v));
                let pts = match edge_points.get(&(e0, e1)) {
                    Some(p) => p.clone(),
                    None => {
                        let (a, c) = (self.positions[e0 as usize], self.positions[e1 as usize]);
                        let mut pts = Vec::new();
                        if let Some((t0, t1)) = b.clip_segment(a, c) {
                            for t in [t0, t1] {
                                if t > 0.0 && t < 1.0 && pts.iter().all(|&(s, _)| s != t) {
                                    self.positions.push(a.lerp(c, t));
                                    stats.vertices_added += 1;
                                    pts.push((t, (self.positions.len() - 1) as u32));
                                }
                            }
                        }
                        edge_points.insert((e0, e1), pts.clone());
                        pts
                    }
                };
                // Along this face's edge u → v.
                on_edges[k] = if u == e0 {
                    pts
                } else {
                    pts.into_iter().rev().map(|(t, id)| (1.0 - t, id)).collect()
                };
            }
            // Box edges piercing the face.
            let mut pierce: Vec<(u32, [f32; 3])> = Vec::new();
            for (i, j) in BOX_EDGES {
                if let Some(bary) = segment_triangle(box_corners[i], box_corners[j], p0, p1, p2) {
                    self.positions
                        .push(p0 * bary[0] + p1 * bary[1] + p2 * bary[2]);
                    stats.vertices_added += 1;
                    pierce.push(((self.positions.len() - 1) as u32, bary));
                }
            }
            let any_edge_point = on_edges.iter().any(|e| !e.is_empty());
            if !any_edge_point && pierce.is_empty() {
                if inside.iter().all(|&i| i) {
                    // Wholly inside: removed.
                    self.alive[f as usize] = false;
                    stats.faces_clipped += 1;
                }
                continue;
            }
            work.push(FaceWork {
                face: f,
                inside,
                on_edges,
                pierce,
            });
        }
        // New points of one face closer than the weld would keep apart (the two long edges of
        // a sliver face, a box edge passing near a face's edge) become one point, in every
        // face that uses them.
        let first_new = first_new as u32;
        let mut alias = super::plane::DisjointSets::new(self.positions.len() - first_new as usize);
        for w in &work {
            let mut pts: Vec<u32> = w.on_edges.iter().flatten().map(|&(_, id)| id).collect();
            pts.extend(w.pierce.iter().map(|&(id, _)| id));
            for (i, &a) in pts.iter().enumerate() {
                for &c in &pts[i + 1..] {
                    let (pa, pc) = (self.positions[a as usize], self.positions[c as usize]);
                    if a != c && pa.distance(pc) < MERGE_M {
                        alias.union(a - first_new, c - first_new);
                    }
                }
            }
        }
        let resolve = |alias: &mut super::plane::DisjointSets, id: u32| {
            if id >= first_new {
                alias.find(id - first_new) + first_new
            } else {
                id
            }
        };
        for w in &work {
            let mut w = w.clone();
            for e in &mut w.on_edges {
                for p in e.iter_mut() {
                    p.1 = resolve(&mut alias, p.1);
                }
            }
            for p in &mut w.pierce {
                p.0 = resolve(&mut alias, p.0);
            }
            stats.faces_clipped += 1;
            stats.faces_added += self.retriangulate(&w, &b);
        }
        stats
    }

    /// Whether box `b` comes within [`CLEARANCE_M`] of a degenerate configuration with the
    /// candidate faces: a vertex near one of its planes, an edge crossing it over a tiny
    /// length, or one of its edges passing near a face's edge.
    fn grazes(&self, b: &TearBox, candidates: &[u32]) -> bool {
        let Some(corners) = b.corners() else {
            return false;
        };
        for &f in candidates {
            let tri = self.faces[f as usize];
            let p = tri.map(|v| self.positions[v as usize]);
            for q in p {
                if b.planes.iter().any(|h| h.distance(q).abs() <= CLEARANCE_M) {
                    return true;
                }
            }
            for k in 0..3 {
                let (a, c) = (p[k], p[(k + 1) % 3]);
                if let Some((t0, t1)) = b.clip_segment(a, c) {
                    if t1 > t0 && (t1 - t0) * a.distance(c) < CLEARANCE_M {
                        return true;
                    }
                }
            }
            for (i, j) in BOX_EDGES {
                if let Some(bary) = segment_triangle(corners[i], corners[j], p[0], p[1], p[2]) {
                    // Distance from the pierce point to each edge: twice the area of the
                    // sub-triangle over the edge's length.
                    let q = p[0] * bary[0] + p[1] * bary[1] + p[2] * bary[2];
                    for k in 0..3 {
                        let (a, c) = (p[k], p[(k + 1) % 3]);
                        let d = (c - a).cross(q - a).length() / a.distance(c).max(1e-12);
                        if d < CLEARANCE_M {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }

    /// Replaces face `f` by the part of it outside the box; returns (faces, vertices) added.
    /// Replaces a face by the part of it outside the box; returns the faces added.
    fn retriangulate(&mut self, w: &FaceWork, b: &TearBox) -> usize {
        let (f, inside) = (w.face, w.inside);
        let tri = self.faces[f as usize];
        let ns = self.corner_normals[f as usize];
        let [p0, p1, p2] = tri.map(|v| self.positions[v as usize]);
        // Points: corners, edge points, pierce points, with their normals.
        let mut ids: Vec<u32> = Vec::new();
        let mut normals: Vec<Vec3> = Vec::new();
        let mut boundary: Vec<usize> = Vec::new(); // the face's outline, in order
        let mut section_pts: Vec<usize> = Vec::new(); // vertices of face ∩ box
        for k in 0..3 {
            ids.push(tri[k]);
            normals.push(ns[k]);
            boundary.push(ids.len() - 1);
            if inside[k] {
                section_pts.push(ids.len() - 1);
            }
            for &(t, id) in &w.on_edges[k] {
                ids.push(id);
                normals.push((ns[k] * (1.0 - t) + ns[(k + 1) % 3] * t).normalize_or_zero());
                boundary.push(ids.len() - 1);
                section_pts.push(ids.len() - 1);
            }
        }
        for &(id, bary) in &w.pierce {
            ids.push(id);
            normals.push((ns[0] * bary[0] + ns[1] * bary[1] + ns[2] * bary[2]).normalize_or_zero());
            section_pts.push(ids.len() - 1);
        }
        // 2D frame of the face: u × v along its normal, so spade's counter-clockwise faces
        // keep the face's winding.
        let n = (p1 - p0).cross(p2 - p0).as_dvec3().normalize_or_zero();
        let u = (p1 - p0).as_dvec3().normalize_or_zero();
        let v = n.cross(u);
        let origin = p0.as_dvec3();
        let to2 = |p: Vec3| {
            let d: DVec3 = p.as_dvec3() - origin;
            Point2::new(d.dot(u), d.dot(v))
        };
        let pts2: Vec<Point2<f64>> = ids
            .iter()
            .map(|&i| to2(self.positions[i as usize]))
            .collect();
        // One CDT vertex per vertex id (merged points share an id) and per 2D position (spade
        // would drop an exact duplicate and shift the indices).
        let mut first_id: HashMap<u32, usize> = HashMap::new();
        let mut first: HashMap<[u64; 2], usize> = HashMap::new();
        let mut cdt_of: Vec<usize> = Vec::with_capacity(pts2.len());
        let mut local_of_cdt: Vec<usize> = Vec::new();
        let mut verts: Vec<Point2<f64>> = Vec::new();
        for (i, q) in pts2.iter().enumerate() {
            let id = match first_id.get(&ids[i]) {
                Some(&c) => c,
                None => {
                    let c = *first
                        .entry([q.x.to_bits(), q.y.to_bits()])
                        .or_insert_with(|| {
                            verts.push(*q);
                            local_of_cdt.push(i);
                            verts.len() - 1
                        });
                    first_id.insert(ids[i], c);
                    c
                }
            };
            cdt_of.push(id);
        }
        let mut walls: Vec<(usize, usize)> = (0..boundary.len())
            .map(|w| {
                let (a, c) = (
                    cdt_of[boundary[w]],
                    cdt_of[boundary[(w + 1) % boundary.len()]],
                );
                (a.min(c), a.max(c))
            })
            .filter(|&(a, c)| a != c)
            .collect();
        walls.sort_unstable();
        // A pair that appears twice (the collapsed tip of a sliver whose two edge points
        // merged) bounds the face on neither side: only odd counts are walls.
        let mut odd: Vec<(usize, usize)> = Vec::with_capacity(walls.len());
        for w in walls {
            if odd.last() == Some(&w) {
                odd.pop();
            } else {
                odd.push(w);
            }
        }
        let walls = odd;
        let mut edges: Vec<[usize; 2]> = Vec::new();
        let mut push_edge = |a: usize, c: usize| {
            let (a, c) = (cdt_of[a], cdt_of[c]);
            if a != c {
                edges.push([a, c]);
            }
        };
        for w in 0..boundary.len() {
            push_edge(boundary[w], boundary[(w + 1) % boundary.len()]);
        }
        // The face's own outline: the walls of the even–odd rule (a point computed on an edge
        // may sit a hair inside it, leaving a sliver between the outline and the hull that
        // is not part of the face).

        // The outline of face ∩ box: its points sorted by angle about their mean (convex).
        if section_pts.len() >= 2 {
            let mean = section_pts
                .iter()
                .fold((0.0, 0.0), |(x, y), &i| (x + pts2[i].x, y + pts2[i].y));
            let (mx, my) = (
                mean.0 / section_pts.len() as f64,
                mean.1 / section_pts.len() as f64,
            );
            let mut sorted = section_pts.clone();
            sorted.sort_by(|&a, &c| {
                let ka = (pts2[a].y - my).atan2(pts2[a].x - mx);
                let kc = (pts2[c].y - my).atan2(pts2[c].x - mx);
                ka.total_cmp(&kc).then(a.cmp(&c))
            });
            let m = sorted.len();
            for w in 0..m {
                if m == 2 && w == 1 {
                    break;
                }
                push_edge(sorted[w], sorted[(w + 1) % m]);
            }
        }
        let cdt = match ConstrainedDelaunayTriangulation::<Point2<f64>>::try_bulk_load_cdt(
            verts,
            edges,
            |_| {},
        ) {
            Ok(c) => c,
            Err(_) => return 0,
        };
        let in_face = super::cap::even_odd(&cdt, |e| {
            let [a, c] = e.vertices().map(|v| v.fix().index());
            walls.binary_search(&(a.min(c), a.max(c))).is_ok()
        });
        self.alive[f as usize] = false;
        let section = self.sections.section_of(f);
        let mut added = 0;
        for face in cdt.inner_faces() {
            if !in_face[face.fix().index()] {
                continue;
            }
            let local = face.vertices().map(|vh| local_of_cdt[vh.fix().index()]);
            let [a, c, d] = local.map(|l| self.positions[ids[l] as usize]);
            if b.contains((a + c + d) / 3.0) {
                continue;
            }
            let new = self.faces.len() as u32;
            self.faces.push(local.map(|l| ids[l]));
            self.corner_normals.push(local.map(|l| normals[l]));
            self.alive.push(true);
            self.sections.add(section, new, &[a, c, d]);
            added += 1;
        }
        added
    }

    /// The torn mesh as a render mesh (live faces only, unused vertices dropped).
    pub fn to_mesh(&self) -> Mesh {
        let mut b = PieceBuilder::default();
        for (f, tri) in self.faces.iter().enumerate() {
            if !self.alive[f] {
                continue;
            }
            let out = std::array::from_fn(|k| {
                b.vertex(
                    self.positions[tri[k] as usize],
                    tri[k],
                    self.corner_normals[f][k],
                )
            });
            b.triangles.push(out);
        }
        b.finish().mesh
    }
}

/// Where the segment `a → b` crosses the triangle's interior, as barycentric coordinates
/// (Möller–Trumbore; a segment in the triangle's plane counts as no crossing).
fn segment_triangle(a: Vec3, b: Vec3, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<[f32; 3]> {
    let d = b - a;
    let (e1, e2) = (p1 - p0, p2 - p0);
    let h = d.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = a - p0;
    let u = s.dot(h) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    if !(0.0..=1.0).contains(&t) {
        return None;
    }
    // Strictly inside: on an edge it is an edge point, found from the edge.
    if u <= 0.0 || v <= 0.0 || u + v >= 1.0 {
        return None;
    }
    Some([1.0 - u - v, u, v])
}
