//! The plane cut (tear paper Algorithm 2) and the separation into pieces.
//!
//! Steps, each a pass over the welded triangles in their order (so the output is a pure
//! function of the input):
//! 1. Weld the render mesh (seams must not split a cross-section outline) and keep each
//!    triangle corner's render normal.
//! 2. Choose the plane offset: if a vertex lies within `eps` (20 µm, or 10⁻⁵ of the mesh's
//!    size if larger) of the plane, the plane moves by a few `eps` (at most 12) so no vertex
//!    sits on it and every crossing edge has one interior intersection point — no zero-length
//!    edges, no special cases.
//! 3. Split every crossing triangle: its lone vertex keeps one triangle, the other side a quad
//!    cut along its shorter diagonal. Each intersection point is computed once per welded edge
//!    (from the edge's lower-numbered end, so both faces agree to the bit) and each side gets
//!    its own copy of it.
//! 4. Cap: the crossing triangles' segments are the section's outline; `cap` triangulates it
//!    and both sides take its triangles, wound outward.
//! 5. Separate: each side's connected components become the pieces.

use std::collections::HashMap;

use glam::Vec3;

use super::{cap, CutError, CutPlane, MAX_CUT_TRIANGLES};
use crate::mesh::{bounds, enclosed_volume, Mesh};

/// Which side of the plane a piece lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    /// Where the plane's normal points.
    Positive,
    /// The other side.
    Negative,
}

/// One connected piece after a cut: a render mesh of its own.
#[derive(Clone, Debug)]
pub struct Piece {
    /// The piece's render mesh: surface vertices keep their (interpolated) normals; cap
    /// vertices are separate render vertices with the cap's flat normal.
    pub mesh: Mesh,
    /// Its side of the plane.
    pub side: Side,
    /// How many of its triangles belong to the cap.
    pub cap_triangles: usize,
    /// Its enclosed volume, m³ (meaningful when the cut was capped).
    pub volume_m3: f32,
}

/// The result of a cut.
#[derive(Clone, Debug)]
pub struct Cut {
    /// The pieces, positive side first, each side's in order of their first triangle.
    pub pieces: Vec<Piece>,
    /// Intersection points added (each appears once per side).
    pub intersection_points: usize,
    /// Whether the section was capped. An open mesh (an edge not shared by exactly two faces)
    /// has no inside to cap: its pieces stay open like the input.
    pub capped: bool,
    /// How far the plane was moved along its normal so that no vertex lay on it, metres.
    pub plane_shift_m: f32,
    /// Outline segments the cap triangulation had to drop because they crossed another (a
    /// self-intersecting input mesh); 0 for a sound mesh.
    pub cap_conflicts: usize,
}

/// Welding tolerance for cutting: positions that the simulation would weld (1 µm) are one.
const WELD_EPS_M: f32 = 1e-6;

/// Least distance of any vertex from the (shifted) plane, metres.
const CLEARANCE_M: f32 = 2e-5;

/// Two intersection points of one triangle closer than this become one, metres.
const MERGE_M: f32 = 5e-6;

/// How a triangle crosses the plane.
struct Crossing {
    /// Its corner alone on its side.
    lone: usize,
    /// The point on the edge from the lone corner to the next.
    lx: u32,
    /// The point on the edge from the previous corner to the lone one.
    yl: u32,
    /// The lone corner's weight in `lx` and in `yl`.
    w_lx: f32,
    w_yl: f32,
}

