//! `softsync bench abuse`: a live room of four honest peers (a host and three bots that grab,
//! squeeze and sway) on real WebRTC, and one hostile process (`softsync-hostile`, built from
//! the test crate, never part of this binary) that attacks the host one way after another.
//!
//! Before each attack the honest room is measured for the same window: the host's CPU, the
//! bots' CPU, and the remote error p95 of every peer's view (10 Hz dumps; every object another
//! peer owns, center and particles, against its owner's own state). During the attack: the
//! same, and the host's resident memory (sampled every 250 ms; the growth is the largest
//! reading minus the one at the attack's start). Targets (issue 32): growth ≤ 10 MB, host CPU
//! ≤ 2× the honest room's, honest p95 ≤ 2× the honest room's.

use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use softsync_benchkit::{Csv, Progress, ResultLine, Summary};

use super::load::cpu_seconds;
use super::views::remote_errors;
use super::{grab_script, Proc};
use softsync_peer::dump::read_dump;

/// Every attack the hostile client knows.
pub const ATTACKS: [&str; 6] = [
    "hello-flood",
    "never-ack",
    "request-flood",
    "junk",
    "idents",
    "beacons",
];

/// Resident memory of a process, MB (`/proc/PID/status`).
fn rss_mb(pid: u32) -> Option<f64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb = s
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .split_whitespace()
        .next()?
        .parse::<f64>()
        .ok()?;
    Some(kb / 1024.0)
}

fn refs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

fn wall_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// CPU of each process over `seconds` of sleep, % of one core; the host's memory is sampled
/// meanwhile (its largest reading, MB).
fn window(pids: &[u32], seconds: f64) -> (Vec<f64>, f64) {
    let c0: Vec<Option<f64>> = pids.iter().map(|p| cpu_seconds(*p)).collect();
    let start = Instant::now();
    let mut rss_max = rss_mb(pids[0]).unwrap_or(f64::NAN);
    while start.elapsed().as_secs_f64() < seconds {
        std::thread::sleep(Duration::from_millis(250));
        if let Some(r) = rss_mb(pids[0]) {
            rss_max = rss_max.max(r);
        }
    }
    let dt = start.elapsed().as_secs_f64();
    let cpu = pids
        .iter()
        .zip(&c0)
        .map(|(p, c)| match (cpu_seconds(*p), c) {
            (Some(b), Some(a)) => (b - a) / dt * 100.0,
            _ => f64::NAN,
        })
        .collect();
    (cpu, rss_max)
}

struct Row {
    kind: String,
    host_rss_growth_mb: f64,
    host_cpu: f64,
    baseline_host_cpu: f64,
    honest_cpu: f64,
    baseline_honest_cpu: f64,
    honest_p95: f64,
    baseline_p95: f64,
    /// What the host told the hostile client (its drop reason), if anything.
    told: String,
    windows: [(u64, u64); 2],
}

