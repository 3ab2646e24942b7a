//! Opus through libopus (the `opus` crate): 48 kHz mono, 20 ms frames, VoIP mode, in-band FEC
//! and DTX. The encoder's bitrate and expected loss follow what the listeners report
//! ([`Encoder::adapt`]).

use crate::{FRAME_SAMPLES, SAMPLE_RATE};
use softsync_net::voice::MAX_OPUS_BYTES;

/// What libopus said.
#[derive(Debug, thiserror::Error)]
#[error("opus: {0}")]
pub struct CodecError(#[from] opus::Error);

/// The lowest and highest bitrates the encoder is set to, bits a second.
pub const BITRATE_RANGE: (i32, i32) = (8_000, 40_000);

/// The speaker's encoder.
pub struct Encoder {
    inner: opus::Encoder,
    bitrate: i32,
    loss_pct: i32,
    fec: bool,
}

impl std::fmt::Debug for Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Encoder")
            .field("bitrate", &self.bitrate)
            .field("loss_pct", &self.loss_pct)
            .finish()
    }
}

impl Encoder {
    /// An encoder at `bitrate` bits a second (clamped to [`BITRATE_RANGE`]), with FEC and DTX
    /// as asked.
    pub fn new(bitrate: i32, fec: bool, dtx: bool) -> Result<Self, CodecError> {
        let mut inner =
            opus::Encoder::new(SAMPLE_RATE, opus::Channels::Mono, opus::Application::Voip)?;
        inner.set_inband_fec(fec)?;
        inner.set_dtx(dtx)?;
        inner.set_signal(opus::Signal::Voice)?;
        let mut e = Encoder {
            inner,
            bitrate: 0,
            loss_pct: 0,
            fec,
        };
        e.set(bitrate, 0)?;
        Ok(e)
    }

    fn set(&mut self, bitrate: i32, loss_pct: i32) -> Result<(), CodecError> {
        let bitrate = bitrate.clamp(BITRATE_RANGE.0, BITRATE_RANGE.1);
        let loss_pct = loss_pct.clamp(0, 30);
        if bitrate != self.bitrate {
            self.inner.set_bitrate(opus::Bitrate::Bits(bitrate))?;
            self.bitrate = bitrate;
        }
        if loss_pct != self.loss_pct {
            self.inner.set_packet_loss_perc(loss_pct)?;
            self.loss_pct = loss_pct;
        }
        Ok(())
    }

    /// The bitrate now, bits a second.
    pub fn bitrate(&self) -> i32 {
        self.bitrate
    }

    /// The loss the encoder protects against now, percent.
    pub fn loss_pct(&self) -> i32 {
        self.loss_pct
    }

    /// Follow the listeners: `worst_loss` (0–1) is the worst loss any listener reports,
    /// `cap` the bitrate the uplink budget leaves for voice (if any), `wanted` the
    /// configured bitrate. With FEC, libopus spends part of the bitrate on the redundant copy
    /// of the previous frame, which it only does when told to expect loss; the bitrate is
    /// raised a little with loss so that the primary copy keeps its quality, never above
    /// the budget's share.
    pub fn adapt(
        &mut self,
        wanted: i32,
        worst_loss: f64,
        cap: Option<i32>,
    ) -> Result<(), CodecError> {
        let loss_pct = if self.fec {
            ((worst_loss * 100.0).ceil() as i32 + 2).min(30)
        } else {
            0
        };
        let boosted = if self.fec && worst_loss > 0.01 {
            wanted + wanted / 4
        } else {
            wanted
        };
        let bitrate = cap.map_or(boosted, |c| boosted.min(c));
        self.set(bitrate, loss_pct)
    }

    /// One 20 ms frame of 960 samples into an Opus packet. With DTX, a packet of at most 2
    /// bytes is "nothing to send" (silence): the caller does not send it.
    pub fn encode(&mut self, pcm: &[i16; FRAME_SAMPLES]) -> Result<Vec<u8>, CodecError> {
        Ok(self.inner.encode_vec(pcm, MAX_OPUS_BYTES)?)
    }
}

/// A listener's decoder for one speaker.
pub struct Decoder {
    inner: opus::Decoder,
}

impl std::fmt::Debug for Decoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Decoder")
    }
}

