//! Over 800 lines: the clip, its clearance search and the incremental render mesh share the
//! `TearMesh` state and one invariant (conforming edges); splitting them is the next clean-up.
//!
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
//! - **Clearance.** Before clipping, the box's planes move out (by the least amount, plane by
//!   plane) until no vertex is within [`CLEARANCE_M`] of one and no box edge or short chord
//!   grazes a face; a box that cannot be cleared is refused, changing nothing, rather than
//!   leave a sliver the simulation's weld would collapse.
//! - **An incremental render mesh.** The render vertices of the live faces are kept per tear
//!   (only the faces it removed and added are touched), so [`TearMesh::to_mesh`] copies them
//!   out instead of rebuilding; a unit test checks the patched mesh against a full rebuild.

use glam::{DVec3, Vec3};
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

use super::plane::{weld_positions, IdMap};
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

/// How far around a segment's box faces are gathered, metres: the box's planes may move out
/// by the clearance (a fraction of a millimetre) and must still meet only gathered faces.
const SEARCH_MARGIN_M: f32 = 1e-3;

/// Most rounds of moving the box's planes clear of the mesh before the segment is refused.
const CLEARANCE_ROUNDS: usize = 16;

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

impl TearSegment {
    /// Whether every peer can apply it: finite, the segment and the blade each 10 µm to 1 m
    /// long, the blade not along the segment. An owner checks before it asks for a tear, so
    /// the room's log never holds an entry every peer then refuses.
    pub fn validate(&self) -> Result<(), CutError> {
        self.frame().map(|_| ())
    }

