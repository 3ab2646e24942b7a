//! Shared helpers of the integration tests.
#![allow(dead_code, clippy::unwrap_used)]

use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::{
    ClassConfig, ClassId, ConditionerConfig, Event, Instant, NetId, ObjectState, SendPolicy,
    SessionConfig, SoftBodyMode,
};

pub const RIGID: ClassId = ClassId(0);
pub const SOFT: ClassId = ClassId(1);

pub fn config() -> SessionConfig {
    SessionConfig {
        classes: vec![
            ClassConfig::rigid("rigid", SendPolicy::default()),
            ClassConfig::soft_body("soft", SendPolicy::default(), SoftBodyMode::Particles),
        ],
        ..SessionConfig::default()
    }
}

/// A room of `n` peers that have all joined.
pub fn room(n: usize, link: ConditionerConfig) -> Harness {
    let mut h = Harness::new(n, config(), link);
    h.advance(Duration::from_millis(1500));
    for i in 0..n {
        assert!(h.peers[i].session.is_connected(), "peer {i} did not join");
    }
    h
}

/// Rest offsets of a 60-particle soft body (a squashed sphere of radius ~0.15 m).
pub fn rest_offsets(n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            let t = i as f32 / n as f32;
            let phi = std::f32::consts::PI * (1.0 + 5f32.sqrt()) * i as f32;
            let y = 1.0 - 2.0 * t;
            let r = (1.0 - y * y).max(0.0).sqrt();
            Vec3::new(r * phi.cos(), y, r * phi.sin()) * 0.15
        })
        .collect()
}

/// Soft-body state at time `t` seconds: moving center, squeezed along x.
pub fn soft_state(center: Vec3, rot: Quat, squeeze: f32) -> ObjectState {
    let particles = rest_offsets(60)
        .into_iter()
        .map(|o| {
            let d = Vec3::new(
                o.x * (1.0 - squeeze),
                o.y * (1.0 + 0.5 * squeeze),
                o.z * (1.0 + 0.5 * squeeze),
            );
            center + rot * d
        })
        .collect();
    ObjectState {
        pos: center,
        rot,
        particles,
    }
}

/// Id of the object spawned for `request` by peer `i` (from its events).
pub fn spawned_id(h: &Harness, i: usize, request: u32) -> Option<NetId> {
    h.peers[i].events.iter().find_map(|e| match e {
        Event::Spawned {
            id,
            request: Some(r),
            ..
        } if *r == request => Some(*id),
        _ => None,
    })
}

pub fn max_particle_error(a: &ObjectState, b: &ObjectState) -> f32 {
    let mut e = a.pos.distance(b.pos);
    for (x, y) in a.particles.iter().zip(&b.particles) {
        e = e.max(x.distance(*y));
    }
    assert_eq!(a.particles.len(), b.particles.len());
    e
}

pub fn t(h: &Harness) -> f32 {
    h.now.as_secs_f64() as f32
}

pub fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

pub fn _unused(_: Instant) {}
