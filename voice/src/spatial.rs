//! Each speaker placed at their avatar's head: distance attenuation, equal-power panning and
//! an interaural time difference (up to 0.66 ms, the far ear hears later). No HRTF: the
//! headless and desktop audio paths here have none (said in the GUIDE).

use glam::{Quat, Vec3};

use crate::{FRAME_SAMPLES, SAMPLE_RATE};

/// Distance (m) within which a speaker is at full gain.
pub const REF_DISTANCE: f32 = 1.0;
/// The largest interaural delay, seconds (a head's width over the speed of sound).
pub const MAX_ITD_S: f32 = 0.00066;
const ITD_SAMPLES: usize = (MAX_ITD_S * SAMPLE_RATE as f32) as usize + 1;

/// Where one speaker sits for the listener.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Left and right gains.
    pub gains: [f32; 2],
    /// Samples the far ear hears later, and which ear that is (0 left, 1 right).
    pub itd: (usize, usize),
}

/// Where `source` is heard by a listener at `pos` looking along `rot` (−Z forward, +X
/// right, as the avatar's head). An unknown or coincident place is heard centred at full
/// gain.
pub fn place(listener: Option<(Vec3, Quat)>, source: Option<Vec3>) -> Placement {
    let centred = Placement {
        gains: [std::f32::consts::FRAC_1_SQRT_2; 2],
        itd: (0, 0),
    };
    let (Some((pos, rot)), Some(src)) = (listener, source) else {
        return centred;
    };
    let d = src - pos;
    let dist = d.length();
    if !dist.is_finite() || dist < 1e-3 || !rot.is_finite() {
        return centred;
    }
    let right = rot * Vec3::X;
    let pan = (d / dist).dot(right).clamp(-1.0, 1.0);
    let theta = (pan + 1.0) * std::f32::consts::FRAC_PI_4;
    let gain = REF_DISTANCE / dist.max(REF_DISTANCE);
    let itd = ((pan.abs() * MAX_ITD_S * SAMPLE_RATE as f32).round() as usize).min(ITD_SAMPLES - 1);
    Placement {
        gains: [theta.cos() * gain, theta.sin() * gain],
        itd: (itd, usize::from(pan < 0.0)),
    }
}

/// One speaker's panner: keeps the last samples so the far ear's delay runs across blocks.
#[derive(Clone, Debug)]
pub struct Panner {
    history: [f32; ITD_SAMPLES],
}

impl Default for Panner {
    fn default() -> Self {
        Panner {
            history: [0.0; ITD_SAMPLES],
        }
    }
}

impl Panner {
    /// Add `mono` (960 samples), placed, times `volume`, into `stereo` (interleaved L R).
    pub fn mix(
        &mut self,
        mono: &[i16; FRAME_SAMPLES],
        p: Placement,
        volume: f32,
        stereo: &mut [f32],
    ) {
        let (delay, far) = p.itd;
        let h = self.history.len();
        for (i, frame) in stereo.chunks_exact_mut(2).take(FRAME_SAMPLES).enumerate() {
            let now = f32::from(mono[i]) / 32768.0;
            let late = if i >= delay {
                f32::from(mono[i - delay]) / 32768.0
            } else {
                self.history[h - (delay - i)]
            };
            for (ear, out) in frame.iter_mut().enumerate() {
                let s = if ear == far { late } else { now };
                *out += s * p.gains[ear] * volume;
            }
        }
        for (k, slot) in self.history.iter_mut().enumerate() {
            *slot = f32::from(mono[FRAME_SAMPLES - h + k]) / 32768.0;
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn left_right_near_far() {
        let head = Some((Vec3::new(0.0, 1.6, 0.0), Quat::IDENTITY));
        let left = place(head, Some(Vec3::new(-2.0, 1.6, 0.0)));
        assert!(left.gains[0] > 0.49 && left.gains[1] < 0.01, "{left:?}");
        assert_eq!(left.itd.1, 1, "the right ear is the far one");
        assert!(left.itd.0 >= 30);
        let front = place(head, Some(Vec3::new(0.0, 1.6, -0.5)));
        assert!((front.gains[0] - front.gains[1]).abs() < 1e-5 && front.itd.0 == 0);
        assert!((front.gains[0] - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-5);
        let far = place(head, Some(Vec3::new(0.0, 1.6, -4.0)));
        assert!((far.gains[0] / front.gains[0] - 0.25).abs() < 1e-4);
        // turned to face −X, the same source is in front
        let turned = Some((
            Vec3::new(0.0, 1.6, 0.0),
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
        ));
        let p = place(turned, Some(Vec3::new(-2.0, 1.6, 0.0)));
        assert!((p.gains[0] - p.gains[1]).abs() < 1e-4, "{p:?}");
        // NaN poses are heard centred, not as NaN
        let nan = place(Some((Vec3::NAN, Quat::IDENTITY)), Some(Vec3::ZERO));
        assert!(nan.gains.iter().all(|g| g.is_finite()));
    }

    #[test]
    fn the_far_ear_hears_the_same_signal_later() {
        let p = Placement {
            gains: [1.0, 1.0],
            itd: (10, 1),
        };
        let mut pan = Panner::default();
        let mut out = vec![0.0f32; FRAME_SAMPLES * 2];
        let mono: [i16; FRAME_SAMPLES] = std::array::from_fn(|i| (i as i16).wrapping_mul(31));
        pan.mix(&mono, p, 1.0, &mut out);
        for i in 10..FRAME_SAMPLES {
            assert_eq!(out[2 * i + 1], out[2 * (i - 10)]);
        }
    }
}