/// Cuts `mesh` by `plane` into closed pieces.
///
/// Refuses (and changes nothing) when the plane does not cross the mesh or the mesh is
/// unusable. A cut always separates the two sides: the plane is unbounded, as in the paper. A
/// partial incision that leaves the object in one piece is a tear, not a cut.
pub fn cut_mesh(mesh: &Mesh, plane: &CutPlane) -> Result<Cut, CutError> {
    if mesh.triangles.len() > MAX_CUT_TRIANGLES {
        return Err(CutError::Mesh(format!(
            "{} triangles, more than the {MAX_CUT_TRIANGLES} a cut accepts",
            mesh.triangles.len()
        )));
    }
    mesh.validate("cut input")
        .map_err(|e| CutError::Mesh(e.to_string()))?;
    if !(plane.normal.is_finite() && plane.offset_m.is_finite()) {
        return Err(CutError::NonFinite("plane"));
    }
    let welded = mesh.weld(WELD_EPS_M);
    let pos = &welded.positions;
    let tris = &welded.triangles;
    let corner_normals = corner_normals(mesh, &welded.positions, tris);

    let (lo, hi) = bounds(pos);
    let size = (hi - lo).max_element().max(1e-6);
    // Clearance: new vertices at least this far from old ones, well above the 1 µm at which
    // the simulation welds vertices (`SoftBodyConfig::weld_epsilon_m`), so a piece never has
    // two vertices the next weld would merge.
    let eps = (1e-5 * size).max(CLEARANCE_M);
    let (shift, dist) = choose_offset(pos, plane, eps);
    if dist.iter().all(|&s| s > 0.0) || dist.iter().all(|&s| s < 0.0) {
        return Err(CutError::Misses);
    }
    let closed = is_closed(tris);

    // Pass 3a: the intersection points, one per crossing welded edge.
    let mut cut_points: Vec<Vec3> = Vec::new();
    let mut cut_of_edge: HashMap<(u32, u32), u32> = HashMap::new();
    // Per crossing triangle: (its lone corner, point on edge lone→next, point on prev→lone,
    // the lone corner's weight in each point).
    let mut crossings: Vec<Option<Crossing>> = Vec::with_capacity(tris.len());
    for tri in tris {
        let s = tri.map(|v| dist[v as usize] > 0.0);
        if s[0] == s[1] && s[1] == s[2] {
            crossings.push(None);
            continue;
        }
        let k = (0..3)
            .find(|&k| s[(k + 1) % 3] == s[(k + 2) % 3])
            .unwrap_or(0);
        let (l, x, y) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
        let mut point = |a: u32, b: u32| -> (u32, f32) {
            let (e0, e1) = (a.min(b), a.max(b));
            let t = dist[e0 as usize] / (dist[e0 as usize] - dist[e1 as usize]);
            let id = *cut_of_edge.entry((e0, e1)).or_insert_with(|| {
                cut_points.push(pos[e0 as usize].lerp(pos[e1 as usize], t));
                (cut_points.len() - 1) as u32
            });
            (id, if a == e0 { 1.0 - t } else { t })
        };
        let (lx, w_lx) = point(l, x);
        let (yl, w_yl) = point(y, l);
        crossings.push(Some(Crossing {
            lone: k,
            lx,
            yl,
            w_lx,
            w_yl,
        }));
    }
    // Pass 3b: a sliver triangle (two nearly parallel edges) puts its two points closer than
    // the simulation's weld: they become one point (the triangle's lone part collapses), so
    // no piece has two vertices the next weld would merge.
    let mut alias = DisjointSets::new(cut_points.len());
    for c in crossings.iter().flatten() {
        if cut_points[c.lx as usize].distance(cut_points[c.yl as usize]) < MERGE_M {
            alias.union(c.lx, c.yl);
        }
    }

    // Pass 3c: split.
    let mut sides = [SideBuilder::new(pos.len()), SideBuilder::new(pos.len())];
    let mut segments: Vec<[u32; 2]> = Vec::new();
    for ((tri, ns), crossing) in tris.iter().zip(&corner_normals).zip(&crossings) {
        let Some(c) = crossing else {
            let b = &mut sides[side_index(dist[tri[0] as usize] > 0.0)];
            let v = tri.map(|i| b.original(i, pos));
            b.push(v, *ns);
            continue;
        };
        let k = c.lone;
        let (l, x, y) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
        let (nl, nx, ny) = (ns[k], ns[(k + 1) % 3], ns[(k + 2) % 3]);
        let (c_lx, c_yl) = (alias.find(c.lx), alias.find(c.yl));
        let n_lx = (nl * c.w_lx + nx * (1.0 - c.w_lx)).normalize_or_zero();
        let n_yl = (nl * c.w_yl + ny * (1.0 - c.w_yl)).normalize_or_zero();
        let merged = c_lx == c_yl;
        if !merged {
            // The outline segment, directed as the lone side's triangle runs (l → lx → yl).
            segments.push([c_lx, c_yl]);
        }

        let lone = &mut sides[side_index(dist[l as usize] > 0.0)];
        let (vl, vlx, vyl) = (
            lone.original(l, pos),
            lone.cut(c_lx, &cut_points),
            lone.cut(c_yl, &cut_points),
        );
        if !merged {
            lone.push([vl, vlx, vyl], [nl, n_lx, n_yl]);
        }

        let other = &mut sides[side_index(dist[x as usize] > 0.0)];
        let (vx, vy, wlx, wyl) = (
            other.original(x, pos),
            other.original(y, pos),
            other.cut(c_lx, &cut_points),
            other.cut(c_yl, &cut_points),
        );
        if merged {
            other.push([wlx, vx, vy], [n_lx, nx, ny]);
            continue;
        }
        // The quad lx → x → y → yl, split along its shorter diagonal.
        let p_lx = cut_points[c_lx as usize];
        let p_yl = cut_points[c_yl as usize];
        if p_lx.distance_squared(pos[y as usize]) <= pos[x as usize].distance_squared(p_yl) {
            other.push([wlx, vx, vy], [n_lx, nx, ny]);
            other.push([wlx, vy, wyl], [n_lx, ny, n_yl]);
        } else {
            other.push([wlx, vx, wyl], [n_lx, nx, n_yl]);
            other.push([vx, vy, wyl], [nx, ny, n_yl]);
        }
    }

    // Pass 4: cap.
    let mut cap_conflicts = 0;
    let mut cap_tris = [0usize; 2];
    if closed {
        let section = cap::triangulate_section(&cut_points, &segments, plane.normal);
        cap_conflicts = section.conflicts;
        // Section triangles face +normal: the negative side's outward direction.
        for (si, flip, n) in [(0usize, true, -plane.normal), (1, false, plane.normal)] {
            let b = &mut sides[si];
            for t in &section.triangles {
                let v = t.map(|c| b.cut(c, &cut_points));
                let v = if flip { [v[0], v[2], v[1]] } else { v };
                b.push_cap(v, n);
                cap_tris[si] += 1;
            }
        }
    }

    // Pass 5: separate.
    let mut pieces = Vec::new();
    for (si, side) in [(0usize, Side::Positive), (1, Side::Negative)] {
        for mut piece in sides[si].pieces() {
            piece.side = side;
            pieces.push(piece);
        }
    }
    Ok(Cut {
        pieces,
        intersection_points: cut_points.len(),
        capped: closed,
        plane_shift_m: shift,
        cap_conflicts,
    })
}

