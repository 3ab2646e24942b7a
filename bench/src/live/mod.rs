//! The live benches: rooms of real `softsync` processes on real WebRTC, each a subcommand of
//! `softsync-bench` (they were `softsync bench …` before they left the product binary).
//!
//! `softsync-bench net-live`: the thesis's Tables 9-11 on real WebRTC between real processes.
//!
//! For each send rate × ignore threshold, a host opens the `bench-ball` room and a bot joins:
//! - avatar: the bot sways its head and both hands, with pauses (it owns its avatar);
//! - softbody60: the bot (no avatar) takes the host's 60-particle ball by one particle through
//!   the authority request and drags it around, deforming it, without pause.
//!
//! Bytes/s: every byte of the bot's datagrams (header, messages, heartbeats, acks; without
//! IP/UDP/DTLS/SCTP) over the measured window, from the cumulative counter in its dump. Remote
//! error: for each line of the host's dump (30 Hz) and each object the bot owns, the distance
//! between what the host shows and the bot's own state at the time the shown state stands for
//! (the bot's dump at 60 Hz, interpolated), for the center and every particle.
//!
//! Also: connect time (signaling to first data channel) and migration time (host SIGKILLed,
//! earliest joiner announces itself). Must run where WebRTC may run: on the shared machines
//! inside `scripts/netns-run` (`scripts/bench-net-live` does it).
//!
//! `softsync-bench room-load` (rooms of growing size) is in `load.rs`; both spawn peers with
//! this module's `Proc`.

#![allow(clippy::disallowed_methods)] // real processes on the wall clock: clocks, sleeps

mod abuse;
mod auto;
mod clock;
mod comanip;
mod lb;
mod load;
mod soak;
mod soak_check;
mod views;
mod voice;

pub use abuse::{abuse, ATTACKS};
pub use auto::auto;
pub use clock::room_clock;
pub use comanip::comanip;
pub use lb::{signal_lb, LbPlan};
pub use load::room_load;
pub use soak::{soak, SoakPlan};
pub use voice::{voice, voice_processing};

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use softsync_benchkit::plotters::style::{Palette, Palette99, RGBColor};
use softsync_benchkit::{
    median, thesis, write_svg, ChartStyle, Csv, LineChart, Progress, ResultLine, Series, Summary,
};

use softsync_peer::dump::{read_dump, DumpLine};
use views::{near_cut, points, truth_at, Track};

/// The `softsync` binary the live benches run: `SOFTSYNC_BIN` if set, else the one beside
/// this `softsync-bench` (cargo builds both into one target directory).
pub fn softsync_binary() -> Result<PathBuf, String> {
    let bin = match std::env::var_os("SOFTSYNC_BIN").filter(|v| !v.is_empty()) {
        Some(p) => PathBuf::from(p),
        None => std::env::current_exe()
            .map_err(|e| e.to_string())?
            .with_file_name("softsync"),
    };
    if bin.is_file() {
        Ok(bin)
    } else {
        Err(format!(
            "{}: no softsync binary (build it: cargo build -p softsync, with --release for \
             a release softsync-bench; or set SOFTSYNC_BIN)",
            bin.display()
        ))
    }
}

struct Proc {
    child: Child,
    out: PathBuf,
}

impl Proc {
    /// A `softsync` process ([`softsync_binary`]), its output in `dir/NAME.out` and `.err`.
    fn spawn(dir: &Path, name: &str, args: &[String]) -> Result<Proc, String> {
        let exe = softsync_binary()?;
        Self::spawn_program(dir, name, &exe, args)
    }

    /// Any program (the hostile client), its output in `dir/NAME.out` and `.err`.
    fn spawn_program(
        dir: &Path,
        name: &str,
        exe: &Path,
        args: &[impl AsRef<std::ffi::OsStr>],
    ) -> Result<Proc, String> {
        let out = dir.join(format!("{name}.out"));
        let file = std::fs::File::create(&out).map_err(|e| e.to_string())?;
        let err =
            std::fs::File::create(dir.join(format!("{name}.err"))).map_err(|e| e.to_string())?;
        let child = Command::new(exe)
            .args(args)
            .stdout(Stdio::from(file))
            .stderr(Stdio::from(err))
            .spawn()
            .map_err(|e| format!("cannot start {name}: {e}"))?;
        Ok(Proc { child, out })
    }

