//! Tears and cuts of a soft body (issue 14 point 3; tear paper §3.3.3): the rest mesh is torn
//! or cut in the rest frame, the welded and render meshes are rebuilt from it and the particle
//! map follows (Algorithm 4, in `cut::particles`); a cut's pieces are planned as new bodies.
//!
//! Everything here is a function of the rest mesh, the particle map and the event, never of
//! the simulated state, so every peer applying the same events gets the same topology and map.
//! Only a cut's *placement* of the pieces reads the state (the old center's pose and velocity
//! and the particles' displacement).

use rustc_hash::FxHashMap;

use glam::Vec3;
use rapier3d::prelude::PhysicsWorld;

use super::{neighbour_scale, BodyPlan, SoftBody, Spawn};
use crate::cluster::ClusterMethod;
use crate::cut::particles::{update_after_tear, TearBoxPlanes, TornVertices};
use crate::cut::{cut_welded, CutError, CutPlane, TearMesh, TearSegment, TearStats};
use crate::mesh::{enclosed_volume, Mesh, WeldedMesh};
use crate::{SoftBodyConfig, SoftBodyError};

/// A cut's piece that would get fewer particles than this is clustered finer (see
/// [`finer`]), at most [`MAX_REFINEMENTS`] times.
pub const MIN_PIECE_PARTICLES: usize = 4;

/// Most halvings of the clustering scale for one small piece.
pub const MAX_REFINEMENTS: u32 = 6;

/// How far beyond a tear box's ends and depth a vertex still counts as beside the slit: the
/// tear moves a box's planes out by 20–60 µm where they graze a vertex (0.5 mm at the very
/// most), and the rim's vertices lie on the moved planes. Consecutive boxes share their end
/// plane, so their zones tile the cut; a larger margin would make them overlap at a bend,
/// where a vertex is then on opposite sides of the two tear planes.
pub const ZONE_TOLERANCE_M: f32 = 1e-4;

/// Where the last tear segment's time went, per stage of the tear paper's Table 1, in
/// milliseconds as read from the set's [`StageClock`] (all zero without one; measured, never
/// used by the simulation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TearTimings {
    /// The clip of the faces in the segment's box ("perform tear").
    pub clip_ms: f64,
    /// The torn render mesh copied out ("update mesh").
    pub mesh_ms: f64,
    /// The welded mesh rebuilt and the new vertices matched to the old ones.
    pub weld_ms: f64,
    /// Algorithm 4: new vertices given particles, links across the box removed, influences
    /// across the tear plane removed and weights renormalised ("update particles",
    /// "disconnect particles", "calculate bone weights").
    pub particles_ms: f64,
    /// The body's arrays resized and its vertices placed from the new map.
    pub rebuild_ms: f64,
}

impl TearTimings {
    /// Every stage.
    pub fn total_ms(&self) -> f64 {
        self.clip_ms + self.mesh_ms + self.weld_ms + self.particles_ms + self.rebuild_ms
    }
}

/// A clock for profiling, in milliseconds from any fixed origin (the core crates take time as
/// an argument: a bench passes one that reads the wall clock, see
/// [`SoftBodySet::set_stage_clock`](crate::SoftBodySet::set_stage_clock)).
pub type StageClock = fn() -> f64;

/// Reads `clock` (0 without one) and returns the time since `*last`, which it moves on.
fn lap(clock: Option<StageClock>, last: &mut f64) -> f64 {
    let now = clock.map_or(0.0, |c| c());
    let d = now - *last;
    *last = now;
    d
}

fn position_key(p: Vec3) -> [u32; 3] {
    p.to_array().map(f32::to_bits)
}

/// The old welded vertex at each exact rest position: tears and cuts copy the positions of the
/// vertices they keep bit for bit, so this finds every kept vertex.
fn vertex_index(rest_vertices: &[Vec3]) -> FxHashMap<[u32; 3], u32> {
    rest_vertices
        .iter()
        .enumerate()
        .map(|(i, p)| (position_key(*p), i as u32))
        .collect()
}

