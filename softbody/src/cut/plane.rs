//! Over 800 lines: the split, the exact weld and the piece builder share one numbering of
//! welded vertices; the weld can move to `cut/weld.rs` in the next clean-up.
//!
//! The plane cut (tear paper Algorithm 2) and the separation into pieces.
//!
//! Steps, each a pass over the welded triangles in their order (so the output is a pure
//! function of the input):
//! 1. Weld the render mesh (seams must not split a cross-section outline) and keep each
//!    triangle corner's render normal. [`weld_positions`] gives `Mesh::weld`'s numbering bit
//!    for bit at a fraction of its cost (a coarser grid, a fast hash, no normal slots): it
//!    was two thirds of a cut's time.
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
use std::hash::{BuildHasherDefault, Hasher};

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
    check_cut_input(mesh, plane)?;
    let (welded_positions, welded_triangles) =
        weld_positions(&mesh.positions, &mesh.triangles, WELD_EPS_M);
    cut_checked(mesh, &welded_positions, &welded_triangles, plane)
}

/// [`cut_mesh`] of a mesh already welded: `positions` and `triangles` are its welded form
/// (what a soft body keeps from its build or last tear: each render triangle's corners as
/// welded vertices, numbered by first use), so the cut does not weld again — the weld is most
/// of a cut's time, and a body has paid it once. The welded form must match the mesh: one
/// welded triangle per render triangle, every corner within the weld tolerance of its render
/// vertex; else refused. With the welded form `cut_mesh` would make, the result is identical.
pub fn cut_welded(
    mesh: &Mesh,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    plane: &CutPlane,
) -> Result<Cut, CutError> {
    check_cut_input(mesh, plane)?;
    let n = positions.len();
    if triangles.len() != mesh.triangles.len() || n > mesh.positions.len() {
        return Err(CutError::Mesh(format!(
            "welded form of {n} vertices and {} triangles for a mesh of {} and {}",
            triangles.len(),
            mesh.positions.len(),
            mesh.triangles.len()
        )));
    }
    let tolerance_sq = (2.0 * WELD_EPS_M) * (2.0 * WELD_EPS_M);
    for (w, r) in triangles.iter().zip(&mesh.triangles) {
        for k in 0..3 {
            let ok = positions.get(w[k] as usize).is_some_and(|p| {
                p.is_finite() && p.distance_squared(mesh.positions[r[k] as usize]) <= tolerance_sq
            });
            if !ok {
                return Err(CutError::Mesh(
                    "the welded form does not match the mesh's triangles".into(),
                ));
            }
        }
    }
    cut_checked(mesh, positions, triangles, plane)
}

/// What a cut refuses before it looks at the geometry.
fn check_cut_input(mesh: &Mesh, plane: &CutPlane) -> Result<(), CutError> {
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
    Ok(())
}

/// The cut proper, on a checked mesh and its welded form `pos`, `tris`.
fn cut_checked(
    mesh: &Mesh,
    pos: &[Vec3],
    tris: &[[u32; 3]],
    plane: &CutPlane,
) -> Result<Cut, CutError> {
    let corner_normals = corner_normals(mesh, pos, tris);

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
    let closed = is_closed(pos.len(), tris);

    // Pass 3a: the intersection points, one per crossing welded edge.
    let mut cut_points: Vec<Vec3> = Vec::new();
    let mut cut_of_edge: IdMap<(u32, u32), u32> = IdMap::default();
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
    let mut sides = [
        SideBuilder::new(pos.len(), tris.len()),
        SideBuilder::new(pos.len(), tris.len()),
    ];
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
            for n in &mut vn {
                *n = n.normalize_or_zero();
            }
            tris.iter().map(|t| t.map(|i| vn[i as usize])).collect()
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

/// Whether every undirected edge of `tris` (over `vertex_count` vertices) is shared by exactly
/// two triangles. Each edge is filed under its lower end (a compressed row per vertex) and a
/// row's upper ends must each appear twice: linear, where a hash map per edge cost a tenth of
/// a cut.
fn is_closed(vertex_count: usize, tris: &[[u32; 3]]) -> bool {
    let edge = |t: &[u32; 3], k: usize| {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        (a.min(b) as usize, a.max(b))
    };
    let mut start = vec![0u32; vertex_count + 1];
    for t in tris {
        for k in 0..3 {
            start[edge(t, k).0 + 1] += 1;
        }
    }
    for v in 0..vertex_count {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut upper = vec![0u32; tris.len() * 3];
    for t in tris {
        for k in 0..3 {
            let (lo, hi) = edge(t, k);
            upper[fill[lo] as usize] = hi;
            fill[lo] += 1;
        }
    }
    start.windows(2).all(|w| {
        let row = &mut upper[w[0] as usize..w[1] as usize];
        if row.len() <= 16 {
            // A vertex's few edges: counting beats sorting.
            row.iter()
                .all(|u| row.iter().filter(|&x| x == u).count() == 2)
        } else {
            row.sort_unstable();
            row.chunk_by(|a, b| a == b).all(|run| run.len() == 2)
        }
    })
}

/// FxHash's mixing step with a final rotation (as rustc-hash 2 does, so the low bits a table
/// indexes by depend on every input bit): for the integer keys of the maps here. Deterministic;
/// no map here is iterated in an order that reaches the output.
#[derive(Clone, Copy, Default)]
pub(super) struct IdHasher(u64);

impl Hasher for IdHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut b = [0u8; 8];
            b[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(b));
        }
    }

    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0xf135_7aea_2e62_a9c5);
    }

    fn write_u32(&mut self, i: u32) {
        self.write_u64(u64::from(i));
    }

    fn write_i64(&mut self, i: i64) {
        self.write_u64(i as u64);
    }

    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }

    fn finish(&self) -> u64 {
        self.0.rotate_left(26)
    }
}

