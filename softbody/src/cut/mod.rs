//! Cutting soft-body meshes (the tear paper's Algorithm 2, `../shared/seeds/001_…` §3.2), with
//! what the paper leaves out: every piece is capped with a triangulated cross-section, so it
//! stays a closed solid whose volume and collision shape still mean something.
//!
//! - [`CutPlane`]: the plane, from a point and normal or from the paper's three points (the
//!   scalpel's entry point and its two endpoints), validated (finite, not degenerate).
//! - [`cut_mesh`] (in `plane`): splits every crossing face, gives each side its own copy of
//!   the new vertices (normals interpolated per face corner, so hard edges stay hard), caps
//!   both sides (`cap`: a constrained Delaunay triangulation of the section, inside chosen by
//!   the even–odd rule, so nested outlines and holes come out right) and separates each side
//!   into its connected pieces. [`cut_welded`] does the same for a mesh whose welded form the
//!   caller already has (a soft body keeps it), skipping the weld, most of a cut's time.
//! - [`TearMesh`] (in `tear`): progressive tearing (Algorithm 1) by the boxes of consecutive
//!   scalpel segments, over mesh [`Sections`] so a segment searches only nearby faces.
//! - [`MeshReport`] (in `check`): the validity of a mesh after cuts — degenerate or duplicate
//!   triangles, edges not shared by exactly two faces, inconsistent winding, volume.
//! - [`topology_hash`] (in `hash`): a hash of the triangles and quantised positions that two
//!   peers compare to know they hold the identical mesh.
//!
//! Everything here is a pure function of its input: no clock, no random numbers, no iteration
//! over hashed containers in an order that reaches the output. The same mesh and plane give
//! bit-identical pieces on every peer running the same build.

mod cap;
mod check;
mod hash;
pub mod particles;
mod plane;
mod sections;
mod tear;

use glam::Vec3;
use thiserror::Error;

pub use check::MeshReport;
pub use hash::topology_hash;
pub use particles::TearBoxPlanes;
pub use plane::{cut_mesh, cut_welded, Cut, Piece, Side};
pub use sections::{Aabb, Sections};
pub use tear::{TearMesh, TearSegment, TearStats, MAX_SEGMENT_M, MAX_TEAR_WIDTH_M, SECTION_FACES};

/// Most triangles a mesh may have to be cut: bounds the work a hostile event can ask for.
pub const MAX_CUT_TRIANGLES: usize = 1_000_000;

/// Why a cut was refused. A refused cut changes nothing.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CutError {
    /// A point, normal or offset is NaN or infinite.
    #[error("cut plane is not finite: {0}")]
    NonFinite(&'static str),
    /// The normal is zero, or the three points are (nearly) on one line.
    #[error("cut plane is degenerate: {0}")]
    Degenerate(&'static str),
    /// Every vertex lies on one side: the plane does not cross the object.
    #[error("the cut plane does not cross the mesh")]
    Misses,
    /// The mesh is empty, too large, or otherwise unusable.
    #[error("mesh cannot be cut: {0}")]
    Mesh(String),
}

/// An oriented plane: the points `x` with `normal · x = offset_m`. `normal` is unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutPlane {
    /// Unit normal; the positive side is where it points.
    pub normal: Vec3,
    /// Signed distance of the plane from the origin along `normal`, metres.
    pub offset_m: f32,
}

impl CutPlane {
    /// The plane through `point` with normal `normal` (any length but zero).
    pub fn new(point: Vec3, normal: Vec3) -> Result<Self, CutError> {
        if !point.is_finite() {
            return Err(CutError::NonFinite("point"));
        }
        if !normal.is_finite() {
            return Err(CutError::NonFinite("normal"));
        }
        let len = normal.length();
        if len <= 1e-12 || !len.is_finite() {
            return Err(CutError::Degenerate("zero normal"));
        }
        let normal = normal / len;
        let offset_m = normal.dot(point);
        if !offset_m.is_finite() {
            return Err(CutError::NonFinite("offset"));
        }
        Ok(Self { normal, offset_m })
    }

    /// The paper's plane (§3.2): through the scalpel's entry point into the mesh and the
    /// scalpel's two endpoints after the stroke. Its normal follows the right-hand rule on
    /// `(entry, tip_a, tip_b)`.
    pub fn through(entry: Vec3, tip_a: Vec3, tip_b: Vec3) -> Result<Self, CutError> {
        if !(entry.is_finite() && tip_a.is_finite() && tip_b.is_finite()) {
            return Err(CutError::NonFinite("scalpel point"));
        }
        let (u, v) = (tip_a - entry, tip_b - entry);
        let n = u.cross(v);
        // Collinear (or coincident) points: the area is tiny against the lengths.
        let scale = u.length() * v.length();
        if scale <= 0.0 || !scale.is_finite() || n.length() <= 1e-6 * scale {
            return Err(CutError::Degenerate("the three points are on one line"));
        }
        Self::new(entry, n)
    }

    /// Signed distance of `p` from the plane, metres (positive on the normal's side).
    pub fn distance(&self, p: Vec3) -> f32 {
        self.normal.dot(p) - self.offset_m
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn plane_rejects_bad_input() {
        assert_eq!(
            CutPlane::new(Vec3::ZERO, Vec3::ZERO),
            Err(CutError::Degenerate("zero normal"))
        );
        assert!(matches!(
            CutPlane::new(Vec3::NAN, Vec3::X),
            Err(CutError::NonFinite(_))
        ));
        assert!(matches!(
            CutPlane::new(Vec3::ZERO, Vec3::new(f32::INFINITY, 0.0, 0.0)),
            Err(CutError::NonFinite(_))
        ));
        assert!(matches!(
            CutPlane::through(Vec3::ZERO, Vec3::X, Vec3::X * 2.0),
            Err(CutError::Degenerate(_))
        ));
        assert!(matches!(
            CutPlane::through(Vec3::ZERO, Vec3::ZERO, Vec3::Y),
            Err(CutError::Degenerate(_))
        ));
    }

    #[test]
    fn plane_through_three_points_contains_them() {
        let (a, b, c) = (
            Vec3::new(0.1, 0.2, 0.3),
            Vec3::new(0.5, -0.2, 0.1),
            Vec3::new(-0.3, 0.4, 0.9),
        );
        let p = CutPlane::through(a, b, c).unwrap();
        for q in [a, b, c] {
            assert!(p.distance(q).abs() < 1e-6, "{}", p.distance(q));
        }
        assert!((p.normal.length() - 1.0).abs() < 1e-6);
        // Right-hand rule.
        assert!(p.normal.dot((b - a).cross(c - a)) > 0.0);
    }
}