    /// The unit direction along the segment and the blade's unit direction across it.
    fn frame(&self) -> Result<(Vec3, Vec3), CutError> {
        if !(self.from.is_finite() && self.to.is_finite() && self.blade.is_finite()) {
            return Err(CutError::NonFinite("tear segment"));
        }
        let along = self.to - self.from;
        let (len, blade_len) = (along.length(), self.blade.length());
        for l in [len, blade_len] {
            if !(1e-5..=MAX_SEGMENT_M).contains(&l) {
                return Err(CutError::Degenerate(
                    "tear segment or blade shorter than 10 µm or longer than 1 m",
                ));
            }
        }
        let along = along / len;
        let up = self.blade - along * self.blade.dot(along);
        if up.length() < 0.05 * blade_len {
            return Err(CutError::Degenerate("blade along the tear direction"));
        }
        Ok((along, up.normalize()))
    }
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
        self.clip_segment_planes(p, q)
            .map(|(t0, t1, _, _)| (t0, t1))
    }

    /// [`clip_segment`](Self::clip_segment) with the planes that set `t0` and `t1` (6 when
    /// an end of the segment sets it).
    fn clip_segment_planes(&self, p: Vec3, q: Vec3) -> Option<(f32, f32, usize, usize)> {
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        let (mut i0, mut i1) = (6, 6);
        let d = q - p;
        for (i, h) in self.planes.iter().enumerate() {
            let (num, den) = (-h.distance(p), h.normal.dot(d));
            if den == 0.0 {
                if num < 0.0 {
                    return None;
                }
            } else {
                let t = num / den;
                if den < 0.0 {
                    if t > t0 {
                        (t0, i0) = (t, i);
                    }
                } else if t < t1 {
                    (t1, i1) = (t, i);
                }
                if t0 > t1 {
                    return None;
                }
            }
        }
        Some((t0, t1, i0, i1))
    }

    /// Of the two planes meeting along the box edge from corner `i` to `j`, the one whose
    /// shift moves the point where that edge pierces the triangle `tri` fastest across the
    /// triangle's edge along `edge`. Shifting both together can slide the point along the
    /// edge and never clear it (a mesh torn many times over, seed 0 of the soak).
    fn plane_moving_across(&self, i: usize, j: usize, tri: [Vec3; 3], edge: Vec3) -> usize {
        let [a, c] = box_edge_planes(i, j);
        let face = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
        let across = face.cross(edge).normalize_or_zero();
        // Shifting plane `a` slides the point along the line where plane `c` meets the face;
        // it moves the plane's distance by `n_a · u` per unit of that slide.
        let rate = |moved: usize, kept: usize| {
            let u = self.planes[kept].normal.cross(face).normalize_or_zero();
            let along = self.planes[moved].normal.dot(u).abs();
            if along > 1e-6 {
                across.dot(u).abs() / along
            } else {
                0.0
            }
        };
        if rate(c, a) > rate(a, c) {
            c
        } else {
            a
        }
    }

    /// The box's bounds grown by `margin_m`, if its corners exist.
    fn reach(&self, margin_m: f32) -> Option<Aabb> {
        let (lo, hi) = bounds(&self.corners()?);
        Some(Aabb {
            lo: lo - Vec3::splat(margin_m),
            hi: hi + Vec3::splat(margin_m),
        })
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
    /// The render vertices of the live faces, patched face by face.
    render: RenderSlots,
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
        let (positions, faces) = weld_positions(&mesh.positions, &mesh.triangles, 1e-6);
        let corner_normals = super::plane::corner_normals(mesh, &positions, &faces);
        let sections = Sections::build(&positions, &faces, SECTION_FACES);
        let mut torn = Self {
            alive: vec![true; faces.len()],
            render: RenderSlots::default(),
            positions,
            faces,
            corner_normals,
            sections,
            last_end: None,
            width_m,
        };
        torn.render
            .rebuild(&torn.faces, &torn.corner_normals, &torn.alive);
        Ok(torn)
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
        let first_new_face = self.faces.len();
        let stats = self.clip(&tear_box)?;
        self.render.add_faces(
            first_new_face,
            &self.faces,
            &self.corner_normals,
            &self.alive,
        );
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
        let (along, up) = seg.frame()?;
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

    /// Clips every face the box meets. The box's planes first move out a little until no
    /// vertex is within [`CLEARANCE_M`] of one and nothing else grazes it (see
    /// [`clear_box`](Self::clear_box)), so no edge is cut at its very end; a box that cannot be
    /// cleared is refused before anything changes.
    fn clip(&mut self, tear_box: &TearBox) -> Result<TearStats, CutError> {
        let mut stats = TearStats::default();
        let Some(search) = tear_box.reach(SEARCH_MARGIN_M) else {
            return Ok(stats);
        };
        let candidates: Vec<u32> = self
            .sections
            .faces_near(&search)
            .filter(|&f| self.alive[f as usize])
            .collect();
        stats.faces_searched = candidates.len();
        let refused = CutError::Degenerate("no placement of the tear box clear of the mesh");
        let Some(b) = self.clear_box(tear_box, &candidates) else {
            return Err(refused);
        };
        let (Some(box_corners), Some(reach)) = (b.corners(), b.reach(1e-4)) else {
            return Ok(stats);
        };
        // Every face the moved box can meet was gathered (a box nearly flat between two of
        // its planes could move far).
        if reach.lo.cmplt(search.lo).any() || reach.hi.cmpgt(search.hi).any() {
            return Err(refused);
        }

        // Edge points, once per welded edge: (t along low→high, vertex id).
        let first_new = self.positions.len();
        let mut work: Vec<FaceWork> = Vec::new();
        let mut edge_points: IdMap<(u32, u32), Vec<(f32, u32)>> = IdMap::default();
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
                    self.kill(f);
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
        Ok(stats)
    }

    /// Removes face `f` from the live mesh.
    fn kill(&mut self, f: u32) {
        if std::mem::replace(&mut self.alive[f as usize], false) {
            self.render.remove_face(f);
        }
    }

    /// Moves `tear_box`'s planes out (the box only grows) until nothing in the candidate
    /// faces grazes it (see [`graze`](Self::graze)). Each round first takes, per plane, the
    /// least further shift that leaves every vertex more than [`CLEARANCE_M`] from it (exact,
    /// over the vertices' sorted distances), then pushes the planes of any remaining conflict
    /// out by twice the clearance. `None` after [`CLEARANCE_ROUNDS`] rounds.
    ///
    /// (The first version moved all six planes together by a fixed schedule and, after eight
    /// tries, clipped anyway: in a mesh torn many times over the same spot some vertex was
    /// always near some plane, and the box that was used at last cut an edge 0.4 µm from its
    /// end — a triangle the 1 µm weld collapses, seed 30 of the soak.)
    fn clear_box(&self, tear_box: &TearBox, candidates: &[u32]) -> Option<TearBox> {
        let mut verts: Vec<u32> = candidates
            .iter()
            .flat_map(|&f| self.faces[f as usize])
            .collect();
        verts.sort_unstable();
        verts.dedup();
        // Per plane, the distances that can conflict with some shift of at most the search
        // margin, increasing.
        let distances: [Vec<f32>; 6] = std::array::from_fn(|i| {
            let h = tear_box.planes[i];
            let mut d: Vec<f32> = verts
                .iter()
                .map(|&v| h.distance(self.positions[v as usize]))
                .filter(|&d| (-2.0 * CLEARANCE_M..=SEARCH_MARGIN_M).contains(&d))
                .collect();
            d.sort_unstable_by(f32::total_cmp);
            d
        });
        let mut shift = [0.0f32; 6];
        for _ in 0..CLEARANCE_ROUNDS {
            let mut b = *tear_box;
            for i in 0..6 {
                shift[i] = clear_shift(&distances[i], shift[i]);
                b.planes[i].offset = tear_box.planes[i].offset + shift[i];
            }
            match self.graze(&b, candidates) {
                0 => return Some(b),
                planes => {
                    for (i, s) in shift.iter_mut().enumerate() {
                        if planes & (1 << i) != 0 {
                            *s += 2.0 * CLEARANCE_M;
                        }
                    }
                }
            }
        }
        None
    }

    /// The planes of box `b` (a bit each) that come within [`CLEARANCE_M`] of a degenerate
    /// configuration with the candidate faces it can meet: a vertex near the plane, an edge
    /// crossing the box between two planes over a tiny length (its two new points would
    /// nearly coincide), or a box edge (two planes) passing near a face's edge. 0 when clear.
    fn graze(&self, b: &TearBox, candidates: &[u32]) -> u8 {
        let (Some(corners), Some(reach)) = (b.corners(), b.reach(1e-4)) else {
            return 0;
        };
        let mut planes = 0u8;
        for &f in candidates {
            let tri = self.faces[f as usize];
            let p = tri.map(|v| self.positions[v as usize]);
            // Only the faces the clip will look at (its quick reject).
            let (flo, fhi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            if flo.cmpgt(reach.hi).any() || fhi.cmplt(reach.lo).any() {
                continue;
            }
            for q in p {
                for (i, h) in b.planes.iter().enumerate() {
                    if h.distance(q).abs() <= CLEARANCE_M {
                        planes |= 1 << i;
                    }
                }
            }
            for k in 0..3 {
                let (a, c) = (p[k], p[(k + 1) % 3]);
                // Two new points on the edge (an end inside the box is a vertex, which is
                // clear of every plane, so its one new point is far from it).
                if let Some((t0, t1, i0, i1)) = b.clip_segment_planes(a, c) {
                    if t0 > 0.0 && t1 < 1.0 && (t1 - t0) * a.distance(c) < CLEARANCE_M {
                        planes |= (1 << i0) | (1 << i1);
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
                            planes |= 1 << b.plane_moving_across(i, j, p, c - a);
                        }
                    }
                }
            }
        }
        planes
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
        let mut first_id: IdMap<u32, usize> = IdMap::default();
        let mut first: IdMap<[u64; 2], usize> = IdMap::default();
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
        self.kill(f);
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
            self.render.of_corner.push([u32::MAX; 3]);
            self.sections.add(section, new, &[a, c, d]);
            added += 1;
        }
        added
    }

    /// The torn mesh as a render mesh: the live faces in the order they were made, over one
    /// render vertex per distinct (vertex, corner normal) they use, in increasing order of
    /// vertex and then of the normal's bits (unused vertices dropped). The render vertices
    /// are kept up to date by each tear (only the faces it removed and added), so this only
    /// copies them out.
    pub fn to_mesh(&self) -> Mesh {
        self.render.mesh(&self.positions, &self.faces, &self.alive)
    }
}

