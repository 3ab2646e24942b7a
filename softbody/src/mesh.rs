//! Triangle meshes: loading (OBJ, glTF/GLB), validation, baking the object's transform into
//! the vertices (thesis 3.5.1), welding duplicate positions, and procedural shapes.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::SoftBodyError;

/// Upper bound on the vertices or triangles we accept from a file: a hostile count never
/// becomes an allocation larger than this.
pub const MAX_MESH_ELEMENTS: usize = 4_000_000;

/// Largest coordinate accepted, metres: beyond it grid keys and f32 precision stop meaning
/// anything for a hand-sized simulation.
pub const MAX_COORDINATE_M: f32 = 1e5;

/// A triangle mesh as a renderer sees it: render vertices (possibly duplicated along UV or
/// normal seams) and triangles indexing them.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Render vertex positions, in the object's local space (after [`Mesh::bake`], the world
    /// placement is folded in).
    pub positions: Vec<Vec3>,
    /// Render vertex normals if the source had them (used to keep hard edges hard).
    pub normals: Option<Vec<Vec3>>,
    /// Counter-clockwise (outward) triangles over `positions`.
    pub triangles: Vec<[u32; 3]>,
}

/// Translation, rotation and scale of an object as placed in a scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Translation in metres.
    pub translation_m: Vec3,
    /// Rotation.
    pub rotation: Quat,
    /// Per-axis scale (1 = as modelled).
    pub scale: Vec3,
}

impl Default for Placement {
    fn default() -> Self {
        Self {
            translation_m: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        }
    }
}

impl Placement {
    /// A uniform scale.
    pub fn scaled(scale: f32) -> Self {
        Self {
            scale: Vec3::splat(scale),
            ..Self::default()
        }
    }
}

/// A mesh whose duplicate positions have been merged, with the map back to render vertices.
#[derive(Clone, Debug)]
pub struct WeldedMesh {
    /// Unique positions.
    pub positions: Vec<Vec3>,
    /// Triangles over the unique positions (same order and count as the render triangles).
    pub triangles: Vec<[u32; 3]>,
    /// For each render vertex, its welded vertex: seams never crack because both sides read
    /// the same welded position.
    pub render_to_welded: Vec<u32>,
    /// For each render vertex, its normal slot: render vertices of one welded vertex share a
    /// slot when their source normals agree (smooth across UV seams, hard across creases).
    pub render_to_normal_slot: Vec<u32>,
    /// Number of normal slots.
    pub normal_slots: usize,
}

impl Mesh {
    /// Loads an OBJ, glTF, GLB or PLY file, chosen by extension.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, SoftBodyError> {
        let path = path.as_ref();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        let bytes = std::fs::read(path).map_err(|source| SoftBodyError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        match ext.as_str() {
            "obj" => {
                let text = std::str::from_utf8(&bytes)
                    .map_err(|e| SoftBodyError::malformed(path, format!("not UTF-8 text: {e}")))?;
                Self::from_obj_str(text, path)
            }
            "gltf" | "glb" => Self::from_gltf_slice(&bytes, path),
            "ply" => crate::ply::parse_ply(&bytes, path),
            _ => Err(SoftBodyError::UnsupportedFormat {
                path: path.to_path_buf(),
            }),
        }
    }

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

