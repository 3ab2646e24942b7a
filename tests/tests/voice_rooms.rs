//! Voice in a live room of `softsync` processes on real WebRTC: a bot says a sentence
//! (espeak-ng, `--voice-in`), two listeners record what they play (`--voice-out`); both
//! recordings hold the sentence at its expected delay, and when the host is SIGKILLed while
//! it is being said (the voice goes from speaker to listeners directly, not through the
//! host), no stretch of it longer than 200 ms is lost.
// real processes on the wall clock: waits and sleeps
#![allow(clippy::unwrap_used, clippy::disallowed_methods)]

mod common;

use std::time::Duration;

use common::*;
use softsync_voice::analysis::{heard_in, longest_dropout_ms};
use softsync_voice::files::{read_wav, speak};

const SENTENCE: &str = "The surgeon lifts the liver and cuts along the marked line.";

#[test]
fn two_listeners_hear_a_bot_at_its_delay_and_a_host_kill_costs_no_audio() {
    require_netns();
    let dir = scratch("voice");
    let said_path = dir.join("said.wav");
    let said =
        speak(SENTENCE, 160, &said_path).unwrap_or_else(|e| panic!("{e} (.ci/run installs it)"));
    let len_s = said.len() as f64 / 48_000.0;
    assert!((2.0..6.0).contains(&len_s), "{len_s}");

    let (_signal, url) = standalone_signal(&dir);
    let mut host = peer_on(
        &dir,
        "host",
        "host",
        &url,
        "voice",
        &["--voice", "--duration", "60"],
    );
    host.wait_line("hosting", Duration::from_secs(40));
    let said_s = said_path.to_string_lossy().to_string();
    let speaker = peer_on(
        &dir,
        "speaker",
        "join",
        &url,
        "voice",
        &[
            "--voice-in",
            &said_s,
            "--voice-after",
            "3",
            "--voice-every",
            "6",
            "--duration",
            "24",
        ],
    );
    let spk = speaker.peer_id();
    speaker.wait_line("joined", Duration::from_secs(40));
    let mut listeners = Vec::new();
    for k in ["l1", "l2"] {
        let out = dir.join(k).to_string_lossy().to_string();
        let l = peer_on(
            &dir,
            k,
            "join",
            &url,
            "voice",
            &["--voice-out", &out, "--duration", "18"],
        );
        listeners.push(l);
    }
    for l in &listeners {
        l.wait_line("joined", Duration::from_secs(40));
    }
    // the second saying: kill the host a second into it
    let wait_said = |speaker: &Proc, n: usize| {
        let start = std::time::Instant::now();
        loop {
            let lines: Vec<f64> = speaker
                .stdout()
                .lines()
                .filter(|l| l.contains("voice_said"))
                .map(|l| field(l, "room_ms").parse().unwrap())
                .collect();
            if lines.len() >= n {
                return lines;
            }
            assert!(
                start.elapsed() < Duration::from_secs(40),
                "the speaker said {} of {n}\n{}",
                lines.len(),
                speaker.logs()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    wait_said(&speaker, 2);
    std::thread::sleep(Duration::from_millis(1000));
    host.kill();
    // a late joiner, through the new host: it hears the room within a second of being in it
    let l3_dir = dir.join("l3").to_string_lossy().to_string();
    let mut late = peer_on(
        &dir,
        "l3",
        "join",
        &url,
        "voice",
        &["--voice-out", &l3_dir, "--duration", "10"],
    );
    let mut speaker = speaker;
    speaker.wait_exit(Duration::from_secs(60));
    for l in &mut listeners {
        l.wait_exit(Duration::from_secs(60));
    }
    late.wait_exit(Duration::from_secs(60));
    let said_at = wait_said(&speaker, 2);
    let logs = || {
        format!(
            "{}\n{}\n{}",
            speaker.logs(),
            listeners[0].logs(),
            listeners[1].logs()
        )
    };
    for (k, name) in ["l1", "l2"].iter().enumerate() {
        let ldir = dir.join(name);
        let rec = read_wav(&ldir.join(format!("peer-{spk}.wav")))
            .unwrap_or_else(|e| panic!("{e}\n{}", logs()));
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(ldir.join("voice.json")).unwrap())
                .unwrap();
        let start = meta["start_room_ms"].as_f64().unwrap();
        for (i, at) in said_at.iter().take(2).enumerate() {
            let h = heard_in(&said, *at, &ldir, spk, 1000.0)
                .unwrap_or_else(|e| panic!("{e}\n{}", logs()));
            println!(
                "{name} saying {i}: mouth to ear {:.1} ms, sample correlation {:.3}",
                h.mouth_to_ear_ms, h.alignment.sample_corr
            );
            assert!(
                h.alignment.sample_corr > 0.6,
                "{name} saying {i}: the recording is not the sentence ({h:?})\n{}",
                logs()
            );
            // loopback: the frame's 20 ms, the jitter buffer's one frame and the block's
            // alignment, a little more under load
            assert!(
                (30.0..400.0).contains(&h.mouth_to_ear_ms),
                "{name} saying {i}: mouth to ear {:.1} ms\n{}",
                h.mouth_to_ear_ms,
                logs()
            );
            let from = ((at + h.mouth_to_ear_ms - start) * 48.0) as usize;
            let cut = &rec[from..(from + said.len()).min(rec.len())];
            let gap = longest_dropout_ms(&said, cut);
            println!("{name} saying {i}: longest dropout {gap:.0} ms");
            assert!(
                gap <= 200.0,
                "{name} saying {i} (the host killed during saying 1): {gap} ms of speech lost\n{}",
                logs()
            );
            let _ = k;
        }
        // the listener dropped nothing it should have played
        let out = listeners[k].stdout();
        let stats = out
            .lines()
            .rev()
            .find(|l| l.contains("voice_stats"))
            .unwrap_or_else(|| panic!("{name}: no voice stats\n{}", logs()));
        assert_eq!(field(stats, "dropped"), "0", "{stats}");
    }

    // the late joiner: from when it started playing (just after its welcome and the room
    // clock) to the first speech it played, less any silence the speaker was in then
    let ldir = dir.join("l3");
    let said_at = wait_said(&speaker, 3);
    let meta: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(ldir.join("voice.json"))
            .unwrap_or_else(|e| panic!("l3: {e}\n{}", late.logs())),
    )
    .unwrap();
    let start = meta["start_room_ms"].as_f64().unwrap();
    let rec = read_wav(&ldir.join(format!("peer-{spk}.wav")))
        .unwrap_or_else(|e| panic!("l3: {e}\n{}", late.logs()));
    let speech = |x: &[i16]| softsync_voice::level::level_db(x) > -40.0;
    let heard = rec
        .chunks_exact(960)
        .position(speech)
        .map(|k| start + k as f64 * 20.0)
        .unwrap_or_else(|| panic!("l3 heard no speech\n{}", late.logs()));
    // when the speaker next said something from `start` on (in a saying, or the next one)
    let len_ms = said.len() as f64 / 48.0;
    let expected = said_at
        .iter()
        .find_map(|at| {
            let from = ((start - at).max(0.0) * 48.0) as usize;
            if from >= said.len() {
                return None;
            }
            let k = said[from..].chunks_exact(960).position(speech)?;
            Some(at.max(start) + k as f64 * 20.0)
        })
        .unwrap_or(start);
    println!(
        "l3: playing from room time {start:.0} ms; speech from {expected:.0} ms; heard at {heard:.0} ms ({:.0} ms later; sayings of {len_ms:.0} ms at {said_at:?})",
        heard - expected
    );
    assert!(
        heard - expected <= 1000.0,
        "the late joiner heard the room {:.0} ms after it could have\n{}",
        heard - expected,
        late.logs()
    );
}
