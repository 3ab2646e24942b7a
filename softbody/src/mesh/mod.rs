//! Triangle meshes: the [`Mesh`] type, validation, baking the object's transform into the
//! vertices (thesis 3.5.1), and where a mesh comes from. The children add to [`Mesh`]:
//! loading (`obj`, `gltf`, `ply`, chosen by extension in [`Mesh::load`]), welding duplicate
//! positions (`weld`) and procedural shapes (`procedural`). They depend on this module; it
//! reaches into them only through the loader's dispatch.

mod gltf;
mod obj;
mod ply;
mod procedural;
mod weld;

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

/// Largest mesh file (or glTF buffer) [`Mesh::load`] reads, bytes.
pub const MAX_MESH_FILE_BYTES: u64 = 256 << 20;

/// Reads a mesh file or a glTF buffer: only a regular file (after links; not a device, a FIFO
/// or a folder, which could block or never end), of at most [`MAX_MESH_FILE_BYTES`], checked
/// before anything is read, and read through a bound in case it grows meanwhile.
pub(crate) fn read_mesh_file(path: &Path) -> Result<Vec<u8>, SoftBodyError> {
    use std::io::Read as _;
    let io = |source| SoftBodyError::Io {
        path: path.to_path_buf(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(SoftBodyError::malformed(
            path,
            "not a regular file (a device, a pipe or a folder is never read)",
        ));
    }
    if meta.len() > MAX_MESH_FILE_BYTES {
        return Err(SoftBodyError::malformed(
            path,
            format!(
                "{} bytes, more than the {MAX_MESH_FILE_BYTES} a mesh file may have",
                meta.len()
            ),
        ));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    std::fs::File::open(path)
        .map_err(io)?
        .take(MAX_MESH_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > MAX_MESH_FILE_BYTES {
        return Err(SoftBodyError::malformed(
            path,
            format!("grew past the {MAX_MESH_FILE_BYTES} bytes a mesh file may have"),
        ));
    }
    Ok(bytes)
}

impl Mesh {
    /// Loads an OBJ, glTF, GLB or PLY file, chosen by extension (checked before anything is
    /// read; the file must be a regular one of at most [`MAX_MESH_FILE_BYTES`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, SoftBodyError> {
        let path = path.as_ref();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        if !matches!(ext.as_str(), "obj" | "gltf" | "glb" | "ply") {
            return Err(SoftBodyError::UnsupportedFormat {
                path: path.to_path_buf(),
            });
        }
        let bytes = read_mesh_file(path)?;
        match ext.as_str() {
            "obj" => {
                let text = std::str::from_utf8(&bytes)
                    .map_err(|e| SoftBodyError::malformed(path, format!("not UTF-8 text: {e}")))?;
                Self::from_obj_str(text, path)
            }
            "gltf" | "glb" => Self::from_gltf_slice(&bytes, path),
            "ply" => ply::parse_ply(&bytes, path),
            _ => Err(SoftBodyError::UnsupportedFormat {
                path: path.to_path_buf(),
            }),
        }
    }

    /// The files [`Mesh::load`] reads for `path`, relative to its folder: the file itself and,
    /// for a `.gltf`, its external buffers (`data:` URIs and a GLB's own chunk need nothing
    /// else). So a mesh can be copied elsewhere whole (a scene shared with a joiner).
    pub fn files_read(path: impl AsRef<Path>) -> Result<Vec<String>, SoftBodyError> {
        let path = path.as_ref();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .ok_or_else(|| SoftBodyError::malformed(path, "not a file name"))?
            .to_owned();
        let is_gltf = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("gltf"));
        if !is_gltf {
            return Ok(vec![name]);
        }
        let bytes = read_mesh_file(path)?;
        let mut files = vec![name];
        files.extend(gltf::external_buffers(&bytes, path)?);
        Ok(files)
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
