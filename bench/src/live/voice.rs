//! `softsync-bench voice`: voice in live rooms of `softsync` processes on real WebRTC.
//!
//! **voice.live**, per link condition (one-way latency × loss on the speaker's sends, the
//! project's seeded link conditioner, `--net-condition`): a host, a speaking bot and two
//! listening bots. The speaker says a sentence rendered by espeak-ng (`--voice-in`, every
//! [`EVERY_S`] s) and nods with its voice (`--voice-nod`: its head rises with the level); the
//! listeners write what they play (`--voice-out`). For each saying and listener:
//! - **mouth to ear**: when the listener played the sentence's first sample, less when the
//!   speaker captured it, both on the room clock (the speaker logs `voice_said room_ms=…`,
//!   the listener's `voice.json` the room time of its first block; the sentence is found in
//!   the recording by cross-correlation, `softsync_voice::analysis`);
//! - **quality**: wide-band PESQ (`scripts/pesq`, ITU-T P.862.2) of the recording, cut at the
//!   found delay, against the sentence;
//! - **lip-sync skew**: the listener's `heads.csv` is where it showed the speaker's head at
//!   each block it played; the head's height follows the speaker's level, so the lag between
//!   that curve and the level of what was played is how much later the voice is heard than
//!   the lips are seen (positive: the voice lags).
//!
//! **voice.room**: a room of 8 (a host and 7 bots), two of them talking, once with every frame
//! sent to every member (mesh) and once relayed by the host: each peer's voice uplink.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use softsync_benchkit::plotters::style::RGBColor;
use softsync_benchkit::{
    median, percentile, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series,
};
use softsync_voice::analysis::{align, heard_in};
use softsync_voice::files::{read_wav, speak, write_wav};
use softsync_voice::level::{level_db, FLOOR_DB};
use softsync_voice::{FRAME_SAMPLES, SAMPLE_RATE};

use super::{field, Proc};

/// The sentence (about 4.7 s).
const SENTENCE: &str =
    "The surgeon lifts the liver and cuts along the marked line, then holds it still.";
/// Seconds between the starts of two sayings.
const EVERY_S: f64 = 6.0;

/// One condition's figures.
#[derive(Clone, Debug)]
struct Live {
    lat_ms: u32,
    loss_pct: u32,
    m2e: Vec<f64>,
    pesq: Vec<f64>,
    corr: Vec<f64>,
    skew: Vec<f64>,
    bitrate_kbps: f64,
}

/// espeak-ng's sentence as a 48 kHz WAV under `dir`.
fn sentence(dir: &Path) -> Result<(PathBuf, Vec<i16>), String> {
    let path = dir.join("sentence.wav");
    let said = speak(SENTENCE, 150, &path).map_err(|e| e.to_string())?;
    Ok((path, said))
}

/// Wide-band PESQ of `deg` against `reference` (`scripts/pesq`); None if it cannot run.
fn pesq(reference: &Path, deg: &Path) -> Option<f64> {
    let script = std::env::var_os("SOFTSYNC_PESQ")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("scripts/pesq"));
    let out = std::process::Command::new(script)
        .arg(reference)
        .arg(deg)
        .output()
        .ok()?;
    String::from_utf8_lossy(&out.stdout).trim().parse().ok()
}

/// The level of each 20 ms block as the nod maps it (0..1).
fn lift(db: f32) -> f64 {
    f64::from(((db - FLOOR_DB) / -FLOOR_DB).clamp(0.0, 1.0))
}

