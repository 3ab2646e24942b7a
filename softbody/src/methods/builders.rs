//! One constructor per method and resolution: a [`MethodSpec`] names the method, its
//! resolution knob and its solver budget; [`build_model`] turns it into a model in a world.

use glam::Vec3;
use rapier3d::prelude::PhysicsWorld;
use serde::{Deserialize, Serialize};

use crate::cluster::build_particle_map;
use crate::methods::ispc::ispc_links;
use crate::methods::model::DeformableModel;
use crate::methods::native::NativeModel;
use crate::methods::particle::ParticleModel;
use crate::methods::pbd::{
    BendingGroup, DistanceGroup, PbdBody, PbdParams, ShapeClusters, SolverKind, SurfaceMap,
    VolumeGroup,
};
use crate::methods::tets::{tet_edges, tetrahedralize};
use crate::{ClusterMethod, Mesh, SimulationSpace, SoftBodyConfig, SoftBodyError, SoftRegion};

/// The methods compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum MethodKind {
    /// The thesis's particle method on rapier ([`crate::SoftBodySet`]).
    Particle,
    /// PBD/XPBD on the surface only: edge distance + dihedral bending.
    Surface,
    /// The surface model plus internal shape-preserving links (ISPC paper).
    Ispc,
    /// XPBD on tets (edges + volume) with the surface embedded: the accuracy reference.
    Tet,
    /// Shape matching on overlapping clusters from the particle map (Müller et al. 2005).
    ShapeMatching,
    /// rapier 0.36's own volumetric soft body, surface embedded in its cells.
    RapierNative,
}

impl MethodKind {
    /// All methods.
    pub const ALL: [MethodKind; 6] = [
        MethodKind::Particle,
        MethodKind::Surface,
        MethodKind::Ispc,
        MethodKind::Tet,
        MethodKind::ShapeMatching,
        MethodKind::RapierNative,
    ];

    /// Short name.
    pub fn name(&self) -> &'static str {
        match self {
            MethodKind::Particle => "particle",
            MethodKind::Surface => "surface_pbd",
            MethodKind::Ispc => "ispc",
            MethodKind::Tet => "tet",
            MethodKind::ShapeMatching => "shape_matching",
            MethodKind::RapierNative => "rapier_native",
        }
    }
}

/// Material shared by the position-based methods, so that they model the same object.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Young's modulus, Pa (distance constraints get `E · V_share / L²`).
    pub young_pa: f32,
    /// Bulk modulus of the tet volume constraints, Pa.
    pub bulk_pa: f32,
    /// Bending stiffness as a fraction of `E · L³`.
    pub bend_ratio: f32,
    /// Density, kg/m³.
    pub density_kg_m3: f32,
    /// Plain-PBD stiffness per iteration, (0, 1].
    pub pbd_stiffness: f32,
    /// Shape-matching rate, 1/s.
    pub shape_rate_per_s: f32,
    /// Stiffness of the ISPC links relative to a rod sharing the body's volume evenly: links
    /// span the body, so a thin rod underestimates the solid they stand for (the paper tunes
    /// its link stiffness against the tet model the same way).
    pub link_scale: f32,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            young_pa: 2.0e5,
            bulk_pa: 4.0e5,
            bend_ratio: 0.05,
            density_kg_m3: 1000.0,
            pbd_stiffness: 0.5,
            shape_rate_per_s: 120.0,
            link_scale: 30.0,
        }
    }
}

/// A method at one resolution and solver budget.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MethodSpec {
    /// The method.
    pub kind: MethodKind,
    /// Resolution knob as a fraction of the object's size: tet / native cell size, particle
    /// and shape-matching cluster radius. Unused by the surface and ISPC models (they use the
    /// mesh's own vertices).
    pub cell_frac: f32,
    /// Substeps and iterations, solver and contact settings of the position-based methods.
    pub params: PbdParams,
    /// Material.
    pub material: Material,
    /// Only this region (world coordinates of the mesh given to [`build_model`]) is soft; the
    /// rest follows rigidly (thesis 3.5.2). Particle method only; `None` = all soft.
    #[serde(default)]
    pub soft_region: Option<SoftRegion>,
}

impl MethodSpec {
    /// `kind` with its default resolution and budget.
    pub fn new(kind: MethodKind) -> Self {
        Self {
            kind,
            cell_frac: match kind {
                MethodKind::Particle | MethodKind::ShapeMatching => 0.06,
                _ => 0.12,
            },
            params: PbdParams::default(),
            material: Material::default(),
            soft_region: None,
        }
    }

    /// With substeps and iterations.
    pub fn budget(mut self, substeps: u32, iterations: u32) -> Self {
        self.params.substeps = substeps.max(1);
        self.params.iterations = iterations.max(1);
        self
    }

