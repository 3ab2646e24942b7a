//! The particle map after a tear (tear paper Algorithm 4, §3.3.3): pure functions of the old
//! map, the torn mesh's vertices and the tear boxes.
//!
//! 1. Vertices the tear made join particles as in clustering ([`weights_for_point`]: the
//!    map's own method and weights).
//! 2. Two neighbouring particles whose connecting segment meets a tear box are no longer
//!    neighbours.
//! 3. A vertex and a particle's anchor on different sides of a box's *tear plane* (the plane
//!    halfway between its left and right faces, holding the scalpel's path) part, weights
//!    renormalised — where the paper checks "sufficiently close" boxes, "close" here means
//!    that the vertex lies in the box's *zone* (within the box along the cut and in depth,
//!    any distance sideways) or that the straight line from the anchor to the vertex crosses
//!    the tear plane inside that zone (Figure 10's red segments). A particle beyond the end
//!    of a slit keeps vertices on both sides: the material there still joins them.
//!
//! A vertex left with no particle takes the nearest one it can reach without crossing a tear
//! (no box separates them), among its 64 nearest; failing that (a vertex in the narrow wedge
//! where two slits meet at a sharp angle, with no particle in it), the nearest.
//!
//! Work per tear is incremental: pairs already checked against older boxes are checked only
//! against the new ones; a new vertex is checked against every box near it. Everything runs
//! in index order with index tie-breaks, so equal input gives bit-equal output on every peer.

use glam::Vec3;

use super::CutError;
use crate::cluster::{weights_for_point, ClusterMethod, ParticleMap, WeightedRows};

/// A tear box as six half-spaces `normals[k] · x <= offsets_m[k]`, in the order start, end,
/// left, right, bottom (the blade's tip), top (its back end); see [`super::TearMesh::box_for`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TearBoxPlanes {
    /// Outward unit normals.
    pub normals: [Vec3; 6],
    /// Offsets along the normals, metres.
    pub offsets_m: [f32; 6],
}

/// The hexahedron's faces meeting at each corner: (start|end, left|right, bottom|top).
const CORNER_FACES: [[usize; 3]; 8] = [
    [0, 2, 4],
    [1, 2, 4],
    [0, 3, 4],
    [1, 3, 4],
    [0, 2, 5],
    [1, 2, 5],
    [0, 3, 5],
    [1, 3, 5],
];

impl TearBoxPlanes {
    /// Signed distance of `p` from face `k` (positive outside), metres.
    pub fn face_distance(&self, k: usize, p: Vec3) -> f32 {
        self.normals[k].dot(p) - self.offsets_m[k]
    }

    /// True if `p` lies in the box grown by `margin_m` (shrunk if negative).
    pub fn contains(&self, p: Vec3, margin_m: f32) -> bool {
        (0..6).all(|k| self.face_distance(k, p) <= margin_m)
    }

    /// The tear's width: the distance between the left and right faces, metres.
    pub fn width_m(&self) -> f32 {
        self.offsets_m[2] + self.offsets_m[3]
    }

    /// Signed distance of `p` from the tear plane (halfway between left and right, through
    /// the scalpel's path), positive towards the right face, metres.
    pub fn tear_plane_distance(&self, p: Vec3) -> f32 {
        self.normals[3].dot(p) - 0.5 * (self.offsets_m[3] - self.offsets_m[2])
    }

    /// True if `p` lies within the box along the cut and in depth (start, end, bottom and
    /// top faces, grown by `tolerance_m`), at any distance sideways.
    pub fn in_zone(&self, p: Vec3, tolerance_m: f32) -> bool {
        [0, 1, 4, 5]
            .iter()
            .all(|&k| self.face_distance(k, p) <= tolerance_m)
    }

    /// Algorithm 4 line 4: whether the tear separates a particle anchored at `anchor` from a
    /// vertex at `v`. They lie on different sides of the tear plane (an anchor on the plane
    /// counts as the right side), and the vertex lies in the zone or the line between them
    /// crosses the tear plane in it ([`in_zone`](Self::in_zone), grown by `tolerance_m`).
    pub fn separates(&self, anchor: Vec3, v: Vec3, tolerance_m: f32) -> bool {
        let (da, dv) = (
            self.tear_plane_distance(anchor),
            self.tear_plane_distance(v),
        );
        if (da >= 0.0) == (dv >= 0.0) {
            return false;
        }
        if self.in_zone(v, tolerance_m) {
            return true;
        }
        // da and dv differ in sign, so da − dv is not zero.
        let q = anchor + (v - anchor) * (da / (da - dv));
        q.is_finite() && self.in_zone(q, tolerance_m)
    }

