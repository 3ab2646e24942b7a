//! `softsync-bench room-clock`: the room clock (`Session::room_time`) measured live.
//!
//! A host and two bots on real WebRTC, each dumping what it shows 20 times a second with its
//! room time (`room_s`). The host is SIGKILLed halfway; the first bot takes over. Every
//! process has its own local clock (its session's time starts with the process), so the room
//! time is a real agreement between clocks, not a shared one.
//!
//! How far apart two peers read the room time: each dump line has the peer's local time `t`,
//! the wall clock (`wall_ms`, the same for every process of the machine) and the room time.
//! A process's local clock maps to the wall clock by one constant (the median of
//! `wall − t` over its lines: both clocks run at one rate for a minute, and the median takes
//! the wall clock's millisecond steps out). A line's room error is `room − wall` at its
//! instant; the skew between two peers is the difference of their errors, compared at each
//! line of one against the other's interpolated. Reported: the p95 over the time before the
//! kill (from 2 s after every peer knows the room time), and after the migration (from 2 s
//! after the new host announced itself). `RESULT clock.room` and a CSV of every line's room
//! error in `docs/results/clock/`.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Duration;

use softsync_benchkit::{percentile, Csv, ResultLine};
use softsync_peer::dump::{read_dump, DumpLine};

use super::{field, Proc};

/// One peer's dump reduced to (wall s, room error s), with its id.
struct Track {
    peer: u64,
    /// (wall time s, room time − wall time s), in order.
    error: Vec<(f64, f64)>,
}

impl Track {
    fn new(lines: &[DumpLine]) -> Option<Track> {
        let peer = lines.first()?.peer;
        let mut epoch: Vec<f64> = lines.iter().map(|l| l.wall_ms as f64 / 1e3 - l.t).collect();
        epoch.sort_by(f64::total_cmp);
        // the wall clock's ms steps: the median maps local time to the wall within ~0.1 ms
        let e = epoch[epoch.len() / 2] + 0.0005;
        let error = lines
            .iter()
            .filter_map(|l| l.room_s.map(|r| (l.t + e, r - (l.t + e))))
            .collect();
        Some(Track { peer, error })
    }

    /// The room error at wall time `w`, interpolated; none outside the track.
    fn at(&self, w: f64) -> Option<f64> {
        let k = self.error.partition_point(|(t, _)| *t < w);
        let (a, b) = (self.error.get(k.checked_sub(1)?)?, self.error.get(k)?);
        if b.0 - a.0 > 0.5 {
            return None; // a gap (a stall): no reading to compare with
        }
        let f = (w - a.0) / (b.0 - a.0).max(1e-9);
        Some(a.1 + f * (b.1 - a.1))
    }
}

/// |skew| samples (ms) between every pair of tracks, over wall times in `[from, to]`.
fn skews(tracks: &[&Track], from: f64, to: f64) -> Vec<f64> {
    let mut out = Vec::new();
    for (i, a) in tracks.iter().enumerate() {
        for b in tracks.iter().skip(i + 1) {
            for &(w, e) in a.error.iter().filter(|(w, _)| *w >= from && *w <= to) {
                if let Some(f) = b.at(w) {
                    out.push((e - f).abs() * 1e3);
                }
            }
        }
    }
    out
}