/// Lip-sync skew from a listener's folder: lag (ms) of the played level of `speaker` behind
/// its shown head height, over the blocks from `from_ms` to `to_ms` (room time).
fn skew(dir: &Path, speaker: u64, from_ms: f64, to_ms: f64) -> Option<f64> {
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("voice.json")).ok()?).ok()?;
    let start = meta["start_room_ms"].as_f64()?;
    let rec = read_wav(&dir.join(format!("peer-{speaker}.wav"))).ok()?;
    let heads = std::fs::read_to_string(dir.join("heads.csv")).ok()?;
    let mut head: Vec<(f64, f64)> = heads
        .lines()
        .skip(1)
        .filter_map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            (c.get(1)?.parse::<u64>().ok()? == speaker)
                .then(|| Some((c[0].parse().ok()?, c[3].parse().ok()?)))?
        })
        .filter(|(t, _)| *t >= from_ms && *t <= to_ms)
        .collect();
    head.dedup_by(|a, b| (a.0 - b.0).abs() < 1.0);
    let base = head.iter().map(|h| h.1).fold(f64::INFINITY, f64::min);
    // both curves on the blocks' timeline
    let (mut h, mut v) = (Vec::new(), Vec::new());
    for (t, y) in &head {
        let k = ((t - start) / 20.0).round();
        if k < 0.0 {
            continue;
        }
        let i = k as usize * FRAME_SAMPLES;
        let Some(block) = rec.get(i..i + FRAME_SAMPLES) else {
            continue;
        };
        h.push(y - base);
        v.push(lift(level_db(block)) * 0.05);
    }
    if h.len() < 100 {
        return None;
    }
    let ncc = |lag: i64| -> f64 {
        let pairs: Vec<(f64, f64)> = (0..h.len() as i64)
            .filter_map(|i| Some((h[i as usize], *v.get(usize::try_from(i + lag).ok()?)?)))
            .collect();
        let n = pairs.len() as f64;
        let (ma, mb) = (
            pairs.iter().map(|p| p.0).sum::<f64>() / n,
            pairs.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
        for (a, b) in &pairs {
            ab += (a - ma) * (b - mb);
            aa += (a - ma).powi(2);
            bb += (b - mb).powi(2);
        }
        ab / (aa * bb).sqrt().max(1e-12)
    };
    let lags: Vec<(i64, f64)> = (-15..=15).map(|l| (l, ncc(l))).collect();
    let (best, c) = lags.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1))?;
    if c < 0.3 {
        return None;
    }
    // parabolic refinement between the neighbouring lags
    let at = |l: i64| lags.iter().find(|x| x.0 == l).map(|x| x.1);
    let frac = match (at(best - 1), at(best + 1)) {
        (Some(a), Some(b)) if (a - 2.0 * c + b).abs() > 1e-12 => 0.5 * (a - b) / (a - 2.0 * c + b),
        _ => 0.0,
    };
    Some((best as f64 + frac) * 20.0)
}

/// The last `voice_stats` line of a process's output: its fields.
fn last_stats(out: &str) -> Option<(f64, String)> {
    out.lines()
        .rev()
        .find(|l| l.contains("voice_stats"))
        .map(|l| {
            let t = field(l, "t").and_then(|t| t.parse().ok()).unwrap_or(0.0);
            (t, l.to_owned())
        })
}

/// The first `voice_stats` line.
fn first_stats(out: &str) -> Option<(f64, String)> {
    out.lines().find(|l| l.contains("voice_stats")).map(|l| {
        let t = field(l, "t").and_then(|t| t.parse().ok()).unwrap_or(0.0);
        (t, l.to_owned())
    })
}

/// Voice bytes a second a process sent between its first and last stats lines.
fn up_rate(out: &str) -> Option<f64> {
    let (t0, a) = first_stats(out)?;
    let (t1, b) = last_stats(out)?;
    let bytes = |l: &str| field(l, "sent_bytes").and_then(|v| v.parse::<f64>().ok());
    if t1 <= t0 {
        return None;
    }
    Some((bytes(&b)? - bytes(&a)?) / (t1 - t0))
}

