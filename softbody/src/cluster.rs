//! Clustering mesh vertices into particles (thesis 3.1, tear paper Algorithm 3) and the
//! particle map built from it (thesis 3.2.1, Appendix A.4–5).
//!
//! The thesis sorts every remaining vertex by distance for each particle, O(n² log n); here
//! every query goes through a uniform grid, so clustering is about O(n log n) overall.

use std::collections::HashMap;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::SoftBodyError;

/// How vertices are grouped into particles (Appendix A item 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "method")]
pub enum ClusterMethod {
    /// Thesis 3.1.1: each particle takes the `vertices_per_particle` closest unclustered
    /// vertices (Appendix A item 6, "division").
    ClosestN {
        /// Vertices per particle (≥ 1).
        vertices_per_particle: u32,
    },
    /// Thesis 3.1.2: each particle takes every unclustered vertex within `radius_m`
    /// (Appendix A item 7, "creation distance").
    Distance {
        /// Clustering radius in metres.
        radius_m: f32,
    },
    /// Thesis 3.1.3: two layers; vertices within `radius_m` are claimed, vertices within
    /// `soft_radius_m` are shared, and each vertex gets inverse-distance weights (Figure 3.6).
    WeightedDistance {
        /// Inner (claiming) radius in metres.
        radius_m: f32,
        /// Outer (sharing) radius in metres, the "soft interaction distance" (item 9).
        soft_radius_m: f32,
    },
    /// Tear paper Algorithm 3: Poisson-disk samples among the vertices as anchors, every vertex
    /// within `radius_m` of an anchor assigned with a smooth falloff weight.
    PoissonDisk {
        /// Disk radius in metres.
        radius_m: f32,
        /// Seed of the sampling order.
        seed: u64,
    },
}

impl ClusterMethod {
    /// Short name for tables and RESULT lines.
    pub fn name(&self) -> &'static str {
        match self {
            ClusterMethod::ClosestN { .. } => "closest_n",
            ClusterMethod::Distance { .. } => "distance",
            ClusterMethod::WeightedDistance { .. } => "weighted",
            ClusterMethod::PoissonDisk { .. } => "poisson",
        }
    }

    fn validate(&self) -> Result<(), SoftBodyError> {
        let ok = |r: f32| r.is_finite() && r > 0.0;
        match *self {
            ClusterMethod::ClosestN {
                vertices_per_particle: 0,
            } => Err(SoftBodyError::Config(
                "closest_n: vertices_per_particle must be at least 1".into(),
            )),
            ClusterMethod::Distance { radius_m } | ClusterMethod::PoissonDisk { radius_m, .. }
                if !ok(radius_m) =>
            {
                Err(SoftBodyError::Config(format!(
                    "{}: radius_m must be a positive length, got {radius_m}",
                    self.name()
                )))
            }
            ClusterMethod::WeightedDistance {
                radius_m,
                soft_radius_m,
            } if !ok(radius_m) || !ok(soft_radius_m) || soft_radius_m < radius_m => {
                Err(SoftBodyError::Config(format!(
                    "weighted: need 0 < radius_m ({radius_m}) <= soft_radius_m ({soft_radius_m})"
                )))
            }
            _ => Ok(()),
        }
    }
}

/// Compressed rows: `offsets[i]..offsets[i+1]` index `ids` and `weights`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WeightedRows {
    /// Row starts, one more than the number of rows.
    pub offsets: Vec<u32>,
    /// Column ids.
    pub ids: Vec<u32>,
    /// Weights, parallel to `ids`.
    pub weights: Vec<f32>,
}

impl WeightedRows {
    fn from_lists(lists: &[Vec<(u32, f32)>]) -> Self {
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

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Row `i` as (ids, weights).
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        let (a, b) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        (&self.ids[a..b], &self.weights[a..b])
    }

    /// The transpose (columns become rows), with `cols` rows.
    pub fn transpose(&self, cols: usize) -> Self {
        let mut lists: Vec<Vec<(u32, f32)>> = vec![Vec::new(); cols];
        for i in 0..self.rows() {
            let (ids, ws) = self.row(i);
            for (&j, &w) in ids.iter().zip(ws) {
                lists[j as usize].push((i as u32, w));
            }
        }
        Self::from_lists(&lists)
    }
}

