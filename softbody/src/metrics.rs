//! Shape metrics used by tests and benchmarks: volume ratio, rest-shape error after the best
//! rigid fit, displacement, kinetic energy, non-finite and explosion flags.

use glam::{Mat3, Quat, Vec3};
use rapier3d::prelude::PhysicsWorld;
use serde::Serialize;

use crate::mesh::enclosed_volume;
use crate::SoftBody;

/// A snapshot of how far a soft body is from its rest shape.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ShapeMetrics {
    /// Enclosed volume / rest volume.
    pub volume_ratio: f32,
    /// RMS distance of the vertices to the rest shape after the best rigid fit, metres.
    pub rest_rms_m: f32,
    /// Largest such distance, metres.
    pub rest_max_m: f32,
    /// Largest distance of a vertex from where the center's rigid motion puts it, metres.
    pub max_displacement_m: f32,
    /// Kinetic energy of particles and center, joules.
    pub kinetic_energy_j: f32,
    /// Any vertex or particle is NaN or infinite.
    pub non_finite: bool,
    /// Displacement beyond twice the body's size or a particle faster than 100 m/s.
    pub exploded: bool,
}

/// Measures `body` in `world`.
pub fn measure(body: &SoftBody, world: &PhysicsWorld) -> ShapeMetrics {
    let verts = body.vertices();
    let rest = body.rest_vertices();
    let (c, r) = body.center_pose(world);
    let non_finite = verts.iter().any(|v| !v.is_finite());
    let (rest_rms_m, rest_max_m) = rigid_fit_error(verts, rest, r);
    let max_displacement_m = verts
        .iter()
        .zip(rest)
        .map(|(v, p)| v.distance(c + r * *p))
        .fold(0.0f32, f32::max);
    let mut ke = 0.0f32;
    let mut max_speed = 0.0f32;
    for h in body
        .particles()
        .iter()
        .chain(std::iter::once(&body.center()))
    {
        if let Some(b) = world.bodies.get(*h) {
            let v = b.linvel();
            max_speed = max_speed.max(v.length());
            ke += 0.5 * b.mass() * v.length_squared();
        }
    }
    let vol = enclosed_volume(verts, &body.welded().triangles);
    ShapeMetrics {
        volume_ratio: vol / body.rest_volume_m3(),
        rest_rms_m,
        rest_max_m,
        max_displacement_m,
        kinetic_energy_j: ke,
        non_finite,
        exploded: !non_finite && (max_displacement_m > 2.0 * body.size_m() || max_speed > 100.0),
    }
}

/// RMS and max distance between `current` and `reference` after the rigid transform that best
/// maps `reference` onto `current` (rotation by polar decomposition, started from `guess`).
pub fn rigid_fit_error(current: &[Vec3], reference: &[Vec3], guess: Quat) -> (f32, f32) {
    let d = rigid_fit_distances(current, reference, guess);
    if d.is_empty() {
        return (0.0, 0.0);
    }
    let mut sum = 0.0f64;
    let mut max = 0.0f32;
    for &v in &d {
        sum += (v as f64) * (v as f64);
        max = max.max(v);
    }
    (((sum / d.len() as f64).sqrt()) as f32, max)
}

/// Each vertex's distance between `current` and `reference` after the rigid fit of
/// [`rigid_fit_error`] (over the shorter of the two; empty if either is).
pub fn rigid_fit_distances(current: &[Vec3], reference: &[Vec3], guess: Quat) -> Vec<f32> {
    let n = current.len().min(reference.len());
    if n == 0 {
        return Vec::new();
    }
    let cx = current[..n].iter().copied().sum::<Vec3>() / n as f32;
    let cy = reference[..n].iter().copied().sum::<Vec3>() / n as f32;
    let mut a = Mat3::ZERO;
    for (x, y) in current[..n].iter().zip(&reference[..n]) {
        let (dx, dy) = (*x - cx, *y - cy);
        a += Mat3::from_cols(dx * dy.x, dx * dy.y, dx * dy.z);
    }
    let q = extract_rotation(a, guess);
    current[..n]
        .iter()
        .zip(&reference[..n])
        .map(|(x, y)| (q * (*y - cy) + cx).distance(*x))
        .collect()
}

/// Rotational part of `a` (Müller et al. 2016, "A Robust Method to Extract the Rotational Part
/// of Deformations"): converges from any start, never produces a reflection.
pub fn extract_rotation(a: Mat3, guess: Quat) -> Quat {
    let mut q = if guess.is_finite() {
        guess.normalize()
    } else {
        Quat::IDENTITY
    };
    for _ in 0..40 {
        let r = Mat3::from_quat(q);
        let omega_num =
            r.x_axis.cross(a.x_axis) + r.y_axis.cross(a.y_axis) + r.z_axis.cross(a.z_axis);
        let omega_den =
            (r.x_axis.dot(a.x_axis) + r.y_axis.dot(a.y_axis) + r.z_axis.dot(a.z_axis)).abs() + 1e-9;
        let omega = omega_num / omega_den;
        let w = omega.length();
        if !w.is_finite() || w < 1e-7 {
            break;
        }
        q = (Quat::from_axis_angle(omega / w, w) * q).normalize();
    }
    q
}
