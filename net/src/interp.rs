//! Snapshot interpolation on remote peers: a per-object buffer played back with a delay of
//! about two send intervals plus measured jitter; bounded extrapolation; snap on teleports.

use std::collections::VecDeque;
use std::time::Duration;

use glam::{Quat, Vec3};

use crate::time::Instant;

/// A replicated object state: center transform plus particle offsets in the center's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// Sample time, in the local clock (sender time mapped through the link's offset).
    pub time: Instant,
    /// Center position.
    pub pos: Vec3,
    /// Center rotation.
    pub rot: Quat,
    /// Particle offsets in the center's local frame.
    pub offsets: Vec<Vec3>,
    /// The owner marked the object at rest (never extrapolate past it).
    pub rest: bool,
}

/// Interpolation settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InterpolationConfig {
    /// Delay in send intervals (before jitter is added).
    pub intervals: f32,
    /// Jitter multiplier added to the delay.
    pub jitter_factor: f32,
    /// Longest extrapolation past the newest sample.
    pub max_extrapolation: Duration,
    /// Snap (drop history) when a new sample is this far from the previous one (metres).
    pub snap_distance_m: f32,
}

impl Default for InterpolationConfig {
    fn default() -> Self {
        InterpolationConfig {
            intervals: 2.0,
            jitter_factor: 2.0,
            max_extrapolation: Duration::from_millis(50),
            snap_distance_m: 2.0,
        }
    }
}

impl InterpolationConfig {
    /// The same settings made usable: the delay factors (`intervals`, `jitter_factor`)
    /// clamped to [0, 100], a non-finite one replaced by the default; a negative or non-finite
    /// snap distance replaced by the default.
    pub fn sanitized(self) -> Self {
        let d = InterpolationConfig::default();
        let factor = |v: f32, def: f32| {
            if v.is_finite() {
                v.clamp(0.0, 100.0)
            } else {
                def
            }
        };
        InterpolationConfig {
            intervals: factor(self.intervals, d.intervals),
            jitter_factor: factor(self.jitter_factor, d.jitter_factor),
            max_extrapolation: self.max_extrapolation,
            snap_distance_m: if self.snap_distance_m.is_finite() && self.snap_distance_m >= 0.0 {
                self.snap_distance_m
            } else {
                d.snap_distance_m
            },
        }
    }
}

/// Buffer of recent snapshots of one object.
#[derive(Clone, Debug, Default)]
pub struct SnapshotBuffer {
    samples: VecDeque<Snapshot>,
}

const MAX_SAMPLES: usize = 64;

/// The shortest span between the last two samples that a velocity is read from to
/// extrapolate. A peer whose frame runs several fixed steps back to back (a slow renderer, a
/// starved machine) sends their states a fraction of a millisecond apart: a step's motion over
/// such a span reads as metres a second, and 50 ms of it threw a held body's particles half a
/// metre out (and, on the host, the props they struck off the table).
pub const MIN_EXTRAPOLATION_SPAN: Duration = Duration::from_millis(8);

impl SnapshotBuffer {
    /// Add a sample (older-than-newest samples are inserted in order; duplicates replace).
    pub fn push(&mut self, s: Snapshot, cfg: &InterpolationConfig) {
        if let Some(last) = self.samples.back() {
            if last.pos.distance(s.pos) > cfg.snap_distance_m {
                self.samples.clear();
            }
        }
        let at = self.samples.partition_point(|x| x.time <= s.time);
        if at > 0 && self.samples.get(at - 1).is_some_and(|x| x.time == s.time) {
            if let Some(x) = self.samples.get_mut(at - 1) {
                *x = s;
            }
        } else {
            self.samples.insert(at, s);
        }
        while self.samples.len() > MAX_SAMPLES {
            self.samples.pop_front();
        }
    }

    /// Newest sample.
    pub fn latest(&self) -> Option<&Snapshot> {
        self.samples.back()
    }

