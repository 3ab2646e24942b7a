//! A microphone's processing before it is encoded: acoustic echo cancellation (what this peer's
//! loudspeaker played, heard again by its microphone, is removed), noise suppression, residual
//! echo suppression and automatic gain control — libspeexdsp's MDF canceller and preprocessor
//! (`softsync-speexdsp`, a small binding to the system's library).
//!
//! Only a device's microphone is processed (a bot's WAV file is clean). [`measure`] runs the
//! chain on speech with a synthetic echo path and noise and says what each part does; the
//! tests and `softsync-bench voice` report it.

use std::collections::VecDeque;

use softsync_speexdsp::{PreprocessConfig, VoiceProcessor};

use crate::{FRAME_SAMPLES, SAMPLE_RATE};

/// Which parts run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProcessingConfig {
    /// Cancel the loudspeaker's echo.
    pub echo_cancel: bool,
    /// Suppress stationary noise.
    pub noise_suppress: bool,
    /// Bring the voice to a steady level.
    pub gain_control: bool,
    /// The longest echo path modelled, ms (the devices' buffers and the room's reverberation).
    pub echo_tail_ms: u32,
}

impl Default for ProcessingConfig {
    fn default() -> Self {
        ProcessingConfig {
            echo_cancel: true,
            noise_suppress: true,
            gain_control: true,
            echo_tail_ms: 200,
        }
    }
}

impl ProcessingConfig {
    /// Everything off.
    pub const OFF: ProcessingConfig = ProcessingConfig {
        echo_cancel: false,
        noise_suppress: false,
        gain_control: false,
        echo_tail_ms: 200,
    };

    /// Whether anything runs.
    pub fn any(&self) -> bool {
        self.echo_cancel || self.noise_suppress || self.gain_control
    }
}

/// Played blocks kept for the canceller's reference (1.28 s: the longest device path).
const HISTORY: usize = 64;
/// Echo-delay estimates the reference's delay is the median of.
const DELAY_SAMPLES: usize = 50;
/// Envelope points per 20 ms block (4 ms each).
const ENV_PER_BLOCK: usize = 5;
/// Frames the delay estimator looks back over (3 s), and how often it looks (0.5 s).
const EST_WINDOW: usize = 150;
const EST_EVERY: u64 = 25;
/// The correlation the estimator needs before it overrides the devices' own latency figures.
const EST_CONFIDENCE: f64 = 0.5;

/// 4 ms mean-absolute envelope of a block.
fn envelope(x: &[i16; FRAME_SAMPLES]) -> [f32; ENV_PER_BLOCK] {
    let mut e = [0.0; ENV_PER_BLOCK];
    for (o, c) in e
        .iter_mut()
        .zip(x.chunks_exact(FRAME_SAMPLES / ENV_PER_BLOCK))
    {
        *o = c.iter().map(|s| f32::from(*s).abs()).sum::<f32>() / c.len() as f32;
    }
    e
}

/// Where the echo is: the microphone's envelope against the loudspeaker's, block by block.
#[derive(Debug, Default)]
struct DelayEstimator {
    /// Each played block's envelope, with its number.
    far: VecDeque<(u64, [f32; ENV_PER_BLOCK])>,
    /// Each captured frame's envelope (before processing), with the number of blocks played
    /// when it was processed.
    mic: VecDeque<(u64, [f32; ENV_PER_BLOCK])>,
    far_total: u64,
    mic_total: u64,
    /// The last estimate: (blocks back from the newest played, correlation).
    best: Option<(usize, f64)>,
}

impl DelayEstimator {
    fn played(&mut self, b: &[i16; FRAME_SAMPLES]) {
        self.far.push_back((self.far_total, envelope(b)));
        self.far_total += 1;
        while self.far.len() > HISTORY + EST_WINDOW {
            self.far.pop_front();
        }
    }

