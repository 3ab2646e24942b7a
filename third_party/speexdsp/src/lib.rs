//! A small safe binding to two parts of libspeexdsp (Xiph's maintained speech DSP library,
//! linked from the system):
//!
//! - [`EchoCanceller`]: the MDF acoustic echo canceller (`speex_echo_*`): given what the
//!   loudspeaker played and what the microphone heard, it removes the loudspeaker's echo.
//! - [`Preprocessor`]: noise suppression, automatic gain control and residual echo
//!   suppression (`speex_preprocess_*`).
//!
//! Both work on fixed-size frames of 16-bit mono samples. Every call checks the frame's length
//! first, so no call can read or write out of bounds; the states are owned and freed on drop.
//! This crate holds the only `unsafe` code of softsync's voice path.

#![warn(missing_docs)]

use std::os::raw::{c_int, c_void};

#[repr(C)]
struct SpeexEchoState {
    _private: [u8; 0],
}
#[repr(C)]
struct SpeexPreprocessState {
    _private: [u8; 0],
}

#[link(name = "speexdsp")]
extern "C" {
    fn speex_echo_state_init(frame_size: c_int, filter_length: c_int) -> *mut SpeexEchoState;
    fn speex_echo_state_destroy(st: *mut SpeexEchoState);
    fn speex_echo_cancellation(
        st: *mut SpeexEchoState,
        rec: *const i16,
        play: *const i16,
        out: *mut i16,
    );
    fn speex_echo_state_reset(st: *mut SpeexEchoState);
    fn speex_echo_ctl(st: *mut SpeexEchoState, request: c_int, ptr: *mut c_void) -> c_int;

    fn speex_preprocess_state_init(frame_size: c_int, rate: c_int) -> *mut SpeexPreprocessState;
    fn speex_preprocess_state_destroy(st: *mut SpeexPreprocessState);
    fn speex_preprocess_run(st: *mut SpeexPreprocessState, x: *mut i16) -> c_int;
    fn speex_preprocess_ctl(
        st: *mut SpeexPreprocessState,
        request: c_int,
        ptr: *mut c_void,
    ) -> c_int;
}

const SPEEX_ECHO_SET_SAMPLING_RATE: c_int = 24;
const SPEEX_PREPROCESS_SET_DENOISE: c_int = 0;
const SPEEX_PREPROCESS_SET_AGC: c_int = 2;
const SPEEX_PREPROCESS_SET_DEREVERB: c_int = 8;
const SPEEX_PREPROCESS_SET_NOISE_SUPPRESS: c_int = 18;
const SPEEX_PREPROCESS_SET_ECHO_SUPPRESS: c_int = 20;
const SPEEX_PREPROCESS_SET_ECHO_SUPPRESS_ACTIVE: c_int = 22;
const SPEEX_PREPROCESS_SET_ECHO_STATE: c_int = 24;
const SPEEX_PREPROCESS_SET_AGC_MAX_GAIN: c_int = 30;
const SPEEX_PREPROCESS_GET_AGC_GAIN: c_int = 35;
const SPEEX_PREPROCESS_SET_AGC_TARGET: c_int = 46;

/// What can go wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// A frame of the wrong length was passed.
    FrameLength {
        /// The state's frame.
        expected: usize,
        /// What was passed.
        got: usize,
    },
    /// A size or rate the library cannot take (zero, negative or too large).
    BadParameter(&'static str),
    /// The library returned no state (out of memory).
    Init,
    /// A control request was refused.
    Control(&'static str),
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Error::FrameLength { expected, got } => {
                write!(f, "frame of {got} samples, expected {expected}")
            }
            Error::BadParameter(p) => write!(f, "bad parameter: {p}"),
            Error::Init => write!(f, "libspeexdsp returned no state"),
            Error::Control(c) => write!(f, "libspeexdsp refused {c}"),
        }
    }
}

impl std::error::Error for Error {}

fn checked_int(v: usize, what: &'static str) -> Result<c_int, Error> {
    c_int::try_from(v)
        .ok()
        .filter(|v| *v > 0 && *v <= 1 << 20)
        .ok_or(Error::BadParameter(what))
}

