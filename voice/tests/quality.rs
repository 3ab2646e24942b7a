//! Speech through the codec and a listener's jitter buffer, scored with wide-band PESQ
//! (`scripts/pesq`, ITU-T P.862.2): a sentence from espeak-ng, sent as 20 ms Opus frames over
//! a seeded lossy, jittery link and played; the played speech is lined up with the sentence
//! and scored.
#![allow(clippy::unwrap_used)]

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};

use softsync_net::PeerId;
use softsync_voice::analysis::align;
use softsync_voice::files::{speak, write_wav};
use softsync_voice::{VoiceChat, VoiceConfig, FRAME_SAMPLES};

fn repo() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn sentence(dir: &Path) -> Vec<i16> {
    speak(
        "Hold the clamp steady while I cut along the line, then lift it gently.",
        150,
        &dir.join("said.wav"),
    )
    .unwrap_or_else(|e| panic!("{e} (.ci/run installs it)"))
}

/// The sentence through a speaker and a listener over a link of `transit` ms (capture to
/// arrival, the frame's 20 ms included) ± `jitter`, losing `loss` of the frames (seeded):
/// what the listener played of the speaker, and (played, fec, concealed).
fn through(
    said: &[i16],
    loss: f64,
    transit: f64,
    jitter: f64,
    seed: u64,
) -> (Vec<i16>, softsync_voice::jitter::JitterStats) {
    let mut a = VoiceChat::new(VoiceConfig::default()).unwrap();
    let mut b = VoiceChat::new(VoiceConfig::default()).unwrap();
    let mut x = seed;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x % 1_000_000) as f64 / 1_000_000.0
    };
    let mut wire: Vec<(f64, softsync_net::voice::VoiceFrame)> = Vec::new();
    let mut out = Vec::new();
    let frames = said.len() / FRAME_SAMPLES + 40;
    let heads = BTreeMap::new();
    let mut pending: VecDeque<(f64, softsync_net::voice::VoiceFrame)> = VecDeque::new();
    for k in 0..frames {
        let t = 5_000.0 + k as f64 * 20.0;
        let mut pcm = [0i16; FRAME_SAMPLES];
        if let Some(s) = said.get(k * FRAME_SAMPLES..((k + 1) * FRAME_SAMPLES).min(said.len())) {
            pcm[..s.len()].copy_from_slice(s);
        }
        if let Some(f) = a.capture(t - 20.0, &pcm) {
            // a report a second, as the room sends them
            if k % 50 == 0 {
                for (_, r) in b.reports() {
                    a.on_report(PeerId(2), r);
                }
            }
            if rnd() >= loss {
                wire.push((t + transit - 20.0 + rnd() * jitter, f));
            }
        }
        wire.sort_by(|p, q| p.0.total_cmp(&q.0));
        pending.extend(wire.drain(..));
        while pending.front().is_some_and(|(at, _)| *at <= t + 3.0) {
            let (at, f) = pending.pop_front().unwrap();
            b.hear(at, PeerId(1), f);
        }
        let block = b.play(t + 3.0, None, &heads);
        match block.speakers.iter().find(|(p, _)| *p == PeerId(1)) {
            Some((_, pcm)) => out.extend_from_slice(pcm),
            None => out.extend_from_slice(&[0; FRAME_SAMPLES]),
        }
    }
    (out, b.status(PeerId(1)).unwrap().stats)
}

fn pesq(dir: &Path, said: &[i16], played: &[i16], tag: &str) -> f64 {
    let a = align(said, played, 1.0).unwrap();
    let from = a.lag as usize;
    let cut = &played[from..(from + said.len()).min(played.len())];
    let (r, d) = (dir.join("ref.wav"), dir.join(format!("{tag}.wav")));
    write_wav(&r, 1, said).unwrap();
    write_wav(&d, 1, cut).unwrap();
    let out = std::process::Command::new(repo().join("scripts/pesq"))
        .arg(&r)
        .arg(&d)
        .output()
        .expect("scripts/pesq");
    assert!(
        out.status.success(),
        "scripts/pesq (its virtualenv comes from PyPI: run `scripts/pesq --install` outside a network namespace first): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().parse().unwrap()
}

/// The sentence through the codec alone, every 50th frame lost: PESQ with FEC, and with
/// concealment only.
fn codec_only(dir: &Path, said: &[i16]) -> (f64, f64) {
    use softsync_voice::codec::{Decoder, Encoder};
    let mut enc = Encoder::new(24_000, true, false).unwrap();
    enc.adapt(24_000, 0.1, None).unwrap();
    let pk: Vec<Vec<u8>> = said
        .chunks_exact(FRAME_SAMPLES)
        .map(|c| enc.encode(c.try_into().unwrap()).unwrap())
        .collect();
    let run = |fec: bool| {
        let mut dec = Decoder::new().unwrap();
        let mut out = Vec::new();
        for k in 0..pk.len() {
            let mut o = [0i16; FRAME_SAMPLES];
            if k % 50 != 25 {
                dec.decode(&pk[k], &mut o);
            } else if fec && k + 1 < pk.len() {
                dec.decode_fec(&pk[k + 1], &mut o);
            } else {
                dec.conceal(&mut o);
            }
            out.extend_from_slice(&o);
        }
        out
    };
    (
        pesq(dir, said, &run(true), "codec-fec"),
        pesq(dir, said, &run(false), "codec-plc"),
    )
}

#[test]
fn speech_through_the_codec_and_the_buffer_keeps_its_quality() {
    let dir = std::env::temp_dir().join(format!("softsync-voice-quality-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let said = sentence(&dir);
    let (clean, _) = through(&said, 0.0, 45.0, 0.0, 1);
    let p_clean = pesq(&dir, &said, &clean, "clean");
    let (lossy, st) = through(&said, 0.05, 45.0, 0.0, 7);
    let p_lossy = pesq(&dir, &said, &lossy, "lossy");
    let (rough, st_rough) = through(&said, 0.05, 45.0, 30.0, 7);
    let p_rough = pesq(&dir, &said, &rough, "rough");
    println!("PESQ-WB: no loss {p_clean:.2}; 5 % loss {p_lossy:.2} ({st:?}); 5 % loss and 30 ms of jitter {p_rough:.2} ({st_rough:?})");
    // Opus at 24 kb/s wide-band on this synthetic voice: 3.8 without loss (measured)
    assert!(p_clean >= 3.6, "PESQ-WB {p_clean} without loss");
    // at 5 % loss each frame also travels in the next datagram: lost frames come back whole
    // (3.73 measured)
    assert!(st.redundant > 0, "no frame came back from its copy: {st:?}");
    assert!(p_lossy >= 3.4, "PESQ-WB {p_lossy} at 5 % loss");
    // with 30 ms of jitter too, the buffer waits a frame once it sees late ones: the spurt
    // it happens in is shifted by 20 ms, which PESQ weighs heavily on a 4 s sentence (2.8
    // measured)
    assert!(
        p_rough >= 2.5,
        "PESQ-WB {p_rough} at 5 % loss and 30 ms of jitter"
    );
    // the codec alone: a frame in 50 lost, rebuilt from the next frame's FEC or concealed
    let (p_fec, p_plc) = codec_only(&dir, &said);
    println!("PESQ-WB, codec alone, 2 % loss: FEC {p_fec:.2}, concealment {p_plc:.2}");
    assert!(
        p_fec > p_plc + 0.3,
        "FEC {p_fec} is no better than concealment {p_plc}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