    /// Parses a glTF 2.0 document (JSON `.gltf` or binary `.glb`): every triangle primitive of
    /// every mesh, with node transforms of the default scene applied. Buffers come from the GLB
    /// chunk, `data:` URIs, or files next to `source`.
    pub fn from_gltf_slice(bytes: &[u8], source: impl AsRef<Path>) -> Result<Self, SoftBodyError> {
        let src = source.as_ref();
        let gltf = gltf::Gltf::from_slice(bytes)
            .map_err(|e| SoftBodyError::malformed(src, format!("invalid glTF: {e}")))?;
        let mut buffers: Vec<Vec<u8>> = Vec::new();
        for buffer in gltf.buffers() {
            let data = match buffer.source() {
                gltf::buffer::Source::Bin => gltf.blob.clone().ok_or_else(|| {
                    SoftBodyError::malformed(src, "glTF refers to a binary chunk that is missing")
                })?,
                gltf::buffer::Source::Uri(uri) => {
                    if let Some(rest) = uri.strip_prefix("data:") {
                        let b64 = rest.split_once(";base64,").map(|(_, d)| d).ok_or_else(|| {
                            SoftBodyError::malformed(src, "glTF data URI is not base64")
                        })?;
                        decode_base64(b64).ok_or_else(|| {
                            SoftBodyError::malformed(src, "glTF data URI has invalid base64")
                        })?
                    } else {
                        if uri.contains("..") || uri.starts_with('/') || uri.contains(':') {
                            return Err(SoftBodyError::malformed(
                                src,
                                format!("glTF buffer URI `{uri}` leaves the file's folder"),
                            ));
                        }
                        let p = src.parent().unwrap_or(Path::new(".")).join(uri);
                        std::fs::read(&p).map_err(|source| SoftBodyError::Io {
                            path: p.clone(),
                            source,
                        })?
                    }
                }
            };
            if data.len() < buffer.length() {
                return Err(SoftBodyError::malformed(
                    src,
                    format!(
                        "glTF buffer {} has {} bytes, declares {}",
                        buffer.index(),
                        data.len(),
                        buffer.length()
                    ),
                ));
            }
            buffers.push(data);
        }
        let mut out = Mesh {
            positions: Vec::new(),
            normals: Some(Vec::new()),
            triangles: Vec::new(),
        };
        let scene = gltf.default_scene().or_else(|| gltf.scenes().next());
        // (node, parent transform, depth). glTF node graphs must be trees, but nothing in the
        // parser stops a cycle or a node listed as a child many times: depth and the total
        // number of visits are bounded before anything is pushed.
        const MAX_DEPTH: usize = 64;
        const MAX_VISITS: usize = 100_000;
        let mut stack: Vec<(gltf::Node, glam::Mat4, usize)> = match scene {
            Some(s) => s.nodes().map(|n| (n, glam::Mat4::IDENTITY, 0)).collect(),
            None => Vec::new(),
        };
        let mut visits = stack.len();
        while let Some((node, parent, depth)) = stack.pop() {
            if depth > MAX_DEPTH {
                return Err(SoftBodyError::malformed(
                    src,
                    format!("glTF node graph is deeper than {MAX_DEPTH} (cyclic?)"),
                ));
            }
            let local = glam::Mat4::from_cols_array_2d(&node.transform().matrix());
            let world = parent * local;
            for child in node.children() {
                visits += 1;
                if visits > MAX_VISITS {
                    return Err(SoftBodyError::malformed(
                        src,
                        format!("glTF node graph has more than {MAX_VISITS} node visits (cyclic?)"),
                    ));
                }
                stack.push((child, world, depth + 1));
            }
            let Some(mesh) = node.mesh() else { continue };
            let normal_m = glam::Mat3::from_mat4(world).inverse().transpose();
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    return Err(SoftBodyError::malformed(
                        src,
                        format!(
                            "glTF mesh {} primitive uses {:?}, not triangles",
                            mesh.index(),
                            prim.mode()
                        ),
                    ));
                }
                // The gltf reader trusts accessors (stride, type, count) and panics on bad ones:
                // check every accessor it will read against its buffer first.
                let position = prim.get(&gltf::Semantic::Positions).ok_or_else(|| {
                    SoftBodyError::malformed(
                        src,
                        format!("glTF mesh {} has no POSITION", mesh.index()),
                    )
                })?;
                check_accessor(
                    &position,
                    &buffers,
                    &[gltf::accessor::DataType::F32],
                    gltf::accessor::Dimensions::Vec3,
                    src,
                )?;
                let has_normals = match prim.get(&gltf::Semantic::Normals) {
                    Some(a) if a.count() == position.count() => {
                        check_accessor(
                            &a,
                            &buffers,
                            &[gltf::accessor::DataType::F32],
                            gltf::accessor::Dimensions::Vec3,
                            src,
                        )?;
                        true
                    }
                    _ => false,
                };
                if let Some(a) = prim.indices() {
                    use gltf::accessor::DataType::{U16, U32, U8};
                    check_accessor(
                        &a,
                        &buffers,
                        &[U8, U16, U32],
                        gltf::accessor::Dimensions::Scalar,
                        src,
                    )?;
                }
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
                let pos: Vec<Vec3> = reader
                    .read_positions()
                    .ok_or_else(|| {
                        SoftBodyError::malformed(
                            src,
                            format!("glTF mesh {} has no POSITION", mesh.index()),
                        )
                    })?
                    .map(|p| world.transform_point3(Vec3::from_array(p)))
                    .collect();
                let base = out.positions.len() as u32;
                let n = pos.len() as u32;
                match reader.read_normals().filter(|_| has_normals) {
                    Some(ns) if ns.len() == pos.len() => {
                        if let Some(v) = out.normals.as_mut() {
                            v.extend(
                                ns.map(|x| (normal_m * Vec3::from_array(x)).normalize_or_zero()),
                            );
                        }
                    }
                    _ => out.normals = None,
                }
                out.positions.extend(pos);
                let idx: Vec<u32> = match reader.read_indices() {
                    Some(i) => i.into_u32().collect(),
                    None => (0..n).collect(),
                };
                if idx.len() % 3 != 0 {
                    return Err(SoftBodyError::malformed(
                        src,
                        format!("glTF index count {} is not a multiple of 3", idx.len()),
                    ));
                }
                for t in idx.chunks_exact(3) {
                    if t.iter().any(|&i| i >= n) {
                        return Err(SoftBodyError::malformed(
                            src,
                            format!(
                                "glTF index {} out of range (primitive has {n} vertices)",
                                t.iter().max().copied().unwrap_or(0)
                            ),
                        ));
                    }
                    out.triangles.push([base + t[0], base + t[1], base + t[2]]);
                }
                if out.positions.len() > MAX_MESH_ELEMENTS
                    || out.triangles.len() > MAX_MESH_ELEMENTS
                {
                    return Err(SoftBodyError::malformed(src, "glTF mesh is too large"));
                }
            }
        }
        out.validate(src)?;
        Ok(out)
    }

    /// Checks the mesh is usable: non-empty, finite, indices in range, no triangle repeating a
    /// vertex. The error names `source` and what is wrong.
    pub fn validate(&self, source: impl AsRef<Path>) -> Result<(), SoftBodyError> {
        let src = source.as_ref();
        if self.positions.is_empty() {
            return Err(SoftBodyError::malformed(src, "mesh has no vertices"));
        }
        if self.triangles.is_empty() {
            return Err(SoftBodyError::malformed(src, "mesh has no triangles"));
        }
        if let Some(i) = self
            .positions
            .iter()
            .position(|p| p.is_finite() && p.abs().max_element() > MAX_COORDINATE_M)
        {
            return Err(SoftBodyError::malformed(
                src,
                format!(
                    "vertex {i} lies {:.3e} m from the origin, beyond {MAX_COORDINATE_M} m",
                    self.positions[i].abs().max_element()
                ),
            ));
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(SoftBodyError::malformed(
                src,
                format!("vertex {i} is not finite: {:?}", self.positions[i]),
            ));
        }
        if let Some(n) = &self.normals {
            if n.len() != self.positions.len() {
                return Err(SoftBodyError::malformed(
                    src,
                    "normal count differs from vertex count",
                ));
            }
        }
        let nv = self.positions.len() as u32;
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(&bad) = tri.iter().find(|&&i| i >= nv) {
                return Err(SoftBodyError::malformed(
                    src,
                    format!("triangle {t} uses vertex {bad}, but there are {nv}"),
                ));
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(SoftBodyError::malformed(
                    src,
                    format!("triangle {t} repeats a vertex: {tri:?}"),
                ));
            }
        }
        Ok(())
    }

    /// Folds a placement into the vertices and normals (thesis 3.5.1, Appendix A.9): the body
    /// then lives at the identity transform, so the simulation never multiplies by it again.
    pub fn bake(mut self, placement: &Placement) -> Self {
        let m = glam::Affine3A::from_scale_rotation_translation(
            placement.scale,
            placement.rotation,
            placement.translation_m,
        );
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        if let Some(ns) = &mut self.normals {
            let nm = glam::Mat3::from(m.matrix3).inverse().transpose();
            for n in ns {
                *n = (nm * *n).normalize_or_zero();
            }
        }
        // A mirroring scale flips the winding; keep triangles outward.
        if placement.scale.x * placement.scale.y * placement.scale.z < 0.0 {
            for t in &mut self.triangles {
                t.swap(1, 2);
            }
        }
        self
    }

    /// Translates so the centroid of the vertices is the origin; returns the offset removed.
    pub fn recenter(&mut self) -> Vec3 {
        let c = self.positions.iter().copied().sum::<Vec3>() / self.positions.len().max(1) as f32;
        for p in &mut self.positions {
            *p -= c;
        }
        c
    }

    /// Scales uniformly so the largest extent of the bounding box is `size_m`.
    pub fn fit_size(mut self, size_m: f32) -> Self {
        let (lo, hi) = bounds(&self.positions);
        let ext = (hi - lo).max_element();
        if ext > 0.0 {
            let s = size_m / ext;
            for p in &mut self.positions {
                *p *= s;
            }
        }
        self
    }

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