impl SoftBody {
    /// Tears the rest mesh along `seg` (rest frame), rebuilds the meshes and updates the
    /// particle map (Algorithm 4). A refused segment changes nothing; a segment that meets no
    /// face changes nothing but the stroke (the next segment's box touches this one's).
    pub(crate) fn tear_rest(
        &mut self,
        world: &PhysicsWorld,
        seg: &TearSegment,
        clock: Option<StageClock>,
    ) -> Result<TearStats, CutError> {
        if self.tear.is_none() {
            self.tear = Some(TearMesh::new(
                &self.rest_mesh,
                self.config.effective_tear_width_m(),
            )?);
        }
        let Some(tear) = self.tear.as_mut() else {
            return Err(CutError::Mesh("the tear mesh could not be made".into()));
        };
        let mut t = 0.0;
        lap(clock, &mut t);
        let planes = tear.box_for(seg)?;
        let stats = tear.tear(seg)?;
        self.last_tear_timings = TearTimings {
            clip_ms: lap(clock, &mut t),
            ..TearTimings::default()
        };
        if stats.faces_clipped == 0 {
            return Ok(stats);
        }
        let mesh = tear.to_mesh();
        self.last_tear_timings.mesh_ms = lap(clock, &mut t);
        self.tear_boxes.push(planes);
        if let Err(e) = self.retopologise(mesh, world, clock, t) {
            // Cannot happen (the update's input is built right here); if it did, the body
            // keeps its last mesh and map, and the next tear starts from that mesh.
            self.tear_boxes.pop();
            self.tear = None;
            return Err(e);
        }
        self.open_slit(&planes);
        Ok(stats)
    }

    /// Tear paper §3.3.4, the wound opening: each particle beside the slit of box `b` (rest
    /// frame; within two particle sizes of its mid-plane, along the box's length and depth
    /// with that margin) has its anchor moved away from the slit, `slit_open_m` for one on the
    /// mid-plane fading linearly to nothing at two particle sizes, at most `slit_open_m` in
    /// all. The paper adds particles around the slit for this and notes their running time;
    /// moving the anchors of the particles already there (the tear has just given each side
    /// its own, Algorithm 4) opens the lips the same way without a new rapier body — and
    /// without changing the particle count a room replicates.
    fn open_slit(&mut self, b: &TearBoxPlanes) {
        let open = self.config.slit_open_m;
        if open <= 0.0 || self.rest_offsets.is_empty() {
            return;
        }
        // the box's planes: [start, end, -side, +side, -up, +up], outward normals
        let side = b.normals[3];
        let mid = 0.5 * (b.offsets_m[3] - b.offsets_m[2]);
        let size = self.map.particle_extent_m.iter().sum::<f32>()
            / self.map.particle_extent_m.len().max(1) as f32;
        let reach = (2.0 * size).max(1e-3);
        for (i, o) in self.rest_offsets.iter().enumerate() {
            let beside = [0usize, 1, 4, 5]
                .iter()
                .all(|&k| b.normals[k].dot(*o) <= b.offsets_m[k] + reach);
            let d = side.dot(*o) - mid;
            if !beside || d.abs() >= reach {
                continue;
            }
            let push = side * d.signum() * open * (1.0 - d.abs() / reach);
            let s = self.anchor_shift[i] + push;
            self.anchor_shift[i] = s.clamp_length_max(open);
        }
    }

    /// Ends the current tear stroke: the next segment starts a new slit.
    pub(crate) fn lift_tear(&mut self) {
        if let Some(t) = self.tear.as_mut() {
            t.lift();
        }
    }