/// A hash map over integer keys with [`IdHasher`].
pub(super) type IdMap<K, V> = HashMap<K, V, BuildHasherDefault<IdHasher>>;

/// `Mesh::weld(epsilon_m)`'s positions and triangles, identical to the bit (the same welded
/// numbering): each vertex joins the earlier welded vertex within `epsilon_m` that `weld`'s
/// search would find first — its 27 grid cells of side `epsilon_m` in order, then insertion
/// order — else starts a new one. Found through a grid four times coarser (about three cells
/// looked up instead of 27) with a fast hash; any input is accepted (a non-finite position
/// never welds, as in `weld`).
pub(super) fn weld_positions(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    epsilon_m: f32,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let eps = epsilon_m.max(1e-9);
    // `weld`'s cell key, computed exactly as it does.
    let fine = |p: Vec3| -> [i64; 3] {
        let q = (p / eps).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    };
    // A vertex within `eps` of `p` lies within `eps (1 + 3·2⁻²⁴)` of it on every axis (the
    // float distance test's rounding); 1 % of margin covers that.
    let coarse = 1.0 / (4.0 * f64::from(eps));
    let reach = 1.01 * f64::from(eps);
    // ⌊x⌋ (saturating; NaN gives 0, as `floor() as i64` does) without a call to libm's floor.
    let floor = |x: f64| {
        let t = x as i64;
        t.saturating_sub(i64::from(x < t as f64))
    };
    // Cells within ±2²⁰ on every axis (a mesh 8 m across at the 1 µm weld) go in a flat
    // table of packed keys; anything else (far, huge or non-finite) in a hash map.
    let packable = positions.iter().all(|p| {
        p.to_array().iter().all(|&x| {
            let c = f64::from(x) * coarse;
            c.abs() < f64::from(1u32 << 20) - 2.0
        })
    });
    let mut head = if packable {
        CellHeads::Packed(PackedCells::new(positions.len()))
    } else {
        let mut m = IdMap::default();
        m.reserve(positions.len());
        CellHeads::Map(m)
    };
    let mut next: Vec<u32> = Vec::with_capacity(positions.len());
    let mut welded: Vec<Vec3> = Vec::with_capacity(positions.len());
    let mut map: Vec<u32> = Vec::with_capacity(positions.len());
    for &p in positions {
        let pd = [f64::from(p.x), f64::from(p.y), f64::from(p.z)];
        let lo = pd.map(|x| floor((x - reach) * coarse));
        let hi = pd.map(|x| floor((x + reach) * coarse));
        // (offset of the cell in `weld`'s search order, welded id) of the best match; the
        // cell keys only for vertices within `eps` (few).
        let mut best: Option<([i128; 3], u32)> = None;
        for cx in lo[0]..=hi[0].min(lo[0].saturating_add(2)) {
            for cy in lo[1]..=hi[1].min(lo[1].saturating_add(2)) {
                for cz in lo[2]..=hi[2].min(lo[2].saturating_add(2)) {
                    let mut w = head.get([cx, cy, cz]);
                    while w != u32::MAX {
                        let wi = w as usize;
                        if welded[wi].distance_squared(p) <= eps * eps {
                            let (kw, kp) = (fine(welded[wi]), fine(p));
                            let off: [i128; 3] =
                                std::array::from_fn(|a| i128::from(kw[a]) - i128::from(kp[a]));
                            if off.iter().all(|o| o.abs() <= 1) && best.is_none_or(|b| (off, w) < b)
                            {
                                best = Some((off, w));
                            }
                        }
                        w = next[wi];
                    }
                }
            }
        }
        let w = match best {
            Some((_, w)) => w,
            None => {
                let w = welded.len() as u32;
                next.push(head.replace(pd.map(|x| floor(x * coarse)), w));
                welded.push(p);
                w
            }
        };
        map.push(w);
    }
    let tris = triangles
        .iter()
        .map(|t| t.map(|i| map.get(i as usize).copied().unwrap_or(u32::MAX)))
        .collect();
    (welded, tris)
}

