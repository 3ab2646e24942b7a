//! The system's sound devices through `cpal` (ALSA on Linux; PulseAudio and PipeWire through
//! ALSA's plugins): [`AudioIn`] captures 48 kHz mono 20 ms frames from a microphone,
//! [`AudioOut`] plays 48 kHz stereo blocks on a loudspeaker or headset.
//!
//! The device runs on its own clock and thread; the room's 20 ms ticks meet it at a small ring
//! buffer on each side. Capture waits for 30 ms in the ring before it starts (so a tick always
//! finds a whole frame), and a ring that grows past 100 ms (the device ran faster than the
//! room, or the room stalled) drops its oldest samples back to the start level; playback does
//! the same at 40 ms / 150 ms. Every such event is counted ([`DeviceStats`]).
//!
//! Opening never panics: no device, a busy device or a format it cannot give return an error,
//! and the room then goes on silent on that side with a warning. A device that fails while
//! running (unplugged) is reported by [`AudioIn::error`] / [`AudioOut::error`].

use std::collections::VecDeque;
use std::sync::mpsc;
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;

use cpal::traits::{DeviceTrait, HostTrait, StreamTrait};

use crate::{FRAME_SAMPLES, SAMPLE_RATE};

/// Which device: the system's default, or one named as `softsync audio-devices` lists it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DeviceChoice {
    /// The system's default input or output.
    Default,
    /// A device by name (its name as listed, or a part of it).
    Named(String),
}

impl DeviceChoice {
    /// `default` or a name.
    pub fn parse(s: &str) -> DeviceChoice {
        if s == "default" {
            DeviceChoice::Default
        } else {
            DeviceChoice::Named(s.to_owned())
        }
    }
}

/// Why a device did not open.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// No such device (or none at all).
    #[error("no {0} device{1}")]
    NotFound(&'static str, String),
    /// The device has no format we can use.
    #[error("{0}: no usable format ({1})")]
    Format(String, String),
    /// The device refused the stream.
    #[error("{0}: {1}")]
    Stream(String, String),
}

/// What a device's ring did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeviceStats {
    /// Ticks that found less than a frame (capture) / callbacks that found the ring empty
    /// (playback).
    pub underruns: u64,
    /// Times the ring grew too long and dropped its oldest samples.
    pub overruns: u64,
    /// Samples that crossed the ring.
    pub samples: u64,
    /// Glitches the device itself reported (xruns and the like; the stream goes on).
    pub glitches: u64,
}

#[derive(Default)]
struct Shared {
    ring: VecDeque<f32>,
    stats: DeviceStats,
    error: Option<String>,
    /// Playback: the ring reached its start level.
    started: bool,
    /// The device's own latency at its last callback (capture to callback, or callback to
    /// playback).
    latency: std::time::Duration,
}

/// The device's error callback: a lost device ends the stream (reported once by
/// `error()`); an xrun or other glitch is counted and the stream goes on.
fn on_error(sh: Arc<Mutex<Shared>>) -> impl FnMut(cpal::Error) + Send + 'static {
    move |e: cpal::Error| {
        let mut g = lock(&sh);
        match e.kind() {
            cpal::ErrorKind::DeviceNotAvailable
            | cpal::ErrorKind::HostUnavailable
            | cpal::ErrorKind::StreamInvalidated
            | cpal::ErrorKind::PermissionDenied => g.error = Some(e.to_string()),
            _ => g.stats.glitches += 1,
        }
    }
}