/// The MDF acoustic echo canceller.
pub struct EchoCanceller {
    st: *mut SpeexEchoState,
    frame: usize,
}

// SAFETY: the state is owned exclusively by this value (no aliasing; libspeexdsp keeps no
// global state), so moving it to another thread is sound. It is not Sync: `&self` exposes
// nothing.
unsafe impl Send for EchoCanceller {}

impl EchoCanceller {
    /// A canceller for frames of `frame` samples at `rate` Hz, modelling echo paths up to
    /// `tail` samples long.
    pub fn new(frame: usize, tail: usize, rate: u32) -> Result<Self, Error> {
        let n = checked_int(frame, "frame")?;
        let t = checked_int(tail, "tail")?;
        let mut r = c_int::try_from(rate)
            .ok()
            .filter(|r| (8_000..=96_000).contains(r))
            .ok_or(Error::BadParameter("rate"))?;
        // SAFETY: positive sizes checked above; a null return is handled.
        let st = unsafe { speex_echo_state_init(n, t) };
        if st.is_null() {
            return Err(Error::Init);
        }
        let me = EchoCanceller { st, frame };
        // SAFETY: `st` is a live state; the request takes a pointer to an int.
        let rc = unsafe {
            speex_echo_ctl(
                me.st,
                SPEEX_ECHO_SET_SAMPLING_RATE,
                (&mut r as *mut c_int).cast(),
            )
        };
        if rc != 0 {
            return Err(Error::Control("SPEEX_ECHO_SET_SAMPLING_RATE"));
        }
        Ok(me)
    }

    /// The frame length, samples.
    pub fn frame(&self) -> usize {
        self.frame
    }

    /// `out` = `mic` with the echo of `played` removed. `played` is what the loudspeaker was
    /// given at about the time `mic` was captured (the echo may lag it by up to the tail).
    pub fn cancel(&mut self, mic: &[i16], played: &[i16], out: &mut [i16]) -> Result<(), Error> {
        for s in [mic.len(), played.len(), out.len()] {
            if s != self.frame {
                return Err(Error::FrameLength {
                    expected: self.frame,
                    got: s,
                });
            }
        }
        // SAFETY: all three buffers hold exactly `frame` samples (checked above), the length
        // the state was made for; `out` does not alias the inputs (&mut).
        unsafe {
            speex_echo_cancellation(self.st, mic.as_ptr(), played.as_ptr(), out.as_mut_ptr())
        };
        Ok(())
    }

    /// Forget the echo path (after the devices changed).
    pub fn reset(&mut self) {
        // SAFETY: `st` is a live state.
        unsafe { speex_echo_state_reset(self.st) };
    }
}

impl Drop for EchoCanceller {
    fn drop(&mut self) {
        // SAFETY: `st` came from speex_echo_state_init and is freed once, here. A
        // preprocessor linked to it borrows it (see `Preprocessor::link_echo`), so it is
        // dropped first.
        unsafe { speex_echo_state_destroy(self.st) };
    }
}

/// Noise suppression, automatic gain control and residual echo suppression.
pub struct Preprocessor {
    st: *mut SpeexPreprocessState,
    frame: usize,
}

// SAFETY: as for `EchoCanceller`: exclusively owned.
unsafe impl Send for Preprocessor {}

/// How the preprocessor treats each frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreprocessConfig {
    /// Noise suppression on.
    pub denoise: bool,
    /// Maximum attenuation of noise, dB (negative; speex's default is −15).
    pub noise_suppress_db: i32,
    /// Automatic gain control on.
    pub agc: bool,
    /// The level AGC aims for, in 16-bit sample units RMS (8 000 ≈ −12 dBFS).
    pub agc_target: i32,
    /// The most gain AGC may apply, dB.
    pub agc_max_gain_db: i32,
    /// Maximum attenuation of residual echo, dB (negative), when linked to a canceller.
    pub echo_suppress_db: i32,
    /// The same while the near end talks too, dB (negative).
    pub echo_suppress_active_db: i32,
}

