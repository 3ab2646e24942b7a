//! Loudness and "is speaking": a frame's RMS level in dBFS, its byte on the wire, and a voice
//! activity flag with a hold, for mouths and indicators any app can read.

use crate::FRAME_SAMPLES;

/// The quietest level the byte tells apart (dBFS): byte 0.
pub const FLOOR_DB: f32 = -70.0;
/// A frame louder than this is speech (dBFS).
pub const SPEAKING_DB: f32 = -45.0;
/// How long "speaking" holds after the last loud frame, in frames (300 ms).
pub const HOLD_FRAMES: u32 = 15;

/// RMS level of a frame in dBFS (full scale 0 dB), at least [`FLOOR_DB`].
pub fn level_db(pcm: &[i16]) -> f32 {
    if pcm.is_empty() {
        return FLOOR_DB;
    }
    let sum: f64 = pcm.iter().map(|s| f64::from(*s).powi(2)).sum();
    let rms = (sum / pcm.len() as f64).sqrt() / 32768.0;
    if rms <= 0.0 {
        return FLOOR_DB;
    }
    (20.0 * rms.log10() as f32).max(FLOOR_DB)
}

/// A level as the wire's byte (0 = [`FLOOR_DB`] or less, 255 = 0 dBFS).
pub fn level_byte(db: f32) -> u8 {
    (((db - FLOOR_DB) / -FLOOR_DB).clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The byte back to dBFS.
pub fn byte_db(b: u8) -> f32 {
    FLOOR_DB + f32::from(b) / 255.0 * -FLOOR_DB
}

/// "Is speaking", from frame levels, with a hold so a word's pauses do not flicker.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Activity {
    hold: u32,
    /// The last frame's level, dBFS.
    pub level_db: f32,
}

impl Activity {
    /// One frame's level in; whether the speaker is speaking now.
    pub fn frame(&mut self, db: f32) -> bool {
        self.level_db = db;
        if db >= SPEAKING_DB {
            self.hold = HOLD_FRAMES;
        } else {
            self.hold = self.hold.saturating_sub(1);
        }
        self.hold > 0
    }

    /// Speaking now.
    pub fn speaking(&self) -> bool {
        self.hold > 0
    }

    /// Silence (no frame came).
    pub fn silent(&mut self) {
        self.frame(FLOOR_DB);
    }
}

const _: () = assert!(FRAME_SAMPLES == 960);

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn levels_and_bytes() {
        assert_eq!(level_db(&[0; 960]), FLOOR_DB);
        let full = [i16::MAX; 960];
        assert!(level_db(&full).abs() < 0.01);
        assert_eq!(level_byte(0.0), 255);
        assert_eq!(level_byte(-100.0), 0);
        assert!((byte_db(level_byte(-30.0)) + 30.0).abs() < 0.2);
        let mut a = Activity::default();
        assert!(a.frame(-20.0));
        for _ in 0..HOLD_FRAMES - 1 {
            assert!(a.frame(-60.0));
        }
        assert!(!a.frame(-60.0));
    }
}