/// One condition's room.
fn live_room(
    dir: &Path,
    sentence: &(PathBuf, Vec<i16>),
    lat_ms: u32,
    loss_pct: u32,
    sayings: u32,
) -> Result<Live, String> {
    let tag = format!("l{lat_ms}-p{loss_pct}");
    let dir = dir.join(&tag);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let (_signal, url) = Proc::signal(&dir, "signal")?;
    let room = "voice";
    let total = 3.0 + EVERY_S * f64::from(sayings) + 2.0;
    let dur = format!("{total:.0}");
    let mut host = Proc::peer(
        &dir,
        "host",
        "host",
        room,
        &url,
        &["--voice", "--duration", &dur],
    )?;
    host.line("hosting", Duration::from_secs(20))?;
    let cond = format!("lat={lat_ms}ms,loss={loss_pct}%,seed=7");
    let said = sentence.0.to_string_lossy().to_string();
    let every = format!("{EVERY_S}");
    let speaker = Proc::peer(
        &dir,
        "speaker",
        "join",
        room,
        &url,
        &[
            "--voice-in",
            &said,
            "--voice-after",
            "2.5",
            "--voice-every",
            &every,
            "--voice-nod",
            "--net-condition",
            &cond,
            "--duration",
            &dur,
        ],
    )?;
    let spk =
        field(&speaker.line("joining", Duration::from_secs(20))?, "peer").ok_or("no speaker id")?;
    let mut listeners = Vec::new();
    for k in ["l1", "l2"] {
        let out = dir.join(k).to_string_lossy().to_string();
        listeners.push(Proc::peer(
            &dir,
            k,
            "join",
            room,
            &url,
            &["--voice-out", &out, "--duration", &dur],
        )?);
    }
    let mut speaker = speaker;
    speaker.wait(Duration::from_secs_f64(total + 30.0))?;
    for l in &mut listeners {
        l.wait(Duration::from_secs(30))?;
    }
    let _ = host.wait(Duration::from_secs(30));
    let spk_out = std::fs::read_to_string(dir.join("speaker.out")).map_err(|e| e.to_string())?;
    let said_at: Vec<f64> = spk_out
        .lines()
        .filter(|l| l.contains("voice_said"))
        .filter_map(|l| field(l, "room_ms")?.parse().ok())
        .collect();
    let spk_id: u64 = spk.parse().map_err(|_| "speaker id")?;
    let mut live = Live {
        lat_ms,
        loss_pct,
        m2e: Vec::new(),
        pesq: Vec::new(),
        corr: Vec::new(),
        skew: Vec::new(),
        bitrate_kbps: 0.0,
    };
    let len_ms = sentence.1.len() as f64 * 1000.0 / f64::from(SAMPLE_RATE);
    for k in ["l1", "l2"] {
        let ldir = dir.join(k);
        for (i, at) in said_at.iter().enumerate() {
            let Ok(h) = heard_in(&sentence.1, *at, &ldir, spk_id, 1000.0) else {
                continue;
            };
            // a saying cut by the end of the run is not scored
            let rec =
                read_wav(&ldir.join(format!("peer-{spk_id}.wav"))).map_err(|e| e.to_string())?;
            let meta: serde_json::Value = serde_json::from_str(
                &std::fs::read_to_string(ldir.join("voice.json")).map_err(|e| e.to_string())?,
            )
            .map_err(|e| e.to_string())?;
            let start = meta["start_room_ms"].as_f64().unwrap_or(0.0);
            let from = ((at + h.mouth_to_ear_ms - start) * 48.0) as usize;
            let Some(cut) = rec.get(from..from + sentence.1.len()) else {
                continue;
            };
            live.m2e.push(h.mouth_to_ear_ms);
            live.corr.push(h.alignment.sample_corr);
            let deg = dir.join(format!("{k}-{i}.wav"));
            write_wav(&deg, 1, cut).map_err(|e| e.to_string())?;
            if let Some(p) = pesq(&sentence.0, &deg) {
                live.pesq.push(p);
            }
            if let Some(s) = skew(&ldir, spk_id, *at, at + len_ms + 300.0) {
                live.skew.push(s);
            }
        }
    }
    // the speaker's payload rate per copy while it speaks: bytes over frames sent (3 copies:
    // the host and two listeners in a mesh)
    if let Some((_, l)) = last_stats(&spk_out) {
        let bytes: f64 = field(&l, "sent_bytes")
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.0);
        let frames: f64 = field(&l, "frames")
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.0);
        if frames > 0.0 {
            live.bitrate_kbps = bytes / 3.0 / (frames * 0.02) * 8.0 / 1000.0;
        }
    }
    if live.m2e.is_empty() {
        return Err(format!(
            "{tag}: no saying was found in the listeners' recordings ({})",
            dir.display()
        ));
    }
    Ok(live)
}