    /// Makes `mesh` (rest frame, just torn by the last of `tear_boxes`) the body's mesh.
    /// `clock` and `t` (its last reading) time the stages.
    fn retopologise(
        &mut self,
        mesh: Mesh,
        world: &PhysicsWorld,
        clock: Option<StageClock>,
        mut t: f64,
    ) -> Result<(), CutError> {
        let (welded, index) = weld_exact(&mesh);
        let old = match self.rest_index.take() {
            Some(i) => i,
            None => vertex_index(&self.rest_vertices),
        };
        let source: Vec<Option<u32>> = welded
            .positions
            .iter()
            .map(|p| old.get(&position_key(*p)).copied())
            .collect();
        let soft: Vec<bool> = welded
            .positions
            .iter()
            .zip(&source)
            .map(|(p, s)| match (s, &self.config.soft_region) {
                (Some(s), _) => self.map.soft_vertex[*s as usize],
                (None, Some(region)) => region.contains(*p + self.rest_center),
                (None, None) => true,
            })
            .collect();
        self.last_tear_timings.weld_ms = lap(clock, &mut t);
        let (map, stats) = update_after_tear(
            &self.map,
            &self.rest_offsets,
            self.config.cluster,
            &TornVertices {
                positions: &welded.positions,
                source: &source,
                soft: &soft,
            },
            &self.tear_boxes,
            1,
            ZONE_TOLERANCE_M,
        )?;
        self.neighbour_scale = neighbour_scale(&map, self.config.neighbour_share);
        self.map = map;
        self.last_particle_update = stats;
        self.last_tear_timings.particles_ms = lap(clock, &mut t);
        // Open along the slit: the volume is that of the surface closed across it.
        self.rest_volume_m3 = enclosed_volume(&welded.positions, &welded.triangles);
        let n = welded.positions.len();
        self.vertices = vec![Vec3::ZERO; n];
        self.render_positions = vec![Vec3::ZERO; welded.render_to_welded.len()];
        self.render_normals = vec![Vec3::ZERO; welded.render_to_welded.len()];
        self.slot_normals = vec![Vec3::ZERO; welded.normal_slots];
        self.render_triangles = mesh.triangles.clone();
        self.rest_vertices = welded.positions.clone();
        self.rest_index = Some(index);
        let rest_center = self.rest_center;
        self.welded = WeldedMesh {
            positions: welded.positions.iter().map(|p| *p + rest_center).collect(),
            ..welded
        };
        self.rest_mesh = mesh;
        self.deform(world);
        self.last_tear_timings.rebuild_ms = lap(clock, &mut t);
        Ok(())
    }

    /// Plans the bodies `plane` (rest frame) cuts this body into: each piece clustered with
    /// this body's config (finer if small, see [`finer`]), placed where its part of this body
    /// is now and moving with it. Nothing changes here; a refused cut or piece refuses all.
    pub(crate) fn plan_cut(
        &self,
        world: &PhysicsWorld,
        plane: &CutPlane,
    ) -> Result<Vec<(BodyPlan, Spawn)>, CutError> {
        self.plan_cut_pieces(world, plane, None)
    }