/// The first vertex of each grid cell's list (`u32::MAX`: none).
enum CellHeads {
    Packed(PackedCells),
    Map(IdMap<[i64; 3], u32>),
}

impl CellHeads {
    fn get(&self, c: [i64; 3]) -> u32 {
        match self {
            CellHeads::Packed(t) => t.get(c),
            CellHeads::Map(m) => m.get(&c).copied().unwrap_or(u32::MAX),
        }
    }

    /// Makes `w` the cell's first vertex; returns the one before it.
    fn replace(&mut self, c: [i64; 3], w: u32) -> u32 {
        match self {
            CellHeads::Packed(t) => t.replace(c, w),
            CellHeads::Map(m) => m.insert(c, w).unwrap_or(u32::MAX),
        }
    }
}

/// An open-addressing table (linear probing, at most half full) from cells with coordinates
/// in ±2²⁰ packed in a `u64` to their first vertex.
struct PackedCells {
    keys: Vec<u64>,
    heads: Vec<u32>,
    shift: u32,
}

impl PackedCells {
    const EMPTY: u64 = u64::MAX;

    fn new(vertices: usize) -> Self {
        let size = (2 * vertices).next_power_of_two().max(16);
        Self {
            keys: vec![Self::EMPTY; size],
            heads: vec![u32::MAX; size],
            shift: 64 - size.trailing_zeros(),
        }
    }

    fn pack(c: [i64; 3]) -> u64 {
        c.iter()
            .fold(0u64, |k, &x| (k << 21) | (x as u64 & 0x1f_ffff))
    }

    /// The slot holding `key`, or the empty one where it would go.
    fn slot(&self, key: u64) -> usize {
        let mask = self.keys.len() - 1;
        let mut i = (key.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> self.shift) as usize;
        while self.keys[i] != key && self.keys[i] != Self::EMPTY {
            i = (i + 1) & mask;
        }
        i
    }

    fn get(&self, c: [i64; 3]) -> u32 {
        self.heads[self.slot(Self::pack(c))]
    }

    fn replace(&mut self, c: [i64; 3], w: u32) -> u32 {
        let key = Self::pack(c);
        let i = self.slot(key);
        self.keys[i] = key;
        std::mem::replace(&mut self.heads[i], w)
    }
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
    fn new(original_vertices: usize, original_triangles: usize) -> Self {
        Self {
            positions: Vec::with_capacity(original_vertices),
            of_original: vec![u32::MAX; original_vertices],
            of_cut: Vec::new(),
            triangles: Vec::with_capacity(original_triangles),
            normals: Vec::with_capacity(original_triangles),
            is_cap: Vec::with_capacity(original_triangles),
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
        let mut piece_of_root: Vec<u32> = vec![u32::MAX; self.positions.len()];
        let mut builders: Vec<PieceBuilder> = Vec::new();
        // A vertex belongs to one piece, so one table serves them all.
        let mut render = RenderVertices::new(self.positions.len());
        for (t, tri) in self.triangles.iter().enumerate() {
            let root = sets.find(tri[0]) as usize;
            if piece_of_root[root] == u32::MAX {
                piece_of_root[root] = builders.len() as u32;
                builders.push(PieceBuilder::default());
            }
            let b = &mut builders[piece_of_root[root] as usize];
            let out = std::array::from_fn(|k| {
                let (v, n) = (tri[k], self.normals[t][k]);
                render.get_or_insert(v, n, || b.push_vertex(self.positions[v as usize], n))
            });
            b.triangles.push(out);
            b.cap_triangles += usize::from(self.is_cap[t]);
        }
        builders.into_iter().map(PieceBuilder::finish).collect()
    }
}

/// Render vertices keyed by (vertex, normal bits), no hashing: each vertex's first normal in
/// place, any further ones (a crease, a cut point's per-face normals) in a chain.
pub(super) struct RenderVertices {
    /// Per vertex: (normal bits, render vertex, first further entry), render `u32::MAX` if
    /// none yet.
    first: Vec<([u32; 3], u32, u32)>,
    /// (normal bits, render vertex, next further entry of the same vertex).
    further: Vec<([u32; 3], u32, u32)>,
}

impl RenderVertices {
    pub(super) fn new(vertices: usize) -> Self {
        Self {
            first: vec![([0; 3], u32::MAX, u32::MAX); vertices],
            further: Vec::new(),
        }
    }