/// Runs the room, kills its host after `seconds`, runs `seconds` more; writes the results.
pub fn room_clock(out: &Path, seconds: f64) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let dir = std::env::temp_dir().join(format!("softsync-clock-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let (_signal, url) = Proc::signal(&dir, "signal")?;
    let room = "clock";
    let total = format!("{}", (2.0 * seconds + 10.0).ceil());
    let dump = |name: &str| dir.join(format!("{name}.jsonl"));
    let host_dump = dump("host");
    let host_dump_s = host_dump.to_string_lossy().to_string();
    let mut host = Proc::peer(
        &dir,
        "host",
        "host",
        room,
        &url,
        &["--dump", &host_dump_s, "--dump-hz", "20"],
    )?;
    host.line("hosting", Duration::from_secs(20))?;
    let mut bots = Vec::new();
    let mut heir = None;
    for k in ["b1", "b2"] {
        let d = dump(k).to_string_lossy().to_string();
        let b = Proc::peer(
            &dir,
            k,
            "join",
            room,
            &url,
            &[
                "--bot",
                "idle",
                "--duration",
                &total,
                "--dump",
                &d,
                "--dump-hz",
                "20",
            ],
        )?;
        let id = field(&b.line("joining", Duration::from_secs(20))?, "peer").ok_or("no peer id")?;
        b.line("joined", Duration::from_secs(20))?;
        heir.get_or_insert(id);
        bots.push(b);
    }
    let heir = heir.ok_or("no bots")?;
    std::thread::sleep(Duration::from_secs_f64(seconds));
    let _ = host.child.kill();
    let _ = host.child.wait();
    bots[0].line(
        &format!("host-changed host={heir}"),
        Duration::from_secs(15),
    )?;
    std::thread::sleep(Duration::from_secs_f64(seconds));
    let mut tracks = Vec::new();
    for name in ["host", "b1", "b2"] {
        let lines = read_dump(&dump(name)).map_err(|e| format!("{name}'s dump: {e}"))?;
        tracks.push(Track::new(&lines).ok_or(format!("{name} dumped nothing"))?);
    }
    drop(bots);
    // before the kill: from 2 s after every peer knew the room time, to the host's last line
    let known = tracks
        .iter()
        .filter_map(|t| t.error.first().map(|e| e.0))
        .fold(f64::MIN, f64::max);
    let killed = tracks[0].error.last().map_or(known, |e| e.0);
    let before = skews(&tracks.iter().collect::<Vec<_>>(), known + 2.0, killed);
    let after = skews(&[&tracks[1], &tracks[2]], killed + 2.0, f64::MAX);
    if before.is_empty() || after.is_empty() {
        return Err("no overlapping readings to compare".into());
    }
    // how the heir's room time went on across the kill: its readings never go back
    let jump_ms = tracks[1]
        .error
        .windows(2)
        .filter(|w| w[0].0 <= killed + 1.0 && w[1].0 >= killed - 1.0)
        .map(|w| (w[1].1 - w[0].1) * 1e3)
        .fold(0.0f64, |m, d| if d.abs() > m.abs() { d } else { m });
    let line = ResultLine::new("clock.room")
        .field("peers", 3)
        .fixed("skew_p50_ms", percentile(&before, 0.5), 2)
        .fixed("skew_p95_ms", percentile(&before, 0.95), 2)
        .fixed("after_migration_skew_p95_ms", percentile(&after, 0.95), 2)
        .fixed("heir_step_at_migration_ms", jump_ms, 2)
        .field("samples", before.len() + after.len());
    println!("{line}");
    let mut csv = Csv::new(&["peer", "wall_s", "room_minus_wall_ms"]);
    let t0 = tracks
        .iter()
        .filter_map(|t| t.error.first().map(|e| e.0))
        .fold(f64::MAX, f64::min);
    for t in &tracks {
        for (w, e) in &t.error {
            csv.row([
                t.peer.to_string(),
                format!("{:.4}", w - t0),
                format!("{:.3}", e * 1e3),
            ]);
        }
    }
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# The room clock, live\n\n`scripts/netns-run target/release/softsync-bench room-clock` \
         (a host and two bots on real WebRTC on one machine, {seconds} s, the host SIGKILLed, \
         {seconds} s more). Skew: how far two peers' room times are apart at one wall-clock \
         instant (see `bench/src/live/clock.rs`).\n\n```\n{line}\n```"
    );
    let path = |f: &str| out.join(f);
    std::fs::write(path("clock.csv"), csv.text()).map_err(|e| e.to_string())?;
    std::fs::write(path("README.md"), md).map_err(|e| e.to_string())?;
    std::fs::write(path("results.txt"), format!("{line}\n")).map_err(|e| e.to_string())?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