/// The particle map: which vertices each particle moves and by how much, and which particles
/// are neighbours (tear paper 3.3.1; thesis 3.2.1).
#[derive(Clone, Debug)]
pub struct ParticleMap {
    /// Rest positions of the particles, in the body's local frame.
    pub rest_particles: Vec<Vec3>,
    /// Collider radius of each particle before `particle_scale`, in metres: half the distance
    /// to its nearest particle (capped at twice the median).
    pub particle_extent_m: Vec<f32>,
    /// Particle → (vertex, weight).
    pub particle_vertices: WeightedRows,
    /// Vertex → (particle, weight); every soft vertex's weights sum to 1.
    pub vertex_particles: WeightedRows,
    /// Particle → (neighbour particle, clamp(1 − d/δ, 0, 1)).
    pub neighbours: WeightedRows,
    /// Per vertex: true if it is simulated, false if it follows the center rigidly (3.5.2).
    pub soft_vertex: Vec<bool>,
}

impl ParticleMap {
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.rest_particles.len()
    }

    /// True if no vertex is soft.
    pub fn is_empty(&self) -> bool {
        self.rest_particles.is_empty()
    }
}

/// A uniform grid over points for radius and nearest queries.
struct PointGrid {
    inv_cell: f32,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl PointGrid {
    fn new(points: &[Vec3], ids: impl Iterator<Item = u32>, cell_m: f32) -> Self {
        let mut g = PointGrid {
            inv_cell: 1.0 / cell_m.max(1e-6),
            cells: HashMap::new(),
        };
        for i in ids {
            let k = g.key(points[i as usize]);
            g.cells.entry(k).or_default().push(i);
        }
        g
    }

    fn key(&self, p: Vec3) -> [i64; 3] {
        let q = (p * self.inv_cell).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    }

    fn remove(&mut self, points: &[Vec3], i: u32) {
        let k = self.key(points[i as usize]);
        if let Some(list) = self.cells.get_mut(&k) {
            if let Some(pos) = list.iter().position(|&x| x == i) {
                list.swap_remove(pos);
            }
        }
    }

    /// Calls `f` for every point within `r` of `p`.
    fn within(&self, points: &[Vec3], p: Vec3, r: f32, mut f: impl FnMut(u32, f32)) {
        let lo = self.key(p - Vec3::splat(r));
        let hi = self.key(p + Vec3::splat(r));
        let r2 = r * r;
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    if let Some(list) = self.cells.get(&[x, y, z]) {
                        for &i in list {
                            let d2 = points[i as usize].distance_squared(p);
                            if d2 <= r2 {
                                f(i, d2.sqrt());
                            }
                        }
                    }
                }
            }
        }
    }

    /// The `k` nearest points to `p` (ties broken by index), by expanding shells of cells;
    /// after `MAX_SHELLS` shells (far-apart parts of a mesh) every remaining point is tried,
    /// so the cost stays bounded whatever the geometry.
    fn nearest(&self, points: &[Vec3], p: Vec3, k: usize, total: usize, out: &mut Vec<(f32, u32)>) {
        const MAX_SHELLS: i64 = 8;
        out.clear();
        if k == 0 {
            return;
        }
        let c = self.key(p);
        let cell = 1.0 / self.inv_cell;
        let mut seen = 0usize;
        let by_distance = |a: &(f32, u32), b: &(f32, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
        for shell in 0..=MAX_SHELLS {
            // Only the surface of the (2·shell+1)³ cube is new.
            for x in -shell..=shell {
                for y in -shell..=shell {
                    let rim = x.abs() == shell || y.abs() == shell;
                    let mut visit = |z: i64| {
                        if let Some(list) = self.cells.get(&[c[0] + x, c[1] + y, c[2] + z]) {
                            for &i in list {
                                seen += 1;
                                out.push((points[i as usize].distance(p), i));
                            }
                        }
                    };
                    if rim {
                        (-shell..=shell).for_each(&mut visit);
                    } else {
                        visit(-shell);
                        if shell != 0 {
                            visit(shell);
                        }
                    }
                }
            }
            // Every point within `shell * cell` of p has been seen.
            if out.len() >= k {
                out.sort_unstable_by(by_distance);
                if out[k - 1].0 <= shell as f32 * cell || seen >= total {
                    out.truncate(k);
                    return;
                }
            } else if seen >= total {
                out.sort_unstable_by(by_distance);
                return;
            }
        }
        out.clear();
        for list in self.cells.values() {
            for &i in list {
                out.push((points[i as usize].distance(p), i));
            }
        }
        out.sort_unstable_by(by_distance);
        out.truncate(k);
    }
}