impl Default for PreprocessConfig {
    fn default() -> Self {
        PreprocessConfig {
            denoise: true,
            noise_suppress_db: -25,
            agc: true,
            agc_target: 8_000,
            agc_max_gain_db: 30,
            echo_suppress_db: -40,
            echo_suppress_active_db: -15,
        }
    }
}

impl Preprocessor {
    /// A preprocessor for frames of `frame` samples at `rate` Hz.
    pub fn new(frame: usize, rate: u32, cfg: PreprocessConfig) -> Result<Self, Error> {
        let n = checked_int(frame, "frame")?;
        let r = c_int::try_from(rate)
            .ok()
            .filter(|r| (8_000..=96_000).contains(r))
            .ok_or(Error::BadParameter("rate"))?;
        // SAFETY: positive sizes checked above; a null return is handled.
        let st = unsafe { speex_preprocess_state_init(n, r) };
        if st.is_null() {
            return Err(Error::Init);
        }
        let mut me = Preprocessor { st, frame };
        me.set_int(
            SPEEX_PREPROCESS_SET_DENOISE,
            i32::from(cfg.denoise),
            "DENOISE",
        )?;
        me.set_int(
            SPEEX_PREPROCESS_SET_NOISE_SUPPRESS,
            cfg.noise_suppress_db,
            "NOISE_SUPPRESS",
        )?;
        me.set_int(SPEEX_PREPROCESS_SET_AGC, i32::from(cfg.agc), "AGC")?;
        if cfg.agc {
            me.set_int(
                SPEEX_PREPROCESS_SET_AGC_TARGET,
                cfg.agc_target,
                "AGC_TARGET",
            )?;
            me.set_int(
                SPEEX_PREPROCESS_SET_AGC_MAX_GAIN,
                cfg.agc_max_gain_db,
                "AGC_MAX_GAIN",
            )?;
        }
        // (voice activity detection stays at its default, off: setting it, even to off, makes
        // libspeexdsp print a warning on stderr)
        me.set_int(SPEEX_PREPROCESS_SET_DEREVERB, 0, "DEREVERB")?;
        me.set_int(
            SPEEX_PREPROCESS_SET_ECHO_SUPPRESS,
            cfg.echo_suppress_db,
            "ECHO_SUPPRESS",
        )?;
        me.set_int(
            SPEEX_PREPROCESS_SET_ECHO_SUPPRESS_ACTIVE,
            cfg.echo_suppress_active_db,
            "ECHO_SUPPRESS_ACTIVE",
        )?;
        Ok(me)
    }

    fn set_int(&mut self, req: c_int, v: i32, what: &'static str) -> Result<(), Error> {
        let mut v: c_int = v;
        // SAFETY: `st` is live; every request used here takes a pointer to an int (see
        // speex_preprocess.h).
        let rc = unsafe { speex_preprocess_ctl(self.st, req, (&mut v as *mut c_int).cast()) };
        if rc == 0 {
            Ok(())
        } else {
            Err(Error::Control(what))
        }
    }

    /// Suppress the residual echo the canceller leaves: its state is read on every frame.
    /// The canceller must outlive this preprocessor's use of it; [`VoiceProcessor`] owns both
    /// and keeps that order.
    fn link_echo(&mut self, echo: &EchoCanceller) -> Result<(), Error> {
        // SAFETY: `st` is live; SET_ECHO_STATE takes the echo state pointer itself. The
        // caller keeps the echo state alive as long as this preprocessor runs.
        let rc = unsafe {
            speex_preprocess_ctl(self.st, SPEEX_PREPROCESS_SET_ECHO_STATE, echo.st.cast())
        };
        if rc == 0 {
            Ok(())
        } else {
            Err(Error::Control("ECHO_STATE"))
        }
    }

    /// Process one frame in place.
    pub fn run(&mut self, frame: &mut [i16]) -> Result<(), Error> {
        if frame.len() != self.frame {
            return Err(Error::FrameLength {
                expected: self.frame,
                got: frame.len(),
            });
        }
        // SAFETY: the buffer holds exactly `frame` samples, the length the state was made for.
        unsafe { speex_preprocess_run(self.st, frame.as_mut_ptr()) };
        Ok(())
    }

