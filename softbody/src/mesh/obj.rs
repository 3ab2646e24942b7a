//! Wavefront OBJ text: `v`, `vn` and `f` statements, polygons fan-triangulated.

use std::collections::HashMap;
use std::path::Path;

use glam::Vec3;

use super::{Mesh, MAX_MESH_ELEMENTS};
use crate::SoftBodyError;

impl Mesh {
    /// Parses Wavefront OBJ text (`v`, `vn`, `f` with `v`, `v/vt`, `v//vn`, `v/vt/vn` and
    /// negative indices; polygons are fan-triangulated; other statements are ignored).
    /// `source` names the file in errors.
    pub fn from_obj_str(text: &str, source: impl AsRef<Path>) -> Result<Self, SoftBodyError> {
        let src = source.as_ref();
        let mut vs: Vec<Vec3> = Vec::new();
        let mut vns: Vec<Vec3> = Vec::new();
        // Render vertices are unique (position, normal) index pairs.
        let mut corner_map: HashMap<(u32, Option<u32>), u32> = HashMap::new();
        let mut positions = Vec::new();
        let mut normals: Vec<Option<Vec3>> = Vec::new();
        let mut triangles = Vec::new();
        for (line_no, line) in text.lines().enumerate() {
            let line_no = line_no + 1;
            let mut it = line.split_whitespace();
            let Some(tag) = it.next() else { continue };
            match tag {
                "v" | "vn" => {
                    let mut xyz = [0.0f32; 3];
                    for (k, slot) in xyz.iter_mut().enumerate() {
                        let tok = it.next().ok_or_else(|| {
                            SoftBodyError::malformed(
                                src,
                                format!("line {line_no}: `{tag}` needs 3 numbers, found {k}"),
                            )
                        })?;
                        *slot = tok.parse::<f32>().map_err(|_| {
                            SoftBodyError::malformed(
                                src,
                                format!("line {line_no}: `{tok}` is not a number"),
                            )
                        })?;
                        if !slot.is_finite() {
                            return Err(SoftBodyError::malformed(
                                src,
                                format!("line {line_no}: non-finite coordinate `{tok}`"),
                            ));
                        }
                    }
                    let target = if tag == "v" { &mut vs } else { &mut vns };
                    if target.len() >= MAX_MESH_ELEMENTS {
                        return Err(SoftBodyError::malformed(
                            src,
                            format!("line {line_no}: more than {MAX_MESH_ELEMENTS} vertices"),
                        ));
                    }
                    target.push(Vec3::from_array(xyz));
                }
                "f" => {
                    let mut corners: Vec<u32> = Vec::with_capacity(4);
                    for tok in it {
                        let mut parts = tok.split('/');
                        let vi = parts.next().unwrap_or("");
                        let _vt = parts.next();
                        let vn = parts.next().filter(|s| !s.is_empty());
                        let vi = resolve_obj_index(vi, vs.len(), src, line_no, "vertex")?;
                        let vn = match vn {
                            Some(s) => {
                                Some(resolve_obj_index(s, vns.len(), src, line_no, "normal")?)
                            }
                            None => None,
                        };
                        let next = positions.len() as u32;
                        let id = *corner_map.entry((vi, vn)).or_insert_with(|| {
                            positions.push(vs[vi as usize]);
                            normals.push(vn.map(|n| vns[n as usize]));
                            next
                        });
                        corners.push(id);
                    }
                    if corners.len() < 3 {
                        return Err(SoftBodyError::malformed(
                            src,
                            format!(
                                "line {line_no}: face has {} vertices; a face needs at least 3",
                                corners.len()
                            ),
                        ));
                    }
                    for k in 1..corners.len() - 1 {
                        if triangles.len() >= MAX_MESH_ELEMENTS {
                            return Err(SoftBodyError::malformed(
                                src,
                                format!("line {line_no}: more than {MAX_MESH_ELEMENTS} triangles"),
                            ));
                        }
                        triangles.push([corners[0], corners[k], corners[k + 1]]);
                    }
                }
                "l" | "p" => {
                    return Err(SoftBodyError::malformed(
                        src,
                        format!("line {line_no}: `{tag}` (line/point) elements are not triangles"),
                    ))
                }
                _ => {}
            }
        }
        if triangles.is_empty() && !vs.is_empty() {
            return Err(SoftBodyError::malformed(
                src,
                format!("mesh has {} vertices but no triangles", vs.len()),
            ));
        }
        let normals = if !normals.is_empty() && normals.iter().all(Option::is_some) {
            Some(
                normals
                    .into_iter()
                    .flatten()
                    .map(|n| n.normalize_or_zero())
                    .collect(),
            )
        } else {
            None
        };
        let mesh = Mesh {
            positions,
            normals,
            triangles,
        };
        mesh.validate(src)?;
        Ok(mesh)
    }
}

fn resolve_obj_index(
    tok: &str,
    len: usize,
    src: &Path,
    line: usize,
    what: &str,
) -> Result<u32, SoftBodyError> {
    let i: i64 = tok.parse().map_err(|_| {
        SoftBodyError::malformed(src, format!("line {line}: `{tok}` is not a {what} index"))
    })?;
    let resolved = if i < 0 { len as i64 + i } else { i - 1 };
    if i == 0 || resolved < 0 || resolved >= len as i64 {
        return Err(SoftBodyError::malformed(
            src,
            format!("line {line}: {what} index {i} out of range (have {len})"),
        ));
    }
    Ok(resolved as u32)
}
