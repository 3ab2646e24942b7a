//! WAV files for bots that speak and listen: a source that reads any PCM WAV (mixed to mono,
//! resampled linearly to 48 kHz) in 20 ms frames, and a sink that writes what a peer plays —
//! the mix in stereo and each speaker alone in mono — with the room time of its first sample
//! beside it (`voice.json`), so a recording can be lined up with what was said.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use softsync_net::PeerId;

use crate::{FRAME_SAMPLES, SAMPLE_RATE};

/// A file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The WAV reader or writer said so.
    #[error("{path}: {source}")]
    Wav {
        /// The file.
        path: PathBuf,
        /// Why.
        source: hound::Error,
    },
    /// Something else.
    #[error("{0}")]
    Other(String),
}

/// Read a WAV file as 48 kHz mono samples.
pub fn read_wav(path: &Path) -> Result<Vec<i16>, FileError> {
    let wav = |source| FileError::Wav {
        path: path.to_path_buf(),
        source,
    };
    let mut r = hound::WavReader::open(path).map_err(wav)?;
    let spec = r.spec();
    let ch = usize::from(spec.channels.max(1));
    let raw: Vec<f32> = match spec.sample_format {
        hound::SampleFormat::Float => r.samples::<f32>().collect::<Result<_, _>>().map_err(wav)?,
        hound::SampleFormat::Int => {
            let scale = 2f32.powi(i32::from(spec.bits_per_sample.clamp(1, 32)) - 1);
            r.samples::<i32>()
                .map(|s| s.map(|v| v as f32 / scale))
                .collect::<Result<_, _>>()
                .map_err(wav)?
        }
    };
    if raw.len() / ch > 60 * 60 * spec.sample_rate as usize {
        return Err(FileError::Other(format!(
            "{}: longer than an hour",
            path.display()
        )));
    }
    let mono: Vec<f32> = raw
        .chunks(ch)
        .map(|c| c.iter().sum::<f32>() / c.len() as f32)
        .collect();
    let rate = spec.sample_rate;
    if rate == 0 {
        return Err(FileError::Other(format!(
            "{}: sample rate 0",
            path.display()
        )));
    }
    let n = (mono.len() as u64 * u64::from(SAMPLE_RATE) / u64::from(rate)) as usize;
    let step = f64::from(rate) / f64::from(SAMPLE_RATE);
    Ok((0..n)
        .map(|i| {
            let x = i as f64 * step;
            let j = x.floor() as usize;
            let f = (x - j as f64) as f32;
            let a = mono.get(j).copied().unwrap_or(0.0);
            let b = mono.get(j + 1).copied().unwrap_or(a);
            ((a + (b - a) * f).clamp(-1.0, 1.0) * 32767.0) as i16
        })
        .collect())
}

/// Write 48 kHz 16-bit samples (`channels` interleaved).
pub fn write_wav(path: &Path, channels: u16, samples: &[i16]) -> Result<(), FileError> {
    let wav = |source| FileError::Wav {
        path: path.to_path_buf(),
        source,
    };
    let mut w = hound::WavWriter::create(path, spec(channels)).map_err(wav)?;
    for s in samples {
        w.write_sample(*s).map_err(wav)?;
    }
    w.finalize().map_err(wav)
}

fn spec(channels: u16) -> hound::WavSpec {
    hound::WavSpec {
        channels,
        sample_rate: SAMPLE_RATE,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    }
}

/// `text` spoken by espeak-ng (Debian's `espeak-ng`) at `words_per_min`, written to `path` as
/// 48 kHz mono, and its samples: the test and bench voice of bots.
pub fn speak(text: &str, words_per_min: u32, path: &Path) -> Result<Vec<i16>, FileError> {
    let raw = path.with_extension("espeak.wav");
    let st = std::process::Command::new("espeak-ng")
        .args(["-s", &words_per_min.to_string(), "-w"])
        .arg(&raw)
        .arg(text)
        .status()
        .map_err(|e| FileError::Other(format!("espeak-ng: {e} (install Debian's espeak-ng)")))?;
    if !st.success() {
        return Err(FileError::Other(format!("espeak-ng exited with {st}")));
    }
    let said = read_wav(&raw)?;
    write_wav(path, 1, &said)?;
    let _ = std::fs::remove_file(&raw);
    Ok(said)
}