    /// The gain AGC applies now (linear), when AGC is on.
    pub fn agc_gain(&self) -> f32 {
        let mut g: i32 = 0;
        // SAFETY: `st` is live; GET_AGC_GAIN writes one spx_int32_t (gain in dB).
        let rc = unsafe {
            speex_preprocess_ctl(
                self.st,
                SPEEX_PREPROCESS_GET_AGC_GAIN,
                (&mut g as *mut i32).cast(),
            )
        };
        if rc == 0 {
            10f32.powf(g as f32 / 20.0)
        } else {
            1.0
        }
    }
}

impl Drop for Preprocessor {
    fn drop(&mut self) {
        // SAFETY: `st` came from speex_preprocess_state_init and is freed once, here.
        unsafe { speex_preprocess_state_destroy(self.st) };
    }
}

/// A microphone's whole chain: echo cancellation (when given what was played), then noise
/// suppression, residual echo suppression and gain control. Owns both states, so the
/// preprocessor's link to the canceller can never outlive it.
pub struct VoiceProcessor {
    // field order matters: `pre` (which reads `echo`'s state) drops first
    pre: Option<Preprocessor>,
    echo: Option<EchoCanceller>,
    frame: usize,
    scratch: Vec<i16>,
}

impl VoiceProcessor {
    /// A chain for frames of `frame` samples at `rate` Hz; `echo_tail`: the echo path's length,
    /// samples, or `None` for no canceller; `pre`: the preprocessor's settings, or `None`.
    pub fn new(
        frame: usize,
        rate: u32,
        echo_tail: Option<usize>,
        pre: Option<PreprocessConfig>,
    ) -> Result<Self, Error> {
        checked_int(frame, "frame")?;
        let echo = echo_tail
            .map(|t| EchoCanceller::new(frame, t, rate))
            .transpose()?;
        let mut pre = pre.map(|c| Preprocessor::new(frame, rate, c)).transpose()?;
        if let (Some(p), Some(e)) = (&mut pre, &echo) {
            p.link_echo(e)?;
        }
        Ok(VoiceProcessor {
            pre,
            echo,
            frame,
            scratch: vec![0; frame],
        })
    }

    /// Whether it cancels echo.
    pub fn cancels_echo(&self) -> bool {
        self.echo.is_some()
    }

    /// Process `mic` in place; `played`: what the loudspeaker was given meanwhile (silence
    /// when nothing played).
    pub fn process(&mut self, mic: &mut [i16], played: &[i16]) -> Result<(), Error> {
        if mic.len() != self.frame {
            return Err(Error::FrameLength {
                expected: self.frame,
                got: mic.len(),
            });
        }
        if let Some(e) = &mut self.echo {
            e.cancel(mic, played, &mut self.scratch)?;
            mic.copy_from_slice(&self.scratch);
        }
        if let Some(p) = &mut self.pre {
            p.run(mic)?;
        }
        Ok(())
    }

    /// AGC's gain now (linear; 1 without AGC).
    pub fn agc_gain(&self) -> f32 {
        self.pre.as_ref().map_or(1.0, Preprocessor::agc_gain)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrong_lengths_are_refused_not_read() {
        let mut p = VoiceProcessor::new(960, 48_000, Some(4800), Some(PreprocessConfig::default()))
            .expect("state");
        let mut short = vec![0i16; 100];
        assert!(matches!(
            p.process(&mut short, &[0; 960]),
            Err(Error::FrameLength {
                expected: 960,
                got: 100
            })
        ));
        let mut ok = vec![0i16; 960];
        assert!(p.process(&mut ok, &[0; 10]).is_err());
        assert!(p.process(&mut ok, &[0; 960]).is_ok());
        assert!(VoiceProcessor::new(0, 48_000, None, None).is_err());
        assert!(EchoCanceller::new(960, 4800, 1).is_err());
    }

    #[test]
    fn silence_stays_silent() {
        let mut p = VoiceProcessor::new(960, 48_000, Some(4800), Some(PreprocessConfig::default()))
            .expect("state");
        for _ in 0..50 {
            let mut f = vec![0i16; 960];
            p.process(&mut f, &[0; 960]).expect("process");
            assert!(f.iter().all(|s| s.unsigned_abs() < 4));
        }
    }
}
