//! Validity of a mesh after cuts and tears: what the tests assert and what a peer can log when
//! an event produced something it should not have.

use glam::Vec3;

use super::plane::{weld_positions, IdMap};
use crate::mesh::{enclosed_volume, Mesh};

/// What is wrong (or right) with a mesh, measured on its welded positions: render vertices at
/// the same position count as one vertex, as the simulation sees them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshReport {
    /// Triangles.
    pub triangles: usize,
    /// Welded vertices.
    pub vertices: usize,
    /// Triangles with a repeated welded vertex or zero area.
    pub degenerate: usize,
    /// Triangles using the same three welded vertices as an earlier one (either winding).
    pub duplicate: usize,
    /// Undirected edges used by one triangle only (a boundary: a tear's rim, an open mesh).
    pub boundary_edges: usize,
    /// Undirected edges used by three or more triangles.
    pub non_manifold_edges: usize,
    /// Edges whose two triangles run them the same way (inconsistent winding).
    pub misoriented_edges: usize,
    /// Enclosed volume, m³ (meaningful when closed).
    pub volume_m3: f32,
}

impl MeshReport {
    /// Measures `mesh` (welded as `Mesh::weld(1e-6)` would).
    pub fn of(mesh: &Mesh) -> Self {
        let (positions, triangles) = weld_positions(&mesh.positions, &mesh.triangles, 1e-6);
        Self::of_welded(&positions, &triangles)
    }

    /// Measures welded positions and triangles. A triangle with an index out of range counts
    /// as degenerate and is otherwise left out.
    pub fn of_welded(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let n = positions.len();
        let (valid, broken): (Vec<[u32; 3]>, Vec<[u32; 3]>) = triangles
            .iter()
            .partition(|t| t.iter().all(|&i| (i as usize) < n));
        let mut r = MeshReport {
            triangles: triangles.len(),
            vertices: n,
            degenerate: broken.len(),
            volume_m3: enclosed_volume(positions, &valid),
            ..Default::default()
        };
        let mut seen: IdMap<[u32; 3], ()> = IdMap::default();
        seen.reserve(valid.len());
        // Per undirected edge: (uses, uses running low → high).
        let mut edges: IdMap<(u32, u32), (u32, u32)> = IdMap::default();
        edges.reserve(valid.len() * 2);
        for t in &valid {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || (b - a).cross(c - a) == Vec3::ZERO {
                r.degenerate += 1;
            }
            let mut key = *t;
            key.sort_unstable();
            if seen.insert(key, ()).is_some() {
                r.duplicate += 1;
            }
            for k in 0..3 {
                let (u, v) = (t[k], t[(k + 1) % 3]);
                let e = edges.entry((u.min(v), u.max(v))).or_default();
                e.0 += 1;
                e.1 += u32::from(u < v);
            }
        }
        for &(uses, forward) in edges.values() {
            match uses {
                1 => r.boundary_edges += 1,
                2 => r.misoriented_edges += usize::from(forward != 1),
                _ => r.non_manifold_edges += 1,
            }
        }
        r
    }

    /// Closed and sound: no degenerate or duplicate triangles, every edge shared by exactly two
    /// triangles running it in opposite directions, positive volume.
    pub fn is_closed_solid(&self) -> bool {
        self.is_sound()
            && self.boundary_edges == 0
            && self.non_manifold_edges == 0
            && self.volume_m3 > 0.0
    }

    /// No degenerate or duplicate triangles and consistent winding (boundaries allowed).
    pub fn is_sound(&self) -> bool {
        self.degenerate == 0 && self.duplicate == 0 && self.misoriented_edges == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_icosphere_is_a_closed_solid() {
        let r = MeshReport::of(&Mesh::icosphere(0.1, 2));
        assert!(r.is_closed_solid(), "{r:?}");
    }

    #[test]
    fn flaws_are_counted() {
        let mut m = Mesh::icosphere(0.1, 1);
        let t0 = m.triangles[0];
        m.triangles[1].swap(1, 2); // flips one face: three misoriented edges
        m.triangles.push([t0[0], t0[2], t0[1]]); // duplicate (other winding) + non-manifold
        let r = MeshReport::of(&m);
        assert_eq!(r.duplicate, 1);
        assert_eq!(r.non_manifold_edges, 3);
        assert_eq!(r.misoriented_edges, 3);
        assert!(!r.is_closed_solid());
        m.triangles.truncate(m.triangles.len() - 2);
        let r = MeshReport::of(&m);
        assert_eq!(r.boundary_edges, 3);
        // An index out of range is a flaw, not a panic.
        m.triangles.push([0, 1, 1_000_000]);
        let r = MeshReport::of(&m);
        assert_eq!(r.degenerate, 1);
        assert_eq!(r.boundary_edges, 3);
    }
}