impl WeldedMesh {
    /// Signed volume enclosed by the welded triangles (positive for outward winding).
    pub fn volume(&self, positions: &[Vec3]) -> f32 {
        enclosed_volume(positions, &self.triangles)
    }
}

/// Signed volume of a closed triangle mesh (divergence theorem).
pub fn enclosed_volume(positions: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    let mut v = 0.0f64;
    for t in triangles {
        let (a, b, c) = (
            positions[t[0] as usize],
            positions[t[1] as usize],
            positions[t[2] as usize],
        );
        v += a.as_dvec3().dot(b.as_dvec3().cross(c.as_dvec3()));
    }
    (v / 6.0) as f32
}

/// Axis-aligned bounds of a point set (zero box for an empty set).
pub fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    if points.is_empty() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    points.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

/// Checks that an accessor the gltf reader will iterate is of the expected type and lies
/// inside its buffer view and buffer (checked arithmetic throughout).
fn check_accessor(
    a: &gltf::Accessor,
    buffers: &[Vec<u8>],
    types: &[gltf::accessor::DataType],
    dims: gltf::accessor::Dimensions,
    src: &Path,
) -> Result<(), SoftBodyError> {
    let bad = |what: String| {
        SoftBodyError::malformed(src, format!("glTF accessor {}: {what}", a.index()))
    };
    if a.sparse().is_some() {
        return Err(bad("sparse accessors are not supported".into()));
    }
    if a.dimensions() != dims || !types.contains(&a.data_type()) {
        return Err(bad(format!(
            "is {:?} {:?}, expected {dims:?} of {types:?}",
            a.dimensions(),
            a.data_type()
        )));
    }
    if a.count() == 0 {
        return Err(bad("has no elements".into()));
    }
    if a.count() > MAX_MESH_ELEMENTS {
        return Err(bad(format!(
            "has {} elements, more than {MAX_MESH_ELEMENTS}",
            a.count()
        )));
    }
    let view = a.view().ok_or_else(|| bad("has no buffer view".into()))?;
    let size = a.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(bad(format!(
            "stride {stride} is smaller than its element ({size} bytes)"
        )));
    }
    let buffer_len = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    let view_end = view.offset().checked_add(view.length());
    let last = stride
        .checked_mul(a.count() - 1)
        .and_then(|x| x.checked_add(a.offset()))
        .and_then(|x| x.checked_add(size));
    match (view_end, last) {
        (Some(end), Some(last)) if end <= buffer_len && last <= view.length() => Ok(()),
        _ => Err(bad(
            "reaches past the end of its buffer view or buffer".into()
        )),
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

fn decode_base64(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0u32;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b'\r' | b'\n' | b' ' => continue,
            _ => return None,
        } as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// Where a mesh comes from, for configs and scene files.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeshSource {
    /// A file (OBJ, glTF, GLB).
    File(PathBuf),
    /// An icosphere with this many subdivisions.
    Icosphere {
        /// Radius in metres.
        radius_m: f32,
        /// Subdivision levels.
        subdivisions: u32,
    },
    /// A box.
    Cuboid {
        /// Half extents in metres.
        half_extents_m: Vec3,
        /// Cells per edge.
        subdivisions: u32,
    },
}

impl MeshSource {
    /// Builds or loads the mesh.
    pub fn build(&self) -> Result<Mesh, SoftBodyError> {
        match self {
            MeshSource::File(p) => Mesh::load(p),
            MeshSource::Icosphere {
                radius_m,
                subdivisions,
            } => Ok(Mesh::icosphere(*radius_m, (*subdivisions).min(7))),
            MeshSource::Cuboid {
                half_extents_m,
                subdivisions,
            } => Ok(Mesh::cuboid(*half_extents_m, (*subdivisions).min(64))),
        }
    }
}
