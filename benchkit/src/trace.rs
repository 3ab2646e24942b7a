//! Recorded object-state traces for benchmarks and demos (e.g. the soft-body crate's
//! squeeze/poke/pull recording in `assets/traces/softbody60.sstr`): replaying them lets the
//! network code be measured on real deformation without depending on the simulation.
//! Frames are plain glam values so that neither the network nor the soft-body crate is needed
//! here: the network benches turn a [`Frame`] into their object state.

use glam::{Quat, Vec3};

/// Shortest frame interval a trace may have (seconds).
pub const MIN_DT_S: f32 = 1e-4;
/// Longest frame interval a trace may have (seconds).
pub const MAX_DT_S: f32 = 10.0;

/// One recorded instant of the body.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Center position.
    pub pos: Vec3,
    /// Center rotation.
    pub rot: Quat,
    /// Particle positions in world space.
    pub particles: Vec<Vec3>,
}

/// A recorded soft-body trace (`assets/traces/softbody60.sstr`, written by
/// `cargo run --release -p softsync-softbody --example trace`): magic `SSTR`, u32 version 1,
/// u32 frames, u32 particles, f32 dt_s (within [`MIN_DT_S`, `MAX_DT_S`]), then per frame center position (3 × f32), rotation
/// xyzw (4 × f32) and world particle positions (3 × f32 each), little endian.
#[derive(Clone, Debug)]
pub struct Trace {
    /// Seconds between frames.
    pub dt_s: f32,
    /// The frames.
    pub frames: Vec<Frame>,
    /// Per frame: the body is being interacted with (thesis: only that time was measured).
    pub active: Vec<bool>,
}

impl Trace {
    /// Parses a trace file's bytes; `None` if they are not a valid trace.
    pub fn parse(b: &[u8]) -> Option<Trace> {
        let u32_at = |o: usize| -> Option<u32> {
            Some(u32::from_le_bytes(b.get(o..o + 4)?.try_into().ok()?))
        };
        let f32_at = |o: usize| -> Option<f32> {
            Some(f32::from_le_bytes(b.get(o..o + 4)?.try_into().ok()?))
        };
        if b.get(0..4)? != b"SSTR" || u32_at(4)? != 1 {
            return None;
        }
        let frames = u32_at(8)? as usize;
        let n = u32_at(12)? as usize;
        let dt_s = f32_at(16)?;
        let stride = (7 + 3 * n) * 4;
        if frames == 0
            || n > 100_000
            || b.len() != 20 + frames.checked_mul(stride)?
            || !(MIN_DT_S..=MAX_DT_S).contains(&dt_s)
        {
            return None;
        }
        let mut out = Vec::with_capacity(frames);
        for f in 0..frames {
            let o = 20 + f * stride;
            let v = |k: usize| f32_at(o + 4 * k);
            let pos = Vec3::new(v(0)?, v(1)?, v(2)?);
            let rot = Quat::from_xyzw(v(3)?, v(4)?, v(5)?, v(6)?).normalize();
            let particles = (0..n)
                .map(|i| Some(Vec3::new(v(7 + 3 * i)?, v(8 + 3 * i)?, v(9 + 3 * i)?)))
                .collect::<Option<Vec<_>>>()?;
            let st = Frame {
                pos,
                rot,
                particles,
            };
            if !(st.pos.is_finite()
                && st.rot.is_finite()
                && st.particles.iter().all(|p| p.is_finite()))
            {
                return None;
            }
            out.push(st);
        }
        // interaction = some particle moves faster than 1 cm/s, dilated by 0.2 s
        let moving: Vec<bool> = (0..out.len())
            .map(|f| {
                f > 0
                    && out[f]
                        .particles
                        .iter()
                        .zip(&out[f - 1].particles)
                        .any(|(a, b)| a.distance(*b) / dt_s > 0.01)
            })
            .collect();
        let pad = (0.2 / dt_s).ceil() as usize;
        let active = (0..out.len())
            .map(|f| (f.saturating_sub(pad)..(f + pad + 1).min(out.len())).any(|g| moving[g]))
            .collect();
        Some(Trace {
            dt_s,
            frames: out,
            active,
        })
    }

    /// Is someone interacting with the body at `t` (looped)?
    pub fn active(&self, t: f32) -> bool {
        let x = (t.rem_euclid(self.duration_s())) / self.dt_s;
        let i = (x.floor() as usize).min(self.frames.len() - 1);
        self.active[i]
    }

    /// Fraction of frames with interaction.
    pub fn active_fraction(&self) -> f32 {
        self.active.iter().filter(|a| **a).count() as f32 / self.active.len().max(1) as f32
    }

    /// Length in seconds.
    pub fn duration_s(&self) -> f32 {
        self.dt_s * self.frames.len() as f32
    }

    /// State at `t` seconds, looping (the trace starts and ends at rest), interpolated.
    pub fn state(&self, t: f32) -> Frame {
        let x = (t.rem_euclid(self.duration_s())) / self.dt_s;
        let i = (x.floor() as usize).min(self.frames.len() - 1);
        let j = (i + 1) % self.frames.len();
        let f = (x - i as f32).clamp(0.0, 1.0);
        let (a, b) = (&self.frames[i], &self.frames[j]);
        Frame {
            pos: a.pos.lerp(b.pos, f),
            rot: a.rot.slerp(b.rot, f),
            particles: a
                .particles
                .iter()
                .zip(&b.particles)
                .map(|(p, q)| p.lerp(*q, f))
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn bytes(frames: u32, n: u32) -> Vec<u8> {
        let mut b = b"SSTR".to_vec();
        for v in [1u32, frames, n] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&(1.0f32 / 90.0).to_le_bytes());
        for f in 0..frames {
            let mut vals = vec![0.0f32, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
            for i in 0..n {
                vals.extend_from_slice(&[i as f32 * 0.01 + f as f32 * 0.001, 1.0, 0.0]);
            }
            for v in vals {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn parses_and_interpolates() {
        let t = Trace::parse(&bytes(3, 4)).unwrap();
        assert_eq!(t.frames.len(), 3);
        assert_eq!(t.frames[0].particles.len(), 4);
        let mid = t.state(0.5 * t.dt_s);
        assert!((mid.particles[1].x - 0.0105).abs() < 1e-5);
    }

    #[test]
    fn hostile_bytes_are_refused() {
        let good = bytes(3, 4);
        assert!(Trace::parse(&good[..good.len() - 1]).is_none());
        assert!(Trace::parse(b"SSTR").is_none());
        let mut huge = good.clone();
        huge[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(Trace::parse(&huge).is_none());
        let mut nan = good;
        let at = nan.len() - 4;
        nan[at..].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(Trace::parse(&nan).is_none());
    }

    /// A frame interval far outside what a recording can have: refused, no overflow.
    #[test]
    fn absurd_frame_intervals_are_refused() {
        for dt in [1e-30f32, 1e-5, 0.0, -0.01, 11.0, f32::INFINITY, f32::NAN] {
            let mut b = bytes(3, 4);
            b[16..20].copy_from_slice(&dt.to_le_bytes());
            assert!(Trace::parse(&b).is_none(), "dt {dt}");
        }
        for dt in [MIN_DT_S, 1.0 / 90.0, MAX_DT_S] {
            let mut b = bytes(3, 4);
            b[16..20].copy_from_slice(&dt.to_le_bytes());
            assert!(Trace::parse(&b).is_some(), "dt {dt}");
        }
    }
}
