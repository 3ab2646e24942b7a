//! Mesh sections (tear paper §3.1, Figure 4): the faces grouped into axis-aligned boxes so a
//! tear segment tests only the faces near it. A median split on face centroids along the
//! longest axis, until a group has at most `max_faces`; each section's box bounds its faces, so
//! boxes of neighbouring sections overlap where their faces interleave (the paper's overlap).

use glam::Vec3;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub lo: Vec3,
    /// Upper corner.
    pub hi: Vec3,
}

impl Aabb {
    fn empty() -> Self {
        Self {
            lo: Vec3::splat(f32::MAX),
            hi: Vec3::splat(f32::MIN),
        }
    }

    fn grow(&mut self, p: Vec3) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    fn overlaps(&self, o: &Aabb) -> bool {
        self.lo.cmple(o.hi).all() && o.lo.cmple(self.hi).all()
    }
}

/// The sections of a mesh.
#[derive(Clone, Debug)]
pub struct Sections {
    boxes: Vec<Aabb>,
    faces: Vec<Vec<u32>>,
    section_of_face: Vec<u32>,
}

impl Sections {
    /// Groups `triangles` into sections of at most `max_faces` faces. Every index must be
    /// below `positions.len()` (the callers weld first).
    pub fn build(positions: &[Vec3], triangles: &[[u32; 3]], max_faces: usize) -> Self {
        let centroids: Vec<Vec3> = triangles
            .iter()
            .map(|t| t.iter().map(|&v| positions[v as usize]).sum::<Vec3>() / 3.0)
            .collect();
        // Order by the centroid on the axis (face id breaks ties): a total order, so the
        // halves are the same whichever algorithm finds them.
        let order = |axis: usize| {
            let centroids = &centroids;
            move |a: &u32, c: &u32| {
                let (ka, kc) = (centroids[*a as usize][axis], centroids[*c as usize][axis]);
                ka.total_cmp(&kc).then(a.cmp(c))
            }
        };
        let mut groups: Vec<Vec<u32>> = Vec::new();
        // (faces, the axis of the split that made the group): a split only needs the median
        // (linear); a final group is sorted on its axis, as a full sort at every split left it.
        let mut stack: Vec<(Vec<u32>, Option<usize>)> =
            vec![((0..triangles.len() as u32).collect(), None)];
        while let Some((mut g, made_on)) = stack.pop() {
            if g.len() <= max_faces.max(1) {
                if let Some(axis) = made_on {
                    g.sort_unstable_by(order(axis));
                }
                groups.push(g);
                continue;
            }
            let mut b = Aabb::empty();
            for &f in &g {
                b.grow(centroids[f as usize]);
            }
            let ext = b.hi - b.lo;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = g.len() / 2;
            g.select_nth_unstable_by(mid, order(axis));
            let upper = g.split_off(mid);
            stack.push((upper, Some(axis)));
            stack.push((g, Some(axis)));
        }
        let mut s = Sections {
            boxes: Vec::with_capacity(groups.len()),
            faces: Vec::with_capacity(groups.len()),
            section_of_face: vec![0; triangles.len()],
        };
        for (i, g) in groups.into_iter().enumerate() {
            let mut b = Aabb::empty();
            for &f in &g {
                s.section_of_face[f as usize] = i as u32;
                for &v in &triangles[f as usize] {
                    b.grow(positions[v as usize]);
                }
            }
            s.boxes.push(b);
            s.faces.push(g);
        }
        s
    }

    /// Number of sections.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// The faces of every section whose box overlaps `query`, section by section.
    pub fn faces_near<'a>(&'a self, query: &'a Aabb) -> impl Iterator<Item = u32> + 'a {
        self.boxes
            .iter()
            .zip(&self.faces)
            .filter(move |(b, _)| b.overlaps(query))
            .flat_map(|(_, f)| f.iter().copied())
    }

    /// The section face `f` belongs to.
    pub fn section_of(&self, f: u32) -> u32 {
        self.section_of_face[f as usize]
    }

    /// Adds face `f` (with corners `corners`) to section `s`, growing its box if needed.
    pub fn add(&mut self, s: u32, f: u32, corners: &[Vec3; 3]) {
        let si = s as usize;
        if f as usize >= self.section_of_face.len() {
            self.section_of_face.resize(f as usize + 1, 0);
        }
        self.section_of_face[f as usize] = s;
        self.faces[si].push(f);
        for &p in corners {
            self.boxes[si].grow(p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Mesh;

    #[test]
    fn every_face_is_in_one_section_whose_box_holds_it() {
        let m = Mesh::icosphere(0.1, 3);
        let s = Sections::build(&m.positions, &m.triangles, 64);
        assert!(s.len() >= m.triangles.len() / 64);
        let mut seen = vec![0u32; m.triangles.len()];
        for (i, faces) in s.faces.iter().enumerate() {
            assert!(faces.len() <= 64);
            for &f in faces {
                seen[f as usize] += 1;
                assert_eq!(s.section_of(f), i as u32);
                for &v in &m.triangles[f as usize] {
                    let p = m.positions[v as usize];
                    assert!(s.boxes[i].lo.cmple(p).all() && p.cmple(s.boxes[i].hi).all());
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
        // A small query finds few faces.
        let q = Aabb {
            lo: Vec3::new(0.09, -0.01, -0.01),
            hi: Vec3::new(0.11, 0.01, 0.01),
        };
        let near: Vec<u32> = s.faces_near(&q).collect();
        assert!(
            !near.is_empty() && near.len() < m.triangles.len() / 4,
            "{}",
            near.len()
        );
    }
}