fn lock(s: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    s.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The devices the system offers: `(inputs, outputs)`, by name; the defaults first.
pub fn list() -> (Vec<String>, Vec<String>) {
    let host = cpal::default_host();
    let names = |devs: Option<Vec<cpal::Device>>, default: Option<cpal::Device>| {
        let mut out: Vec<String> = default
            .map(|d| format!("{d} (default)"))
            .into_iter()
            .collect();
        for d in devs.unwrap_or_default() {
            out.push(d.to_string());
        }
        out
    };
    (
        names(
            host.input_devices().ok().map(Iterator::collect),
            host.default_input_device(),
        ),
        names(
            host.output_devices().ok().map(Iterator::collect),
            host.default_output_device(),
        ),
    )
}

fn find(input: bool, choice: &DeviceChoice) -> Result<cpal::Device, DeviceError> {
    let host = cpal::default_host();
    let side = if input { "input" } else { "output" };
    match choice {
        DeviceChoice::Default => {
            let d = if input {
                host.default_input_device()
            } else {
                host.default_output_device()
            };
            d.ok_or_else(|| DeviceError::NotFound(side, String::new()))
        }
        DeviceChoice::Named(name) => {
            let devs: Vec<cpal::Device> = if input {
                host.input_devices().map(Iterator::collect)
            } else {
                host.output_devices().map(Iterator::collect)
            }
            .map_err(|e| DeviceError::NotFound(side, format!(" ({e})")))?;
            // an exact name first, then a part of one
            let mut part = None;
            for d in devs {
                let n = d.to_string();
                if n == *name {
                    return Ok(d);
                }
                if part.is_none() && n.contains(name.as_str()) {
                    part = Some(d);
                }
            }
            part.ok_or_else(|| DeviceError::NotFound(side, format!(" named {name:?}")))
        }
    }
}

/// The config to open: 48 kHz in f32 or i16 where the device offers it, else its default.
fn pick_config(
    dev: &cpal::Device,
    input: bool,
) -> Result<(cpal::StreamConfig, cpal::SampleFormat), DeviceError> {
    let name = dev.to_string();
    let usable =
        |f: cpal::SampleFormat| matches!(f, cpal::SampleFormat::F32 | cpal::SampleFormat::I16);
    let ranges: Vec<cpal::SupportedStreamConfigRange> = if input {
        dev.supported_input_configs().map(Iterator::collect)
    } else {
        dev.supported_output_configs().map(Iterator::collect)
    }
    .map_err(|e| DeviceError::Format(name.clone(), e.to_string()))?;
    let wanted_channels = if input { 1 } else { 2 };
    let mut best: Option<cpal::SupportedStreamConfig> = None;
    let mut score = i32::MIN;
    for r in ranges {
        if !usable(r.sample_format())
            || !(r.min_sample_rate()..=r.max_sample_rate()).contains(&SAMPLE_RATE)
        {
            continue;
        }
        let s = -(i32::from(r.channels()) - wanted_channels).abs() * 10
            + i32::from(r.sample_format() == cpal::SampleFormat::F32);
        if s > score {
            score = s;
            best = Some(r.with_sample_rate(SAMPLE_RATE));
        }
    }
    let chosen = match best {
        Some(c) => c,
        None => {
            let d = if input {
                dev.default_input_config()
            } else {
                dev.default_output_config()
            }
            .map_err(|e| DeviceError::Format(name.clone(), e.to_string()))?;
            if !usable(d.sample_format()) {
                return Err(DeviceError::Format(
                    name,
                    format!("only {:?} samples", d.sample_format()),
                ));
            }
            d
        }
    };
    // the device's own buffer: its default (a fixed 10 ms double buffer made the ALSA pulse
    // plugin report an xrun every few callbacks on a loaded machine; the canceller and the
    // rings work from the latency each callback reports, so a longer buffer costs delay only)
    let config = chosen.config();
    Ok((config, chosen.sample_format()))
}

/// Linear resampling between two rates, carrying its phase across calls.
#[derive(Debug)]
struct Resampler {
    /// Input samples per output sample.
    step: f64,
    pos: f64,
    last: f32,
}

impl Resampler {
    fn new(from: u32, to: u32) -> Self {
        Resampler {
            step: f64::from(from) / f64::from(to),
            pos: 0.0,
            last: 0.0,
        }
    }

    fn identity(&self) -> bool {
        (self.step - 1.0).abs() < 1e-12
    }

    /// Resample `input` (one channel), appending to `out`.
    fn run(&mut self, input: &[f32], out: &mut Vec<f32>) {
        if self.identity() {
            out.extend_from_slice(input);
            return;
        }
        let n = input.len();
        let Some(&tail) = input.last() else {
            return;
        };
        // stream position `pos` is relative to input[0]; −1 is the last chunk's last sample
        let last = self.last;
        let at = |k: isize| -> f32 {
            usize::try_from(k)
                .ok()
                .and_then(|k| input.get(k).copied())
                .unwrap_or(last)
        };
        while self.pos <= (n - 1) as f64 {
            let i = self.pos.floor();
            let frac = (self.pos - i) as f32;
            let k = i as isize;
            let a = at(k);
            let b = if k + 1 < n as isize { at(k + 1) } else { a };
            out.push(a + (b - a) * frac);
            self.pos += self.step;
        }
        self.pos -= n as f64;
        self.last = tail;
    }
}

/// Capture start level: a frame and a half.
const IN_START: usize = FRAME_SAMPLES * 3 / 2;
/// Capture ring's most: 100 ms.
const IN_MAX: usize = FRAME_SAMPLES * 5;

/// An open device: its ring, its name and rate, and the thread its stream lives on (ended
/// and joined on drop).
struct Device {
    shared: Arc<Mutex<Shared>>,
    name: String,
    rate: u32,
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Device {
    fn stats(&self) -> DeviceStats {
        lock(&self.shared).stats
    }

    fn error(&mut self) -> Option<String> {
        lock(&self.shared).error.take()
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // dropping the sender ends the thread's wait; the stream closes there
        self.stop.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl std::fmt::Debug for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Device")
            .field("name", &self.name)
            .field("rate", &self.rate)
            .finish()
    }
}

/// A microphone: 48 kHz mono frames of 20 ms.
#[derive(Debug)]
pub struct AudioIn {
    dev: Device,
    started: bool,
}

/// Open a stream on its own thread (a cpal stream may not move between threads on every
/// platform): `build` makes it there, and it lives until the returned sender is dropped.
fn spawn_stream<F>(
    what: &'static str,
    build: F,
) -> Result<(mpsc::Sender<()>, JoinHandle<()>, String, u32), DeviceError>
where
    F: FnOnce() -> Result<(cpal::Stream, String, u32), DeviceError> + Send + 'static,
{
    let (stop_tx, stop_rx) = mpsc::channel::<()>();
    let (ready_tx, ready_rx) = mpsc::channel();
    let thread = std::thread::Builder::new()
        .name(format!("softsync-audio-{what}"))
        .spawn(move || match build() {
            Ok((stream, name, rate)) => {
                let _ = ready_tx.send(Ok((name, rate)));
                // keep the stream until the owner goes (recv fails when the sender drops)
                let _ = stop_rx.recv();
                drop(stream);
            }
            Err(e) => {
                let _ = ready_tx.send(Err(e));
            }
        })
        .map_err(|e| DeviceError::Stream(what.into(), e.to_string()))?;
    match ready_rx.recv() {
        Ok(Ok((name, rate))) => Ok((stop_tx, thread, name, rate)),
        Ok(Err(e)) => {
            let _ = thread.join();
            Err(e)
        }
        Err(_) => Err(DeviceError::Stream(
            what.into(),
            "audio thread ended".into(),
        )),
    }
}

impl AudioIn {
    /// Open `choice` for capture.
    pub fn open(choice: &DeviceChoice) -> Result<AudioIn, DeviceError> {
        let shared = Arc::new(Mutex::new(Shared::default()));
        let sh = shared.clone();
        let choice = choice.clone();
        let (stop, thread, name, rate) = spawn_stream("in", move || {
            let dev = find(true, &choice)?;
            let name = dev.to_string();
            let (config, format) = pick_config(&dev, true)?;
            let channels = usize::from(config.channels.max(1));
            let rate = config.sample_rate;
            let on_error = on_error(sh.clone());
            let mut rs = Resampler::new(rate, SAMPLE_RATE);
            let mut mono = Vec::new();
            let mut out = Vec::new();
            let mut take = move |data: &mut dyn Iterator<Item = f32>,
                                 info: &cpal::InputCallbackInfo| {
                let ts = info.timestamp();
                mono.clear();
                let mut acc = 0.0;
                for (i, s) in data.enumerate() {
                    acc += s;
                    if i % channels == channels - 1 {
                        mono.push(acc / channels as f32);
                        acc = 0.0;
                    }
                }
                out.clear();
                rs.run(&mono, &mut out);
                let mut g = lock(&sh);
                g.stats.samples += out.len() as u64;
                g.ring.extend(out.iter().copied());
                g.latency = ts.callback.duration_since(ts.capture);
            };
            let stream = match format {
                cpal::SampleFormat::I16 => dev.build_input_stream::<i16, _, _>(
                    config,
                    move |d: &[i16], info: &cpal::InputCallbackInfo| {
                        take(&mut d.iter().map(|s| f32::from(*s) / 32768.0), info);
                    },
                    on_error,
                    None,
                ),
                _ => dev.build_input_stream::<f32, _, _>(
                    config,
                    move |d: &[f32], info: &cpal::InputCallbackInfo| {
                        take(&mut d.iter().copied(), info);
                    },
                    on_error,
                    None,
                ),
            }
            .map_err(|e| DeviceError::Stream(name.clone(), e.to_string()))?;
            stream
                .play()
                .map_err(|e| DeviceError::Stream(name.clone(), e.to_string()))?;
            Ok((stream, name, rate))
        })?;
        Ok(AudioIn {
            dev: Device {
                shared,
                name,
                rate,
                stop: Some(stop),
                thread: Some(thread),
            },
            started: false,
        })
    }

    /// The device's name.
    pub fn name(&self) -> &str {
        &self.dev.name
    }

    /// The device's own rate (resampled to 48 kHz here).
    pub fn device_rate(&self) -> u32 {
        self.dev.rate
    }

    /// The next 20 ms: what the microphone heard, or silence while the ring fills (and after
    /// an underrun, until it has filled again).
    pub fn next_frame(&mut self) -> [i16; FRAME_SAMPLES] {
        let mut out = [0i16; FRAME_SAMPLES];
        let mut g = lock(&self.dev.shared);
        if !self.started {
            if g.ring.len() < IN_START {
                return out;
            }
            self.started = true;
        }
        if g.ring.len() < FRAME_SAMPLES {
            g.stats.underruns += 1;
            self.started = false;
            let n = g.ring.len();
            for (o, s) in out.iter_mut().zip(g.ring.drain(..n)) {
                *o = to_i16(s);
            }
            return out;
        }
        for (o, s) in out.iter_mut().zip(g.ring.drain(..FRAME_SAMPLES)) {
            *o = to_i16(s);
        }
        if g.ring.len() > IN_MAX {
            let excess = g.ring.len() - (IN_START - FRAME_SAMPLES);
            g.ring.drain(..excess);
            g.stats.overruns += 1;
        }
        out
    }

    /// What the ring did.
    pub fn stats(&self) -> DeviceStats {
        self.dev.stats()
    }

    /// How long ago the last frame taken ended, as sound at the microphone: the device's
    /// latency and what is still in the ring.
    pub fn latency(&self) -> std::time::Duration {
        let g = lock(&self.dev.shared);
        g.latency + std::time::Duration::from_secs_f64(g.ring.len() as f64 / f64::from(SAMPLE_RATE))
    }

    /// An error the device reported while running, taken once.
    pub fn error(&mut self) -> Option<String> {
        self.dev.error()
    }
}

fn to_i16(s: f32) -> i16 {
    (s * 32767.0).round().clamp(-32768.0, 32767.0) as i16
}

/// Playback start level, in 48 kHz frames: 40 ms.
const OUT_START_MS: usize = 40;
/// Playback ring's most: 150 ms.
const OUT_MAX_MS: usize = 150;

/// A loudspeaker or headset: 48 kHz stereo blocks in.
#[derive(Debug)]
pub struct AudioOut {
    dev: Device,
    channels: usize,
    left: Resampler,
    right: Resampler,
    scratch: (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>),
}

impl AudioOut {
    /// Open `choice` for playback.
    pub fn open(choice: &DeviceChoice) -> Result<AudioOut, DeviceError> {
        let shared = Arc::new(Mutex::new(Shared::default()));
        let sh = shared.clone();
        let choice = choice.clone();
        let channels_seen = Arc::new(Mutex::new(2usize));
        let ch_out = channels_seen.clone();
        let (stop, thread, name, rate) = spawn_stream("out", move || {
            let dev = find(false, &choice)?;
            let name = dev.to_string();
            let (config, format) = pick_config(&dev, false)?;
            let channels = usize::from(config.channels.max(1));
            *ch_out.lock().unwrap_or_else(PoisonError::into_inner) = channels;
            let rate = config.sample_rate;
            let start = rate as usize * channels * OUT_START_MS / 1000;
            let on_error = on_error(sh.clone());
            let fill = move |n: usize,
                             info: &cpal::OutputCallbackInfo,
                             put: &mut dyn FnMut(usize, f32)| {
                let ts = info.timestamp();
                let mut g = lock(&sh);
                g.latency = ts.playback.duration_since(ts.callback);
                if !g.started && g.ring.len() >= start {
                    g.started = true;
                }
                if !g.started {
                    return;
                }
                if g.ring.len() < n {
                    g.stats.underruns += 1;
                    g.started = false;
                }
                let k = g.ring.len().min(n);
                for (i, s) in g.ring.drain(..k).enumerate() {
                    put(i, s);
                }
                g.stats.samples += (k / channels) as u64;
            };
            let stream = match format {
                cpal::SampleFormat::I16 => dev.build_output_stream::<i16, _, _>(
                    config,
                    move |d: &mut [i16], info: &cpal::OutputCallbackInfo| {
                        d.fill(0);
                        let n = d.len();
                        fill(n, info, &mut |i, s| {
                            if let Some(o) = d.get_mut(i) {
                                *o = to_i16(s);
                            }
                        });
                    },
                    on_error,
                    None,
                ),
                _ => dev.build_output_stream::<f32, _, _>(
                    config,
                    move |d: &mut [f32], info: &cpal::OutputCallbackInfo| {
                        d.fill(0.0);
                        let n = d.len();
                        fill(n, info, &mut |i, s| {
                            if let Some(o) = d.get_mut(i) {
                                *o = s;
                            }
                        });
                    },
                    on_error,
                    None,
                ),
            }
            .map_err(|e| DeviceError::Stream(name.clone(), e.to_string()))?;
            stream
                .play()
                .map_err(|e| DeviceError::Stream(name.clone(), e.to_string()))?;
            Ok((stream, name, rate))
        })?;
        let channels = *channels_seen.lock().unwrap_or_else(PoisonError::into_inner);
        Ok(AudioOut {
            dev: Device {
                shared,
                name,
                rate,
                stop: Some(stop),
                thread: Some(thread),
            },
            channels,
            left: Resampler::new(SAMPLE_RATE, rate),
            right: Resampler::new(SAMPLE_RATE, rate),
            scratch: Default::default(),
        })
    }

    /// The device's name.
    pub fn name(&self) -> &str {
        &self.dev.name
    }

    /// The device's own rate (resampled from 48 kHz here).
    pub fn device_rate(&self) -> u32 {
        self.dev.rate
    }

    /// How long until a block queued now is heard: what the ring holds and the device's
    /// latency.
    pub fn latency(&self) -> std::time::Duration {
        let g = lock(&self.dev.shared);
        let per_s = f64::from(self.dev.rate) * self.channels as f64;
        g.latency + std::time::Duration::from_secs_f64(g.ring.len() as f64 / per_s)
    }

    /// Queue a block: interleaved L R at 48 kHz, in −1..1.
    pub fn play(&mut self, stereo: &[f32]) {
        let (l, r, lo, ro) = &mut self.scratch;
        l.clear();
        r.clear();
        for p in stereo.chunks_exact(2) {
            l.push(p[0]);
            r.push(p[1]);
        }
        lo.clear();
        ro.clear();
        self.left.run(l, lo);
        self.right.run(r, ro);
        let ch = self.channels;
        let max = self.dev.rate as usize * ch * OUT_MAX_MS / 1000;
        let start = self.dev.rate as usize * ch * OUT_START_MS / 1000;
        let mut g = lock(&self.dev.shared);
        for (a, b) in lo.iter().zip(ro.iter()) {
            match ch {
                1 => g.ring.push_back((a + b) * 0.5),
                _ => {
                    g.ring.push_back(*a);
                    g.ring.push_back(*b);
                    for _ in 2..ch {
                        g.ring.push_back(0.0);
                    }
                }
            }
        }
        if g.ring.len() > max {
            // whole device frames only, so the channels stay in step
            let excess = (g.ring.len() - start) / ch * ch;
            g.ring.drain(..excess);
            g.stats.overruns += 1;
        }
    }

    /// What the ring did.
    pub fn stats(&self) -> DeviceStats {
        self.dev.stats()
    }

    /// An error the device reported while running, taken once.
    pub fn error(&mut self) -> Option<String> {
        self.dev.error()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn resampling_keeps_a_tone_and_its_length_across_calls() {
        // 44.1 kHz → 48 kHz, in uneven chunks
        let mut rs = Resampler::new(44_100, 48_000);
        let tone: Vec<f32> = (0..44_100)
            .map(|i| (i as f32 * 440.0 * std::f32::consts::TAU / 44_100.0).sin())
            .collect();
        let mut out = Vec::new();
        for c in tone.chunks(441 + 7) {
            rs.run(c, &mut out);
        }
        assert!((out.len() as i64 - 48_000).abs() <= 2, "{}", out.len());
        // the same tone at 48 kHz
        let mut err = 0.0f32;
        for (i, s) in out.iter().enumerate().skip(10).take(47_000) {
            let t = i as f32 * 440.0 * std::f32::consts::TAU / 48_000.0;
            err = err.max((s - t.sin()).abs());
        }
        assert!(err < 0.01, "{err}");
        let mut id = Resampler::new(48_000, 48_000);
        let mut o = Vec::new();
        id.run(&[0.5, -0.5], &mut o);
        assert_eq!(o, vec![0.5, -0.5]);
    }

    #[test]
    fn a_missing_named_device_is_an_error_not_a_panic() {
        let e = AudioIn::open(&DeviceChoice::Named("no-such-device-softsync".into()));
        assert!(e.is_err());
        let e = AudioOut::open(&DeviceChoice::Named("no-such-device-softsync".into()));
        assert!(e.is_err());
    }
}