/// Mean length of the mesh's triangle edges (a natural length scale for grids and radii).
pub fn mean_edge_length(positions: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for t in triangles {
        for k in 0..3 {
            sum += positions[t[k] as usize].distance(positions[t[(k + 1) % 3] as usize]) as f64;
            n += 1;
        }
    }
    if n == 0 {
        0.0
    } else {
        (sum / n as f64) as f32
    }
}

/// The greedy cover shared by the closest-N and distance methods (thesis 3.2.1): in vertex
/// order, each soft vertex not yet clustered anchors a particle whose (vertex, raw weight)
/// list `gather` returns; `gather` marks the vertices it takes as clustered.
fn greedy_clusters(
    positions: &[Vec3],
    soft: &[u32],
    mut gather: impl FnMut(u32, &mut [bool]) -> Vec<(u32, f32)>,
) -> (Vec<Vec<(u32, f32)>>, Vec<Vec3>) {
    let mut members = Vec::new();
    let mut anchors = Vec::new();
    let mut clustered = vec![false; positions.len()];
    for &v in soft {
        if clustered[v as usize] {
            continue;
        }
        members.push(gather(v, &mut clustered));
        anchors.push(positions[v as usize]);
    }
    (members, anchors)
}

/// Clusters the soft vertices of `positions` into particles and builds the particle map.
///
/// `soft_vertex[v]` false excludes vertex `v` (restricted soft region, thesis 3.5.2);
/// `affect_range_m` is the neighbour distance δ of thesis 3.2.1.
pub fn build_particle_map(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    soft_vertex: &[bool],
    method: ClusterMethod,
    affect_range_m: f32,
) -> Result<ParticleMap, SoftBodyError> {
    method.validate()?;
    if !(affect_range_m.is_finite() && affect_range_m >= 0.0) {
        return Err(SoftBodyError::Config(format!(
            "affect_range_m must be a length >= 0, got {affect_range_m}"
        )));
    }
    let soft: Vec<u32> = (0..positions.len() as u32)
        .filter(|&v| soft_vertex[v as usize])
        .collect();
    if soft.is_empty() {
        return Err(SoftBodyError::Config(
            "no vertex lies in the soft region".into(),
        ));
    }
    let edge = mean_edge_length(positions, triangles).max(1e-4);
    // Particle → list of (vertex, raw weight).
    let mut members: Vec<Vec<(u32, f32)>> = Vec::new();
    let mut anchors: Vec<Vec3> = Vec::new();
    let mut recenter = true;
    match method {
        ClusterMethod::ClosestN {
            vertices_per_particle,
        } => {
            let n = vertices_per_particle as usize;
            let cell = edge * (n as f32).sqrt().max(1.0);
            let mut grid = PointGrid::new(positions, soft.iter().copied(), cell);
            let mut remaining = soft.len();
            let mut near = Vec::new();
            (members, anchors) = greedy_clusters(positions, &soft, |v, clustered| {
                clustered[v as usize] = true;
                grid.remove(positions, v);
                remaining -= 1;
                grid.nearest(
                    positions,
                    positions[v as usize],
                    n - 1,
                    remaining,
                    &mut near,
                );
                let mut list = vec![(v, 1.0)];
                for &(_, u) in &near {
                    clustered[u as usize] = true;
                    grid.remove(positions, u);
                    remaining -= 1;
                    list.push((u, 1.0));
                }
                list
            });
        }
        ClusterMethod::Distance { radius_m } => {
            let mut grid = PointGrid::new(positions, soft.iter().copied(), radius_m);
            (members, anchors) = greedy_clusters(positions, &soft, |v, clustered| {
                let mut list = Vec::new();
                grid.within(positions, positions[v as usize], radius_m, |u, _| {
                    list.push((u, 1.0))
                });
                list.sort_unstable_by_key(|e| e.0);
                for &(u, _) in &list {
                    clustered[u as usize] = true;
                    grid.remove(positions, u);
                }
                list
            });
        }
        ClusterMethod::WeightedDistance {
            radius_m,
            soft_radius_m,
        } => {
            let grid = PointGrid::new(positions, soft.iter().copied(), soft_radius_m);
            (members, anchors) = greedy_clusters(positions, &soft, |v, clustered| {
                let mut list = Vec::new();
                grid.within(positions, positions[v as usize], soft_radius_m, |u, d| {
                    list.push((u, 1.0));
                    if d <= radius_m {
                        clustered[u as usize] = true;
                    }
                });
                list.sort_unstable_by_key(|e| e.0);
                list
            });
        }
        ClusterMethod::PoissonDisk { radius_m, seed } => {
            recenter = false;
            // Dart throwing over the vertices in a seeded order; trying every vertex makes the
            // sampling maximal, so every vertex lies within radius_m of some anchor.
            let mut order = soft.clone();
            let mut rng = SplitMix64(seed);
            for i in (1..order.len()).rev() {
                let j = (rng.next_u64() % (i as u64 + 1)) as usize;
                order.swap(i, j);
            }
            let mut accepted = PointGrid::new(positions, std::iter::empty(), radius_m);
            for &v in &order {
                let p = positions[v as usize];
                let mut blocked = false;
                accepted.within(positions, p, radius_m, |_, d| blocked |= d < radius_m);
                if !blocked {
                    anchors.push(p);
                    let k = accepted.key(p);
                    accepted.cells.entry(k).or_default().push(v);
                }
            }
            let all = PointGrid::new(positions, soft.iter().copied(), radius_m);
            for &a in &anchors {
                let mut list = Vec::new();
                all.within(positions, a, radius_m, |u, d| {
                    let x = d / radius_m;
                    // Smooth falloff, never exactly zero inside the disk.
                    list.push((u, (1.0 - x * x).powi(2) + 1e-3));
                });
                list.sort_unstable_by_key(|e| e.0);
                members.push(list);
            }
        }
    }

    // Appendix A.4: a particle sits at the mean of its vertices.
    let mut rest: Vec<Vec3> = anchors;
    if recenter {
        for (p, list) in rest.iter_mut().zip(&members) {
            *p = list
                .iter()
                .map(|&(v, _)| positions[v as usize])
                .sum::<Vec3>()
                / list.len() as f32;
        }
    }

    // Per-vertex weights.
    let mut vertex_lists: Vec<Vec<(u32, f32)>> = vec![Vec::new(); positions.len()];
    for (p, list) in members.iter().enumerate() {
        for &(v, w) in list {
            vertex_lists[v as usize].push((p as u32, w));
        }
    }
    for (v, list) in vertex_lists.iter_mut().enumerate() {
        if list.is_empty() {
            continue;
        }
        match method {
            ClusterMethod::WeightedDistance { .. } => {
                // Figure 3.6: w_k = (1 - d_k / D) / Σ_j (1 - d_j / D), D = Σ d. With one
                // particle (or all at distance 0) the thesis divides 0 by 0; the weight is 1.
                let d: Vec<f32> = list
                    .iter()
                    .map(|&(p, _)| positions[v].distance(rest[p as usize]))
                    .collect();
                let total: f32 = d.iter().sum();
                let raw: Vec<f32> = d
                    .iter()
                    .map(|&dk| if total > 0.0 { 1.0 - dk / total } else { 1.0 })
                    .collect();
                let sum: f32 = raw.iter().sum();
                for (e, r) in list.iter_mut().zip(raw) {
                    e.1 = if sum > 0.0 {
                        r / sum
                    } else {
                        1.0 / d.len() as f32
                    };
                }
            }
            _ => {
                let sum: f32 = list.iter().map(|e| e.1).sum();
                for e in list.iter_mut() {
                    e.1 /= sum;
                }
            }
        }
    }
    let vertex_particles = WeightedRows::from_lists(&vertex_lists);
    let particle_vertices = vertex_particles.transpose(rest.len());

    // Collider extent: half the distance to the nearest other particle, so neighbouring
    // colliders just touch and tile the surface; capped at twice the median, since closest-N's
    // last particles sit among scattered leftovers.
    let mut particle_extent_m: Vec<f32> = {
        let spacing = (edge * 4.0).max(1e-4);
        let pg = PointGrid::new(&rest, 0..rest.len() as u32, spacing);
        let mut near = Vec::new();
        (0..rest.len())
            .map(|p| {
                pg.nearest(&rest, rest[p], 2, rest.len(), &mut near);
                let d = near
                    .iter()
                    .find(|e| e.1 as usize != p)
                    .map(|e| e.0)
                    .unwrap_or(edge);
                (0.5 * d).max(0.25 * edge)
            })
            .collect()
    };
    let mut sorted = particle_extent_m.clone();
    sorted.sort_unstable_by(f32::total_cmp);
    let cap = 2.0 * sorted[sorted.len() / 2];
    particle_extent_m.iter_mut().for_each(|e| *e = e.min(cap));

    // Thesis 3.2.1 / A.5: neighbours within δ with weight clamp(1 - d/δ, 0, 1).
    let mut neigh: Vec<Vec<(u32, f32)>> = vec![Vec::new(); rest.len()];
    if affect_range_m > 0.0 {
        let pg = PointGrid::new(&rest, 0..rest.len() as u32, affect_range_m);
        for (i, list) in neigh.iter_mut().enumerate() {
            pg.within(&rest, rest[i], affect_range_m, |j, d| {
                let w = (1.0 - d / affect_range_m).clamp(0.0, 1.0);
                if j as usize != i && w > 0.0 {
                    list.push((j, w));
                }
            });
            list.sort_unstable_by_key(|e| e.0);
        }
    }
    Ok(ParticleMap {
        rest_particles: rest,
        particle_extent_m,
        particle_vertices,
        vertex_particles,
        neighbours: WeightedRows::from_lists(&neigh),
        soft_vertex: soft_vertex.to_vec(),
    })
}