    fn captured(&mut self, m: &[i16; FRAME_SAMPLES]) {
        self.mic.push_back((self.far_total, envelope(m)));
        self.mic_total += 1;
        while self.mic.len() > EST_WINDOW {
            self.mic.pop_front();
        }
        if self.mic_total % EST_EVERY == 0 && self.mic.len() == EST_WINDOW {
            // a confident finding replaces the last; a doubtful one (nobody played, or the
            // near end talked over it) leaves it
            if let Some((lag, r)) = self.estimate() {
                if r >= EST_CONFIDENCE || self.best.is_none() {
                    self.best = Some((lag, r));
                }
            }
        }
    }

    /// The lag (blocks before the newest played when the frame was processed) whose played
    /// envelope best matches the microphone's, and how well (Pearson's r).
    fn estimate(&self) -> Option<(usize, f64)> {
        let first = self.far.front()?.0;
        let mut best: Option<(usize, f64)> = None;
        for lag in 0..HISTORY {
            let (mut n, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            for (played_then, me) in &self.mic {
                let Some(b) = played_then.checked_sub(1 + lag as u64) else {
                    continue;
                };
                let Some((_, fe)) = b.checked_sub(first).and_then(|i| self.far.get(i as usize))
                else {
                    continue;
                };
                for (x, y) in me.iter().zip(fe) {
                    let (x, y) = (f64::from(*x), f64::from(*y));
                    n += 1.0;
                    sx += x;
                    sy += y;
                    sxx += x * x;
                    syy += y * y;
                    sxy += x * y;
                }
            }
            if n < (EST_WINDOW * ENV_PER_BLOCK / 2) as f64 {
                continue;
            }
            let vx = sxx - sx * sx / n;
            let vy = syy - sy * sy / n;
            if vx <= 1e-6 || vy <= 1e-6 {
                continue;
            }
            let r = (sxy - sx * sy / n) / (vx * vy).sqrt();
            if best.is_none_or(|(_, b)| r > b) {
                best = Some((lag, r));
            }
        }
        best
    }
}

/// The chain for one microphone.
pub struct MicProcessor {
    inner: VoiceProcessor,
    cfg: ProcessingConfig,
    /// Blocks given to the loudspeaker, newest last.
    played: VecDeque<[i16; FRAME_SAMPLES]>,
    /// The reference is the block played this many blocks before the newest.
    delay_blocks: usize,
    /// The last estimates of the devices' round trip, ms.
    estimates: VecDeque<f64>,
    /// The echo's delay as the signals show it.
    finder: DelayEstimator,
}

impl std::fmt::Debug for MicProcessor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MicProcessor")
            .field("cfg", &self.cfg)
            .field("delay_blocks", &self.delay_blocks)
            .finish()
    }
}

impl MicProcessor {
    /// The chain `cfg` asks for; `None` when it asks for nothing.
    pub fn new(cfg: ProcessingConfig) -> Result<Option<Self>, softsync_speexdsp::Error> {
        if !cfg.any() {
            return Ok(None);
        }
        let tail = (cfg.echo_tail_ms.clamp(20, 1000) as usize) * SAMPLE_RATE as usize / 1000;
        let pre = (cfg.noise_suppress || cfg.gain_control).then(|| PreprocessConfig {
            denoise: cfg.noise_suppress,
            agc: cfg.gain_control,
            ..PreprocessConfig::default()
        });
        let inner = VoiceProcessor::new(
            FRAME_SAMPLES,
            SAMPLE_RATE,
            cfg.echo_cancel.then_some(tail),
            pre,
        )?;
        Ok(Some(MicProcessor {
            inner,
            cfg,
            played: VecDeque::new(),
            delay_blocks: 0,
            estimates: VecDeque::new(),
            finder: DelayEstimator::default(),
        }))
    }

    /// What it runs.
    pub fn config(&self) -> ProcessingConfig {
        self.cfg
    }

