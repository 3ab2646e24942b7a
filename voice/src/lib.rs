//! `softsync-voice`: spatial voice for softsync rooms.
//!
//! - [`codec`]: Opus through libopus, 48 kHz mono, 20 ms frames, in-band FEC and DTX, a
//!   bitrate that follows the listeners' loss reports and the uplink budget.
//! - [`jitter`]: an adaptive jitter buffer per speaker on the room clock (FEC, PLC, talk
//!   spurts, a floor for lip-sync).
//! - [`spatial`]: each speaker at their avatar's head (distance, panning, interaural delay).
//! - [`level`]: levels and "is speaking".
//! - [`chat`]: [`VoiceChat`], one peer's voice, sans-IO.
//! - [`device`]: the system's microphone and loudspeaker (cpal over ALSA), in 20 ms frames.
//! - [`processing`]: echo cancellation, noise suppression and gain control (libspeexdsp).
//! - [`files`]: WAV sources and sinks for bots (`--voice-in`, `--voice-out`).
//! - [`analysis`]: the delay and similarity of a recording against what was said.
//!
//! The datagrams and who may send them are `softsync_net::voice`; the room drives all of it
//! (`softsync_bevy::voice`).

pub mod analysis;
pub mod chat;
pub mod codec;
pub mod device;
pub mod files;
pub mod jitter;
pub mod level;
pub mod processing;
pub mod spatial;

pub use chat::{Block, SpeakerStatus, VoiceChat, VoiceConfig};

/// Samples a second.
pub const SAMPLE_RATE: u32 = 48_000;
/// Samples in a 20 ms frame.
pub const FRAME_SAMPLES: usize = 960;
