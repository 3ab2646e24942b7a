//! `softsync bench room-load`: a host and bots in one room on real WebRTC, for growing room
//! sizes — uplink and downlink rates, grabs taken and refused, join times, and whether every
//! peer agrees on members and owners at one moment.

use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use softsync_benchkit::{Csv, Progress, ResultLine, Summary};

use super::views::{agrees_within, line_at, only, remote_errors, RoomView};
use super::{grab_script, Proc};
use softsync_peer::dump::{read_dump, DumpLine};

/// One room-load measurement.
struct LoadRow {
    peers: usize,
    host_up: f64,
    host_down: f64,
    bot_up: f64,
    grabs: usize,
    failed_grabs: usize,
    slowest_join_ms: f64,
    agree: bool,
    /// CPU of the host over the window, % of one core.
    host_cpu: f64,
    /// Mean CPU of a bot over the window, % of one core.
    bot_cpu: f64,
    /// The busiest bot's CPU over the window, % of one core.
    bot_cpu_max: f64,
    /// CPU of the idle viewer (a peer that joins and only watches; rooms of 3 and more),
    /// % of one core.
    idle_cpu: f64,
    /// Remote error over the window (every view, every object another peer owns), mm.
    p50_mm: f64,
    p95_mm: f64,
    /// The same, scene objects only and avatar parts only (p95).
    scene_p95_mm: f64,
    avatar_p95_mm: f64,
    /// Share of the sampled moments (every 250 ms of the window) at which every view agreed.
    agree_frac: f64,
}

/// CPU time (user + system) a process has used so far, seconds (from `/proc`; `None` where
/// there is none).
pub(super) fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // the fields after the command's closing parenthesis: utime and stime are 14th and 15th
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0) // USER_HZ is 100 on Linux
}

fn window_rate(lines: &[DumpLine], from_wall: u64, to_wall: u64) -> Option<(f64, f64)> {
    // the line at `w`, or the first one after (a peer that joined last may write its first
    // line just after the window opened)
    let at = |w: u64| {
        lines
            .iter()
            .filter(|l| l.wall_ms <= w)
            .max_by_key(|l| l.wall_ms)
            .or_else(|| lines.first())
    };
    let (a, b) = (at(from_wall)?, at(to_wall)?);
    let dt = (b.t - a.t).max(0.1);
    Some((
        b.up_bytes.saturating_sub(a.up_bytes) as f64 / dt,
        b.down_bytes.saturating_sub(a.down_bytes) as f64 / dt,
    ))
}