/// A speech file in 20 ms frames: played once each time it is started.
#[derive(Clone, Debug)]
pub struct WavSource {
    samples: Vec<i16>,
    at: Option<usize>,
}

impl WavSource {
    /// Read `path`.
    pub fn open(path: &Path) -> Result<Self, FileError> {
        Ok(WavSource {
            samples: read_wav(path)?,
            at: None,
        })
    }

    /// From samples (48 kHz mono).
    pub fn from_samples(samples: Vec<i16>) -> Self {
        WavSource { samples, at: None }
    }

    /// Its length, seconds.
    pub fn seconds(&self) -> f64 {
        self.samples.len() as f64 / f64::from(SAMPLE_RATE)
    }

    /// Start from the beginning (again).
    pub fn start(&mut self) {
        self.at = Some(0);
    }

    /// Playing now.
    pub fn playing(&self) -> bool {
        self.at.is_some()
    }

    /// The next 20 ms (silence when not playing); whether it was the file's first frame.
    pub fn next_frame(&mut self) -> ([i16; FRAME_SAMPLES], bool) {
        let mut out = [0i16; FRAME_SAMPLES];
        let Some(at) = self.at else {
            return (out, false);
        };
        let end = (at + FRAME_SAMPLES).min(self.samples.len());
        if let Some(s) = self.samples.get(at..end) {
            out[..s.len()].copy_from_slice(s);
        }
        self.at = (end < self.samples.len()).then_some(end);
        (out, at == 0)
    }
}

type Writer = hound::WavWriter<BufWriter<File>>;

/// What a listener plays, to files under a folder: `mix.wav` (stereo) and `peer-ID.wav` (each
/// speaker, mono, padded with silence from the sink's start), and `voice.json`.
pub struct WavSink {
    dir: PathBuf,
    mix: Writer,
    speakers: BTreeMap<PeerId, Writer>,
    blocks: u64,
    start_room_ms: Option<f64>,
    heads: std::io::BufWriter<File>,
}

impl std::fmt::Debug for WavSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WavSink")
            .field("dir", &self.dir)
            .field("blocks", &self.blocks)
            .finish()
    }
}

impl WavSink {
    /// Files under `dir` (made if missing).
    pub fn create(dir: &Path) -> Result<Self, FileError> {
        std::fs::create_dir_all(dir)
            .map_err(|e| FileError::Other(format!("{}: {e}", dir.display())))?;
        let path = dir.join("mix.wav");
        let mix = hound::WavWriter::create(&path, spec(2))
            .map_err(|source| FileError::Wav { path, source })?;
        let heads = File::create(dir.join("heads.csv"))
            .map_err(|e| FileError::Other(format!("{}: {e}", dir.join("heads.csv").display())))?;
        let mut heads = std::io::BufWriter::new(heads);
        use std::io::Write;
        writeln!(heads, "room_ms,peer,x,y,z").map_err(|e| FileError::Other(e.to_string()))?;
        Ok(WavSink {
            dir: dir.to_path_buf(),
            mix,
            speakers: BTreeMap::new(),
            blocks: 0,
            start_room_ms: None,
            heads,
        })
    }

    /// One block played at room time `room_ms`: the stereo mix and each speaker's mono.
    pub fn write(
        &mut self,
        room_ms: f64,
        stereo: &[f32],
        speakers: &[(PeerId, [i16; FRAME_SAMPLES])],
    ) -> Result<(), FileError> {
        let start = *self.start_room_ms.get_or_insert(room_ms);
        let _ = start;
        let dir = self.dir.clone();
        let err = |path: &Path| {
            let path = path.to_path_buf();
            move |source| FileError::Wav { path, source }
        };
        let mix_path = dir.join("mix.wav");
        for s in stereo {
            self.mix
                .write_sample((s.clamp(-1.0, 1.0) * 32767.0) as i16)
                .map_err(err(&mix_path))?;
        }
        for (p, pcm) in speakers {
            let path = dir.join(format!("peer-{}.wav", p.0));
            if !self.speakers.contains_key(p) {
                let mut w = hound::WavWriter::create(&path, spec(1)).map_err(err(&path))?;
                for _ in 0..self.blocks * FRAME_SAMPLES as u64 {
                    w.write_sample(0i16).map_err(err(&path))?;
                }
                self.speakers.insert(*p, w);
            }
            if let Some(w) = self.speakers.get_mut(p) {
                for s in pcm {
                    w.write_sample(*s).map_err(err(&path))?;
                }
            }
        }
        // a speaker with nothing this block gets silence, so every file stays on one timeline
        for (p, w) in &mut self.speakers {
            if !speakers.iter().any(|(q, _)| q == p) {
                let path = dir.join(format!("peer-{}.wav", p.0));
                for _ in 0..FRAME_SAMPLES {
                    w.write_sample(0i16).map_err(err(&path))?;
                }
            }
        }
        self.blocks += 1;
        if self.blocks % 25 == 0 {
            self.flush()?;
        }
        Ok(())
    }