/// The least shift `≥ from` of a plane that leaves every distance in `sorted` (the vertices'
/// distances from the unshifted plane, increasing) more than [`CLEARANCE_M`] from it.
fn clear_shift(sorted: &[f32], from: f32) -> f32 {
    let mut shift = from;
    let start = sorted.partition_point(|&d| d < shift - CLEARANCE_M);
    for &d in &sorted[start..] {
        if d > shift + CLEARANCE_M {
            break;
        }
        // Past this vertex by a quarter of the clearance more than needed (the shifted
        // plane's distances round differently).
        shift = d + 1.25 * CLEARANCE_M;
    }
    shift
}

/// The two planes whose intersection is the box edge between corners `i` and `j` (corner
/// bits: end?, right?, top?; an edge's corners differ in one bit).
fn box_edge_planes(i: usize, j: usize) -> [usize; 2] {
    let mut planes = [0; 2];
    let mut n = 0;
    for bit in 0..3 {
        if (i ^ j) & (1 << bit) == 0 && n < 2 {
            planes[n] = 2 * bit + ((i >> bit) & 1);
            n += 1;
        }
    }
    planes
}

/// The render vertices of a torn mesh's live faces, kept up to date face by face so
/// [`TearMesh::to_mesh`] is a copy, not a rebuild: a slot per distinct (vertex, corner normal
/// bits), in increasing order of that key, with how many live face corners use it.
#[derive(Clone, Debug, Default, PartialEq)]
struct RenderSlots {
    /// (vertex, normal bits) of each slot, strictly increasing.
    keys: Vec<(u32, [u32; 3])>,
    normals: Vec<Vec3>,
    /// Live face corners using each slot; a slot at 0 is left out of the mesh.
    uses: Vec<u32>,
    /// Each face's corners' slots (`u32::MAX` until the face is registered).
    of_corner: Vec<[u32; 3]>,
}