fn side_index(positive: bool) -> usize {
    if positive {
        0
    } else {
        1
    }
}

/// Each triangle corner's normal: the render normal if the mesh has them, else the welded
/// vertex's area-weighted normal.
pub(super) fn corner_normals(mesh: &Mesh, pos: &[Vec3], tris: &[[u32; 3]]) -> Vec<[Vec3; 3]> {
    match &mesh.normals {
        Some(ns) if ns.len() == mesh.positions.len() => mesh
            .triangles
            .iter()
            .map(|t| t.map(|r| ns[r as usize]))
            .collect(),
        _ => {
            let mut vn = vec![Vec3::ZERO; pos.len()];
            for t in tris {
                let [a, b, c] = t.map(|i| pos[i as usize]);
                let n = (b - a).cross(c - a);
                for &i in t {
                    vn[i as usize] += n;
                }
            }
            tris.iter()
                .map(|t| t.map(|i| vn[i as usize].normalize_or_zero()))
                .collect()
        }
    }
}

/// Moves the plane (by whole steps of `3 eps`, alternating sides, at most 4 steps each way)
/// until no vertex is within `eps` of it. Returns the shift and the signed distances.
fn choose_offset(pos: &[Vec3], plane: &CutPlane, eps: f32) -> (f32, Vec<f32>) {
    let mut dist = vec![0.0f32; pos.len()];
    for k in [0i32, 1, -1, 2, -2, 3, -3, 4, -4] {
        let shift = k as f32 * 3.0 * eps;
        let d = plane.offset_m + shift;
        let mut clear = true;
        for (s, p) in dist.iter_mut().zip(pos) {
            *s = plane.normal.dot(*p) - d;
            clear &= s.abs() > eps;
        }
        if clear {
            return (shift, dist);
        }
    }
    // Nine offsets all touched a vertex (a mesh with vertices every 3 eps along the normal):
    // keep the last one and give an exactly-on-plane vertex the positive side.
    for s in &mut dist {
        if *s == 0.0 {
            *s = f32::MIN_POSITIVE;
        }
    }
    (-4.0 * 3.0 * eps, dist)
}

/// Whether every undirected edge is shared by exactly two triangles.
fn is_closed(tris: &[[u32; 3]]) -> bool {
    let mut count: HashMap<(u32, u32), u32> = HashMap::with_capacity(tris.len() * 3 / 2);
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    count.values().all(|&c| c == 2)
}

