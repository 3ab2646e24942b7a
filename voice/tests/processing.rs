//! The microphone's processing (libspeexdsp through `softsync-speexdsp`), measured on speech:
//! the echo of what the loudspeaker played is removed, noise in the pauses is lowered, quiet
//! speech is raised, and the near talker survives double talk.
#![allow(clippy::unwrap_used, clippy::disallowed_methods)]

use softsync_voice::files::speak;
use softsync_voice::processing::measure;

#[test]
fn echo_noise_and_gain_are_each_what_they_say() {
    let dir = std::env::temp_dir().join(format!("softsync-processing-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let far = speak(
        "The instrument count is correct and the patient is stable.",
        160,
        &dir.join("far.wav"),
    )
    .unwrap_or_else(|e| panic!("{e} (.ci/run installs espeak-ng)"));
    let near = speak(
        "Retract the left lobe a little further, please.",
        150,
        &dir.join("near.wav"),
    )
    .unwrap();
    let f = |x: &[i16]| -> Vec<f64> { x.iter().map(|s| f64::from(*s) / 32768.0).collect() };
    let t0 = std::time::Instant::now();
    let mut clock = || t0.elapsed().as_secs_f64() * 1e6;
    let m = measure(&f(&far), &f(&near), &mut clock);
    println!("{m:?}");
    // speex's MDF canceller alone takes ~17 dB off an 80 ms + 60 ms path (4-7 s in, the
    // delay finder having placed its reference); its residual echo suppressor takes the
    // whole chain to ~31 dB
    assert!(m.erle_db >= 10.0, "echo cancelled by {:.1} dB", m.erle_db);
    assert!(m.erle_chain_db >= 20.0, "{m:?}");
    // while both talk, the canceller still removes ~6 dB of echo from the near talker
    assert!(
        m.double_talk_db >= 4.0,
        "double talk: {:.1} dB",
        m.double_talk_db
    );
    assert!(m.noise_db >= 8.0, "noise lowered by {:.1} dB", m.noise_db);
    assert!(
        m.speech_loss_db <= 4.0,
        "speech lost {:.1} dB",
        m.speech_loss_db
    );
    assert!(
        m.agc_gain_db >= 10.0,
        "quiet speech raised {:.1} dB",
        m.agc_gain_db
    );
    let _ = std::fs::remove_dir_all(&dir);
}