/// A host and `n` bots (the host counted among the peers) in one room for `seconds`: each
/// bot in turn reaches for an object, grabs it (authority requests contend), squeezes, lets
/// go and sways. Traffic of the host (the relay) and of the bots, grabs taken and refused,
/// and whether every peer lists the same members and owners at one moment.
fn load_one(
    dir: &Path,
    exe: &Path,
    peers: usize,
    seconds: f64,
    route: &str,
) -> Result<LoadRow, String> {
    let (_signal, url) = Proc::signal(dir, &format!("load{peers}-signal"))?;
    let room = format!("load{peers}");
    // the last joiner of a room of 3 or more is an idle viewer: it joins and only watches
    let viewer = (peers >= 3).then_some(peers - 1);
    // every bot runs until the measured window (after the last one joined) is over: joins
    // take longer the more processes share the cores
    let total = seconds + 8.0 + 0.75 * peers as f64;
    let hd = dir.join(format!("{room}-host.jsonl"));
    let (hds, host_total) = (hd.display().to_string(), (total + 2.0).to_string());
    let mut host = Proc::peer_with(
        exe,
        dir,
        &format!("{room}-host"),
        "host",
        &room,
        &url,
        &[
            "--bot",
            "wave",
            "--dump-hz",
            "10",
            "--dump",
            &hds,
            "--duration",
            &host_total,
            "--state-route",
            route,
        ],
    )?;
    host.line("hosting", Duration::from_secs(20))?;
    let mut bots = Vec::new();
    for k in 1..peers {
        let script = if Some(k) == viewer {
            "idle".to_owned()
        } else {
            grab_script(k - 1)
        };
        let d = dir.join(format!("{room}-b{k}.jsonl"));
        let (ds, bot_total) = (d.display().to_string(), total.to_string());
        bots.push((
            Proc::peer_with(
                exe,
                dir,
                &format!("{room}-b{k}"),
                "join",
                &room,
                &url,
                &[
                    "--bot",
                    &script,
                    "--dump-hz",
                    "10",
                    "--dump",
                    &ds,
                    "--duration",
                    &bot_total,
                    "--state-route",
                    route,
                ],
            )?,
            d,
        ));
    }
    let start = Instant::now();
    let mut slowest = 0.0f64;
    for (b, _) in &bots {
        b.line("joined", Duration::from_secs(60))?;
        slowest = slowest.max(start.elapsed().as_secs_f64() * 1e3);
    }
    let from = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64);
    let to = from + (seconds * 1000.0) as u64;
    // CPU over the window, per process
    let pids: Vec<u32> = std::iter::once(host.child.id())
        .chain(bots.iter().map(|(b, _)| b.child.id()))
        .collect();
    let cpu0: Vec<Option<f64>> = pids.iter().map(|p| cpu_seconds(*p)).collect();
    std::thread::sleep(Duration::from_secs_f64(seconds));
    let cpu: Vec<f64> = pids
        .iter()
        .zip(&cpu0)
        .filter_map(|(p, c0)| Some((cpu_seconds(*p)? - (*c0)?) / seconds * 100.0))
        .collect();
    if cpu.len() != pids.len() {
        return Err("a peer's CPU time could not be read (did it exit?)".into());
    }
    let host_cpu = cpu[0];
    let idle_cpu = viewer.map_or(f64::NAN, |v| cpu[v]);
    let bot_cpus: Vec<f64> = (1..peers)
        .filter(|k| Some(*k) != viewer)
        .map(|k| cpu[k])
        .collect();
    let bot_cpu = if bot_cpus.is_empty() {
        f64::NAN
    } else {
        bot_cpus.iter().sum::<f64>() / bot_cpus.len() as f64
    };
    let bot_cpu_max = bot_cpus.iter().copied().fold(f64::NAN, f64::max);
    for (b, _) in &mut bots {
        b.wait(Duration::from_secs_f64(total + 60.0))?;
    }
    host.wait(Duration::from_secs(30))?;
    let hlines = read_dump(&hd).map_err(|e| e.to_string())?;
    let (host_up, host_down) = window_rate(&hlines, from, to).ok_or("host dump too short")?;
    let mut bot_up = 0.0;
    let mut views = vec![hlines];
    let (mut grabs, mut failed) = (0, 0);
    for (b, d) in &bots {
        let lines = read_dump(d).map_err(|e| e.to_string())?;
        bot_up += window_rate(&lines, from, to).ok_or("bot dump too short")?.0;
        views.push(lines);
        let out = std::fs::read_to_string(&b.out).unwrap_or_default();
        grabs += out.matches("grabbed object").count();
        failed += out.matches("nothing taken").count();
    }
    // Every 250 ms of the window, every view: the same members (all of the room) and the same
    // owner for every object as the host showed within 300 ms of that moment (a grant or a
    // release takes a link's delay to travel; dumps are taken at 10 Hz). `agree` needs 95 % of
    // the moments: a peer starved of the CPU for a moment shows an older view.
    let mut moments = 0usize;
    let mut agreeing = 0usize;
    for m in (from..=to).step_by(250) {
        moments += 1;
        let all = views.iter().all(|v| {
            line_at(v, m).is_some_and(|l| {
                l.members.len() == peers && agrees_within(&RoomView::of(l), &views[0], m, 300)
            })
        });
        agreeing += usize::from(all);
    }
    let agree_frac = agreeing as f64 / moments.max(1) as f64;
    let errors = remote_errors(&views, from, to).mm;
    let (p50_mm, p95_mm) = Summary::of(&errors).map_or((f64::NAN, f64::NAN), |s| (s.median, s.p95));
    let p95_of = |avatar: bool| {
        Summary::of(&remote_errors(&only(&views, avatar), from, to).mm).map_or(f64::NAN, |s| s.p95)
    };
    let (scene_p95_mm, avatar_p95_mm) = (p95_of(false), p95_of(true));
    Ok(LoadRow {
        peers,
        host_up,
        host_down,
        bot_up: bot_up / (peers - 1).max(1) as f64,
        grabs,
        failed_grabs: failed,
        slowest_join_ms: slowest,
        agree: agree_frac >= 0.95,
        host_cpu,
        bot_cpu,
        bot_cpu_max,
        idle_cpu,
        p50_mm,
        p95_mm,
        scene_p95_mm,
        avatar_p95_mm,
        agree_frac,
    })
}