    /// The devices' round trip now, as they report it, ms: from a block being queued for
    /// the loudspeaker to the end of the captured frame being processed (the acoustic path
    /// is the canceller's tail's to model). Until the signals show where the echo is, the
    /// reference is the block played that long ago (the median of the last 50 figures).
    ///
    /// Once the far end has talked, the microphone's envelope is correlated with the
    /// loudspeaker's over the last 3 s (every 0.5 s); where they match with r ≥ 0.5 that lag
    /// wins over the devices' figures (an ALSA plugin's latency report can be off by a
    /// buffer). Either way the reference is delayed a block less than that (the canceller
    /// models echo that follows its reference, never echo ahead of it), and it moves only
    /// when the echo would leave the canceller's tail.
    pub fn set_device_delay(&mut self, ms: f64) {
        if !ms.is_finite() {
            return;
        }
        self.estimates.push_back(ms.max(0.0));
        while self.estimates.len() > DELAY_SAMPLES {
            self.estimates.pop_front();
        }
    }

    fn update_delay(&mut self) {
        let mut v: Vec<f64> = self.estimates.iter().copied().collect();
        v.sort_by(f64::total_cmp);
        let median = v.get(v.len() / 2).copied().unwrap_or(0.0);
        // a block less than the figure: the reference stream must be delayed less than the
        // echo (the canceller models echo that follows its reference, never echo before it)
        let from_devices = ((median / 20.0).floor() as usize)
            .saturating_sub(1)
            .min(HISTORY - 1);
        let echo_at = match self.finder.best {
            Some((lag, r)) if r >= EST_CONFIDENCE => lag,
            _ => from_devices + 1,
        };
        // any reference that keeps the echo (and 60 ms of its reverberation) inside the
        // canceller's tail is as good as another: it moves only when the echo leaves that
        // window, so the adaptive filter is not thrown about by every new estimate
        let tail_blocks = (self.cfg.echo_tail_ms / 20) as usize;
        let cur = self.delay_blocks;
        if cur > echo_at || echo_at + 3 > cur + tail_blocks {
            self.delay_blocks = echo_at.saturating_sub(1);
        }
    }

    /// The delay the signals show, blocks, and how sure (Pearson's r), once measured.
    pub fn echo_estimate(&self) -> Option<(usize, f64)> {
        self.finder.best
    }

    /// The reference's delay now, blocks of 20 ms.
    pub fn reference_delay_blocks(&self) -> usize {
        self.delay_blocks
    }

    /// A block the loudspeaker was given (interleaved stereo, −1..1): the echo to expect.
    pub fn played(&mut self, stereo: &[f32]) {
        let mut mono = [0i16; FRAME_SAMPLES];
        for (m, p) in mono.iter_mut().zip(stereo.chunks_exact(2)) {
            *m = ((p[0] + p[1]) * 0.5 * 32767.0)
                .round()
                .clamp(-32768.0, 32767.0) as i16;
        }
        self.played_mono(&mono);
    }

    /// A mono block the loudspeaker was given.
    pub fn played_mono(&mut self, mono: &[i16; FRAME_SAMPLES]) {
        if self.cfg.echo_cancel {
            self.finder.played(mono);
            self.played.push_back(*mono);
            while self.played.len() > HISTORY {
                self.played.pop_front();
            }
        }
    }

    /// Process a captured frame in place.
    pub fn process(&mut self, mic: &mut [i16; FRAME_SAMPLES]) {
        if self.cfg.echo_cancel {
            self.finder.captured(mic);
            self.update_delay();
        }
        let far = self
            .played
            .len()
            .checked_sub(1 + self.delay_blocks)
            .and_then(|i| self.played.get(i))
            .copied()
            .unwrap_or([0; FRAME_SAMPLES]);
        // lengths are fixed by the types: the binding's length checks cannot fail here
        let _ = self.inner.process(mic, &far);
    }

    /// AGC's gain now (linear).
    pub fn agc_gain(&self) -> f32 {
        self.inner.agc_gain()
    }
}

/// What the chain did to a test signal ([`measure`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProcessingMeasure {
    /// Echo return loss enhancement while only the far end talks, over 4-7 s, dB (canceller
    /// alone).
    pub erle_db: f64,
    /// The same with the whole chain (the residual echo suppressor too), dB.
    pub erle_chain_db: f64,
    /// During double talk, how much less the output differs from the near speech than the
    /// microphone did, dB (canceller alone).
    pub double_talk_db: f64,
    /// Noise removed in speech pauses, dB (white noise 10 dB under the speech).
    pub noise_db: f64,
    /// How much the speech itself lost with the noise suppressor, dB.
    pub speech_loss_db: f64,
    /// Gain AGC gave speech 30 dB too quiet, over its last 3 s, dB.
    pub agc_gain_db: f64,
    /// The whole chain's cost per 20 ms frame, µs (this machine, median of the run).
    pub cost_us: f64,
}

