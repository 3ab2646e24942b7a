//! bevy 0.19 is built on glam 0.32, rapier 0.36 and the softsync crates on glam 0.33: the
//! same layout, different types. These convert at the boundary.

/// Room vector → bevy vector.
pub fn to_bevy(v: glam::Vec3) -> bevy::math::Vec3 {
    bevy::math::Vec3::new(v.x, v.y, v.z)
}

/// Room rotation → bevy rotation.
pub fn to_bevy_quat(q: glam::Quat) -> bevy::math::Quat {
    bevy::math::Quat::from_xyzw(q.x, q.y, q.z, q.w)
}

/// bevy vector → room vector.
pub fn from_bevy(v: bevy::math::Vec3) -> glam::Vec3 {
    glam::Vec3::new(v.x, v.y, v.z)
}

/// bevy rotation → room rotation.
pub fn from_bevy_quat(q: bevy::math::Quat) -> glam::Quat {
    glam::Quat::from_xyzw(q.x, q.y, q.z, q.w)
}

/// A bevy transform's pose in room types.
pub fn pose_from_bevy(t: &bevy::transform::components::Transform) -> (glam::Vec3, glam::Quat) {
    (from_bevy(t.translation), from_bevy_quat(t.rotation))
}

/// A room pose as a bevy transform (a non-finite pose gives `None`).
pub fn transform(
    pos: glam::Vec3,
    rot: glam::Quat,
) -> Option<bevy::transform::components::Transform> {
    (pos.is_finite() && rot.is_finite()).then(|| {
        bevy::transform::components::Transform::from_translation(to_bevy(pos))
            .with_rotation(to_bevy_quat(rot))
    })
}