/// `softsync bench room-load`: rooms of growing size on real WebRTC.
/// `direct`: every room with direct state (`--state-route direct`); the outputs are named
/// `load_direct.*` then. `builds`: the `softsync` builds to run the rooms with (LABEL, path;
/// none: the one beside this binary, as `this`), each room size `rounds` times with the
/// builds in turn, so a before and an after meet the same machine
/// (`RESULT crowd.cpu … build=…`: the medians of the rounds).
pub fn room_load(
    out: &Path,
    seconds: f64,
    sizes: &[usize],
    direct: bool,
    builds: &[(String, std::path::PathBuf)],
    rounds: usize,
) -> Result<(), String> {
    let route = if direct { "direct" } else { "relay" };
    let builds: Vec<(String, std::path::PathBuf)> = if builds.is_empty() {
        vec![("this".to_owned(), super::softsync_binary()?)]
    } else {
        builds.to_vec()
    };
    let rounds = rounds.max(1);
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let scratch = std::env::temp_dir().join(format!("softsync-load-{}", std::process::id()));
    std::fs::create_dir_all(&scratch).map_err(|e| e.to_string())?;
    let mut csv = Csv::new(&[
        "build",
        "round",
        "peers",
        "host_up_bytes_per_s",
        "host_down_bytes_per_s",
        "bot_up_bytes_per_s",
        "grabs",
        "refused_grabs",
        "slowest_join_ms",
        "agree",
        "host_cpu_pct",
        "bot_cpu_pct",
        "bot_cpu_max_pct",
        "idle_cpu_pct",
        "p50_mm",
        "p95_mm",
        "scene_p95_mm",
        "avatar_p95_mm",
        "agree_frac",
    ]);
    let mut md = format!(
        "# softsync room load ({route} state)\n\nGenerated by `scripts/bench-net-live --load` (= `softsync-bench room-load` in a network namespace; `--state-route direct`: load_direct.md): a host and bots in one room on real WebRTC over loopback, {seconds} s measured; every bot loops reach → grab (authority requests contend) → squeeze → release → sway; in rooms of 3 and more the last joiner is an idle viewer that only watches. One machine runs every peer (2 cores here): CPU is each process's share of one core over the window, and a room whose processes want more than the two cores together shows what they got, not what they wanted. Remote error: every line of every peer's dump (10 Hz) in the window, every object another peer owns, each shown point (center and particles) against the owner's own state at the time the shown state stands for. Agreement: every 250 ms, every peer lists all members and the same owners as the host within 300 ms of that moment; `agree` needs 95 % of the moments.\n\n| build | round | peers | host up B/s | host down B/s | bot up B/s | grabs taken | grabs refused | all joined after ms | remote error p50 / p95 mm (scene p95, avatars p95) | moments agreeing | agree | host CPU % | bot CPU % mean / max | idle viewer CPU % |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|---:|---:|---:|\n"
    );
    let progress = Progress::new((sizes.len() * rounds * builds.len()) as u64, "rooms");
    let mut cpu_lines = Vec::new();
    for &n in sizes {
        // (host, bot, idle) CPU of each round, per build
        let mut cpus: Vec<Vec<(f64, f64, f64)>> = vec![Vec::new(); builds.len()];
        for round in 0..rounds {
            for (b, (label, exe)) in builds.iter().enumerate() {
                progress.set_message(format!("{n} peers, {label}, round {}", round + 1));
                let r = load_one(&scratch, exe, n, seconds, route)?;
                progress.inc();
                cpus[b].push((r.host_cpu, r.bot_cpu, r.idle_cpu));
                csv.row([
                    label.clone(),
                    (round + 1).to_string(),
                    r.peers.to_string(),
                    format!("{:.0}", r.host_up),
                    format!("{:.0}", r.host_down),
                    format!("{:.0}", r.bot_up),
                    r.grabs.to_string(),
                    r.failed_grabs.to_string(),
                    format!("{:.0}", r.slowest_join_ms),
                    r.agree.to_string(),
                    format!("{:.1}", r.host_cpu),
                    format!("{:.1}", r.bot_cpu),
                    format!("{:.1}", r.bot_cpu_max),
                    format!("{:.1}", r.idle_cpu),
                    format!("{:.1}", r.p50_mm),
                    format!("{:.1}", r.p95_mm),
                    format!("{:.1}", r.scene_p95_mm),
                    format!("{:.1}", r.avatar_p95_mm),
                    format!("{:.3}", r.agree_frac),
                ]);
                let _ = writeln!(
                    md,
                    "| {label} | {} | {} | {:.0} | {:.0} | {:.0} | {} | {} | {:.0} | {:.1} / {:.1} ({:.1}, {:.1}) | {:.0} % | {} | {:.1} | {:.1} / {:.1} | {:.1} |",
                    round + 1,
                    r.peers,
                    r.host_up,
                    r.host_down,
                    r.bot_up,
                    r.grabs,
                    r.failed_grabs,
                    r.slowest_join_ms,
                    r.p50_mm,
                    r.p95_mm,
                    r.scene_p95_mm,
                    r.avatar_p95_mm,
                    r.agree_frac * 100.0,
                    if r.agree { "yes" } else { "NO" },
                    r.host_cpu,
                    r.bot_cpu,
                    r.bot_cpu_max,
                    r.idle_cpu
                );
                progress.result(
                    ResultLine::new("live.load")
                        .field("build", label)
                        .field("peers", r.peers)
                        .fixed("host_up_bytes_per_s", r.host_up, 0)
                        .fixed("host_down_bytes_per_s", r.host_down, 0)
                        .fixed("bot_up_bytes_per_s", r.bot_up, 0)
                        .field("grabs", r.grabs)
                        .field("refused", r.failed_grabs)
                        .fixed("join_ms", r.slowest_join_ms, 0)
                        .field("agree", r.agree)
                        .fixed("host_cpu_pct", r.host_cpu, 1)
                        .fixed("bot_cpu_pct", r.bot_cpu, 1)
                        .fixed("idle_cpu_pct", r.idle_cpu, 1),
                );
                progress.result(
                    ResultLine::new("crowd.room")
                        .field("build", label)
                        .field("peers", r.peers)
                        .field("route", route)
                        .fixed("host_up_bytes_per_s", r.host_up, 0)
                        .fixed("bot_up_bytes_per_s", r.bot_up, 0)
                        .fixed("p50_mm", r.p50_mm, 1)
                        .fixed("p95_mm", r.p95_mm, 1)
                        .fixed("scene_p95_mm", r.scene_p95_mm, 1)
                        .fixed("avatar_p95_mm", r.avatar_p95_mm, 1)
                        .fixed("join_ms", r.slowest_join_ms, 0)
                        .fixed("host_cpu_pct", r.host_cpu, 1)
                        .fixed("bot_cpu_pct", r.bot_cpu, 1)
                        .fixed("bot_cpu_max_pct", r.bot_cpu_max, 1)
                        .fixed("idle_cpu_pct", r.idle_cpu, 1)
                        .fixed("agree_frac", r.agree_frac, 3)
                        .field("agree", r.agree),
                );
            }
        }
        for (b, (label, _)) in builds.iter().enumerate() {
            let median = |f: fn(&(f64, f64, f64)) -> f64| {
                Summary::of(&cpus[b].iter().map(f).collect::<Vec<f64>>())
                    .map_or(f64::NAN, |s| s.median)
            };
            let line = ResultLine::new("crowd.cpu")
                .field("peers", n)
                .field("build", label)
                .field("rounds", rounds)
                .fixed("idle_cpu_pct", median(|c| c.2), 1)
                .fixed("bot_cpu_pct", median(|c| c.1), 1)
                .fixed("host_cpu_pct", median(|c| c.0), 1);
            cpu_lines.push(line.to_string());
            progress.result(line);
        }
    }
    progress.finish();
    if builds.len() > 1 || rounds > 1 {
        md += "\nMedians of the rounds, per build (`RESULT crowd.cpu`):\n\n```\n";
        for l in &cpu_lines {
            md += l;
            md.push('\n');
        }
        md += "```\n\nBuilds: ";
        md += &builds
            .iter()
            .map(|(l, p)| format!("`{l}` = {}", p.display()))
            .collect::<Vec<_>>()
            .join(", ");
        md.push('\n');
    }
    let name = if direct { "load_direct" } else { "load" };
    csv.write(out.join(format!("{name}.csv")))
        .map_err(|e| e.to_string())?;
    std::fs::write(out.join(format!("{name}.md")), &md).map_err(|e| e.to_string())?;
    print!("{md}");
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}
