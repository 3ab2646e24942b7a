//! One constructor per method and resolution: a [`MethodSpec`] names the method, its
//! resolution knob and its solver budget; [`build_model`] turns it into a model in a world.

use glam::Vec3;
use rapier3d::prelude::PhysicsWorld;

use crate::cluster::build_particle_map;
use crate::methods::ispc::ispc_links;
use crate::methods::lattice::lattice_tets;
use crate::methods::model::DeformableModel;
use crate::methods::native::NativeModel;
use crate::methods::particle::ParticleModel;
use crate::methods::pbd::{
    BendingGroup, DistanceGroup, NeoHookeanGroup, PbdBody, ShapeClusters, SolverKind, StrainGroup,
    SurfaceMap, VolumeGroup,
};
use crate::methods::tets::{tet_edges, tetrahedralize};
use crate::{ClusterMethod, Mesh, SimulationSpace, SoftBodyConfig, SoftBodyError};

// The spec types were defined here before `spec` took them: their paths stay.
pub use crate::methods::spec::{Material, MethodKind, MethodSpec};

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
    // The surface and shape-matching bodies simulate the mesh's own vertices, of equal mass.
    let surface_body = |name: String| {
        let masses = vec![m.density_kg_m3 * volume / n.max(1) as f32; n];
        PbdBody::new(
            name,
            spec.params,
            positions.to_vec(),
            &masses,
            SurfaceMap::Direct,
            triangles.to_vec(),
        )
    };
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
            let mut body = surface_body(name);
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
        MethodKind::Tet | MethodKind::StrainTet => {
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
            if spec.kind == MethodKind::StrainTet {
                // Shear modulus from E and K (ν = (3K − E) / 6K).
                let nu = ((3.0 * m.bulk_pa - m.young_pa) / (6.0 * m.bulk_pa)).clamp(0.0, 0.49);
                body.strain = Some(StrainGroup::new(
                    tm.tets,
                    &tm.nodes,
                    m.young_pa,
                    m.young_pa / (2.0 * (1.0 + nu)),
                    m.pbd_stiffness,
                ));
            } else {
                body.volume = Some(VolumeGroup::new(
                    tm.tets,
                    &tm.nodes,
                    m.bulk_pa,
                    m.pbd_stiffness,
                ));
            }
            Ok(body)
        }
        MethodKind::NeoHookean => {
            let lt = lattice_tets(positions, triangles, spec.cell_frac * size)?;
            let material_nodes = lt.material_nodes();
            let tm = lt.mesh;
            let mut masses = vec![0.0f32; tm.nodes.len()];
            let mut material_m3 = 0.0f32;
            // Mass follows the material too, but not below a share of a full tet's: a node of
            // the fringe with almost no mass would take all of every contact's and hold's
            // correction (they split by inverse mass) and crush its tets.
            let mass_floor = 0.3f32;
            for (t, w) in tm.tets.iter().zip(&lt.inside_fraction) {
                let v = crate::methods::pbd::tet_volume(t.map(|i| tm.nodes[i as usize])).abs();
                material_m3 += v * w.max(mass_floor);
                for &i in t {
                    masses[i as usize] += m.density_kg_m3 * v * w.max(mass_floor) / 4.0;
                }
            }
            // Keep the body's own mass, like every other method.
            let scale = volume / material_m3.max(1e-12);
            masses.iter_mut().for_each(|m| *m *= scale);
            let mut body = PbdBody::new(
                name,
                spec.params,
                tm.nodes.clone(),
                &masses,
                SurfaceMap::Embedded(tm.embedding),
                triangles.to_vec(),
            );
            let mut group = NeoHookeanGroup::new(
                tm.tets,
                &tm.nodes,
                &lt.inside_fraction,
                m.young_pa,
                m.bulk_pa,
            );
            group.min_volume_ratio = spec.params.volume_floor.max(0.0);
            body.neo_hookean = Some(group);
            body.colliding_nodes = Some(material_nodes);
            body.pin_surface = true;
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
            let mut body = surface_body(name);
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
            // The material's density relative to the default scales the particles' and the
            // center's masses (the defaults model the default density).
            let defaults = SoftBodyConfig::default();
            let heavier = spec.material.density_kg_m3 / Material::default().density_kg_m3;
            let cfg = SoftBodyConfig {
                cluster: ClusterMethod::Distance {
                    radius_m: spec.cell_frac * size,
                },
                stiffness,
                particle_mass_kg: (defaults.particle_mass_kg * heavier).clamp(1e-4, 1e3),
                center_mass_kg: (defaults.center_mass_kg * heavier).clamp(1e-4, 1e5),
                restoring: spec.restoring,
                self_collisions: spec.self_collisions,
                rolling_resistance: spec.rolling_resistance,
                volume_stiffness: spec.volume_stiffness,
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
