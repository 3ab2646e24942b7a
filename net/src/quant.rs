//! Quantization: positions on a grid within bounds, smallest-three quaternions.
//! Dequantized values are finite by construction (bit widths come from local config).

use glam::{Quat, Vec3};

use crate::bits::{BitReader, BitWriter};
use crate::error::NetError;

/// Grid for a vector inside an axis-aligned box, `resolution_m` per step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VecQuantizer {
    min: Vec3,
    resolution_m: f32,
    bits: [u32; 3],
}

impl VecQuantizer {
    /// A grid covering `[min, max]` with steps of `resolution_m` (bits per axis ≤ 24).
    pub fn new(min: Vec3, max: Vec3, resolution_m: f32) -> Self {
        let res = if resolution_m.is_finite() && resolution_m > 1e-6 {
            resolution_m
        } else {
            1e-3
        };
        let ext = (max - min).max(Vec3::splat(res));
        let bits = ext.to_array().map(|e| {
            let steps = (e / res).ceil().max(1.0) as u64 + 1;
            (64 - (steps - 1).leading_zeros()).clamp(1, 24)
        });
        VecQuantizer {
            min,
            resolution_m: res,
            bits,
        }
    }

    /// Bits per axis.
    pub fn bits(&self) -> [u32; 3] {
        self.bits
    }

    /// Total bits of one absolute vector.
    pub fn total_bits(&self) -> u32 {
        self.bits.iter().sum()
    }

    /// Step size in metres.
    pub fn resolution_m(&self) -> f32 {
        self.resolution_m
    }

    /// Quantize (clamped into the box).
    pub fn quantize(&self, v: Vec3) -> [u32; 3] {
        let rel = (v - self.min) / self.resolution_m;
        let mut out = [0u32; 3];
        for (i, o) in out.iter_mut().enumerate() {
            let max = (1u32 << self.bits[i]) - 1;
            let x = rel[i];
            *o = if x.is_finite() {
                x.round().clamp(0.0, max as f32) as u32
            } else {
                0
            };
        }
        out
    }

    /// Back to metres.
    pub fn dequantize(&self, q: [u32; 3]) -> Vec3 {
        self.min + Vec3::new(q[0] as f32, q[1] as f32, q[2] as f32) * self.resolution_m
    }

    /// Clamp a (possibly hostile) grid value into range.
    pub fn clamp(&self, q: [i64; 3]) -> [u32; 3] {
        let mut out = [0u32; 3];
        for ((o, v), b) in out.iter_mut().zip(q).zip(self.bits) {
            *o = v.clamp(0, (1i64 << b) - 1) as u32;
        }
        out
    }

    /// Write an absolute grid value.
    pub fn write(&self, w: &mut BitWriter, q: [u32; 3]) {
        for (v, b) in q.iter().zip(self.bits) {
            w.write(*v, b);
        }
    }

    /// Read an absolute grid value.
    pub fn read(&self, r: &mut BitReader) -> Result<[u32; 3], NetError> {
        Ok([
            r.read(self.bits[0])?,
            r.read(self.bits[1])?,
            r.read(self.bits[2])?,
        ])
    }

    /// Distance between two grid values, in steps.
    pub fn step_distance(a: [u32; 3], b: [u32; 3]) -> f32 {
        let d = [0, 1, 2].map(|i| a[i] as f32 - b[i] as f32);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    }
}

/// Write a delta between grid values: 5-bit width w, then 3 signed values of w bits.
pub fn write_delta(w: &mut BitWriter, from: [u32; 3], to: [u32; 3]) {
    let d = [0, 1, 2].map(|i| i64::from(to[i]) - i64::from(from[i]));
    let need = d
        .iter()
        .map(|&x| {
            // bits for two's complement of x
            let m = if x < 0 { !x } else { x };
            65 - m.leading_zeros()
        })
        .max()
        .unwrap_or(1)
        .clamp(1, 26);
    w.write(need - 1, 5);
    for x in d {
        w.write((x as u32) & ((1u32 << need) - 1), need);
    }
}

/// Read a delta written by [`write_delta`] and apply it to `base`, clamped by `q`.
pub fn read_delta(
    r: &mut BitReader,
    q: &VecQuantizer,
    base: [u32; 3],
) -> Result<[u32; 3], NetError> {
    let need = r.read(5)? + 1;
    if need > 26 {
        return Err(crate::error::decode_err(0, "delta width too large"));
    }
    let mut out = [0i64; 3];
    for (i, o) in out.iter_mut().enumerate() {
        let raw = r.read(need)?;
        let shift = 32 - need;
        let v = ((raw << shift) as i32) >> shift;
        *o = i64::from(base[i]) + i64::from(v);
    }
    Ok(q.clamp(out))
}