    /// State shown at local time `t` (already delayed by the caller).
    pub fn sample(&mut self, t: Instant, cfg: &InterpolationConfig) -> Option<Snapshot> {
        // drop samples no longer needed (keep one before t)
        while self.samples.len() > 2 && self.samples.get(1).is_some_and(|s| s.time <= t) {
            self.samples.pop_front();
        }
        let first = self.samples.front()?;
        if t <= first.time {
            return Some(Snapshot {
                time: t,
                ..first.clone()
            });
        }
        let n = self.samples.len();
        for i in 0..n.saturating_sub(1) {
            let (Some(a), Some(b)) = (self.samples.get(i), self.samples.get(i + 1)) else {
                break;
            };
            if t >= a.time && t <= b.time {
                let span = (b.time - a.time).as_secs_f32();
                let f = if span > 0.0 {
                    (t - a.time).as_secs_f32() / span
                } else {
                    1.0
                };
                return Some(lerp(a, b, f, t));
            }
        }
        // past the newest: bounded extrapolation from the last two samples, only just past
        // it (a late datagram); long after it the object has most likely stopped
        let last = self.samples.back()?;
        let behind = t - last.time;
        if n >= 2 && !last.rest && behind <= cfg.max_extrapolation * 2 {
            if let Some(prev) = self.samples.get(n - 2) {
                let span = (last.time - prev.time).as_secs_f32();
                let ahead = (t - last.time).min(cfg.max_extrapolation).as_secs_f32();
                if span >= MIN_EXTRAPOLATION_SPAN.as_secs_f32() && span < 0.5 {
                    let f = 1.0 + ahead / span;
                    return Some(lerp(prev, last, f, t));
                }
            }
        }
        Some(Snapshot {
            time: t,
            ..last.clone()
        })
    }
}

fn lerp(a: &Snapshot, b: &Snapshot, f: f32, t: Instant) -> Snapshot {
    let offsets = if a.offsets.len() == b.offsets.len() {
        a.offsets
            .iter()
            .zip(&b.offsets)
            .map(|(x, y)| x.lerp(*y, f))
            .collect()
    } else {
        b.offsets.clone()
    };
    let rot = if f <= 1.0 {
        a.rot.slerp(b.rot, f)
    } else {
        // extrapolate rotation: apply the a→b delta scaled by (f - 1), the short way round
        // (q and −q are the same rotation; w < 0 would read as an angle near 2π)
        let mut delta = b.rot * a.rot.inverse();
        if delta.w < 0.0 {
            delta = -delta;
        }
        let (axis, angle) = delta.to_axis_angle();
        let extra = Quat::from_axis_angle(axis, angle * (f - 1.0));
        (extra * b.rot).normalize()
    };
    Snapshot {
        time: t,
        pos: a.pos.lerp(b.pos, f),
        rot: if rot.is_finite() { rot } else { b.rot },
        offsets,
        rest: b.rest && f >= 1.0,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn snap(ms: u64, rot: Quat) -> Snapshot {
        Snapshot {
            time: Instant::from_millis(ms),
            pos: Vec3::ZERO,
            rot,
            offsets: Vec::new(),
            rest: false,
        }
    }

    /// The newer sample's quaternion has the other sign (same orientation): extrapolation
    /// must continue the 0.1 rad turn, not spin the other way round.
    #[test]
    fn extrapolation_across_a_quaternion_sign_flip_takes_the_short_way() {
        let cfg = InterpolationConfig::default();
        let mut b = SnapshotBuffer::default();
        b.push(snap(0, Quat::IDENTITY), &cfg);
        b.push(snap(100, -Quat::from_rotation_y(0.1)), &cfg);
        // 50 ms past the newest sample: f = 1.5
        let s = b.sample(Instant::from_millis(150), &cfg).unwrap();
        let err = s.rot.angle_between(Quat::from_rotation_y(0.15));
        assert!(err < 1e-3, "extrapolated {:?}, {err} rad off", s.rot);
    }

    fn held(ms: u64, x: f32) -> Snapshot {
        Snapshot {
            offsets: vec![Vec3::ZERO, Vec3::X * x],
            ..snap(ms, Quat::IDENTITY)
        }
    }

    /// A bursty sender's last two states a millisecond apart, a particle 1.4 cm further in
    /// the newer: 40 ms past it, the particle stays where it was last put (a velocity read
    /// over 1 ms would throw it 56 cm). Two states 16 ms apart still extrapolate.
    #[test]
    fn states_sent_back_to_back_are_not_extrapolated_from() {
        let cfg = InterpolationConfig::default();
        let mut b = SnapshotBuffer::default();
        b.push(held(0, 0.0), &cfg);
        b.push(held(16, 0.014), &cfg);
        b.push(held(17, 0.028), &cfg);
        let s = b.sample(Instant::from_millis(57), &cfg).unwrap();
        assert!((s.offsets[1].x - 0.028).abs() < 1e-6, "{:?}", s.offsets);
        let mut b = SnapshotBuffer::default();
        b.push(held(0, 0.0), &cfg);
        b.push(held(16, 0.014), &cfg);
        let s = b.sample(Instant::from_millis(24), &cfg).unwrap();
        assert!((s.offsets[1].x - 0.021).abs() < 1e-4, "{:?}", s.offsets);
    }
}