/// How a frame of output was made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoded {
    /// From its own packet.
    Packet,
    /// From the next packet's forward error correction.
    Fec,
    /// Packet loss concealment.
    Concealed,
}

impl Decoder {
    /// A 48 kHz mono decoder.
    pub fn new() -> Result<Self, CodecError> {
        Ok(Decoder {
            inner: opus::Decoder::new(SAMPLE_RATE, opus::Channels::Mono)?,
        })
    }

    /// Decode `packet` into `out` (960 samples). A packet libopus refuses (corrupt, or a
    /// hostile speaker's bytes) is concealed instead; the result says which.
    pub fn decode(&mut self, packet: &[u8], out: &mut [i16; FRAME_SAMPLES]) -> Decoded {
        match self.inner.decode(packet, out, false) {
            Ok(n) if n == FRAME_SAMPLES => Decoded::Packet,
            _ => self.conceal(out),
        }
    }

    /// The frame before `next_packet`, from its in-band FEC (concealed when it has none).
    pub fn decode_fec(&mut self, next_packet: &[u8], out: &mut [i16; FRAME_SAMPLES]) -> Decoded {
        match self.inner.decode(next_packet, out, true) {
            Ok(n) if n == FRAME_SAMPLES => Decoded::Fec,
            _ => self.conceal(out),
        }
    }

    /// A lost frame, concealed.
    pub fn conceal(&mut self, out: &mut [i16; FRAME_SAMPLES]) -> Decoded {
        if !matches!(self.inner.decode(&[], out, false), Ok(n) if n == FRAME_SAMPLES) {
            out.fill(0);
        }
        Decoded::Concealed
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A voiced sound: a 200 Hz pulse train with breath noise, in syllables.
    fn tone(k: usize) -> [i16; FRAME_SAMPLES] {
        let mut x = 5u64 + k as u64;
        std::array::from_fn(|i| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let n = k * FRAME_SAMPLES + i;
            let t = n as f64 / f64::from(SAMPLE_RATE);
            let pulse = if n % 240 < 8 { 6000.0 } else { 0.0 };
            let env = (t * 6.0 * std::f64::consts::PI).sin().abs();
            ((pulse + ((x % 2000) as f64 - 1000.0)) * env) as i16
        })
    }

    #[test]
    fn fec_recovers_a_lost_frame_better_than_concealment() {
        let mut enc = Encoder::new(24_000, true, false).unwrap();
        enc.adapt(24_000, 0.2, None).unwrap();
        let packets: Vec<Vec<u8>> = (0..50).map(|k| enc.encode(&tone(k)).unwrap()).collect();
        // decode 0..30, lose 30, then 31 with and without FEC for 30
        let err = |use_fec: bool| {
            let mut dec = Decoder::new().unwrap();
            let mut out = [0i16; FRAME_SAMPLES];
            for p in &packets[..30] {
                dec.decode(p, &mut out);
            }
            let how = if use_fec {
                dec.decode_fec(&packets[31], &mut out)
            } else {
                dec.conceal(&mut out)
            };
            // compare with a clean decode of frame 30 (codec delay included)
            let mut clean = Decoder::new().unwrap();
            let mut c = [0i16; FRAME_SAMPLES];
            for p in &packets[..31] {
                clean.decode(p, &mut c);
            }
            let e: f64 = out
                .iter()
                .zip(c.iter())
                .map(|(a, b)| (f64::from(*a) - f64::from(*b)).powi(2))
                .sum();
            (how, e)
        };
        let (h_fec, e_fec) = err(true);
        let (h_plc, e_plc) = err(false);
        assert_eq!((h_fec, h_plc), (Decoded::Fec, Decoded::Concealed));
        assert!(e_fec < e_plc * 0.5, "fec {e_fec} plc {e_plc}");
    }

    #[test]
    fn hostile_packets_are_concealed_not_panicked_on() {
        let mut dec = Decoder::new().unwrap();
        let mut out = [0i16; FRAME_SAMPLES];
        for b in [
            &[0xFFu8; 400][..],
            &[0x03, 0xFF, 0xFF],
            &[0x00],
            &[0xFC, 0, 0, 0, 0],
        ] {
            let _ = dec.decode(b, &mut out);
        }
    }
}