    /// As [`plan_cut`](Self::plan_cut), planning only piece `only` if given (each piece's
    /// plan depends on its own part of the mesh alone, so it is the same either way): the
    /// one piece a peer keeps for one of the cut's objects. `only` past the pieces is an
    /// error.
    pub(crate) fn plan_cut_pieces(
        &self,
        world: &PhysicsWorld,
        plane: &CutPlane,
        only: Option<usize>,
    ) -> Result<Vec<(BodyPlan, Spawn)>, CutError> {
        // The body's welded rest mesh is the rest mesh's welded form (built or torn so).
        let cut = cut_welded(
            &self.rest_mesh,
            &self.rest_vertices,
            &self.welded.triangles,
            plane,
        )?;
        let center = world
            .bodies
            .get(self.center)
            .ok_or_else(|| CutError::Mesh("the body's center is not in this world".into()))?;
        let (c, r) = (center.translation(), *center.rotation());
        let (vc, wc) = (center.linvel(), center.angvel());
        if !(c.is_finite() && r.is_finite() && vc.is_finite() && wc.is_finite()) {
            return Err(CutError::NonFinite("the body's center state"));
        }
        let made;
        let old = match &self.rest_index {
            Some(i) => i,
            None => {
                made = vertex_index(&self.rest_vertices);
                &made
            }
        };
        // Each old vertex's displacement from where the center's rigid motion puts it.
        let displaced = |v: usize| {
            let d = self.vertices[v] - (c + r * self.rest_vertices[v]);
            if d.is_finite() {
                d
            } else {
                Vec3::ZERO
            }
        };
        if only.is_some_and(|k| k >= cut.pieces.len()) {
            return Err(CutError::Mesh(format!(
                "the cut makes {} pieces, not {}",
                cut.pieces.len(),
                only.map_or(0, |k| k + 1)
            )));
        }
        let mut out = Vec::with_capacity(cut.pieces.len());
        for (k, piece) in cut.pieces.iter().enumerate() {
            if only.is_some_and(|o| o != k) {
                continue;
            }
            // Back into the frame the body was built in, so its soft region still applies;
            // the piece's rest frame is this body's moved to the piece's own rest center.
            let baked = Mesh {
                positions: piece
                    .mesh
                    .positions
                    .iter()
                    .map(|p| *p + self.rest_center)
                    .collect(),
                normals: piece.mesh.normals.clone(),
                triangles: piece.mesh.triangles.clone(),
            };
            // the plane in the frame the piece is baked in
            let baked_plane = CutPlane {
                normal: plane.normal,
                offset_m: plane.offset_m + plane.normal.dot(self.rest_center),
            };
            let plan = plan_piece(&baked, &self.config, &baked_plane)
                .map_err(|e| CutError::Mesh(format!("piece {k} cannot be a soft body: {e}")))?;
            // The old vertex behind each of the piece's welded vertices (none for the cap's).
            let mut first_render = vec![usize::MAX; plan.rest_vertices.len()];
            for (ri, &w) in plan.welded.render_to_welded.iter().enumerate() {
                let slot = &mut first_render[w as usize];
                if *slot == usize::MAX {
                    *slot = ri;
                }
            }
            let source: Vec<Option<u32>> = first_render
                .iter()
                .map(|&ri| {
                    piece
                        .mesh
                        .positions
                        .get(ri)
                        .and_then(|p| old.get(&position_key(*p)).copied())
                })
                .collect();
            // A new particle starts displaced by the weighted mean displacement of its old
            // vertices, so the piece keeps (a smoothed copy of) its deformation.
            let displacement = mean_displacements(&plan.map, |v| {
                source[v as usize].map(|o| displaced(o as usize))
            });
            let spawn = Spawn {
                origin: self.rest_center,
                translation: c,
                rotation: r,
                linvel: vc,
                angvel: wc,
                displacement,
                keep_center: None,
            };
            out.push((plan, spawn));
        }
        Ok(out)
    }
}

/// Per particle of `map`: the weighted mean of its vertices' displacements (`displaced(v)`,
/// `None` for a vertex that had none), so a body built anew keeps (a smoothed copy of) the
/// deformation of the one it replaces.
pub(super) fn mean_displacements(
    map: &crate::cluster::ParticleMap,
    displaced: impl Fn(u32) -> Option<Vec3>,
) -> Vec<Vec3> {
    (0..map.len())
        .map(|i| {
            let (ids, ws) = map.particle_vertices.row(i);
            let (mut sum, mut total) = (Vec3::ZERO, 0.0f32);
            for (&v, &w) in ids.iter().zip(ws) {
                if let Some(d) = displaced(v) {
                    sum += d * w;
                    total += w;
                }
            }
            if total > 0.0 {
                sum / total
            } else {
                Vec3::ZERO
            }
        })
        .collect()
}