/// Quaternion as smallest-three: index of the largest component + three components.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct QuatQ {
    /// Index of the dropped (largest) component.
    pub largest: u8,
    /// The other three components on a `bits`-bit grid over [-1/√2, 1/√2]: values
    /// 0..=2^bits − 2, an odd number of levels, so 0 (no rotation about that axis) is exact.
    pub comps: [u32; 3],
}

const INV_SQRT2: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// Top grid value of a component: 2^bits − 2. With 2^bits − 1 (an even number of levels) a zero
/// component fell between two levels, and the identity came back as a 0.07° tilt (11 bits) about
/// (−1, −1, −1): an upright object taken over from its replica started out tilted.
fn comp_max(bits: u32) -> u32 {
    ((1u32 << bits.min(16)).saturating_sub(2)).max(1)
}

/// Quantize a rotation with `bits` bits per component (≤ 16).
pub fn quantize_quat(q: Quat, bits: u32) -> QuatQ {
    let q = if q.is_finite() && q.length_squared() > 1e-12 {
        q.normalize()
    } else {
        Quat::IDENTITY
    };
    let a = q.to_array();
    let mut largest = 0usize;
    for i in 1..4 {
        if a[i].abs() > a[largest].abs() {
            largest = i;
        }
    }
    let sign = if a[largest] < 0.0 { -1.0 } else { 1.0 };
    let max = comp_max(bits) as f32;
    let mut comps = [0u32; 3];
    let mut j = 0;
    for (i, v) in a.iter().enumerate() {
        if i == largest {
            continue;
        }
        let n = ((v * sign + INV_SQRT2) / (2.0 * INV_SQRT2)).clamp(0.0, 1.0);
        comps[j] = (n * max).round() as u32;
        j += 1;
    }
    QuatQ {
        largest: largest as u8,
        comps,
    }
}

/// Back to a unit quaternion (always finite).
pub fn dequantize_quat(q: QuatQ, bits: u32) -> Quat {
    let max = comp_max(bits) as f32;
    let mut a = [0.0f32; 4];
    let mut sum = 0.0;
    let mut j = 0;
    for (i, slot) in a.iter_mut().enumerate() {
        if i == usize::from(q.largest & 3) {
            continue;
        }
        let v = (q.comps[j].min(max as u32) as f32 / max) * 2.0 * INV_SQRT2 - INV_SQRT2;
        *slot = v;
        sum += v * v;
        j += 1;
    }
    a[usize::from(q.largest & 3)] = (1.0 - sum).max(0.0).sqrt();
    let out = Quat::from_array(a);
    if out.length_squared() > 1e-12 {
        out.normalize()
    } else {
        Quat::IDENTITY
    }
}

/// Write a quantized rotation.
pub fn write_quat(w: &mut BitWriter, q: QuatQ, bits: u32) {
    w.write(u32::from(q.largest & 3), 2);
    for c in q.comps {
        w.write(c, bits);
    }
}

/// Read a quantized rotation.
pub fn read_quat(r: &mut BitReader, bits: u32) -> Result<QuatQ, NetError> {
    let largest = r.read(2)? as u8;
    let comps = [r.read(bits)?, r.read(bits)?, r.read(bits)?];
    Ok(QuatQ { largest, comps })
}

/// Angle between two rotations in radians.
pub fn angle_between(a: Quat, b: Quat) -> f32 {
    let d = a.dot(b).abs().min(1.0);
    2.0 * d.acos()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn identity_and_axis_rotations_survive_quantization_exactly() {
        for bits in [4, 9, 11, 16] {
            let d = dequantize_quat(quantize_quat(Quat::IDENTITY, bits), bits);
            assert_eq!(d, Quat::IDENTITY, "{bits} bits");
            // a yaw keeps x and z exactly zero: an upright object stays upright
            let yaw = Quat::from_rotation_y(0.7);
            let d = dequantize_quat(quantize_quat(yaw, bits), bits);
            assert_eq!((d.x, d.z), (0.0, 0.0), "{bits} bits: {d:?}");
            // the top value fits in `bits`
            let q = quantize_quat(Quat::from_xyzw(0.7, 0.0, 0.0, 0.714), bits);
            assert!(q.comps.iter().all(|c| *c < 1 << bits), "{q:?}");
        }
    }

    #[test]
    fn quat_round_trip_is_close() {
        let q = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.2, 2.5);
        let d = dequantize_quat(quantize_quat(q, 11), 11);
        assert!(angle_between(q, d) < 0.002, "{}", angle_between(q, d));
    }

    #[test]
    fn delta_round_trip() {
        let q = VecQuantizer::new(Vec3::splat(-8.0), Vec3::splat(8.0), 0.0005);
        let a = q.quantize(Vec3::new(0.1, 0.2, -0.3));
        let b = q.quantize(Vec3::new(0.12, 0.19, -0.35));
        let mut w = BitWriter::new();
        write_delta(&mut w, a, b);
        let bytes = w.into_bytes();
        assert_eq!(read_delta(&mut BitReader::new(&bytes), &q, a).unwrap(), b);
    }
}
