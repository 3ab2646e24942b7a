//! rapier 0.36's own volumetric soft body as a model: `SoftBodyBuilder::volumetric` on the
//! mesh (parry's cover, the same tetrahedralizer as [`crate::methods::tets`]), our surface
//! embedded in its cells so every method reports the same vertices.

use glam::Vec3;
use rapier3d::dynamics::{SoftBodyMaterial, SpringCoefficients};
use rapier3d::prelude::{PhysicsWorld, SoftBodyBuilder, SoftBodyHandle};

use crate::methods::model::DeformableModel;
use crate::methods::pbd::{tet_volume, Embedding};
use crate::methods::spec::{Material, MethodSpec};
use crate::methods::tets::embed;
use crate::{Mesh, SoftBodyError};

/// A rapier soft body, moved by `world.step()`.
pub struct NativeModel {
    name: String,
    handle: SoftBodyHandle,
    cells: Vec<[u32; 4]>,
    embedding: Embedding,
    triangles: Vec<[u32; 3]>,
    surface: Vec<Vec3>,
    nodes: Vec<Vec3>,
    sleeping: bool,
    max_speed: f32,
    skin_m: f32,
}

impl NativeModel {
    /// Inserts the soft body for `mesh` (world space) with cells of `spec.cell_frac` × size.
    pub fn new(
        spec: &MethodSpec,
        mesh: &Mesh,
        world: &mut PhysicsWorld,
    ) -> Result<Self, SoftBodyError> {
        let welded = mesh.weld(1e-6);
        let (lo, hi) = crate::mesh::bounds(&welded.positions);
        let cell = spec.cell_frac * (hi - lo).max_element().max(1e-6);
        let builder = SoftBodyBuilder::volumetric(&welded.positions, &welded.triangles, cell)
            .ok_or_else(|| {
                SoftBodyError::Config(format!(
                    "rapier volumetric: nothing enclosed at cell {cell}"
                ))
            })?;
        let volume = crate::mesh::enclosed_volume(&welded.positions, &welded.triangles).abs();
        // The material's stiffness relative to the default scales the springs' frequency.
        let f = (spec.material.young_pa / Material::default().young_pa)
            .max(1e-4)
            .sqrt();
        let d = SoftBodyMaterial::default();
        let material = SoftBodyMaterial {
            edge_softness: SpringCoefficients::new(30.0 * f, 1.0),
            volume_softness: SpringCoefficients::new(30.0 * f, 1.0),
            young_modulus: d.young_modulus * f * f,
            ..d
        };
        let handle = world.insert_soft_body(
            builder
                .mass(spec.material.density_kg_m3 * volume)
                .material(material)
                .can_sleep(true),
        );
        let body = world
            .soft_bodies
            .get(handle)
            .ok_or_else(|| SoftBodyError::Config("rapier soft body vanished".into()))?;
        let nodes: Vec<Vec3> = body.particle_positions().collect();
        let skin_m = body.particle_radius();
        let cells: Vec<[u32; 4]> = body.cells().iter().map(|c| c.vertices).collect();
        let embedding = embed(&nodes, &cells, &welded.positions, cell);
        let mut m = Self {
            name: spec.label(),
            handle,
            cells,
            embedding,
            triangles: welded.triangles.clone(),
            surface: welded.positions.clone(),
            nodes,
            sleeping: false,
            max_speed: 0.0,
            skin_m,
        };
        m.update(world);
        Ok(m)
    }

    fn update(&mut self, world: &PhysicsWorld) {
        let Some(body) = world.soft_bodies.get(self.handle) else {
            return;
        };
        self.nodes.clear();
        self.nodes.extend(body.particle_positions());
        self.max_speed = body
            .particle_velocities()
            .map(|v| v.length())
            .fold(0.0, f32::max);
        self.sleeping = body.is_sleeping();
        for (s, (n, w)) in self
            .surface
            .iter_mut()
            .zip(self.embedding.nodes.iter().zip(&self.embedding.weights))
        {
            let p: Vec3 = (0..4)
                .map(|k| self.nodes.get(n[k] as usize).copied().unwrap_or(Vec3::NAN) * w[k])
                .sum();
            *s = p;
        }
    }
}

impl DeformableModel for NativeModel {
    fn name(&self) -> &str {
        &self.name
    }

    fn post_physics(&mut self, world: &mut PhysicsWorld, _dt_s: f32) {
        self.update(world);
    }

    fn surface(&self) -> &[Vec3] {
        &self.surface
    }

    fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    fn is_sleeping(&self) -> bool {
        self.sleeping
    }

    fn num_particles(&self) -> usize {
        self.nodes.len()
    }

    fn inverted_elements(&self) -> usize {
        self.cells
            .iter()
            .filter(|c| {
                c.iter().all(|&i| (i as usize) < self.nodes.len())
                    && tet_volume(c.map(|i| self.nodes[i as usize])) <= 0.0
            })
            .count()
    }

    fn max_speed_mps(&self) -> f32 {
        self.max_speed
    }

    fn contact_thickness_m(&self) -> f32 {
        self.skin_m
    }

    fn pin_region(&mut self, world: &mut PhysicsWorld, min_m: Vec3, max_m: Vec3) -> usize {
        let Some(body) = world.soft_bodies.get_mut(self.handle) else {
            return 0;
        };
        let pos: Vec<Vec3> = body.particle_positions().collect();
        let mut n = 0;
        for (i, p) in pos.iter().enumerate() {
            if p.cmpge(min_m).all() && p.cmple(max_m).all() {
                body.set_particle_pinned(i, true);
                n += 1;
            }
        }
        n
    }

    fn set_velocity(&mut self, world: &mut PhysicsWorld, v_mps: Vec3) {
        let Some(body) = world.soft_bodies.get_mut(self.handle) else {
            return;
        };
        for i in 0..body.num_particles() {
            body.set_particle_velocity(i, v_mps);
        }
        body.wake_up();
        self.max_speed = v_mps.length();
    }
}
