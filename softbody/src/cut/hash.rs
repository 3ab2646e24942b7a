//! A hash of a mesh's topology and quantised positions: equal on two peers exactly when they
//! hold the same triangles over the same positions (to `quantum_m`).

use crate::mesh::Mesh;

/// FNV-1a (64-bit) over the triangle and vertex counts, every index, and every position
/// rounded to a multiple of `quantum_m` (e.g. 1e-5 m). Normals are left out: they follow from
/// the same inputs. Deterministic across platforms: no hashed containers, no floats in the
/// mix after rounding.
pub fn topology_hash(mesh: &Mesh, quantum_m: f32) -> u64 {
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut mix = |bytes: &[u8]| {
        for &b in bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(PRIME);
        }
    };
    let q = if quantum_m.is_finite() && quantum_m > 0.0 {
        quantum_m
    } else {
        1e-5
    };
    mix(&(mesh.triangles.len() as u64).to_le_bytes());
    mix(&(mesh.positions.len() as u64).to_le_bytes());
    for t in &mesh.triangles {
        for i in t {
            mix(&i.to_le_bytes());
        }
    }
    for p in &mesh.positions {
        for c in p.to_array() {
            // Saturating: a non-finite or huge coordinate hashes to a fixed value, no panic.
            let k = (c / q).round() as i64;
            mix(&k.to_le_bytes());
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_meshes_hash_equal_and_changes_show() {
        let a = Mesh::icosphere(0.1, 2);
        let b = a.clone();
        assert_eq!(topology_hash(&a, 1e-5), topology_hash(&b, 1e-5));
        let mut c = a.clone();
        c.positions[3].x += 1e-3;
        assert_ne!(topology_hash(&a, 1e-5), topology_hash(&c, 1e-5));
        let mut d = a.clone();
        d.triangles[0].swap(0, 1);
        assert_ne!(topology_hash(&a, 1e-5), topology_hash(&d, 1e-5));
        // Below the quantum, no change.
        let mut e = a.clone();
        e.positions[3].x += 1e-8;
        assert_eq!(topology_hash(&a, 1e-4), topology_hash(&e, 1e-4));
    }
}