/// [`Mesh::weld`] for a mesh whose render vertices of one vertex share its position exactly
/// (the rest mesh: each render vertex sits at its welded position; a tear copies positions
/// and keeps its new vertices 20 µm from any other): one hash lookup per render vertex
/// instead of a search of the neighbouring cells (about 2 ms on the torn bunny), the same
/// normal slots; and the welded vertices' index by position.
fn weld_exact(mesh: &Mesh) -> (WeldedMesh, FxHashMap<[u32; 3], u32>) {
    let mut index: FxHashMap<[u32; 3], u32> =
        FxHashMap::with_capacity_and_hasher(mesh.positions.len(), Default::default());
    let mut positions: Vec<Vec3> = Vec::new();
    let mut render_to_welded = Vec::with_capacity(mesh.positions.len());
    let mut render_to_normal_slot = Vec::with_capacity(mesh.positions.len());
    // As in `Mesh::weld`: render vertices of one welded vertex share a normal slot when their
    // normals are within ~30°. Each welded vertex's slots, in the order they were made, as a
    // list threaded through one array (no allocation per vertex).
    const NONE: u32 = u32::MAX;
    let mut first_slot: Vec<u32> = Vec::with_capacity(mesh.positions.len());
    let mut last_slot: Vec<u32> = Vec::with_capacity(mesh.positions.len());
    // (normal, next slot of the same welded vertex)
    let mut slots: Vec<(Vec3, u32)> = Vec::with_capacity(mesh.positions.len());
    for (r, &p) in mesh.positions.iter().enumerate() {
        let w = *index.entry(position_key(p)).or_insert_with(|| {
            positions.push(p);
            first_slot.push(NONE);
            last_slot.push(NONE);
            (positions.len() - 1) as u32
        });
        render_to_welded.push(w);
        let n = mesh
            .normals
            .as_ref()
            .and_then(|ns| ns.get(r))
            .copied()
            .unwrap_or(Vec3::ZERO);
        let mut at = first_slot[w as usize];
        while at != NONE {
            let sn = slots[at as usize].0;
            if n == Vec3::ZERO || sn == Vec3::ZERO || sn.dot(n) > 0.866 {
                break;
            }
            at = slots[at as usize].1;
        }
        if at == NONE {
            at = slots.len() as u32;
            slots.push((n, NONE));
            match last_slot[w as usize] {
                NONE => first_slot[w as usize] = at,
                l => slots[l as usize].1 = at,
            }
            last_slot[w as usize] = at;
        }
        render_to_normal_slot.push(at);
    }
    let slot_count = slots.len() as u32;
    let triangles = mesh
        .triangles
        .iter()
        .map(|t| t.map(|i| render_to_welded[i as usize]))
        .collect();
    let welded = WeldedMesh {
        positions,
        triangles,
        render_to_welded,
        render_to_normal_slot,
        normal_slots: slot_count as usize,
    };
    (welded, index)
}

/// Plans one piece with `config`; with fewer than [`MIN_PIECE_PARTICLES`] particles, tries
/// [`finer`] configs (up to [`MAX_REFINEMENTS`]) and keeps the one with the most particles.
fn plan_piece(
    mesh: &Mesh,
    config: &SoftBodyConfig,
    plane: &CutPlane,
) -> Result<BodyPlan, SoftBodyError> {
    mesh.validate("<cut piece>")?;
    // A piece's center collider is its convex hull: balls around two sibling pieces would
    // overlap across the cut and throw the pieces apart; their hulls only touch.
    let mut config = config.clone();
    if config.center_collider == crate::CenterCollider::Ball {
        config.center_collider = crate::CenterCollider::ConvexHull;
    }
    let config = &config;
    let mut plan = BodyPlan::new(mesh, config.clone())?;
    let mut cfg = config.clone();
    for _ in 0..MAX_REFINEMENTS {
        if plan.map.len() >= MIN_PIECE_PARTICLES {
            break;
        }
        let Some(next) = finer(&cfg) else { break };
        match BodyPlan::new(mesh, next.clone()) {
            Ok(p) if p.map.len() > plan.map.len() => plan = p,
            Ok(_) => {}
            Err(_) => break,
        }
        cfg = next;
    }
    plan.shave_center(plane);
    Ok(plan)
}