impl RenderSlots {
    /// Rebuilds every slot from the live faces: what the patched slots must always equal.
    fn rebuild(&mut self, faces: &[[u32; 3]], corner_normals: &[[Vec3; 3]], alive: &[bool]) {
        let mut all: Vec<((u32, [u32; 3]), Vec3)> = faces
            .iter()
            .zip(corner_normals)
            .zip(alive)
            .filter(|(_, &a)| a)
            .flat_map(|((t, ns), _)| (0..3).map(move |k| ((t[k], bits(ns[k])), ns[k])))
            .collect();
        all.sort_unstable_by_key(|e| e.0);
        all.dedup_by_key(|e| e.0);
        self.keys = all.iter().map(|e| e.0).collect();
        self.normals = all.iter().map(|e| e.1).collect();
        self.uses = vec![0; all.len()];
        self.of_corner = vec![[u32::MAX; 3]; faces.len()];
        for (f, _) in alive.iter().enumerate().filter(|(_, &a)| a) {
            self.register(f, faces, corner_normals);
        }
    }

    /// Points face `f`'s corners at their slots (which exist) and counts the uses.
    fn register(&mut self, f: usize, faces: &[[u32; 3]], corner_normals: &[[Vec3; 3]]) {
        for k in 0..3 {
            let key = (faces[f][k], bits(corner_normals[f][k]));
            let s = self.keys.binary_search(&key).unwrap_or(usize::MAX);
            if let Some(u) = self.uses.get_mut(s) {
                *u += 1;
                self.of_corner[f][k] = s as u32;
            }
        }
    }

