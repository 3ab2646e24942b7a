//! Welding: render vertices that share a position become one simulated vertex, with the map
//! back to render vertices and normal slots that keep hard edges hard.

use std::collections::HashMap;

use glam::Vec3;

use super::{enclosed_volume, Mesh, WeldedMesh};

impl Mesh {
    /// Merges render vertices closer than `epsilon_m` into one welded vertex.
    pub fn weld(&self, epsilon_m: f32) -> WeldedMesh {
        let eps = epsilon_m.max(1e-9);
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        let key = |p: Vec3| -> [i64; 3] {
            let q = (p / eps).floor();
            [q.x as i64, q.y as i64, q.z as i64]
        };
        let mut welded: Vec<Vec3> = Vec::new();
        let mut map = Vec::with_capacity(self.positions.len());
        for &p in &self.positions {
            let k = key(p);
            let mut found = None;
            'search: for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(list) = cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                            for &w in list {
                                if welded[w as usize].distance_squared(p) <= eps * eps {
                                    found = Some(w);
                                    break 'search;
                                }
                            }
                        }
                    }
                }
            }
            let w = found.unwrap_or_else(|| {
                let w = welded.len() as u32;
                welded.push(p);
                cells.entry(k).or_default().push(w);
                w
            });
            map.push(w);
        }
        let triangles = self
            .triangles
            .iter()
            .map(|t| [map[t[0] as usize], map[t[1] as usize], map[t[2] as usize]])
            .collect();
        // Normal slots: render vertices of a welded vertex whose source normals are within
        // ~30 degrees share a slot.
        let mut slots_of_welded: Vec<Vec<(Vec3, u32)>> = vec![Vec::new(); welded.len()];
        let mut render_to_slot = Vec::with_capacity(self.positions.len());
        let mut slot_count = 0u32;
        for (r, &w) in map.iter().enumerate() {
            // `get`: a hand-built mesh may carry fewer normals than positions.
            let n = self
                .normals
                .as_ref()
                .and_then(|ns| ns.get(r))
                .copied()
                .unwrap_or(Vec3::ZERO);
            let slots = &mut slots_of_welded[w as usize];
            let hit = slots
                .iter()
                .find(|(sn, _)| n == Vec3::ZERO || *sn == Vec3::ZERO || sn.dot(n) > 0.866);
            let s = match hit {
                Some(&(_, s)) => s,
                None => {
                    let s = slot_count;
                    slot_count += 1;
                    slots.push((n, s));
                    s
                }
            };
            render_to_slot.push(s);
        }
        WeldedMesh {
            positions: welded,
            triangles,
            render_to_welded: map,
            render_to_normal_slot: render_to_slot,
            normal_slots: slot_count as usize,
        }
    }
}

impl WeldedMesh {
    /// Signed volume enclosed by the welded triangles (positive for outward winding).
    pub fn volume(&self, positions: &[Vec3]) -> f32 {
        enclosed_volume(positions, &self.triangles)
    }
}