/// The clustering of a piece too small for its particles: every radius and an explicit
/// neighbour range halved, closest-N's vertices per particle halved (down to 1); `None` when
/// nothing can get finer.
pub fn finer(config: &SoftBodyConfig) -> Option<SoftBodyConfig> {
    let cluster = match config.cluster {
        ClusterMethod::ClosestN {
            vertices_per_particle,
        } if vertices_per_particle > 1 => ClusterMethod::ClosestN {
            vertices_per_particle: vertices_per_particle / 2,
        },
        ClusterMethod::ClosestN { .. } => return None,
        ClusterMethod::Distance { radius_m } => ClusterMethod::Distance {
            radius_m: 0.5 * radius_m,
        },
        ClusterMethod::WeightedDistance {
            radius_m,
            soft_radius_m,
        } => ClusterMethod::WeightedDistance {
            radius_m: 0.5 * radius_m,
            soft_radius_m: 0.5 * soft_radius_m,
        },
        ClusterMethod::PoissonDisk { radius_m, seed } => ClusterMethod::PoissonDisk {
            radius_m: 0.5 * radius_m,
            seed,
        },
    };
    Some(SoftBodyConfig {
        cluster,
        affect_range_m: 0.5 * config.affect_range_m,
        ..config.clone()
    })
}

impl BodyPlan {
    /// A cut's piece: its center's hull stays clear of the cut face by the largest particle
    /// radius (at most 40 % of the piece's depth from the face). The sibling piece's particles
    /// sit within a radius of that face; touching this hull (particles push centers, one way)
    /// they would shove it and, while hands hold both pieces, tip it over. The hull's points
    /// nearer the face than that move away from it along its normal.
    pub(crate) fn shave_center(&mut self, plane: &crate::cut::CutPlane) {
        if self.config.space != crate::SimulationSpace::World
            || self.config.center_collider != crate::CenterCollider::ConvexHull
        {
            return;
        }
        let scale = self.config.center_scale;
        let pts: Vec<Vec3> = self.rest_vertices.iter().map(|v| *v * scale).collect();
        // which side of the plane the piece is on, and how deep it goes from the face
        let dist = |p: Vec3| plane.normal.dot(p + self.rest_center) - plane.offset_m;
        let mean = pts.iter().map(|p| dist(*p)).sum::<f32>() / pts.len().max(1) as f32;
        let side = if mean >= 0.0 { 1.0 } else { -1.0 };
        let depth = pts.iter().map(|p| side * dist(*p)).fold(0.0f32, f32::max);
        let radius = self
            .map
            .particle_extent_m
            .iter()
            .fold(0.0f32, |m, e| m.max(e * self.config.particle_scale));
        let d = radius.min(0.4 * depth);
        if d <= 0.0 {
            return;
        }
        let shaved: Vec<Vec3> = pts
            .iter()
            .map(|p| {
                let s = side * dist(*p);
                if s < d {
                    *p + plane.normal * side * (d - s)
                } else {
                    *p
                }
            })
            .collect();
        if let Some(b) = rapier3d::prelude::ColliderBuilder::convex_hull(&shaved) {
            self.center_shape = Some(b);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::cut::TearMesh;

    #[test]
    fn the_exact_weld_of_a_torn_mesh_is_the_weld() {
        let m = Mesh::cuboid(Vec3::splat(0.05), 4);
        let mut t = TearMesh::new(&m, 0.003).unwrap();
        t.tear(&TearSegment {
            from: Vec3::new(-0.02, 0.045, 0.01),
            to: Vec3::new(0.02, 0.045, -0.01),
            blade: Vec3::Y * 0.03,
        })
        .unwrap();
        let torn = t.to_mesh();
        let (a, b) = (weld_exact(&torn).0, torn.weld(1e-6));
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.triangles, b.triangles);
        assert_eq!(a.render_to_welded, b.render_to_welded);
        assert_eq!(a.render_to_normal_slot, b.render_to_normal_slot);
        assert_eq!(a.normal_slots, b.normal_slots);
        assert!(a.positions.len() > 100 && torn.positions.len() > a.positions.len());
    }
}