    /// Where each speaker's head was shown at the block played at `room_ms` (`heads.csv`: how
    /// the voice bench measures lip-sync from outside).
    pub fn write_heads(
        &mut self,
        room_ms: f64,
        heads: &[(PeerId, glam::Vec3)],
    ) -> Result<(), FileError> {
        use std::io::Write;
        for (p, at) in heads {
            writeln!(
                self.heads,
                "{room_ms:.1},{},{:.5},{:.5},{:.5}",
                p.0, at.x, at.y, at.z
            )
            .map_err(|e| FileError::Other(format!("heads.csv: {e}")))?;
        }
        Ok(())
    }

    /// Headers and `voice.json` brought up to date (every half second anyway: a killed
    /// listener leaves readable files).
    pub fn flush(&mut self) -> Result<(), FileError> {
        let dir = self.dir.clone();
        {
            use std::io::Write;
            self.heads
                .flush()
                .map_err(|e| FileError::Other(format!("heads.csv: {e}")))?;
        }
        self.mix.flush().map_err(|source| FileError::Wav {
            path: dir.join("mix.wav"),
            source,
        })?;
        for (p, w) in &mut self.speakers {
            w.flush().map_err(|source| FileError::Wav {
                path: dir.join(format!("peer-{}.wav", p.0)),
                source,
            })?;
        }
        let meta = serde_json::json!({
            "sample_rate": SAMPLE_RATE,
            "start_room_ms": self.start_room_ms,
            "blocks": self.blocks,
            "block_ms": 20,
        });
        std::fs::write(dir.join("voice.json"), meta.to_string())
            .map_err(|e| FileError::Other(format!("{}: {e}", dir.display())))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_22050_hz_file_is_read_at_48k_and_frames_come_in_order() {
        let dir = std::env::temp_dir().join(format!("softsync-voice-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.wav");
        let spec = hound::WavSpec {
            channels: 2,
            sample_rate: 22_050,
            bits_per_sample: 16,
            sample_format: hound::SampleFormat::Int,
        };
        let mut w = hound::WavWriter::create(&path, spec).unwrap();
        for i in 0..22_050 {
            let v = ((i as f64 / 22_050.0 * 440.0 * std::f64::consts::TAU).sin() * 10_000.0) as i16;
            w.write_sample(v).unwrap();
            w.write_sample(v).unwrap();
        }
        w.finalize().unwrap();
        let s = read_wav(&path).unwrap();
        assert!((s.len() as i64 - 48_000).abs() <= 1, "{}", s.len());
        let mut src = WavSource::from_samples(s);
        assert!(!src.next_frame().1);
        src.start();
        let (_, first) = src.next_frame();
        assert!(first);
        let mut n = 1;
        while src.playing() {
            src.next_frame();
            n += 1;
        }
        assert_eq!(n, 50);
        // a broken file is an error naming it
        std::fs::write(dir.join("bad.wav"), b"RIFF\x04\x00\x00\x00WAVEjunk").unwrap();
        let e = read_wav(&dir.join("bad.wav")).unwrap_err().to_string();
        assert!(e.contains("bad.wav"), "{e}");
        let mut sink = WavSink::create(&dir.join("out")).unwrap();
        sink.write(5000.0, &[0.0; 1920], &[(PeerId(4), [7; 960])])
            .unwrap();
        sink.flush().unwrap();
        let meta = std::fs::read_to_string(dir.join("out/voice.json")).unwrap();
        assert!(meta.contains("\"start_room_ms\":5000.0"), "{meta}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
