//! How a recording lines up with what was said: the delay by cross-correlation (coarse on
//! 1 ms envelopes, then fine on the samples) and how alike they are there. Used by the live
//! voice test and the voice benchmark (PESQ, the quality score, is the bench script's:
//! `scripts/bench-voice`).

use crate::SAMPLE_RATE;

/// Where `said` is found in `heard`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// Samples from the start of `heard` to the start of `said` in it.
    pub lag: i64,
    /// The normalised correlation of the 1 ms envelopes there (1 = the same loudness contour).
    pub envelope_corr: f64,
    /// The normalised correlation of the samples there.
    pub sample_corr: f64,
}

impl Alignment {
    /// The lag in milliseconds.
    pub fn lag_ms(&self) -> f64 {
        self.lag as f64 * 1000.0 / f64::from(SAMPLE_RATE)
    }
}

const ENV: usize = (SAMPLE_RATE / 1000) as usize;

fn envelope(x: &[i16]) -> Vec<f64> {
    x.chunks(ENV)
        .map(|c| c.iter().map(|s| f64::from(*s).abs()).sum::<f64>() / c.len() as f64)
        .collect()
}

/// Normalised correlation of `a` against `b` shifted by `lag` (b's index = a's + lag), over
/// the overlap; mean removed.
fn ncc(a: &[f64], b: &[f64], lag: i64) -> f64 {
    let (a0, b0) = if lag >= 0 {
        (0usize, lag as usize)
    } else {
        ((-lag) as usize, 0usize)
    };
    let n = a.len().saturating_sub(a0).min(b.len().saturating_sub(b0));
    if n < 8 {
        return 0.0;
    }
    let (a, b) = (&a[a0..a0 + n], &b[b0..b0 + n]);
    let ma = a.iter().sum::<f64>() / n as f64;
    let mb = b.iter().sum::<f64>() / n as f64;
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (x - ma, y - mb);
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    if aa <= 0.0 || bb <= 0.0 {
        0.0
    } else {
        ab / (aa * bb).sqrt()
    }
}

/// Find `said` in `heard`, starting at most `max_lag_s` in (and not before its start).
pub fn align(said: &[i16], heard: &[i16], max_lag_s: f64) -> Option<Alignment> {
    let (es, eh) = (envelope(said), envelope(heard));
    if es.len() < 50 || eh.len() < 50 {
        return None;
    }
    let max = ((max_lag_s * 1000.0) as i64).min(eh.len() as i64);
    let (mut best, mut best_lag) = (f64::MIN, 0i64);
    for lag in 0..=max {
        let c = ncc(&es, &eh, lag);
        if c > best {
            best = c;
            best_lag = lag;
        }
    }
    // fine: ±2 ms around the coarse lag, on the samples over the first 2 s of speech
    let n = said.len().min(2 * SAMPLE_RATE as usize);
    let s: Vec<f64> = said[..n].iter().map(|v| f64::from(*v)).collect();
    let h: Vec<f64> = heard.iter().map(|v| f64::from(*v)).collect();
    let centre = best_lag * ENV as i64;
    let (mut fine, mut fine_lag) = (f64::MIN, centre);
    for lag in (centre - 2 * ENV as i64)..=(centre + 2 * ENV as i64) {
        if lag < 0 {
            continue;
        }
        let c = ncc(&s, &h, lag);
        if c > fine {
            fine = c;
            fine_lag = lag;
        }
    }
    Some(Alignment {
        lag: fine_lag,
        envelope_corr: best,
        sample_corr: fine,
    })
}

/// What a listener heard of one saying, from its `--voice-out` folder.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Heard {
    /// Mouth to ear: when the listener played the first sample, less when it was said
    /// (both on the room clock), ms.
    pub mouth_to_ear_ms: f64,
    /// The alignment in the recording.
    pub alignment: Alignment,
}

/// Find the saying that started at room time `said_room_ms` (`voice_said` in the speaker's
/// log) in the listener's recording of `speaker` under `dir` (`peer-ID.wav`, `voice.json`),
/// searching from `said_room_ms` to `max_delay_ms` after it.
pub fn heard_in(
    said: &[i16],
    said_room_ms: f64,
    dir: &std::path::Path,
    speaker: u64,
    max_delay_ms: f64,
) -> Result<Heard, String> {
    let meta = std::fs::read_to_string(dir.join("voice.json"))
        .map_err(|e| format!("{}: {e}", dir.join("voice.json").display()))?;
    let meta: serde_json::Value = serde_json::from_str(&meta).map_err(|e| e.to_string())?;
    let start = meta["start_room_ms"]
        .as_f64()
        .ok_or_else(|| format!("{}: no start_room_ms", dir.display()))?;
    let rec = crate::files::read_wav(&dir.join(format!("peer-{speaker}.wav")))
        .map_err(|e| e.to_string())?;
    let rate = f64::from(SAMPLE_RATE) / 1000.0;
    let from = ((said_room_ms - start) * rate).max(0.0) as usize;
    let len = ((max_delay_ms + said.len() as f64 / rate) * rate) as usize;
    let part = rec
        .get(from..(from + len).min(rec.len()))
        .ok_or_else(|| format!("the recording in {} ends before the saying", dir.display()))?;
    let a = align(said, part, max_delay_ms / 1000.0)
        .ok_or_else(|| format!("the recording in {} is too short", dir.display()))?;
    Ok(Heard {
        mouth_to_ear_ms: start + (from as f64 + a.lag as f64) / rate - said_room_ms,
        alignment: a,
    })
}

/// The longest stretch (ms) where `said` speaks (a 20 ms block over −40 dBFS) but `heard`,
/// lined up with it, is silent there (30 dB quieter or more): audio lost, not concealed.
pub fn longest_dropout_ms(said: &[i16], heard: &[i16]) -> f64 {
    let block = (SAMPLE_RATE / 50) as usize;
    let (mut run, mut longest) = (0usize, 0usize);
    for (s, h) in said.chunks_exact(block).zip(heard.chunks_exact(block)) {
        let (ls, lh) = (crate::level::level_db(s), crate::level::level_db(h));
        if ls > -40.0 && lh < ls - 30.0 {
            run += 1;
            longest = longest.max(run);
        } else if ls > -40.0 {
            run = 0;
        }
    }
    longest as f64 * 20.0
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_delayed_noisy_copy_is_found_at_its_delay() {
        let mut x = 99u64;
        let said: Vec<i16> = (0..96_000)
            .map(|i| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                let syl = ((i as f64 / 48_000.0) * 9.0).sin().max(0.0);
                ((x % 20_000) as f64 - 10_000.0) as i16 / 2
                    + (syl * 8000.0 * ((i as f64) * 0.05).sin()) as i16
            })
            .collect();
        let mut heard = vec![0i16; 10_000];
        heard.extend(said.iter().map(|v| v / 2));
        heard.extend(vec![0i16; 5000]);
        let a = align(&said, &heard, 1.0).unwrap();
        assert_eq!(a.lag, 10_000, "{a:?}");
        assert!(a.sample_corr > 0.99 && a.envelope_corr > 0.9, "{a:?}");
        assert!(align(&said[..10], &heard, 1.0).is_none());
        // a 200 ms hole in the copy is found; the copy itself has none
        let copy = &heard[10_000..10_000 + said.len()];
        assert_eq!(longest_dropout_ms(&said, copy), 0.0);
        let mut holed = copy.to_vec();
        holed[24_000..33_600].fill(0);
        let d = longest_dropout_ms(&said, &holed);
        assert!((180.0..=200.0).contains(&d), "{d}");
    }
}
