//! glTF 2.0 (`.gltf` JSON or `.glb` binary): triangle primitives of the default scene, every
//! accessor checked against its buffer before the gltf reader (which trusts them) reads it.

use std::path::Path;

use glam::Vec3;

use super::{Mesh, MAX_MESH_ELEMENTS};
use crate::SoftBodyError;

/// The external buffer files a glTF document names (relative to its folder, checked to stay
/// inside it as [`Mesh::from_gltf_slice`] checks them).
pub(super) fn external_buffers(bytes: &[u8], src: &Path) -> Result<Vec<String>, SoftBodyError> {
    let gltf = gltf::Gltf::from_slice(bytes)
        .map_err(|e| SoftBodyError::malformed(src, format!("invalid glTF: {e}")))?;
    let mut out = Vec::new();
    for buffer in gltf.buffers() {
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            if uri.starts_with("data:") {
                continue;
            }
            if uri.contains("..") || uri.starts_with('/') || uri.contains(':') {
                return Err(SoftBodyError::malformed(
                    src,
                    format!("glTF buffer URI `{uri}` leaves the file's folder"),
                ));
            }
            out.push(uri.to_owned());
        }
    }
    Ok(out)
}

impl Mesh {
    /// Parses a glTF 2.0 document (JSON `.gltf` or binary `.glb`): every triangle primitive of
    /// every mesh, with node transforms of the default scene applied. Buffers come from the GLB
    /// chunk, `data:` URIs, or files next to `source`.
    ///
    /// The `gltf` crate (1.4) panics on some malformed documents (its validation indexes an
    /// accessor before checking it exists: found by `tests/hostile_meshes.rs`); such a panic
    /// is caught and reported as a malformed file, so a hostile mesh cannot take a peer down.
    pub fn from_gltf_slice(bytes: &[u8], source: impl AsRef<Path>) -> Result<Self, SoftBodyError> {
        let src = source.as_ref();
        std::panic::catch_unwind(|| Self::from_gltf_slice_unguarded(bytes, src)).unwrap_or_else(
            |_| {
                Err(SoftBodyError::malformed(
                    src,
                    "invalid glTF (the glTF parser failed on it)",
                ))
            },
        )
    }

    fn from_gltf_slice_unguarded(bytes: &[u8], src: &Path) -> Result<Self, SoftBodyError> {
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
                        super::read_mesh_file(&p)?
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
                // Positions and normals are both three f32s.
                let check_vec3 = |a: &gltf::Accessor| {
                    check_accessor(
                        a,
                        &buffers,
                        &[gltf::accessor::DataType::F32],
                        gltf::accessor::Dimensions::Vec3,
                        src,
                    )
                };
                check_vec3(&position)?;
                let has_normals = match prim.get(&gltf::Semantic::Normals) {
                    Some(a) if a.count() == position.count() => {
                        check_vec3(&a)?;
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