    /// With a resolution knob.
    pub fn cell(mut self, cell_frac: f32) -> Self {
        self.cell_frac = cell_frac;
        self
    }

    /// Rejects values outside their range (a spec may come from a file): resolution in
    /// [0.005, 1] of the size, 1–256 substeps and iterations, a finite positive material.
    pub fn validate(&self) -> Result<(), SoftBodyError> {
        let bad = |what: &str| Err(SoftBodyError::Config(format!("{}: {what}", self.label())));
        if !(self.cell_frac.is_finite() && (0.005..=1.0).contains(&self.cell_frac)) {
            return bad("cell_frac must be in [0.005, 1]");
        }
        let p = &self.params;
        if !(1..=256).contains(&p.substeps) || !(1..=256).contains(&p.iterations) {
            return bad("substeps and iterations must be in 1..=256");
        }
        let m = &self.material;
        let positive = [
            m.young_pa,
            m.bulk_pa,
            m.density_kg_m3,
            m.pbd_stiffness,
            m.shape_rate_per_s,
            m.link_scale,
        ];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0))
            || !(m.bend_ratio.is_finite() && m.bend_ratio >= 0.0)
            || m.pbd_stiffness > 1.0
        {
            return bad("material values must be finite and positive (pbd_stiffness ≤ 1)");
        }
        let nonneg = [
            p.damping_per_s,
            p.contact_radius_m,
            p.friction,
            p.sleep_speed_mps,
            p.sleep_after_s,
        ];
        if nonneg.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return bad("solver values must be finite and non-negative");
        }
        Ok(())
    }

    /// With a restricted soft region (particle method).
    pub fn region(mut self, region: Option<SoftRegion>) -> Self {
        self.soft_region = region;
        self
    }

    /// A label such as `tet c0.08 s4i8`.
    pub fn label(&self) -> String {
        let p = &self.params;
        let region = if self.soft_region.is_some() {
            " region"
        } else {
            ""
        };
        match self.kind {
            MethodKind::Surface | MethodKind::Ispc => {
                format!("{} s{}i{}", self.kind.name(), p.substeps, p.iterations)
            }
            MethodKind::Particle | MethodKind::RapierNative => {
                format!("{} c{:.3}{region}", self.kind.name(), self.cell_frac)
            }
            _ => format!(
                "{} c{:.3} s{}i{}",
                self.kind.name(),
                self.cell_frac,
                p.substeps,
                p.iterations
            ),
        }
    }
}

/// Builds the position-based body of a PBD-family spec (surface, ISPC, tet, shape matching)
/// for `mesh` (world space).
pub fn build_pbd(spec: &MethodSpec, mesh: &Mesh) -> Result<PbdBody, SoftBodyError> {
    mesh.validate("<method mesh>")?;
    let welded = mesh.weld(1e-6);
    build_pbd_welded(spec, &welded.positions, &welded.triangles)
}