    /// True if the segment `a → b` meets the box grown by `margin_m` (shrunk if negative).
    pub fn meets_segment(&self, a: Vec3, b: Vec3, margin_m: f32) -> bool {
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        let d = b - a;
        for k in 0..6 {
            let (num, den) = (
                -(self.face_distance(k, a) - margin_m),
                self.normals[k].dot(d),
            );
            if den == 0.0 {
                if num < 0.0 {
                    return false;
                }
            } else {
                let t = num / den;
                if den < 0.0 {
                    t0 = t0.max(t);
                } else {
                    t1 = t1.min(t);
                }
                if t0 > t1 {
                    return false;
                }
            }
        }
        true
    }

    /// The box's corners' bounds (lo, hi), or `None` for a degenerate box.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for [a, b, c] in CORNER_FACES {
            let (na, nb, nc) = (self.normals[a], self.normals[b], self.normals[c]);
            let det = na.dot(nb.cross(nc));
            if det.abs() < 1e-6 {
                return None;
            }
            let p = (nb.cross(nc) * self.offsets_m[a]
                + nc.cross(na) * self.offsets_m[b]
                + na.cross(nb) * self.offsets_m[c])
                / det;
            if !p.is_finite() {
                return None;
            }
            lo = lo.min(p);
            hi = hi.max(p);
        }
        Some((lo, hi))
    }

    /// The same box moved by `t`.
    pub fn translated(&self, t: Vec3) -> Self {
        let mut out = *self;
        for k in 0..6 {
            out.offsets_m[k] += self.normals[k].dot(t);
        }
        out
    }
}

/// The torn mesh's vertices, as the particle update sees them.
#[derive(Clone, Copy, Debug)]
pub struct TornVertices<'a> {
    /// Rest positions, in the frame of the anchors and boxes.
    pub positions: &'a [Vec3],
    /// Per vertex: the vertex of the old map at the same rest position, or `None` for one
    /// the tear made.
    pub source: &'a [Option<u32>],
    /// Per vertex: simulated (true) or following the center rigidly.
    pub soft: &'a [bool],
}

/// What one particle update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ParticleUpdateStats {
    /// Vertices that kept their old rows.
    pub vertices_carried: usize,
    /// Vertices the tear made, given weights as in clustering (line 1).
    pub vertices_added: usize,
    /// Neighbour links removed (line 2), each counted once.
    pub links_removed: usize,
    /// Vertex–particle influences removed (line 4).
    pub influences_removed: usize,
    /// Vertices left with no particle that took the nearest reachable one.
    pub orphans_reattached: usize,
    /// Vertices left with no particle and none reachable: they took the nearest one.
    pub orphans_unreachable: usize,
}

