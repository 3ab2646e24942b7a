//! The thesis's replication measurements, the reference the benchmarks print beside their own
//! figures: step times per particle count (Tables 5-8) and bytes/s of UNet traffic for a VR
//! avatar and a 60-particle soft body, per send rate and ignore threshold (Tables 9-11).

/// One row of Tables 5-8: particles, minimum and maximum step time (ms).
pub type StepRow = (u32, f32, f32);
/// Table 5: 1731 vertices, hard clustering (closest vertices or distance).
pub const TABLE5: [StepRow; 3] = [(248, 1.1, 2.9), (433, 1.2, 3.2), (865, 1.5, 5.1)];
/// Table 6: 1731 vertices, soft clustering (weights by distance).
pub const TABLE6: [StepRow; 3] = [(215, 1.2, 3.5), (445, 1.3, 4.1), (872, 1.6, 6.3)];
/// Table 7: 2562 vertices, hard clustering.
pub const TABLE7: [StepRow; 3] = [(257, 1.2, 3.2), (427, 1.3, 3.6), (854, 1.6, 5.6)];
/// Table 8: 2562 vertices, soft clustering.
pub const TABLE8: [StepRow; 3] = [(224, 1.3, 3.5), (452, 1.4, 3.9), (863, 1.7, 6.2)];

/// Send rates of the tables (Hz).
pub const RATES_HZ: [f32; 5] = [5.0, 10.0, 15.0, 20.0, 25.0];
/// Ignore thresholds of Tables 10 and 11 (m).
pub const THRESHOLDS_M: [f32; 3] = [0.005, 0.015, 0.025];
/// Table 9: the avatar at 0.005 m, largest bytes/s over 1 s, per rate.
pub const TABLE9_MAX: [u32; 5] = [824, 1582, 2436, 3217, 3978];
/// Table 10: the avatar, average bytes/s, `[rate][threshold]` (Table 9's average column is
/// the first threshold's).
pub const TABLE10_AVATAR: [[u32; 3]; 5] = [
    [762, 662, 596],
    [1419, 1222, 971],
    [2071, 1560, 1196],
    [2312, 1951, 1425],
    [2455, 2015, 1537],
];
/// Table 11: the 60-particle soft body, bytes/s, `[rate][threshold]`; the thesis has no
/// 25 Hz row.
pub const TABLE11_SOFT: [[u32; 3]; 4] = [
    [3974, 3155, 2785],
    [7567, 5785, 4917],
    [11459, 7687, 6813],
    [14895, 10984, 8773],
];

/// The thesis's figure for a cell, if it has one (`avatar` or `softbody60`).
pub fn bytes_per_s(scenario: &str, rate_hz: f32, threshold_m: f32) -> Option<u32> {
    let r = RATES_HZ.iter().position(|x| (x - rate_hz).abs() < 1e-3)?;
    let t = THRESHOLDS_M
        .iter()
        .position(|x| (x - threshold_m).abs() < 1e-6)?;
    match scenario {
        "avatar" => TABLE10_AVATAR.get(r).map(|row| row[t]),
        "softbody60" => TABLE11_SOFT.get(r).map(|row| row[t]),
        _ => None,
    }
}