/// A small seeded generator (SplitMix64): randomness is always an explicit seed here.
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The particle weights of a vertex at `p` that joins the mesh after clustering (a tear's new
/// vertex: tear paper Algorithm 4 line 1, "as in Line 9 of" Algorithm 3), by `method`'s own
/// scheme over the particle rest positions `particles`:
/// - closest-N and distance (a partition: one particle per vertex): the nearest particle;
/// - weighted distance: every particle within `soft_radius_m`, weights of Figure 3.6;
/// - Poisson disk: every particle within `radius_m`, the smooth falloff, normalised.
///
/// With no particle in range the nearest one takes it alone. Ties go to the lower index; the
/// result is sorted by particle and its weights sum to 1 (empty only without particles).
pub fn weights_for_point(method: ClusterMethod, particles: &[Vec3], p: Vec3) -> Vec<(u32, f32)> {
    let nearest = || {
        // The first of the nearest (a plain loop: this runs for every vertex a tear adds).
        let mut best: Option<(f32, u32)> = None;
        for (i, q) in particles.iter().enumerate() {
            let d = q.distance_squared(p);
            if best.is_none_or(|(b, _)| d < b) {
                best = Some((d, i as u32));
            }
        }
        match best {
            Some((d, i)) if d.is_finite() => vec![(i, 1.0)],
            // Non-finite distances: ordered as before, by `total_cmp`.
            _ => particles
                .iter()
                .enumerate()
                .map(|(i, q)| (q.distance_squared(p), i as u32))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
                .map(|(_, i)| vec![(i, 1.0)])
                .unwrap_or_default(),
        }
    };
    let within = |r: f32| -> Vec<(u32, f32)> {
        particles
            .iter()
            .enumerate()
            .filter_map(|(i, q)| {
                let d = q.distance(p);
                (d <= r).then_some((i as u32, d))
            })
            .collect()
    };
    let mut out: Vec<(u32, f32)> = match method {
        ClusterMethod::ClosestN { .. } | ClusterMethod::Distance { .. } => return nearest(),
        ClusterMethod::WeightedDistance { soft_radius_m, .. } => {
            let near = within(soft_radius_m);
            // Figure 3.6, as in `build_particle_map`.
            let total: f32 = near.iter().map(|e| e.1).sum();
            near.into_iter()
                .map(|(i, d)| (i, if total > 0.0 { 1.0 - d / total } else { 1.0 }))
                .collect()
        }
        ClusterMethod::PoissonDisk { radius_m, .. } => within(radius_m)
            .into_iter()
            .map(|(i, d)| {
                let x = d / radius_m;
                (i, (1.0 - x * x).powi(2) + 1e-3)
            })
            .collect(),
    };
    let sum: f32 = out.iter().map(|e| e.1).sum();
    if out.is_empty() || !(sum > 0.0 && sum.is_finite()) {
        return nearest();
    }
    out.iter_mut().for_each(|e| e.1 /= sum);
    out
}