    fn remove_face(&mut self, f: u32) {
        for s in self.of_corner[f as usize] {
            if let Some(u) = self.uses.get_mut(s as usize) {
                *u = u.saturating_sub(1);
            }
        }
    }

    /// Registers the faces from `first` on (just made by a tear). Their new keys sort after
    /// every old one (new faces' corners are new vertices, or old corners with the normal
    /// they had), so they are appended; anything else rebuilds the slots.
    fn add_faces(
        &mut self,
        first: usize,
        faces: &[[u32; 3]],
        corner_normals: &[[Vec3; 3]],
        alive: &[bool],
    ) {
        let mut new: Vec<((u32, [u32; 3]), Vec3)> = Vec::new();
        for f in first..faces.len() {
            for k in 0..3 {
                let key = (faces[f][k], bits(corner_normals[f][k]));
                if self.keys.binary_search(&key).is_err() {
                    new.push((key, corner_normals[f][k]));
                }
            }
        }
        new.sort_unstable_by_key(|e| e.0);
        new.dedup_by_key(|e| e.0);
        if let (Some(last), Some(first_new)) = (self.keys.last(), new.first()) {
            if first_new.0 <= *last {
                self.rebuild(faces, corner_normals, alive);
                return;
            }
        }
        self.keys.extend(new.iter().map(|e| e.0));
        self.normals.extend(new.iter().map(|e| e.1));
        self.uses.resize(self.keys.len(), 0);
        for (f, _) in alive.iter().enumerate().skip(first).filter(|(_, &a)| a) {
            self.register(f, faces, corner_normals);
        }
    }

    /// The render mesh: used slots in order, live faces in order.
    fn mesh(&self, positions: &[Vec3], faces: &[[u32; 3]], alive: &[bool]) -> Mesh {
        let mut remap = vec![u32::MAX; self.keys.len()];
        let used = self.uses.iter().filter(|&&u| u > 0).count();
        let mut out_positions = Vec::with_capacity(used);
        let mut out_normals = Vec::with_capacity(used);
        for (s, &u) in self.uses.iter().enumerate() {
            if u > 0 {
                remap[s] = out_positions.len() as u32;
                out_positions.push(positions[self.keys[s].0 as usize]);
                out_normals.push(self.normals[s]);
            }
        }
        let triangles = self
            .of_corner
            .iter()
            .zip(alive)
            .take(faces.len())
            .filter(|(_, &a)| a)
            .map(|(c, _)| c.map(|s| remap.get(s as usize).copied().unwrap_or(u32::MAX)))
            .collect();
        Mesh {
            positions: out_positions,
            normals: Some(out_normals),
            triangles,
        }
    }
}

