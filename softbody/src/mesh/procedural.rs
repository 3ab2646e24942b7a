//! Procedural shapes for tests, benchmarks and scenes: icosphere, UV sphere, subdivided box.

use std::collections::HashMap;

use glam::Vec3;

use super::Mesh;

impl Mesh {
    /// An icosphere of `subdivisions` levels (0 = icosahedron, 4 = 2562 vertices).
    pub fn icosphere(radius_m: f32, subdivisions: u32) -> Self {
        let t = (1.0 + 5.0f32.sqrt()) / 2.0;
        let mut pos: Vec<Vec3> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .iter()
        .map(|a| Vec3::from_array(*a).normalize())
        .collect();
        let mut tris: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
            let mut next = Vec::with_capacity(tris.len() * 4);
            let mut midpoint = |a: u32, b: u32, pos: &mut Vec<Vec3>| -> u32 {
                let k = (a.min(b), a.max(b));
                *mid.entry(k).or_insert_with(|| {
                    pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                    (pos.len() - 1) as u32
                })
            };
            for [a, b, c] in tris {
                let ab = midpoint(a, b, &mut pos);
                let bc = midpoint(b, c, &mut pos);
                let ca = midpoint(c, a, &mut pos);
                next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            tris = next;
        }
        let normals = pos.clone();
        Mesh {
            positions: pos.into_iter().map(|p| p * radius_m).collect(),
            normals: Some(normals),
            triangles: tris,
        }
    }

    /// A UV sphere with `rings` latitude bands and `segments` longitude bands; the seam and
    /// the poles are duplicated render vertices, as exporters write them.
    pub fn uv_sphere(radius_m: f32, rings: u32, segments: u32) -> Self {
        let rings = rings.max(2);
        let segments = segments.max(3);
        let mut positions = Vec::new();
        let mut normals = Vec::new();
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                let n = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                positions.push(n * radius_m);
                normals.push(n);
            }
        }
        let row = segments + 1;
        let mut triangles = Vec::new();
        for r in 0..rings {
            for s in 0..segments {
                let a = r * row + s;
                let b = a + row;
                if r != 0 {
                    triangles.push([a, a + 1, b]);
                }
                if r != rings - 1 {
                    triangles.push([a + 1, b + 1, b]);
                }
            }
        }
        Mesh {
            positions,
            normals: Some(normals),
            triangles,
        }
    }

    /// A box with `subdivisions` cells per edge on each face; faces have their own render
    /// vertices (hard edges), which weld to shared positions.
    pub fn cuboid(half_extents_m: Vec3, subdivisions: u32) -> Self {
        let n = subdivisions.max(1);
        let mut positions = Vec::new();
        let mut normals = Vec::new();
        let mut triangles = Vec::new();
        let faces = [
            (Vec3::X, Vec3::Y, Vec3::Z),
            (Vec3::NEG_X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::Z, Vec3::X),
            (Vec3::NEG_Y, Vec3::X, Vec3::Z),
            (Vec3::Z, Vec3::X, Vec3::Y),
            (Vec3::NEG_Z, Vec3::Y, Vec3::X),
        ];
        for (normal, u, v) in faces {
            let base = positions.len() as u32;
            for i in 0..=n {
                for j in 0..=n {
                    let a = -1.0 + 2.0 * i as f32 / n as f32;
                    let b = -1.0 + 2.0 * j as f32 / n as f32;
                    positions.push((normal + u * a + v * b) * half_extents_m);
                    normals.push(normal);
                }
            }
            for i in 0..n {
                for j in 0..n {
                    let p = base + i * (n + 1) + j;
                    let q = p + n + 1;
                    triangles.push([p, q, q + 1]);
                    triangles.push([p, q + 1, p + 1]);
                }
            }
        }
        Mesh {
            positions,
            normals: Some(normals),
            triangles,
        }
    }
}