    fn line(&self, needle: &str, within: Duration) -> Result<String, String> {
        let start = Instant::now();
        loop {
            let text = std::fs::read_to_string(&self.out).unwrap_or_default();
            if let Some(l) = text.lines().find(|l| l.contains(needle)) {
                return Ok(l.to_owned());
            }
            if start.elapsed() > within {
                return Err(format!(
                    "{} printed no {needle:?} within {within:?}:\n{text}",
                    self.out.display()
                ));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The signaling URL the process printed (`signaling on ws://…`).
    fn signal_url(&self) -> Result<String, String> {
        Ok(self
            .line("signaling on ", Duration::from_secs(10))?
            .trim_start_matches("signaling on ")
            .trim()
            .to_owned())
    }

    /// A quiet peer (`role`: `host` or `join`) of `room` on signaling server `url`, with
    /// `extra` arguments.
    fn peer(
        dir: &Path,
        name: &str,
        role: &str,
        room: &str,
        url: &str,
        extra: &[&str],
    ) -> Result<Proc, String> {
        Self::peer_with(&softsync_binary()?, dir, name, role, room, url, extra)
    }

    /// [`Proc::peer`] of the `softsync` binary `exe`.
    fn peer_with(
        exe: &Path,
        dir: &Path,
        name: &str,
        role: &str,
        room: &str,
        url: &str,
        extra: &[&str],
    ) -> Result<Proc, String> {
        let args: Vec<String> = [role, "--room", room, "--signal", url, "--quiet"]
            .iter()
            .chain(extra)
            .map(|x| x.to_string())
            .collect();
        Self::spawn_program(dir, name, exe, &args)
    }

    /// A standalone signaling server on a free port, and its URL.
    fn signal(dir: &Path, name: &str) -> Result<(Proc, String), String> {
        let args = ["signal", "--bind", "127.0.0.1:0"].map(String::from);
        let p = Proc::spawn(dir, name, &args)?;
        let url = p.signal_url()?;
        Ok((p, url))
    }

    fn wait(&mut self, within: Duration) -> Result<(), String> {
        let start = Instant::now();
        loop {
            if let Ok(Some(s)) = self.child.try_wait() {
                return if s.success() {
                    Ok(())
                } else {
                    Err(format!("{} exited with {s}", self.out.display()))
                };
            }
            if start.elapsed() > within {
                return Err(format!(
                    "{} still running after {within:?}",
                    self.out.display()
                ));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A bot that reaches for the thesis room's object number `k` (of seven, in turn), grabs it
/// (an authority request that contends with the others'), squeezes, lets go and sways, again
/// and again: room-load's and the soak's bots.
fn grab_script(k: usize) -> String {
    const OBJECTS: [&str; 7] = [
        "bunny", "softbox", "softball", "block", "can", "ball", "plate",
    ];
    let obj = OBJECTS[k % OBJECTS.len()];
    format!(
        "wait 0.5; reach right {obj} in 0.8; grab right timeout 1.5; squeeze right 0.015 in 0.4; \
         release right; offset right 0 0.1 0 in 0.4; wave all 0.08 2 2; loop"
    )
}

fn field(line: &str, key: &str) -> Option<String> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{key}=")))
        .map(str::to_owned)
}

/// One measured configuration.
#[derive(Clone, Debug)]
struct Row {
    scenario: &'static str,
    rate_hz: f32,
    threshold_m: f32,
    bytes_per_s: f64,
    max_1s_bytes_per_s: f64,
    p50_mm: f64,
    p95_mm: f64,
    max_mm: f64,
    samples: usize,
}

/// Bytes/s over the window, the largest over any 1 s inside it, and the error samples (mm).
fn measure(
    host: &[DumpLine],
    bot: &[DumpLine],
    from_t: f64,
) -> Result<(f64, f64, Vec<f64>), String> {
    let me = bot.first().ok_or("empty bot dump")?.peer;
    let to_t = bot.last().map_or(0.0, |l| l.t) - 0.3;
    // The bot's own objects over time.
    let mut tracks: BTreeMap<u32, Track> = BTreeMap::new();
    for l in bot {
        for o in l.objects.iter().filter(|o| o.owner == me) {
            let track = tracks.entry(o.id).or_default();
            // Several dump lines can show the same step: keep the first.
            if track.last().is_none_or(|(t, _)| *t < l.state_t) {
                track.push((l.state_t, points(o)));
            }
        }
    }
    let mut errors = Vec::new();
    for l in host {
        for o in l.objects.iter().filter(|o| o.owner == me) {
            let Some(src) = o.src else { continue };
            if src < from_t || src > to_t {
                continue;
            }
            let Some(track) = tracks.get(&o.id) else {
                continue;
            };
            // a return home in between: the shown state may be from its other side
            if near_cut(track, src) {
                continue;
            }
            let Some(truth) = truth_at(track, src) else {
                continue;
            };
            let shown = points(o);
            if shown.len() != truth.len() {
                continue;
            }
            for (p, q) in shown.iter().zip(&truth) {
                let d =
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                errors.push(f64::from(d) * 1e3);
            }
        }
    }
    let at = |t: f64| {
        bot.iter()
            .min_by(|a, b| (a.t - t).abs().total_cmp(&(b.t - t).abs()))
    };
    let (a, b) = (at(from_t).ok_or("no dump")?, at(to_t).ok_or("no dump")?);
    let bytes_per_s = (b.up_bytes.saturating_sub(a.up_bytes)) as f64 / (b.t - a.t).max(0.1);
    let window: Vec<&DumpLine> = bot
        .iter()
        .filter(|l| l.t >= from_t && l.t <= to_t)
        .collect();
    let mut max_1s = 0.0f64;
    for (i, x) in window.iter().enumerate() {
        if let Some(y) = window[i..].iter().find(|y| y.t >= x.t + 1.0) {
            max_1s = max_1s.max(y.up_bytes.saturating_sub(x.up_bytes) as f64 / (y.t - x.t));
        }
    }
    Ok((bytes_per_s, max_1s, errors))
}

/// The bot takes the ball by one particle and drags it around in an ellipse (6 cm, 1.6 s):
/// the whole body moves and deforms, like the thesis's squeeze/pull interaction.
const SOFTBODY_SCRIPT: &str =
    "wait 0.5; reach right softball in 1; grab right; wave right 0.06 1.6 1000";

/// Head and hands sway at walking-around speeds (up to 0.25 m/s), with pauses.
const AVATAR_SCRIPT: &str = "wave all 0.1 2.5 3; wait 0.7; loop";

#[allow(clippy::too_many_arguments)]
fn run_one(
    dir: &Path,
    n: usize,
    scene: &str,
    scenario: &'static str,
    rate_hz: f32,
    threshold_m: f32,
    seconds: f64,
    connects: &mut Vec<f64>,
) -> Result<Row, String> {
    let room = format!("bench{n}");
    let warm = if scenario == "avatar" { 1.5 } else { 2.5 };
    let common = |dump: &Path, hz: &str| -> Vec<String> {
        [
            "--send-rate",
            &rate_hz.to_string(),
            "--threshold-mm",
            &(threshold_m * 1000.0).to_string(),
            "--dump",
            &dump.display().to_string(),
            "--dump-hz",
            hz,
            "--quiet",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let hd = dir.join(format!("{room}-host.jsonl"));
    let bd = dir.join(format!("{room}-bot.jsonl"));
    let mut args: Vec<String> = [
        "host",
        "--room",
        &room,
        "--bind",
        "127.0.0.1:0",
        "--scene",
        scene,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    args.extend(["--duration".into(), format!("{}", seconds + warm + 6.0)]);
    args.extend(common(&hd, "30"));
    let mut host = Proc::spawn(dir, &format!("{room}-host"), &args)?;
    let url = host.signal_url()?;
    let script = if scenario == "avatar" {
        AVATAR_SCRIPT
    } else {
        SOFTBODY_SCRIPT
    };
    let mut args: Vec<String> = ["join", "--room", &room, "--signal", &url, "--bot", script]
        .iter()
        .map(|s| s.to_string())
        .collect();
    args.extend(["--duration".into(), format!("{}", seconds + warm + 0.5)]);
    if scenario != "avatar" {
        args.push("--no-avatar".into());
    }
    args.extend(common(&bd, "60"));
    let mut bot = Proc::spawn(dir, &format!("{room}-bot"), &args)?;
    if let Some(ms) = bot
        .line("connected to peer", Duration::from_secs(20))
        .ok()
        .and_then(|l| {
            l.split_whitespace()
                .rev()
                .nth(1)
                .and_then(|v| v.parse::<f64>().ok())
        })
    {
        connects.push(ms);
    }
    bot.wait(Duration::from_secs_f64(seconds + warm + 40.0))?;
    drop(host.child.kill());
    let _ = host.child.wait();
    let (h, b) = (
        read_dump(&hd).map_err(|e| e.to_string())?,
        read_dump(&bd).map_err(|e| e.to_string())?,
    );
    let (bytes_per_s, max_1s_bytes_per_s, errors) = measure(&h, &b, warm)?;
    let Some(error) = Summary::of(&errors) else {
        return Err(format!(
            "{scenario} {rate_hz} Hz: no error samples (see {})",
            dir.display()
        ));
    };
    Ok(Row {
        scenario,
        rate_hz,
        threshold_m,
        bytes_per_s,
        max_1s_bytes_per_s,
        p50_mm: error.median,
        p95_mm: error.p95,
        max_mm: error.max,
        samples: errors.len(),
    })
}

/// Host killed with SIGKILL under two bots: ms until the earliest joiner says it is host.
fn migration(dir: &Path, n: usize) -> Result<f64, String> {
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let (_signal, url) = Proc::signal(dir, &format!("mig{n}-signal"))?;
    let room = format!("mig{n}");
    let mut host = Proc::spawn(
        dir,
        &format!("{room}-host"),
        &s(&["host", "--room", &room, "--signal", &url, "--quiet"]),
    )?;
    host.line("hosting", Duration::from_secs(20))?;
    let mut bots = Vec::new();
    let mut heir = None;
    for k in ["b1", "b2"] {
        let args = [
            "join",
            "--room",
            &room,
            "--signal",
            &url,
            "--quiet",
            "--bot",
            "wave",
            "--duration",
            "30",
        ];
        let b = Proc::spawn(dir, &format!("{room}-{k}"), &s(&args))?;
        let id = field(&b.line("joining", Duration::from_secs(20))?, "peer").ok_or("no peer id")?;
        b.line("joined", Duration::from_secs(20))?;
        heir.get_or_insert(id);
        bots.push(b);
    }
    let id = heir.ok_or("no bots")?;
    std::thread::sleep(Duration::from_secs(2));
    let t = Instant::now();
    let _ = host.child.kill();
    bots[0].line(&format!("host-changed host={id}"), Duration::from_secs(15))?;
    Ok(t.elapsed().as_secs_f64() * 1e3)
}

fn chart(rows: &[Row], path: &Path, thresholds: &[f32]) -> Result<(), Box<dyn std::error::Error>> {
    let panel = |scen: &str, title: &str| {
        let rs: Vec<&Row> = rows.iter().filter(|r| r.scenario == scen).collect();
        let xmax = rs.iter().map(|r| r.bytes_per_s).fold(10.0, f64::max) * 1.1;
        let ymax = rs
            .iter()
            .map(|r| r.p95_mm)
            .filter(|v| v.is_finite())
            .fold(1.0, f64::max)
            * 1.15;
        let series = thresholds
            .iter()
            .enumerate()
            .map(|(k, thr)| {
                let (r, g, b) = Palette99::COLORS[k % Palette99::COLORS.len()];
                Series::new(
                    format!("threshold {thr} m"),
                    RGBColor(r, g, b),
                    rs.iter()
                        .filter(|r| (r.threshold_m - thr).abs() < 1e-6)
                        .map(|r| (r.bytes_per_s, r.p95_mm))
                        .collect(),
                )
            })
            .collect();
        LineChart {
            title: title.to_owned(),
            x_desc: "bytes/s (our datagrams, WebRTC)".to_owned(),
            y_desc: "p95 remote error (mm)".to_owned(),
            x_range: 0.0..xmax,
            x_log: false,
            y_range: 0.0..ymax,
            series,
            style: ChartStyle::PANEL,
        }
    };
    write_svg(
        path,
        (1100, 480),
        &[
            panel("avatar", "live: VR avatar (head + 2 hands)"),
            panel(
                "softbody60",
                "live: 60-particle soft body, dragged by a particle",
            ),
        ],
    )?;
    Ok(())
}

/// Centre-only sync (thesis §5.4.1, `replication: (centre_only: true)`: only the centre
/// travels, every other peer simulates the particles with the centre driven) against
/// per-particle sync, live: the bot drags the 60-particle ball by one particle (deforming it)
/// in the `bench-ball` room, and the room's ball class is per-particle in one run and
/// centre-only in the other (the host loads the scene with that one change; the bot receives
/// it). Bytes/s of the bot and the shape error the host shows (centre and every particle
/// against the bot's own state), at 30 Hz and 5 mm. Writes `centre_only.csv` and
/// `centre_only.txt` (the RESULT line) under `out`.
pub fn centre_only_live(out: &Path, seconds: f64) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let scratch = std::env::temp_dir().join(format!("softsync-centre-{}", std::process::id()));
    std::fs::create_dir_all(&scratch).map_err(|e| e.to_string())?;
    let assets = crate::assets_dir();
    let text = std::fs::read_to_string(assets.join("bench-ball.ron"))
        .map_err(|e| format!("{}: {e}", assets.display()))?;
    let ball = "colour: (0.90, 0.25, 0.30),";
    if !text.contains(ball) {
        return Err("bench-ball.ron: the softball's colour line moved".into());
    }
    let centre = text.replacen(
        ball,
        &format!("{ball} replication: (centre_only: true),"),
        1,
    );
    let centre_path = scratch.join("bench-ball-centre-only.ron");
    std::fs::write(&centre_path, centre).map_err(|e| e.to_string())?;
    // the mesh the scene names, beside it
    let _ = std::fs::copy(assets.join("bunny.obj"), scratch.join("bunny.obj"));
    let (rate, thr) = (30.0f32, 0.005f32);
    let mut connects = Vec::new();
    let mut rows = Vec::new();
    for (n, (mode, scene)) in [
        ("per_particle", "bench-ball".to_string()),
        ("centre_only", centre_path.display().to_string()),
    ]
    .into_iter()
    .enumerate()
    {
        let r = run_one(
            &scratch,
            100 + n,
            &scene,
            "softbody60",
            rate,
            thr,
            seconds,
            &mut connects,
        )?;
        println!(
            "{mode}: {:.0} B/s, shape error p50 {:.2} mm, p95 {:.2} mm, max {:.2} mm ({} samples)",
            r.bytes_per_s, r.p50_mm, r.p95_mm, r.max_mm, r.samples
        );
        rows.push((mode, r));
    }
    let mut csv = Csv::new(&[
        "mode",
        "rate_hz",
        "threshold_m",
        "bytes_per_s",
        "p50_mm",
        "p95_mm",
        "max_mm",
        "samples",
    ]);
    for (mode, r) in &rows {
        csv.row([
            mode.to_string(),
            r.rate_hz.to_string(),
            r.threshold_m.to_string(),
            format!("{:.1}", r.bytes_per_s),
            format!("{:.3}", r.p50_mm),
            format!("{:.3}", r.p95_mm),
            format!("{:.3}", r.max_mm),
            r.samples.to_string(),
        ]);
    }
    csv.write(out.join("centre_only.csv"))
        .map_err(|e| e.to_string())?;
    let (pp, co) = (&rows[0].1, &rows[1].1);
    let line = ResultLine::new("centre_only.live")
        .fixed("rate_hz", rate, 0)
        .fixed("threshold_mm", thr * 1000.0, 0)
        .fixed("bytes_per_s", co.bytes_per_s, 0)
        .fixed("shape_p95_mm", co.p95_mm, 2)
        .fixed("per_particle_bytes_per_s", pp.bytes_per_s, 0)
        .fixed("per_particle_p95_mm", pp.p95_mm, 2)
        .fixed("bytes_ratio", co.bytes_per_s / pp.bytes_per_s.max(1.0), 3)
        .field("seconds", seconds);
    println!("{line}");
    std::fs::write(out.join("centre_only.txt"), format!("{line}\n")).map_err(|e| e.to_string())?;
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// Run the benchmark; write CSV, chart and tables under `out`.
pub fn net_live(out: &Path, seconds: f64, quick: bool) -> Result<(), String> {
    let (rates, thresholds): (&[f32], &[f32]) = if quick {
        (&[10.0, 20.0], &[0.005])
    } else {
        (&thesis::RATES_HZ, &thesis::THRESHOLDS_M)
    };
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let scratch = std::env::temp_dir().join(format!("softsync-bench-{}", std::process::id()));
    std::fs::create_dir_all(&scratch).map_err(|e| e.to_string())?;
    let mut rows = Vec::new();
    let mut connects = Vec::new();
    let mut n = 0;
    let kills = if quick { 1 } else { 3 };
    let progress = Progress::new((2 * rates.len() * thresholds.len() + kills) as u64, "rooms");
    for scenario in ["avatar", "softbody60"] {
        for &hz in rates {
            for &thr in thresholds {
                n += 1;
                progress.set_message(format!("{scenario} {hz} Hz, threshold {thr} m"));
                let r = run_one(
                    &scratch,
                    n,
                    "bench-ball",
                    scenario,
                    hz,
                    thr,
                    seconds,
                    &mut connects,
                )?;
                progress.line(format!(
                    "{scenario} {hz} Hz thr {thr} m: {:.0} B/s, p50 {:.2} mm, p95 {:.2} mm, max {:.2} mm ({} samples)",
                    r.bytes_per_s, r.p50_mm, r.p95_mm, r.max_mm, r.samples
                ));
                progress.inc();
                rows.push(r);
            }
        }
    }
    let mut migs = Vec::new();
    for i in 0..kills {
        progress.set_message(format!("host kill {}", i + 1));
        migs.push(migration(&scratch, i)?);
        progress.inc();
    }
    progress.finish();
    let mut csv = Csv::new(&[
        "scenario",
        "rate_hz",
        "threshold_m",
        "bytes_per_s",
        "max_1s_bytes_per_s",
        "p50_mm",
        "p95_mm",
        "max_mm",
        "samples",
    ]);
    for r in &rows {
        csv.row([
            r.scenario.to_string(),
            r.rate_hz.to_string(),
            r.threshold_m.to_string(),
            format!("{:.1}", r.bytes_per_s),
            format!("{:.1}", r.max_1s_bytes_per_s),
            format!("{:.3}", r.p50_mm),
            format!("{:.3}", r.p95_mm),
            format!("{:.3}", r.max_mm),
            r.samples.to_string(),
        ]);
    }
    csv.write(out.join("live.csv")).map_err(|e| e.to_string())?;
    chart(&rows, &out.join("live.svg"), thresholds).map_err(|e| e.to_string())?;
    let mut md = format!(
        "# softsync live network bench\n\nGenerated by `scripts/bench-net-live{}` (= `softsync bench net-live` inside a network namespace): real processes on real WebRTC data channels over loopback, {seconds} s measured per cell. Bytes: every byte of the interacting bot's datagrams (no IP/UDP/DTLS/SCTP). Error: host's shown state vs the bot's own state at the shown time, center and every particle.\n\n",
        if quick { " --quick" } else { "" }
    );
    // Table 9: the avatar at the smallest threshold, largest 1 s and average.
    let _ = writeln!(
        md,
        "### Table 9 (live) — VR avatar, threshold {} m: max (1 s window) and average bytes/s [thesis]\n\n| Hz | max B/s | avg B/s | thesis max | thesis avg |\n|---:|---:|---:|---:|---:|",
        thresholds[0]
    );
    for &hz in rates {
        if let Some(r) = rows
            .iter()
            .find(|r| r.scenario == "avatar" && r.rate_hz == hz && r.threshold_m == thresholds[0])
        {
            let k = thesis::RATES_HZ.iter().position(|x| *x == hz);
            let th = |v: Option<u32>| v.map_or("—".to_owned(), |v| v.to_string());
            let _ = writeln!(
                md,
                "| {hz} | {:.0} | {:.0} | {} | {} |",
                r.max_1s_bytes_per_s,
                r.bytes_per_s,
                th(k.and_then(|k| thesis::TABLE9_MAX.get(k).copied())),
                th(thesis::bytes_per_s("avatar", hz, thresholds[0]))
            );
        }
    }
    md.push('\n');
    for (scen, title) in [
        ("avatar", "Table 10 (live) — VR avatar"),
        ("softbody60", "Table 11 (live) — 60-particle soft body"),
    ] {
        let _ = writeln!(
            md,
            "### {title}: bytes/s (p95 remote error mm) [thesis bytes/s]\n"
        );
        let _ = write!(md, "| Hz |");
        for t in thresholds {
            let _ = write!(md, " {t} m |");
        }
        let _ = write!(md, "\n|---:|");
        for _ in thresholds {
            md.push_str("---:|");
        }
        md.push('\n');
        for &hz in rates {
            let _ = write!(md, "| {hz} |");
            for &t in thresholds {
                if let Some(r) = rows
                    .iter()
                    .find(|r| r.scenario == scen && r.rate_hz == hz && r.threshold_m == t)
                {
                    let th = thesis::bytes_per_s(scen, hz, t)
                        .map_or("—".to_owned(), |v| v.to_string());
                    let _ = write!(md, " {:.0} ({:.2}) [{th}] |", r.bytes_per_s, r.p95_mm);
                }
            }
            md.push('\n');
        }
        md.push('\n');
    }
    let _ = writeln!(
        md,
        "Connect (signaling → first data channel, {} joins): median {:.0} ms. Migration (host SIGKILLed, earliest joiner announces itself; heartbeat timeout 1 s; {} runs): median {:.0} ms.",
        connects.len(),
        median(&connects),
        migs.len(),
        median(&migs)
    );
    std::fs::write(out.join("tables.md"), &md).map_err(|e| e.to_string())?;
    print!("{md}");
    let pick = |scen: &str| {
        rows.iter().find(|r| {
            r.scenario == scen && r.rate_hz == 20.0 && (r.threshold_m - 0.005).abs() < 1e-6
        })
    };
    for scen in ["softbody60", "avatar"] {
        if let Some(r) = pick(scen) {
            println!(
                "{}",
                ResultLine::new(format!("live.{scen}"))
                    .field("hz", 20)
                    .fixed("bytes_per_s", r.bytes_per_s, 0)
                    .fixed("p95_mm", r.p95_mm, 2)
            );
        }
    }
    println!(
        "{}",
        ResultLine::new("live.connect")
            .fixed("median_ms", median(&connects), 0)
            .field("joins", connects.len())
    );
    println!(
        "{}",
        ResultLine::new("live.migration")
            .fixed("median_ms", median(&migs), 0)
            .field("runs", migs.len())
    );
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}