/// A room of 8, two talking, along `route`: (host kbps, each speaker's kbps, each listener's).
fn crowd(
    dir: &Path,
    sentence: &Path,
    route: &str,
    seconds: f64,
) -> Result<(f64, f64, f64), String> {
    let dir = dir.join(format!("room-{route}"));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let (_signal, url) = Proc::signal(&dir, "signal")?;
    let dur = format!("{:.0}", seconds + 6.0);
    let said = sentence.to_string_lossy().to_string();
    let mut host = Proc::peer(
        &dir,
        "host",
        "host",
        "crowd",
        &url,
        &["--voice", "--voice-route", route, "--duration", &dur],
    )?;
    host.line("hosting", Duration::from_secs(20))?;
    let mut peers = Vec::new();
    for k in 0..7 {
        let name = format!("p{k}");
        let mut args = vec!["--voice-route", route, "--duration", &dur];
        if k < 2 {
            args.extend([
                "--voice-in",
                &said,
                "--voice-after",
                "1",
                "--voice-every",
                "5",
            ]);
        } else {
            args.push("--voice");
        }
        let p = Proc::peer(&dir, &name, "join", "crowd", &url, &args)?;
        p.line("joined", Duration::from_secs(30))?;
        peers.push(p);
    }
    for p in &mut peers {
        p.wait(Duration::from_secs_f64(seconds + 40.0))?;
    }
    let _ = host.wait(Duration::from_secs(30));
    let rate = |name: &str| -> Result<f64, String> {
        let out =
            std::fs::read_to_string(dir.join(format!("{name}.out"))).map_err(|e| e.to_string())?;
        up_rate(&out).ok_or_else(|| format!("{route}: {name} printed no voice stats"))
    };
    let host_up = rate("host")? * 8.0 / 1000.0;
    let each = (rate("p0")? + rate("p1")?) / 2.0 * 8.0 / 1000.0;
    let listeners: Vec<f64> = (2..7).filter_map(|k| rate(&format!("p{k}")).ok()).collect();
    let listen = median(&listeners) * 8.0 / 1000.0;
    Ok((host_up, each, listen))
}

/// `voice.svg`: mouth to ear (p50) and lip-sync skew against the one-way latency, a line per
/// loss, with the targets' lines.
fn chart(out: &Path, lives: &[Live]) -> Result<(), String> {
    let colours = [
        RGBColor(30, 110, 200),
        RGBColor(230, 130, 20),
        RGBColor(200, 40, 40),
    ];
    let mut m2e = Vec::new();
    let mut skew = Vec::new();
    for (k, loss) in [0u32, 5, 20].iter().enumerate() {
        let pts = |f: &dyn Fn(&Live) -> f64| -> Vec<(f64, f64)> {
            lives
                .iter()
                .filter(|l| l.loss_pct == *loss)
                .map(|l| (f64::from(l.lat_ms), f(l)))
                .collect()
        };
        let a = pts(&|l| median(&l.m2e));
        if a.is_empty() {
            continue;
        }
        m2e.push(Series::new(format!("{loss} % loss"), colours[k], a));
        skew.push(Series::new(
            format!("{loss} % loss"),
            colours[k],
            pts(&|l| {
                if l.skew.is_empty() {
                    f64::NAN
                } else {
                    median(&l.skew)
                }
            }),
        ));
    }
    let target = |pts: Vec<(f64, f64)>| Series::new("target", RGBColor(120, 120, 120), pts);
    m2e.push(target(vec![(0.0, 60.0), (150.0, 210.0)]));
    let mut skew_band = skew;
    skew_band.push(target(vec![(0.0, -40.0), (150.0, -40.0)]));
    skew_band.push(Series::new(
        "",
        RGBColor(120, 120, 120),
        vec![(0.0, 40.0), (150.0, 40.0)],
    ));
    let charts = [
        LineChart {
            title: "mouth to ear, p50 (target: latency + 60 ms)".into(),
            x_desc: "one-way latency, ms".into(),
            y_desc: "ms".into(),
            x_range: 0.0..160.0,
            x_log: false,
            y_range: 0.0..260.0,
            series: m2e,
            style: ChartStyle::PANEL,
        },
        LineChart {
            title: "lip-sync skew (voice after lips; target ±40 ms)".into(),
            x_desc: "one-way latency, ms".into(),
            y_desc: "ms".into(),
            x_range: 0.0..160.0,
            x_log: false,
            y_range: -80.0..80.0,
            series: skew_band,
            style: ChartStyle::PANEL,
        },
    ];
    write_svg(out.join("voice.svg"), (1000, 380), &charts).map_err(|e| e.to_string())
}