fn energy(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum::<f64>().max(1e-9)
}

fn db(a: f64, b: f64) -> f64 {
    10.0 * (a / b).log10()
}

/// A seeded generator for the noise and the echo path (xorshift).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Run `cfg`'s chain over `mic`, with `far` as what the loudspeaker played (same length,
/// 48 kHz mono); returns the output and the cost of each frame (µs, from `clock`).
fn run(
    cfg: ProcessingConfig,
    mic: &[f64],
    far: &[f64],
    clock: &mut dyn FnMut() -> f64,
) -> (Vec<f64>, Vec<f64>) {
    let Ok(Some(mut p)) = MicProcessor::new(cfg) else {
        return (mic.to_vec(), Vec::new());
    };
    let q = |v: f64| (v * 32767.0).round().clamp(-32768.0, 32767.0) as i16;
    let mut out = Vec::with_capacity(mic.len());
    let mut cost = Vec::new();
    for (m, f) in mic
        .chunks_exact(FRAME_SAMPLES)
        .zip(far.chunks_exact(FRAME_SAMPLES))
    {
        let mut fm = [0i16; FRAME_SAMPLES];
        let mut ff = [0i16; FRAME_SAMPLES];
        for (o, v) in fm.iter_mut().zip(m) {
            *o = q(*v);
        }
        for (o, v) in ff.iter_mut().zip(f) {
            *o = q(*v);
        }
        let t0 = clock();
        p.played_mono(&ff);
        p.process(&mut fm);
        cost.push(clock() - t0);
        out.extend(fm.iter().map(|s| f64::from(*s) / 32768.0));
    }
    (out, cost)
}