    /// The render vertex of vertex `v` with normal `n`; `make` creates it on first use.
    pub(super) fn get_or_insert(&mut self, v: u32, n: Vec3, make: impl FnOnce() -> u32) -> u32 {
        let bits = n.to_array().map(f32::to_bits);
        let v = v as usize;
        if v >= self.first.len() {
            self.first.resize(v + 1, ([0; 3], u32::MAX, u32::MAX));
        }
        let (b, r, mut e) = self.first[v];
        if r == u32::MAX {
            let r = make();
            self.first[v] = (bits, r, u32::MAX);
            return r;
        }
        if b == bits {
            return r;
        }
        let mut last = None;
        while e != u32::MAX {
            let (b, r, next) = self.further[e as usize];
            if b == bits {
                return r;
            }
            last = Some(e);
            e = next;
        }
        let r = make();
        let id = self.further.len() as u32;
        self.further.push((bits, r, u32::MAX));
        match last {
            None => self.first[v].2 = id,
            Some(l) => self.further[l as usize].2 = id,
        }
        r
    }
}

/// One piece's render mesh under construction.
#[derive(Default)]
pub(super) struct PieceBuilder {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    pub(super) triangles: Vec<[u32; 3]>,
    cap_triangles: usize,
}

impl PieceBuilder {
    /// Adds a render vertex; returns its index.
    fn push_vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        self.positions.push(p);
        self.normals.push(n);
        (self.positions.len() - 1) as u32
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `weld_positions` against `Mesh::weld` on `m`.
    fn same_weld(m: &Mesh, eps: f32) {
        let w = m.weld(eps);
        let (p, t) = weld_positions(&m.positions, &m.triangles, eps);
        assert_eq!(p.len(), w.positions.len());
        assert!(p
            .iter()
            .zip(&w.positions)
            .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits)));
        assert_eq!(t, w.triangles);
    }

    #[test]
    fn the_fast_weld_is_the_weld() {
        same_weld(&Mesh::icosphere(0.1, 3), 1e-6);
        same_weld(&Mesh::cuboid(Vec3::new(0.1, 0.06, 0.04), 6), 1e-6);
        // Clusters of points a fraction of `eps` to a few `eps` apart, straddling grid cells
        // on every axis: which earlier vertex wins depends on `weld`'s search order.
        let mut state = 0x1234_5678_u64;
        let mut unit = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let eps = 1e-3;
        let mut positions = Vec::new();
        for c in 0..300 {
            let centre = Vec3::new((c % 7) as f32, (c / 7 % 7) as f32, (c / 49) as f32) * eps;
            for _ in 0..6 {
                let j = Vec3::new(unit(), unit(), unit()) * 2.0 - Vec3::ONE;
                positions.push(centre + j * (1.5 * eps));
            }
        }
        let n = positions.len() as u32;
        let triangles = (0..n - 2).map(|i| [i, i + 1, i + 2]).collect();
        let m = Mesh {
            positions,
            normals: None,
            triangles,
        };
        let w = m.weld(eps);
        assert!(w.positions.len() < m.positions.len() / 2, "few welds");
        same_weld(&m, eps);
        same_weld(&m, eps * 0.3);
        // Non-finite positions (which `Mesh::weld` overflows on) never weld, and do not panic.
        let odd = [
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::new(f32::INFINITY, 0.0, 0.0),
            Vec3::new(f32::INFINITY, 0.0, 0.0),
            Vec3::new(-f32::INFINITY, 1e30, 0.0),
            Vec3::ZERO,
            Vec3::ZERO,
        ];
        let (p, t) = weld_positions(&odd, &[[0, 1, 5], [2, 3, 9]], 1e-6);
        assert_eq!(p.len(), 5);
        assert_eq!(t, vec![[0, 1, 4], [2, 3, u32::MAX]]);
    }

    #[test]
    fn edge_uses_count_each_undirected_edge() {
        let m = Mesh::icosphere(0.1, 1);
        assert!(is_closed(m.positions.len(), &m.triangles));
        let mut open = m.triangles.clone();
        open.pop();
        assert!(!is_closed(m.positions.len(), &open));
        let mut doubled = m.triangles.clone();
        doubled.push(m.triangles[0]);
        assert!(!is_closed(m.positions.len(), &doubled));
    }
}