/// Runs the attacks `kinds` (each `seconds` long, after as long a baseline), writing
/// `abuse.{csv,md}` and `results.txt` to `out`. `hostile` is the `softsync-hostile` binary.
pub fn abuse(out: &Path, seconds: f64, kinds: &[String], hostile: &Path) -> Result<(), String> {
    if !hostile.exists() {
        return Err(format!(
            "{} is missing: build it (cargo build --release -p softsync-integration-tests \
             --bin softsync-hostile; scripts/bench-abuse does)",
            hostile.display()
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let dir = std::env::temp_dir().join(format!("softsync-abuse-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let (_signal, url) = Proc::signal(&dir, "signal")?;
    let room = "abuse";
    let total = kinds.len() as f64 * (2.0 * seconds + 12.0) + 30.0;
    let total_s = total.to_string();
    let hd = dir.join("host.jsonl");
    let hds = hd.display().to_string();
    let dump = |d: &str| -> Vec<String> {
        ["--dump-hz", "10", "--dump", d, "--duration", &total_s]
            .map(String::from)
            .to_vec()
    };
    let host_args = [vec!["--bot".to_string(), "wave".into()], dump(&hds)].concat();
    let host = Proc::peer(&dir, "host", "host", room, &url, &refs(&host_args))?;
    host.line("hosting", Duration::from_secs(30))?;
    let mut bots = Vec::new();
    for k in 0..3 {
        let d = dir.join(format!("bot{k}.jsonl"));
        let args = [
            vec!["--bot".to_string(), grab_script(k)],
            dump(&d.display().to_string()),
        ]
        .concat();
        let p = Proc::peer(&dir, &format!("bot{k}"), "join", room, &url, &refs(&args))?;
        bots.push((p, d));
    }
    for (b, _) in &bots {
        b.line("joined", Duration::from_secs(60))?;
    }
    std::thread::sleep(Duration::from_secs(3));
    let pids: Vec<u32> = std::iter::once(host.child.id())
        .chain(bots.iter().map(|(b, _)| b.child.id()))
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let progress = Progress::new(kinds.len() as u64, "attacks");
    let mut rows = Vec::new();
    for kind in kinds {
        progress.set_message(kind.clone());
        let b0 = wall_ms();
        let (base_cpu, _) = window(&pids, seconds);
        let b1 = wall_ms();
        let name = format!("hostile-{kind}");
        let hostile_out = dir.join(format!("{name}.out"));
        let mut bad = Proc::spawn_program(
            &dir,
            &name,
            hostile,
            &[
                "--signal",
                &url,
                "--room",
                room,
                "--attack",
                kind,
                "--seconds",
                &(seconds + 8.0).to_string(),
            ],
        )?;
        // joined (or, for an attack that never joins, connected) before the window opens
        let ready = if kind == "junk" {
            "hostile id"
        } else {
            "joined"
        };
        bad.line(ready, Duration::from_secs(30))?;
        let rss0 = rss_mb(pids[0]).unwrap_or(f64::NAN);
        let a0 = wall_ms();
        let (cpu, rss_max) = window(&pids, seconds);
        let a1 = wall_ms();
        let _ = bad.wait(Duration::from_secs(15));
        drop(bad);
        let text = std::fs::read_to_string(&hostile_out).unwrap_or_default();
        let reasons: Vec<&str> = text
            .lines()
            .filter_map(|l| l.strip_prefix("told: "))
            .collect();
        let back = text
            .lines()
            .find_map(|l| {
                l.split("; ")
                    .nth(1)?
                    .strip_suffix(" refusal datagrams received")
            })
            .unwrap_or("?");
        let told = match reasons.as_slice() {
            [] => String::new(),
            [one] => format!("{one} ({back} refusals)"),
            [first, rest @ ..] => {
                format!(
                    "{first} (and {} other reasons; {back} refusals)",
                    rest.len()
                )
            }
        };
        rows.push(Row {
            kind: kind.clone(),
            host_rss_growth_mb: rss_max - rss0,
            host_cpu: cpu[0],
            baseline_host_cpu: base_cpu[0],
            honest_cpu: mean(&cpu[1..]),
            baseline_honest_cpu: mean(&base_cpu[1..]),
            honest_p95: f64::NAN,
            baseline_p95: f64::NAN,
            told,
            windows: [(b0, b1), (a0, a1)],
        });
        progress.inc();
        std::thread::sleep(Duration::from_secs(2));
    }
    progress.finish();
    // the honest views' error in each window, from the dumps (read while they still run:
    // every line up to now is written)
    std::thread::sleep(Duration::from_millis(500));
    let mut views = vec![read_dump(&hd).map_err(|e| e.to_string())?];
    for (_, d) in &bots {
        views.push(read_dump(d).map_err(|e| e.to_string())?);
    }
    for r in &mut rows {
        let p95 = |(f, t): (u64, u64)| {
            Summary::of(&remote_errors(&views, f, t).mm).map_or(f64::NAN, |s| s.p95)
        };
        r.baseline_p95 = p95(r.windows[0]);
        r.honest_p95 = p95(r.windows[1]);
    }
    drop(bots);
    drop(host);
    let mut csv = Csv::new(&[
        "kind",
        "peers",
        "host_rss_growth_mb",
        "host_cpu_pct",
        "baseline_host_cpu_pct",
        "honest_cpu_pct",
        "baseline_honest_cpu_pct",
        "honest_p95_mm",
        "baseline_p95_mm",
        "told",
    ]);
    let mut md = format!(
        "# softsync under attack\n\nGenerated by `scripts/bench-abuse` (= `softsync bench abuse` in a network namespace): a room of four honest peers on real WebRTC over loopback (a host and three bots that grab, squeeze and sway; 10 Hz dumps) and one hostile process (`softsync-hostile`, test crate only), one attack after another, each {seconds} s, each after {seconds} s of the honest room alone. Host RSS growth: the host's largest resident memory during the attack minus at its start (sampled every 250 ms). CPU: % of one core over the window (the hostile process's own not counted; one machine of 2 cores runs all six processes). Remote error: every honest view, every object another peer owns, center and particles, against the owner's own state. Targets: growth ≤ 10 MB, host CPU ≤ 2× and p95 ≤ 2× the honest room's.\n\n| attack | host RSS growth MB | host CPU % (honest room) | honest bots' CPU % (honest room) | honest p95 mm (honest room) | within targets | the host told the attacker |\n|---|---:|---:|---:|---:|:---:|---|\n"
    );
    let mut results = String::new();
    for r in &rows {
        let ok = r.host_rss_growth_mb <= 10.0
            && r.host_cpu <= 2.0 * r.baseline_host_cpu.max(1.0)
            && r.honest_p95 <= 2.0 * r.baseline_p95.max(0.5);
        csv.row([
            r.kind.clone(),
            "5".to_string(),
            format!("{:.1}", r.host_rss_growth_mb),
            format!("{:.0}", r.host_cpu),
            format!("{:.0}", r.baseline_host_cpu),
            format!("{:.0}", r.honest_cpu),
            format!("{:.0}", r.baseline_honest_cpu),
            format!("{:.1}", r.honest_p95),
            format!("{:.1}", r.baseline_p95),
            r.told.replace(',', ";"),
        ]);
        let _ = writeln!(
            md,
            "| {} | {:.1} | {:.0} ({:.0}) | {:.0} ({:.0}) | {:.1} ({:.1}) | {} | {} |",
            r.kind,
            r.host_rss_growth_mb,
            r.host_cpu,
            r.baseline_host_cpu,
            r.honest_cpu,
            r.baseline_honest_cpu,
            r.honest_p95,
            r.baseline_p95,
            if ok { "yes" } else { "NO" },
            if r.told.is_empty() { "—" } else { &r.told }
        );
        let line = ResultLine::new("abuse.host")
            .field("kind", &r.kind)
            .field("peers", 5)
            .fixed("host_rss_growth_mb", r.host_rss_growth_mb, 1)
            .fixed("host_cpu_pct", r.host_cpu, 0)
            .fixed("baseline_host_cpu_pct", r.baseline_host_cpu, 0)
            .fixed("honest_cpu_pct", r.honest_cpu, 0)
            .fixed("baseline_honest_cpu_pct", r.baseline_honest_cpu, 0)
            .fixed("honest_p95_mm", r.honest_p95, 1)
            .fixed("baseline_p95_mm", r.baseline_p95, 1)
            .field("dropped", !r.told.is_empty())
            .field("within_targets", ok);
        println!("{line}");
        let _ = writeln!(results, "{line}");
    }
    csv.write(out.join("abuse.csv"))
        .map_err(|e| e.to_string())?;
    std::fs::write(out.join("abuse.md"), &md).map_err(|e| e.to_string())?;
    std::fs::write(out.join("results.txt"), results).map_err(|e| e.to_string())?;
    print!("{md}");
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