/// Measure the chain on speech: `far` and `near` are two different utterances (48 kHz mono,
/// −1..1), each at least 3 s long; `clock` reads microseconds (the caller's; the core crates
/// take time as an argument).
///
/// - Echo: 10 s of the far end played; the microphone hears it through an 80 ms path (the
///   devices' buffers) and a 60 ms decaying reverberant tail, 6 dB down, plus the near speech
///   from 7 s (double talk) and a little noise. ERLE is taken over 4-7 s: the delay finder
///   has placed the reference by 3 s and the filter converged again after it.
/// - Noise: the near speech from 2 s, in white noise 10 dB under its level.
/// - Gain: the near speech 30 dB down.
pub fn measure(far: &[f64], near: &[f64], clock: &mut dyn FnMut() -> f64) -> ProcessingMeasure {
    let sr = SAMPLE_RATE as usize;
    let len = 10 * sr;
    let looped = |s: &[f64], n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| s.get(i % s.len().max(1)).copied().unwrap_or(0.0))
            .collect()
    };
    let far8 = looped(far, len);
    // the echo path: 80 ms of delay, then taps decaying over 60 ms
    let mut rng = Lcg(0x9e37_79b9_7f4a_7c15);
    let delay = sr * 80 / 1000;
    let taps = sr * 60 / 1000;
    let h: Vec<f64> = (0..taps)
        .map(|k| rng.next() * (-(k as f64) / (taps as f64 / 5.0)).exp())
        .collect();
    let norm = h.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mut echo = vec![0.0; len];
    for (i, e) in echo.iter_mut().enumerate() {
        let mut acc = 0.0;
        for (k, hk) in h.iter().enumerate() {
            if let Some(x) = i.checked_sub(delay + k).and_then(|j| far8.get(j)) {
                acc += hk * x;
            }
        }
        *e = acc / norm * 0.5;
    }
    let mut near8 = vec![0.0; len];
    for (i, v) in near8.iter_mut().enumerate().skip(7 * sr) {
        *v = near.get(i - 7 * sr).copied().unwrap_or(0.0) * 0.5;
    }
    let mic: Vec<f64> = (0..len)
        .map(|i| echo[i] + near8[i] + rng.next() * 3e-4)
        .collect();
    let aec = ProcessingConfig {
        echo_cancel: true,
        noise_suppress: false,
        gain_control: false,
        ..ProcessingConfig::default()
    };
    let (out, _) = run(aec, &mic, &far8, clock);
    let far_only = 4 * sr..7 * sr;
    let erle_db = db(
        energy(&mic[far_only.clone()]),
        energy(&out[far_only.clone()]),
    );
    let dt = 7 * sr..len;
    let diff = |a: &[f64]| -> Vec<f64> {
        a[dt.clone()]
            .iter()
            .zip(&near8[dt.clone()])
            .map(|(x, n)| x - n)
            .collect()
    };
    let double_talk_db = db(energy(&diff(&mic)), energy(&diff(&out)));
    let (chain, cost) = run(ProcessingConfig::default(), &mic, &far8, clock);
    let erle_chain_db = db(energy(&mic[far_only.clone()]), energy(&chain[far_only]));

    // noise: speech from 2 s in white noise 10 dB below the speech's active level
    let speech: Vec<f64> = near.iter().take(5 * sr).map(|v| v * 0.5).collect();
    let active: Vec<f64> = speech.iter().copied().filter(|v| v.abs() > 0.01).collect();
    let speech_rms = (energy(&active) / active.len().max(1) as f64).sqrt();
    let sigma = speech_rms / 10f64.powf(10.0 / 20.0);
    let mut noisy = vec![0.0; 2 * sr];
    noisy.extend(speech.iter().copied());
    let noise: Vec<f64> = (0..noisy.len())
        .map(|_| rng.next() * sigma * 3f64.sqrt())
        .collect();
    let clean = noisy.clone();
    for (v, n) in noisy.iter_mut().zip(&noise) {
        *v += n;
    }
    let ns = ProcessingConfig {
        echo_cancel: false,
        noise_suppress: true,
        gain_control: false,
        ..ProcessingConfig::default()
    };
    let silent = vec![0.0; noisy.len()];
    let (den, _) = run(ns, &noisy, &silent, clock);
    let pause = sr..2 * sr;
    let noise_db = db(energy(&noisy[pause.clone()]), energy(&den[pause]));
    // the speech's own level, where it is loud, before and after
    let loud: Vec<usize> = (2 * sr..clean.len().min(den.len()))
        .filter(|i| clean[*i].abs() > speech_rms)
        .collect();
    let pick = |x: &[f64]| -> Vec<f64> { loud.iter().map(|i| x[*i]).collect() };
    let speech_loss_db = db(energy(&pick(&clean)), energy(&pick(&den)));

    // gain: the speech 30 dB too quiet, looped for 8 s
    let quiet: Vec<f64> = looped(near, len)
        .iter()
        .map(|v| v * 0.5 * 10f64.powf(-30.0 / 20.0))
        .collect();
    let agc = ProcessingConfig {
        echo_cancel: false,
        noise_suppress: false,
        gain_control: true,
        ..ProcessingConfig::default()
    };
    let (raised, _) = run(agc, &quiet, &vec![0.0; len], clock);
    let tail = 5 * sr..len;
    let agc_gain_db = db(energy(&raised[tail.clone()]), energy(&quiet[tail]));

    let mut c = cost;
    c.sort_by(f64::total_cmp);
    let cost_us = c.get(c.len() / 2).copied().unwrap_or(0.0);
    ProcessingMeasure {
        erle_db,
        erle_chain_db,
        double_talk_db,
        noise_db,
        speech_loss_db,
        agc_gain_db,
        cost_us,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn nothing_asked_is_no_processor() {
        assert!(MicProcessor::new(ProcessingConfig::OFF).unwrap().is_none());
        let p = MicProcessor::new(ProcessingConfig::default())
            .unwrap()
            .unwrap();
        assert!(p.config().echo_cancel);
    }
}