/// The microphone's chain on speech, five times (the cost varies with the machine; the
/// signal figures do not): `RESULT voice.processing` with medians, `processing.txt` and
/// `processing.csv` under `out`.
pub fn voice_processing(out: &Path) -> Result<(), String> {
    use softsync_voice::processing::measure;
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let dir = std::env::temp_dir().join(format!("softsync-vproc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let say = |text: &str, wpm: u32, name: &str| -> Result<Vec<f64>, String> {
        let s =
            softsync_voice::files::speak(text, wpm, &dir.join(name)).map_err(|e| e.to_string())?;
        Ok(s.iter().map(|v| f64::from(*v) / 32768.0).collect())
    };
    let far = say(
        "The instrument count is correct and the patient is stable.",
        160,
        "far.wav",
    )?;
    let near = say(
        "Retract the left lobe a little further, please.",
        150,
        "near.wav",
    )?;
    let t0 = std::time::Instant::now();
    let mut clock = || t0.elapsed().as_secs_f64() * 1e6;
    let mut csv = Csv::new(&[
        "run",
        "erle_db",
        "erle_chain_db",
        "double_talk_db",
        "noise_db",
        "speech_loss_db",
        "agc_gain_db",
        "cost_us",
    ]);
    let mut runs = Vec::new();
    for run in 0..5 {
        let m = measure(&far, &near, &mut clock);
        csv.row([
            run.to_string(),
            format!("{:.2}", m.erle_db),
            format!("{:.2}", m.erle_chain_db),
            format!("{:.2}", m.double_talk_db),
            format!("{:.2}", m.noise_db),
            format!("{:.2}", m.speech_loss_db),
            format!("{:.2}", m.agc_gain_db),
            format!("{:.1}", m.cost_us),
        ]);
        runs.push(m);
    }
    let med = |f: &dyn Fn(&softsync_voice::processing::ProcessingMeasure) -> f64| {
        let mut v: Vec<f64> = runs.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let line = ResultLine::new("voice.processing")
        .fixed("erle_db", med(&|m| m.erle_db), 1)
        .fixed("erle_chain_db", med(&|m| m.erle_chain_db), 1)
        .fixed("double_talk_db", med(&|m| m.double_talk_db), 1)
        .fixed("noise_db", med(&|m| m.noise_db), 1)
        .fixed("speech_loss_db", med(&|m| m.speech_loss_db), 1)
        .fixed("agc_gain_db", med(&|m| m.agc_gain_db), 1)
        .fixed("cost_us_per_frame", med(&|m| m.cost_us), 0);
    println!("{line}");
    std::fs::write(out.join("processing.csv"), csv.text()).map_err(|e| e.to_string())?;
    std::fs::write(out.join("processing.txt"), format!("{line}\n")).map_err(|e| e.to_string())?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// Runs the rooms and writes `docs/results/voice/`.
pub fn voice(out: &Path, quick: bool) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let dir = std::env::temp_dir().join(format!("softsync-voice-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let s = sentence(&dir)?;
    let conditions: Vec<(u32, u32)> = if quick {
        vec![(50, 5)]
    } else {
        [0, 50, 150]
            .iter()
            .flat_map(|l| [0, 5, 20].map(|p| (*l, p)))
            .collect()
    };
    let sayings = if quick { 2 } else { 3 };
    let mut lines = Vec::new();
    let mut lives: Vec<Live> = Vec::new();
    let mut csv = Csv::new(&[
        "lat_ms",
        "loss_pct",
        "mouth_to_ear_ms",
        "pesq_wb",
        "sample_corr",
        "lipsync_skew_ms",
    ]);
    for (lat, loss) in conditions {
        let l = live_room(&dir, &s, lat, loss, sayings)?;
        for (i, m) in l.m2e.iter().enumerate() {
            csv.row([
                lat.to_string(),
                loss.to_string(),
                format!("{m:.1}"),
                l.pesq.get(i).map_or("".into(), |p| format!("{p:.3}")),
                format!("{:.3}", l.corr[i]),
                l.skew.get(i).map_or("".into(), |s| format!("{s:.1}")),
            ]);
        }
        let line = ResultLine::new("voice.live")
            .field("lat_ms", l.lat_ms)
            .field("loss_pct", l.loss_pct)
            .fixed("mouth_to_ear_p50_ms", median(&l.m2e), 1)
            .fixed("mouth_to_ear_p95_ms", percentile(&l.m2e, 0.95), 1)
            .fixed(
                "pesq_wb",
                if l.pesq.is_empty() {
                    f64::NAN
                } else {
                    median(&l.pesq)
                },
                2,
            )
            .fixed("bitrate_kbps", l.bitrate_kbps, 1)
            .fixed(
                "lipsync_skew_ms",
                if l.skew.is_empty() {
                    f64::NAN
                } else {
                    median(&l.skew)
                },
                1,
            )
            .field("sayings", l.m2e.len());
        println!("{line}");
        lines.push(line.to_string());
        lives.push(l);
    }
    chart(out, &lives)?;
    let seconds = if quick { 10.0 } else { 20.0 };
    for route in ["mesh", "relay"] {
        let (host, each, listen) = crowd(&dir, &s.0, route, seconds)?;
        let line = ResultLine::new("voice.room")
            .field("peers", 8)
            .field("speakers", 2)
            .field("route", route)
            .fixed("host_up_kbps", host, 1)
            .fixed("each_up_kbps", each, 1)
            .fixed("listener_up_kbps", listen, 1);
        println!("{line}");
        lines.push(line.to_string());
    }
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Voice in live rooms\n\n`scripts/netns-run target/debug/softsync-bench voice{}` \
         (a debug build; real `softsync` processes on WebRTC on one machine; see \
         `bench/src/live/voice.rs`; every saying in `voice.csv`, the chart in `voice.svg`). \
         The sentence is espeak-ng's; latency and loss are the speaker's seeded link \
         conditioner (one way). Mouth to ear on the room clock; PESQ wide-band \
         (`scripts/pesq`); the skew is the lag of the voice behind the speaker's head as the \
         listener shows it (positive: the voice lags).\n\n```\n{}\n```\n\n\
         The microphone's processing (echo cancellation, noise suppression, gain control) is \
         measured offline by `softsync-bench voice-processing`: `processing.txt`, \
         `processing.csv`.",
        if quick { " --quick" } else { "" },
        lines.join("\n")
    );
    std::fs::write(out.join("voice.csv"), csv.text()).map_err(|e| e.to_string())?;
    std::fs::write(out.join("README.md"), md).map_err(|e| e.to_string())?;
    std::fs::write(out.join("results.txt"), lines.join("\n") + "\n").map_err(|e| e.to_string())?;
    let _ = std::fs::remove_dir_all(&dir);
    let _ = align;
    Ok(())
}