/// One side's mesh under construction: its own vertex numbering, triangles and corner
/// normals.
struct SideBuilder {
    positions: Vec<Vec3>,
    of_original: Vec<u32>,
    of_cut: Vec<u32>,
    triangles: Vec<[u32; 3]>,
    normals: Vec<[Vec3; 3]>,
    is_cap: Vec<bool>,
}

impl SideBuilder {
    fn new(original_vertices: usize) -> Self {
        Self {
            positions: Vec::new(),
            of_original: vec![u32::MAX; original_vertices],
            of_cut: Vec::new(),
            triangles: Vec::new(),
            normals: Vec::new(),
            is_cap: Vec::new(),
        }
    }

    fn original(&mut self, v: u32, pos: &[Vec3]) -> u32 {
        let slot = &mut self.of_original[v as usize];
        if *slot == u32::MAX {
            *slot = self.positions.len() as u32;
            self.positions.push(pos[v as usize]);
        }
        *slot
    }

    fn cut(&mut self, c: u32, cut_points: &[Vec3]) -> u32 {
        if self.of_cut.len() <= c as usize {
            self.of_cut.resize(c as usize + 1, u32::MAX);
        }
        let slot = &mut self.of_cut[c as usize];
        if *slot == u32::MAX {
            *slot = self.positions.len() as u32;
            self.positions.push(cut_points[c as usize]);
        }
        *slot
    }

    fn push(&mut self, t: [u32; 3], n: [Vec3; 3]) {
        self.triangles.push(t);
        self.normals.push(n);
        self.is_cap.push(false);
    }

    fn push_cap(&mut self, t: [u32; 3], n: Vec3) {
        self.triangles.push(t);
        self.normals.push([n; 3]);
        self.is_cap.push(true);
    }

    /// Splits into connected components (triangles sharing a vertex), each as a render mesh
    /// whose render vertices are the distinct (vertex, normal) pairs in order of first use.
    fn pieces(&self) -> Vec<Piece> {
        let mut sets = DisjointSets::new(self.positions.len());
        for t in &self.triangles {
            sets.union(t[0], t[1]);
            sets.union(t[0], t[2]);
        }
        let mut piece_of_root: HashMap<u32, usize> = HashMap::new();
        let mut builders: Vec<PieceBuilder> = Vec::new();
        for (t, tri) in self.triangles.iter().enumerate() {
            let root = sets.find(tri[0]);
            let idx = *piece_of_root.entry(root).or_insert_with(|| {
                builders.push(PieceBuilder::default());
                builders.len() - 1
            });
            let b = &mut builders[idx];
            let out = std::array::from_fn(|k| {
                b.vertex(self.positions[tri[k] as usize], tri[k], self.normals[t][k])
            });
            b.triangles.push(out);
            b.cap_triangles += usize::from(self.is_cap[t]);
        }
        builders.into_iter().map(PieceBuilder::finish).collect()
    }
}

/// One piece's render mesh under construction.
#[derive(Default)]
pub(super) struct PieceBuilder {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    pub(super) triangles: Vec<[u32; 3]>,
    cap_triangles: usize,
    render_of: HashMap<(u32, [u32; 3]), u32>,
}

impl PieceBuilder {
    /// The render vertex for side vertex `v` with normal `n`, made on first use.
    pub(super) fn vertex(&mut self, p: Vec3, v: u32, n: Vec3) -> u32 {
        let key = (v, n.to_array().map(f32::to_bits));
        *self.render_of.entry(key).or_insert_with(|| {
            self.positions.push(p);
            self.normals.push(n);
            (self.positions.len() - 1) as u32
        })
    }

    pub(super) fn finish(self) -> Piece {
        let volume_m3 = enclosed_volume(&self.positions, &self.triangles);
        Piece {
            mesh: Mesh {
                positions: self.positions,
                normals: Some(self.normals),
                triangles: self.triangles,
            },
            side: Side::Positive,
            cap_triangles: self.cap_triangles,
            volume_m3,
        }
    }
}

/// Union–find over vertex ids; the smaller root always wins, so the result does not depend
/// on the order of unions.
pub(super) struct DisjointSets {
    parent: Vec<u32>,
}

impl DisjointSets {
    pub(super) fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
        }
    }

    pub(super) fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let up = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = up;
            x = up;
        }
        x
    }

    pub(super) fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}