/// Tear paper Algorithm 4 on `map` (see the module docs).
///
/// `anchors` are the particles' rest positions in the frame of `vertices` and `boxes`;
/// `boxes` holds every tear box applied to the body so far, the last `new_boxes` of them this
/// tear's; `tolerance_m` grows each box's zone along the cut and in depth (enough for the
/// clearance moves of the box planes, 0.1 mm: consecutive boxes share their end plane, so
/// their zones already tile the slit, and a crossing segment crosses the tear plane of the
/// box it passes through). Particle rest positions, extents and the particle count are kept. Refused for
/// inconsistent lengths or indices, never panics.
pub fn update_after_tear(
    map: &ParticleMap,
    anchors: &[Vec3],
    method: ClusterMethod,
    vertices: &TornVertices<'_>,
    boxes: &[TearBoxPlanes],
    new_boxes: usize,
    tolerance_m: f32,
) -> Result<(ParticleMap, ParticleUpdateStats), CutError> {
    let n = vertices.positions.len();
    let old_vertices = map.vertex_particles.rows();
    if anchors.len() != map.len()
        || vertices.source.len() != n
        || vertices.soft.len() != n
        || new_boxes > boxes.len()
        || map.neighbours.rows() != map.len()
        || vertices
            .source
            .iter()
            .flatten()
            .any(|&s| s as usize >= old_vertices)
    {
        return Err(CutError::Mesh(
            "particle update: inconsistent map, anchors or vertices".into(),
        ));
    }
    if !(tolerance_m.is_finite() && tolerance_m >= 0.0)
        || anchors
            .iter()
            .chain(vertices.positions)
            .any(|p| !p.is_finite())
    {
        return Err(CutError::NonFinite("particle update input"));
    }
    let pos = vertices.positions;
    let mut stats = ParticleUpdateStats::default();

    // Line 1: carried rows, and new vertices weighted as in clustering. Flat rows; a removed
    // entry gets the id `GONE` and is dropped at the end.
    const GONE: u32 = u32::MAX;
    let mut offsets: Vec<usize> = Vec::with_capacity(n + 1);
    let mut ids: Vec<u32> = Vec::with_capacity(map.vertex_particles.ids.len() + n);
    let mut weights: Vec<f32> = Vec::with_capacity(ids.capacity());
    let mut is_new = vec![false; n];
    offsets.push(0);
    for v in 0..n {
        if vertices.soft[v] {
            let carried = vertices.source[v]
                .map(|s| map.vertex_particles.row(s as usize))
                .filter(|r| !r.0.is_empty());
            match carried {
                Some((i, w)) => {
                    stats.vertices_carried += 1;
                    ids.extend_from_slice(i);
                    weights.extend_from_slice(w);
                }
                None => {
                    stats.vertices_added += 1;
                    is_new[v] = true;
                    for (i, w) in weights_for_point(method, anchors, pos[v]) {
                        ids.push(i);
                        weights.push(w);
                    }
                }
            }
        }
        offsets.push(ids.len());
    }

    let first_new = boxes.len() - new_boxes;
    let bounds: Vec<Option<(Vec3, Vec3)>> = boxes.iter().map(|b| b.bounds()).collect();
    let near = |k: usize, p: Vec3, r: f32| match bounds[k] {
        Some((lo, hi)) => p.cmpge(lo - Vec3::splat(r)).all() && p.cmple(hi + Vec3::splat(r)).all(),
        // A degenerate box: checked everywhere (the predicates stay exact).
        None => true,
    };

    // Line 2: neighbour links through a new box. A link is no longer than `longest`, so a
    // particle further than that from a box's bounds keeps all of its links.
    let longest = (0..map.len())
        .flat_map(|i| {
            let a = anchors[i];
            map.neighbours
                .row(i)
                .0
                .iter()
                .map(move |&j| a.distance_squared(anchors[j as usize]))
        })
        .fold(0.0f32, f32::max)
        .sqrt();
    let mut cut_links: Vec<(u32, u32)> = Vec::new();
    for (k, b) in boxes.iter().enumerate().skip(first_new) {
        for (i, &a) in anchors.iter().enumerate() {
            if !near(k, a, longest) {
                continue;
            }
            for &j in map.neighbours.row(i).0.iter().filter(|&&j| j as usize > i) {
                let c = anchors[j as usize];
                // A link whose bounds miss the box's cannot meet it.
                let misses = bounds[k]
                    .is_some_and(|(lo, hi)| a.min(c).cmpgt(hi).any() || a.max(c).cmplt(lo).any());
                if !misses && b.meets_segment(a, c, 0.0) {
                    cut_links.push((i as u32, j));
                }
            }
        }
    }
    cut_links.sort_unstable();
    cut_links.dedup();
    stats.links_removed = cut_links.len();
    let neighbours = if cut_links.is_empty() {
        map.neighbours.clone()
    } else {
        let mut r = WeightedRows {
            offsets: Vec::with_capacity(map.len() + 1),
            ..Default::default()
        };
        r.offsets.push(0);
        r.ids.reserve(map.neighbours.ids.len());
        r.weights.reserve(map.neighbours.ids.len());
        // Rows of particles no removed link touches are copied whole.
        let mut touches = vec![false; map.len()];
        for &(i, j) in &cut_links {
            touches[i as usize] = true;
            touches[j as usize] = true;
        }
        for (i, &touched) in touches.iter().enumerate() {
            let (js, ws) = map.neighbours.row(i);
            if touched {
                for (&j, &w) in js.iter().zip(ws) {
                    let key = (i.min(j as usize) as u32, i.max(j as usize) as u32);
                    if cut_links.binary_search(&key).is_err() {
                        r.ids.push(j);
                        r.weights.push(w);
                    }
                }
            } else {
                r.ids.extend_from_slice(js);
                r.weights.extend_from_slice(ws);
            }
            r.offsets.push(r.ids.len() as u32);
        }
        r
    };

    // Line 4: influences across a tear plane. A vertex further than `reach` from a box's
    // bounds cannot be separated by it from any of its particles.
    let reach = (0..n)
        .flat_map(|v| ids[offsets[v]..offsets[v + 1]].iter().map(move |&p| (v, p)))
        .map(|(v, p)| pos[v].distance_squared(anchors[p as usize]))
        .fold(0.0f32, f32::max)
        .sqrt()
        + tolerance_m;
    // Which side of each box's tear plane every anchor is on (as `separates` decides it):
    // only an entry whose vertex is on the other side needs the full test.
    let right_of: Vec<Vec<bool>> = boxes
        .iter()
        .map(|b| {
            anchors
                .iter()
                .map(|&a| b.tear_plane_distance(a) >= 0.0)
                .collect()
        })
        .collect();
    let mut touched = vec![false; n];
    for v in 0..n {
        let row = offsets[v]..offsets[v + 1];
        if row.is_empty() {
            continue;
        }
        // Old vertices against the new boxes; new vertices against every box.
        let from = if is_new[v] { 0 } else { first_new };
        for (k, b) in boxes.iter().enumerate().skip(from) {
            if !near(k, pos[v], reach) {
                continue;
            }
            let right = b.tear_plane_distance(pos[v]) >= 0.0;
            for e in row.clone() {
                if ids[e] != GONE
                    && right_of[k][ids[e] as usize] != right
                    && b.separates(anchors[ids[e] as usize], pos[v], tolerance_m)
                {
                    ids[e] = GONE;
                    stats.influences_removed += 1;
                    touched[v] = true;
                }
            }
        }
    }

    // Renormalise; a vertex left with none takes the nearest reachable particle among the
    // `SEARCH` nearest (no tear plane between them), else the nearest.
    const SEARCH: usize = 64;
    let mut order: Vec<(f32, u32)> = Vec::with_capacity(anchors.len());
    let by_distance = |a: &(f32, u32), b: &(f32, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
    for v in 0..n {
        if !touched[v] {
            continue;
        }
        let row = offsets[v]..offsets[v + 1];
        let kept = row.clone().filter(|&e| ids[e] != GONE);
        let (count, sum) = kept.fold((0usize, 0.0f32), |(c, s), e| (c + 1, s + weights[e]));
        if count > 0 {
            for e in row.filter(|&e| ids[e] != GONE) {
                weights[e] = if sum > 0.0 && sum.is_finite() {
                    weights[e] / sum
                } else {
                    1.0 / count as f32
                };
            }
            continue;
        }
        let p = pos[v];
        order.clear();
        order.extend(
            anchors
                .iter()
                .enumerate()
                .map(|(i, a)| (a.distance_squared(p), i as u32)),
        );
        let head = order.len().min(SEARCH);
        if head < order.len() {
            order.select_nth_unstable_by(head, by_distance);
        }
        order[..head].sort_unstable_by(by_distance);
        let reachable = |i: u32| {
            let a = anchors[i as usize];
            let r = a.distance(p) + tolerance_m;
            (0..boxes.len()).all(|k| !near(k, p, r) || !boxes[k].separates(a, p, tolerance_m))
        };
        let found = order[..head].iter().map(|e| e.1).find(|&i| reachable(i));
        let chosen = match found {
            Some(i) => {
                stats.orphans_reattached += 1;
                i
            }
            None => {
                stats.orphans_unreachable += 1;
                order[0].1
            }
        };
        // The row had an entry (all removed): it takes the one particle.
        ids[row.start] = chosen;
        weights[row.start] = 1.0;
    }

    // Compact, then the transpose by counting.
    let mut vertex_particles = WeightedRows {
        offsets: Vec::with_capacity(n + 1),
        ids: Vec::with_capacity(ids.len()),
        weights: Vec::with_capacity(ids.len()),
    };
    vertex_particles.offsets.push(0);
    for v in 0..n {
        for e in offsets[v]..offsets[v + 1] {
            if ids[e] != GONE {
                vertex_particles.ids.push(ids[e]);
                vertex_particles.weights.push(weights[e]);
            }
        }
        vertex_particles
            .offsets
            .push(vertex_particles.ids.len() as u32);
    }
    let particle_vertices = transpose(&vertex_particles, map.len());
    Ok((
        ParticleMap {
            rest_particles: map.rest_particles.clone(),
            particle_extent_m: map.particle_extent_m.clone(),
            particle_vertices,
            vertex_particles,
            neighbours,
            soft_vertex: vertices.soft.to_vec(),
        },
        stats,
    ))
}

/// The transpose of `rows` (ids below `cols`), rows in order: what
/// [`WeightedRows::transpose`] gives, by counting instead of a list per column.
fn transpose(rows: &WeightedRows, cols: usize) -> WeightedRows {
    let mut offsets = vec![0u32; cols + 1];
    for &j in &rows.ids {
        offsets[j as usize + 1] += 1;
    }
    for c in 0..cols {
        offsets[c + 1] += offsets[c];
    }
    let mut fill: Vec<u32> = offsets[..cols].to_vec();
    let mut ids = vec![0u32; rows.ids.len()];
    let mut weights = vec![0.0f32; rows.ids.len()];
    for i in 0..rows.rows() {
        let (js, ws) = rows.row(i);
        for (&j, &w) in js.iter().zip(ws) {
            let at = &mut fill[j as usize];
            ids[*at as usize] = i as u32;
            weights[*at as usize] = w;
            *at += 1;
        }
    }
    WeightedRows {
        offsets,
        ids,
        weights,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::cluster::build_particle_map;

    /// Compressed rows from per-row lists.
    fn rows_from_lists(lists: &[Vec<(u32, f32)>]) -> WeightedRows {
        let mut r = WeightedRows {
            offsets: Vec::with_capacity(lists.len() + 1),
            ..Default::default()
        };
        r.offsets.push(0);
        for l in lists {
            for &(i, w) in l {
                r.ids.push(i);
                r.weights.push(w);
            }
            r.offsets.push(r.ids.len() as u32);
        }
        r
    }

    #[test]
    fn transpose_by_counting_matches_the_map_s_own() {
        let (pos, tris) = grid(7);
        let map = map_of(
            &pos,
            &tris,
            ClusterMethod::WeightedDistance {
                radius_m: 0.012,
                soft_radius_m: 0.025,
            },
        );
        assert_eq!(
            transpose(&map.vertex_particles, map.len()),
            map.vertex_particles.transpose(map.len())
        );
        assert_eq!(
            transpose(&map.vertex_particles, map.len()),
            map.particle_vertices
        );
    }

    /// The box of a scalpel moving along +x from `x0` to `x1` at y = 0, blade along +z from
    /// `z0` to `z1`, `width` wide.
    fn slit(x0: f32, x1: f32, z0: f32, z1: f32, width: f32) -> TearBoxPlanes {
        TearBoxPlanes {
            normals: [-Vec3::X, Vec3::X, -Vec3::Y, Vec3::Y, -Vec3::Z, Vec3::Z],
            offsets_m: [-x0, x1, 0.5 * width, 0.5 * width, -z0, z1],
        }
    }

    /// A flat square grid of `k × k` vertices 1 cm apart in z = 0, centred at the origin,
    /// with two triangles per cell.
    fn grid(k: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let h = 0.01;
        let off = (k - 1) as f32 * h * 0.5;
        let mut pos = Vec::new();
        for j in 0..k {
            for i in 0..k {
                pos.push(Vec3::new(
                    i as f32 * h - off,
                    j as f32 * h - off + 0.003,
                    0.0,
                ));
            }
        }
        let mut tris = Vec::new();
        for j in 0..k - 1 {
            for i in 0..k - 1 {
                let a = j * k + i;
                tris.push([a, a + 1, a + k + 1]);
                tris.push([a, a + k + 1, a + k]);
            }
        }
        (pos, tris)
    }

    fn map_of(pos: &[Vec3], tris: &[[u32; 3]], method: ClusterMethod) -> ParticleMap {
        build_particle_map(pos, tris, &vec![true; pos.len()], method, 0.05).unwrap()
    }

    #[test]
    fn box_geometry() {
        let b = slit(-0.02, 0.02, -0.01, 0.01, 0.004);
        assert!((b.width_m() - 0.004).abs() < 1e-7);
        assert!(b.contains(Vec3::ZERO, 0.0));
        assert!(!b.contains(Vec3::new(0.0, 0.003, 0.0), 0.0));
        assert!(b.tear_plane_distance(Vec3::new(0.0, 0.003, 0.0)) > 0.0);
        let (lo, hi) = b.bounds().unwrap();
        assert!(
            (lo - Vec3::new(-0.02, -0.002, -0.01)).length() < 1e-6,
            "{lo}"
        );
        assert!((hi - Vec3::new(0.02, 0.002, 0.01)).length() < 1e-6, "{hi}");
        // Across the slit: separated; around its end: not; same side: not.
        let (l, r) = (Vec3::new(0.0, -0.01, 0.0), Vec3::new(0.0, 0.01, 0.0));
        assert!(b.separates(l, r, 0.0));
        assert!(b.meets_segment(l, r, 0.0));
        let beyond = Vec3::new(0.04, 0.0, 0.0);
        assert!(!b.separates(Vec3::new(0.04, -0.01, 0.0), Vec3::new(0.05, 0.01, 0.0), 0.0));
        assert!(!b.separates(l, l + Vec3::X * 0.01, 0.0));
        // A far-off anchor whose line crosses the plane beyond the slit keeps a vertex in
        // the zone only if the vertex is on its side.
        assert!(b.separates(beyond + Vec3::Y * 0.01, Vec3::new(0.0, -0.003, 0.0), 0.0));
        let moved = b.translated(Vec3::new(1.0, 0.0, 0.0));
        assert!(moved.contains(Vec3::new(1.0, 0.0, 0.0), 0.0));
        assert!(!moved.contains(Vec3::ZERO, 0.0));
    }

    #[test]
    fn a_slit_parts_particles_and_vertices_across_it() {
        let (pos, tris) = grid(13);
        for method in [
            ClusterMethod::ClosestN {
                vertices_per_particle: 3,
            },
            ClusterMethod::WeightedDistance {
                radius_m: 0.012,
                soft_radius_m: 0.025,
            },
            ClusterMethod::PoissonDisk {
                radius_m: 0.02,
                seed: 3,
            },
        ] {
            let map = map_of(&pos, &tris, method);
            let anchors = map.rest_particles.clone();
            // Two new vertices on the slit's rim.
            let mut torn = pos.clone();
            torn.push(Vec3::new(0.0, 0.002, 0.0));
            torn.push(Vec3::new(0.0, -0.002, 0.0));
            let mut source: Vec<Option<u32>> = (0..pos.len() as u32).map(Some).collect();
            source.extend([None, None]);
            let soft = vec![true; torn.len()];
            let b = slit(-0.025, 0.025, -0.01, 0.01, 0.004);
            let (out, stats) = update_after_tear(
                &map,
                &anchors,
                method,
                &TornVertices {
                    positions: &torn,
                    source: &source,
                    soft: &soft,
                },
                &[b],
                1,
                0.001,
            )
            .unwrap();
            assert_eq!(stats.vertices_added, 2, "{}", method.name());
            assert_eq!(out.len(), map.len());
            // Every soft vertex has weights summing to 1.
            for v in 0..torn.len() {
                let (ids, ws) = out.vertex_particles.row(v);
                assert!(!ids.is_empty(), "{} vertex {v}", method.name());
                assert!((ws.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            }
            // No particle moves vertices in the zone on both sides.
            for p in 0..out.len() {
                let (ids, _) = out.particle_vertices.row(p);
                let sides: Vec<bool> = ids
                    .iter()
                    .map(|&v| torn[v as usize])
                    .filter(|&q| b.in_zone(q, 0.0))
                    .map(|q| b.tear_plane_distance(q) >= 0.0)
                    .collect();
                assert!(
                    sides.iter().all(|&s| s) || sides.iter().all(|&s| !s),
                    "{}: particle {p} spans the slit",
                    method.name()
                );
            }
            // No neighbour link crosses the box.
            for i in 0..out.len() {
                for &j in out.neighbours.row(i).0 {
                    assert!(!b.meets_segment(anchors[i], anchors[j as usize], 0.0));
                }
            }
            assert!(stats.links_removed > 0, "{}: {stats:?}", method.name());
            // Beyond the slit's ends (by more than a particle's reach) nothing changed.
            for (v, p) in pos.iter().enumerate() {
                if p.x.abs() > 0.025 + 0.026 {
                    assert_eq!(out.vertex_particles.row(v), map.vertex_particles.row(v));
                }
            }
        }
    }

    #[test]
    fn an_orphan_takes_the_nearest_particle_on_its_side() {
        // One particle straddling the plane, one clearly on each side.
        let anchors = vec![
            Vec3::new(0.0, 0.0005, 0.0),
            Vec3::new(0.0, -0.02, 0.0),
            Vec3::new(0.0, 0.02, 0.0),
        ];
        let positions = vec![Vec3::new(0.0, -0.004, 0.0), Vec3::new(0.0, 0.004, 0.0)];
        let rows = vec![vec![(0u32, 1.0f32)], vec![(0, 1.0)]];
        let vertex_particles = rows_from_lists(&rows);
        let map = ParticleMap {
            rest_particles: anchors.clone(),
            particle_extent_m: vec![0.005; 3],
            particle_vertices: vertex_particles.transpose(3),
            vertex_particles,
            neighbours: rows_from_lists(&[vec![], vec![], vec![]]),
            soft_vertex: vec![true; 2],
        };
        let b = slit(-0.01, 0.01, -0.01, 0.01, 0.004);
        let (out, stats) = update_after_tear(
            &map,
            &anchors,
            ClusterMethod::Distance { radius_m: 0.01 },
            &TornVertices {
                positions: &positions,
                source: &[Some(0), Some(1)],
                soft: &[true, true],
            },
            &[b],
            1,
            0.001,
        )
        .unwrap();
        // The vertex below lost particle 0 (anchored above) and took particle 1, although
        // particle 0 is nearer.
        assert_eq!(out.vertex_particles.row(0), (&[1u32][..], &[1.0f32][..]));
        assert_eq!(out.vertex_particles.row(1), (&[0u32][..], &[1.0f32][..]));
        assert_eq!(stats.orphans_reattached, 1);
        assert_eq!(stats.orphans_unreachable, 0);
    }

    #[test]
    fn inconsistent_input_is_refused() {
        let (pos, tris) = grid(4);
        let m = ClusterMethod::Distance { radius_m: 0.015 };
        let map = map_of(&pos, &tris, m);
        let soft = vec![true; pos.len()];
        let source: Vec<Option<u32>> = (0..pos.len() as u32).map(Some).collect();
        let v = TornVertices {
            positions: &pos,
            source: &source,
            soft: &soft,
        };
        let b = slit(-0.01, 0.01, -0.01, 0.01, 0.004);
        assert!(update_after_tear(&map, &[], m, &v, &[b], 1, 0.001).is_err());
        assert!(update_after_tear(&map, &map.rest_particles, m, &v, &[b], 2, 0.001).is_err());
        let bad: Vec<Option<u32>> = vec![Some(999); pos.len()];
        let vb = TornVertices { source: &bad, ..v };
        assert!(update_after_tear(&map, &map.rest_particles, m, &vb, &[b], 1, 0.001).is_err());
        assert!(update_after_tear(&map, &map.rest_particles, m, &v, &[b], 1, f32::NAN).is_err());
        // No box: nothing changes.
        let (out, stats) =
            update_after_tear(&map, &map.rest_particles, m, &v, &[], 0, 0.001).unwrap();
        assert_eq!(out.vertex_particles, map.vertex_particles);
        assert_eq!(out.neighbours, map.neighbours);
        assert_eq!(stats.vertices_carried, pos.len());
    }
}