/// [`build_pbd`] on an already welded (possibly open) mesh.
pub fn build_pbd_welded(
    spec: &MethodSpec,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
) -> Result<PbdBody, SoftBodyError> {
    spec.validate()?;
    Mesh {
        positions: positions.to_vec(),
        normals: None,
        triangles: triangles.to_vec(),
    }
    .validate("<method mesh>")?;
    let m = &spec.material;
    let (lo, hi) = crate::mesh::bounds(positions);
    let size = (hi - lo).max_element().max(1e-6);
    let volume = crate::mesh::enclosed_volume(positions, triangles).abs();
    // An open mesh encloses an ill-defined volume: fall back to its box's.
    let volume = if volume > 1e-12 {
        volume
    } else {
        (hi - lo).x * (hi - lo).y * (hi - lo).z * 0.5
    };
    let n = positions.len();
    let name = spec.label();
    match spec.kind {
        MethodKind::Surface | MethodKind::Ispc => {
            let mut edges: Vec<[u32; 2]> = triangles
                .iter()
                .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
                .map(|(a, b)| [a.min(b), a.max(b)])
                .collect();
            edges.sort_unstable();
            edges.dedup();
            let links = if spec.kind == MethodKind::Ispc {
                ispc_links(positions, triangles)?.links
            } else {
                Vec::new()
            };
            let share = volume;
            let masses = vec![m.density_kg_m3 * volume / n.max(1) as f32; n];
            let mut body = PbdBody::new(
                name,
                spec.params,
                positions.to_vec(),
                &masses,
                SurfaceMap::Direct,
                triangles.to_vec(),
            );
            body.distance.push(DistanceGroup::new(
                "edges",
                edges,
                positions,
                m.young_pa,
                share,
                m.pbd_stiffness,
            ));
            if !links.is_empty() {
                body.distance.push(DistanceGroup::new(
                    "ispc_links",
                    links,
                    positions,
                    m.young_pa * m.link_scale,
                    volume,
                    m.pbd_stiffness,
                ));
            }
            body.bending = Some(BendingGroup::from_triangles(
                triangles,
                positions,
                m.young_pa,
                m.bend_ratio,
                m.pbd_stiffness,
            ));
            Ok(body)
        }
        MethodKind::Tet => {
            let tm = tetrahedralize(positions, triangles, spec.cell_frac * size)?;
            let mut masses = vec![0.0f32; tm.nodes.len()];
            for t in &tm.tets {
                let v = crate::methods::pbd::tet_volume(t.map(|i| tm.nodes[i as usize])).abs();
                for &i in t {
                    masses[i as usize] += m.density_kg_m3 * v / 4.0;
                }
            }
            let cover_volume: f32 = tm
                .tets
                .iter()
                .map(|t| crate::methods::pbd::tet_volume(t.map(|i| tm.nodes[i as usize])))
                .sum();
            // The cover contains the surface, so it is larger: keep the body's own mass.
            let scale = volume / cover_volume.max(1e-12);
            masses.iter_mut().for_each(|m| *m *= scale);
            let edges = tet_edges(&tm.tets);
            let mut body = PbdBody::new(
                name,
                spec.params,
                tm.nodes.clone(),
                &masses,
                SurfaceMap::Embedded(tm.embedding),
                triangles.to_vec(),
            );
            body.distance.push(DistanceGroup::new(
                "tet_edges",
                edges,
                &tm.nodes,
                m.young_pa,
                cover_volume,
                m.pbd_stiffness,
            ));
            body.volume = Some(VolumeGroup::new(
                tm.tets,
                &tm.nodes,
                m.bulk_pa,
                m.pbd_stiffness,
            ));
            Ok(body)
        }
        MethodKind::ShapeMatching => {
            let soft = vec![true; n];
            let radius = (spec.cell_frac * size).max(1e-5);
            let cm = ClusterMethod::Distance { radius_m: radius };
            let map = build_particle_map(positions, triangles, &soft, cm, 2.5 * radius)?;
            // Each particle's cluster: its vertices and its neighbours' (overlap couples them),
            // plus the whole body (Müller et al. 2005's global match) for its overall shape.
            let mut clusters = Vec::with_capacity(map.len() + 1);
            clusters.push((0..n as u32).collect::<Vec<u32>>());
            for p in 0..map.len() {
                let mut members: Vec<u32> = map.particle_vertices.row(p).0.to_vec();
                for &q in map.neighbours.row(p).0 {
                    members.extend_from_slice(map.particle_vertices.row(q as usize).0);
                }
                members.sort_unstable();
                members.dedup();
                clusters.push(members);
            }
            let masses = vec![m.density_kg_m3 * volume / n.max(1) as f32; n];
            let mut body = PbdBody::new(
                name,
                spec.params,
                positions.to_vec(),
                &masses,
                SurfaceMap::Direct,
                triangles.to_vec(),
            );
            body.clusters = Some(ShapeClusters::new(&clusters, positions, m.shape_rate_per_s));
            Ok(body)
        }
        MethodKind::Particle | MethodKind::RapierNative => Err(SoftBodyError::Config(format!(
            "{} is not a position-based method",
            spec.kind.name()
        ))),
    }
}

/// Builds any method's model for `mesh` (world space) in `world`. `anchored` selects the
/// particle method's local mode (its center fixed), the counterpart of pinning a region.
pub fn build_model(
    spec: &MethodSpec,
    mesh: &Mesh,
    world: &mut PhysicsWorld,
    anchored: bool,
) -> Result<Box<dyn DeformableModel>, SoftBodyError> {
    spec.validate()?;
    match spec.kind {
        MethodKind::Particle => {
            let welded = mesh.weld(1e-6);
            let (lo, hi) = crate::mesh::bounds(&welded.positions);
            let size = (hi - lo).max_element().max(1e-6);
            // The material's stiffness relative to the default scales the restoring rate.
            let stiffness =
                (20.0 * spec.material.young_pa / Material::default().young_pa).clamp(0.1, 1e4);
            let cfg = SoftBodyConfig {
                cluster: ClusterMethod::Distance {
                    radius_m: spec.cell_frac * size,
                },
                stiffness,
                soft_region: spec.soft_region,
                space: if anchored {
                    SimulationSpace::Local
                } else {
                    SimulationSpace::World
                },
                ..Default::default()
            };
            Ok(Box::new(ParticleModel::new(
                spec.label(),
                mesh,
                cfg,
                world,
            )?))
        }
        MethodKind::RapierNative => Ok(Box::new(NativeModel::new(spec, mesh, world)?)),
        _ => Ok(Box::new(build_pbd(spec, mesh)?)),
    }
}

/// The plain-PBD variant of a spec.
pub fn plain_pbd(mut spec: MethodSpec) -> MethodSpec {
    spec.params.solver = SolverKind::Pbd;
    spec
}