fn bits(n: Vec3) -> [u32; 3] {
    n.to_array().map(f32::to_bits)
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// Strokes over the upper half of `m` (centred at the origin, `up` pointing out of it):
    /// `n` segments of 6 mm along great-circle-like paths, the blade along the outward radius.
    fn segments(m: &Mesh, n: usize) -> Vec<TearSegment> {
        let (lo, hi) = bounds(&m.positions);
        let half = (hi - lo) * 0.5;
        let mut out = Vec::new();
        for k in 0..n {
            let stroke = k / 8;
            let a = 0.7 * stroke as f32;
            let dir = Vec3::new(a.cos(), 0.0, a.sin());
            let s = |i: usize| (i as f32 - 4.0) * 0.006 + 0.002 * stroke as f32;
            let on = |x: f32| {
                let p = dir * x + Vec3::Y * half.y;
                // Onto the surface along the radius, 4 mm deep.
                let r = p.normalize();
                let surface = r * (half / r.abs().max(Vec3::splat(1e-6))).min_element();
                (surface - r * 0.004, r * 0.03)
            };
            let (from, blade) = on(s(k % 8));
            let (to, _) = on(s(k % 8 + 1));
            out.push(TearSegment { from, to, blade });
        }
        out
    }

    #[test]
    fn the_patched_render_mesh_is_the_rebuilt_one() {
        for mesh in [
            Mesh::icosphere(0.1, 3),
            Mesh::cuboid(Vec3::new(0.1, 0.06, 0.04), 4),
        ] {
            let mut t = TearMesh::new(&mesh, 0.003).unwrap();
            let mut clipped = 0;
            for (i, seg) in segments(&mesh, 40).iter().enumerate() {
                if i % 8 == 0 {
                    t.lift();
                }
                clipped += t.tear(seg).unwrap().faces_clipped;
                let mut fresh = t.clone();
                fresh
                    .render
                    .rebuild(&fresh.faces, &fresh.corner_normals, &fresh.alive);
                let m = t.to_mesh();
                assert_eq!(m, fresh.to_mesh(), "segment {i}");
                // Each live face, in order, with its corners' positions and normals.
                let live: Vec<usize> = (0..t.faces.len()).filter(|&f| t.alive[f]).collect();
                assert_eq!(m.triangles.len(), live.len());
                let normals = m.normals.as_ref().unwrap();
                for (tri, &f) in m.triangles.iter().zip(&live) {
                    for (k, &r) in tri.iter().enumerate() {
                        let r = r as usize;
                        assert_eq!(m.positions[r], t.positions[t.faces[f][k] as usize]);
                        assert_eq!(bits(normals[r]), bits(t.corner_normals[f][k]));
                    }
                }
                // Every render vertex used, none twice.
                let mut used = vec![false; m.positions.len()];
                m.triangles
                    .iter()
                    .flatten()
                    .for_each(|&r| used[r as usize] = true);
                assert!(used.iter().all(|&u| u));
                let mut keys: Vec<_> = m
                    .positions
                    .iter()
                    .zip(normals)
                    .map(|(p, n)| (bits(*p), bits(*n)))
                    .collect();
                keys.sort_unstable();
                keys.dedup();
                assert_eq!(keys.len(), m.positions.len());
            }
            assert!(clipped > 100, "the strokes tore: {clipped}");
        }
    }

    #[test]
    fn box_edges_lie_on_the_planes_they_name() {
        let b = TearBox {
            planes: [
                HalfSpace {
                    normal: -Vec3::X,
                    offset: 0.0,
                },
                HalfSpace {
                    normal: Vec3::X,
                    offset: 1.0,
                },
                HalfSpace {
                    normal: -Vec3::Z,
                    offset: 0.5,
                },
                HalfSpace {
                    normal: Vec3::Z,
                    offset: 0.5,
                },
                HalfSpace {
                    normal: -Vec3::Y,
                    offset: 0.0,
                },
                HalfSpace {
                    normal: Vec3::Y,
                    offset: 2.0,
                },
            ],
        };
        let c = b.corners().unwrap();
        for (i, j) in BOX_EDGES {
            for p in box_edge_planes(i, j) {
                for q in [c[i], c[j]] {
                    assert!(b.planes[p].distance(q).abs() < 1e-6, "{i}-{j} plane {p}");
                }
            }
        }
    }

    #[test]
    fn a_shift_clears_every_vertex() {
        let d = [-1e-5, 0.0, 3e-5, 5.5e-5, 2e-4];
        let s = clear_shift(&d, 0.0);
        assert!(d.iter().all(|&x| (x - s).abs() > CLEARANCE_M), "{s}");
        assert!(s < 1.2e-4, "the least such shift: {s}");
        assert_eq!(clear_shift(&[1.0], 0.0), 0.0);
    }
}
