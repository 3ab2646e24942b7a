//! The failure detector on virtual time: how fast a dead host is replaced, against how often a
//! live one is taken for dead, as the adaptive detector's threshold (phi) moves, with the
//! fixed 1 s timeout beside it.
//!
//! `cargo run --release -p softsync-net --example detector -- [--quick]`
//!
//! Detection: 20 kills of the host of a 4-peer room on a loopback-like link (1 ms latency,
//! 1 ms jitter, no loss), from the kill to a survivor being host. False alarms: host changes
//! and members dropped (nobody dies or leaves) in a 5-peer room under 150 ms latency, 30 ms jitter and 20 % loss (the seeded conditioner)
//! over 10 virtual minutes (`--quick`: 1 minute, 5 kills), and on a clean 20 ± 5 ms link
//! whose every process stops now and then for 10 – 249 ms (the seeded CPU-stall model,
//! `harness::StallModel::tolerated`) over as long. Writes
//! `docs/results/net/detector.{csv,svg}` and prints `RESULT wild.migration` lines.
//!
//! What this does not measure: a real process's SIGKILL over WebRTC (the live detection time
//! adds the peers' frame loops and the data channel), and real CPU starvation, which only
//! the stall model stands for (`softsync bench soak --busy-loops 1` runs real processes on a
//! machine whose busy loops take half the CPU).
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::path::Path;
use std::time::Duration;

use softsync_benchkit::plotters::style::{BLUE, RED};
use softsync_benchkit::{percentile, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_net::harness::{Harness, StallModel};
use softsync_net::{ConditionerConfig, FailureDetector, SessionConfig};

fn detection_ms(cfg: &SessionConfig, kills: u64) -> Vec<f64> {
    (1..=kills)
        .map(|seed| {
            let mut h = Harness::new(4, cfg.clone(), ConditionerConfig::rough(seed, 1, 1, 0.0));
            // Each kill at another moment of the heartbeat rhythm.
            h.advance(Duration::from_millis(3000 + 7 * seed));
            h.time_to_new_host(Duration::from_secs(5), Duration::from_millis(5))
                .map_or(f64::NAN, |d| d.as_secs_f64() * 1e3)
        })
        .collect()
}

fn false_alarms(cfg: &SessionConfig, minutes: u64) -> usize {
    let link = ConditionerConfig::rough(11, 150, 30, 0.20);
    let mut h = Harness::new(5, cfg.clone(), link);
    h.advance(Duration::from_secs(3));
    let before = h.failure_verdicts();
    h.advance(Duration::from_secs(60 * minutes));
    h.failure_verdicts() - before
}

/// Host changes and drops in a 5-peer room on a clean 20 ± 5 ms link whose every process
/// stops now and then for 10 – 249 ms (the seeded CPU-stall model), over `minutes`.
fn stall_alarms(cfg: &SessionConfig, minutes: u64) -> (usize, usize) {
    let link = ConditionerConfig {
        seed: 12,
        latency: Duration::from_millis(20),
        jitter: Duration::from_millis(5),
        ..ConditionerConfig::default()
    };
    let mut h = Harness::new(5, cfg.clone(), link);
    h.advance(Duration::from_secs(3));
    let before = h.failure_verdicts();
    let stalls = h.run_with_stalls(
        Duration::from_secs(60 * minutes),
        Duration::from_millis(5),
        StallModel::tolerated(12),
    );
    (h.failure_verdicts() - before, stalls)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let (kills, minutes) = if quick { (5, 1) } else { (20, 10) };
    let base = SessionConfig::default();
    let mut rows = Vec::new();
    // (label, phi or None for the fixed timeout, config)
    let mut setups: Vec<(String, Option<f32>, SessionConfig)> =
        vec![("fixed 1 s".into(), None, base.clone().fixed_detection())];
    for phi in [1.0f32, 2.0, 3.0, 5.0, 9.0, 12.0] {
        let mut cfg = base.clone().fast_detection();
        let FailureDetector::Adaptive { min_timeout, .. } = FailureDetector::ADAPTIVE else {
            unreachable!("the default detector is the adaptive one")
        };
        cfg.detector = FailureDetector::Adaptive {
            phi,
            deviations: 4.0,
            min_timeout,
        };
        setups.push((format!("adaptive phi {phi}"), Some(phi), cfg));
    }
    let progress = softsync_benchkit::Progress::new(setups.len() as u64, "detectors");
    let mut csv = Csv::new(&[
        "detector",
        "phi",
        "kills",
        "p50_ms",
        "p95_ms",
        "false_alarms",
        "minutes",
        "stall_false_alarms",
        "stalls",
    ]);
    for (label, phi, cfg) in &setups {
        progress.set_message(label.clone());
        let mut d = detection_ms(cfg, kills);
        d.sort_by(f64::total_cmp);
        let (p50, p95) = (percentile(&d, 50.0), percentile(&d, 95.0));
        let alarms = false_alarms(cfg, minutes);
        let (stall_alarms, stalls) = stall_alarms(cfg, minutes);
        csv.row([
            label.clone(),
            phi.map_or(String::new(), |p| p.to_string()),
            kills.to_string(),
            format!("{p50:.0}"),
            format!("{p95:.0}"),
            alarms.to_string(),
            minutes.to_string(),
            stall_alarms.to_string(),
            stalls.to_string(),
        ]);
        progress.result(format_args!(
            "{label:<18} detection min {:>5.0} p50 {p50:>5.0} p95 {p95:>5.0} max {:>5.0} ms   false alarms in {minutes} min: {alarms}, under {stalls} stalls: {stall_alarms}",
            d.first().copied().unwrap_or(f64::NAN),
            d.last().copied().unwrap_or(f64::NAN),
        ));
        progress.inc();
        rows.push((label.clone(), *phi, p95, alarms, stall_alarms));
    }
    progress.finish();
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results/net");
    if !quick {
        std::fs::create_dir_all(&out)?;
        csv.write(out.join("detector.csv"))?;
        let adaptive: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.1.is_some())
            .map(|r| (r.2, r.3 as f64))
            .collect();
        let fixed: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.1.is_none())
            .map(|r| (r.2, r.3 as f64))
            .collect();
        let mut series = Series::new("adaptive (phi 1 to 12)", BLUE, adaptive);
        // One note per point: thresholds that land on the same point share it.
        let mut notes: Vec<(String, (f64, f64))> = Vec::new();
        for r in rows.iter().filter(|r| r.1.is_some()) {
            let at = (r.2, r.3 as f64);
            let phi = r.1.unwrap_or_default();
            match notes.iter_mut().find(|(_, p)| *p == at) {
                Some((text, _)) => *text = format!("{text}, {phi}"),
                None => notes.push((format!("phi {phi}"), at)),
            }
        }
        series.notes = notes;
        let ymax = rows.iter().map(|r| r.3).max().unwrap_or(0) as f64 + 1.0;
        let xmax = rows.iter().map(|r| r.2).fold(0.0, f64::max) * 1.1;
        write_svg(
            out.join("detector.svg"),
            (800, 480),
            &[LineChart {
                title: format!(
                    "Host kill to new host (p95 of {kills}, loopback-like) vs false alarms ({minutes} min, 150 ms ± 30 ms, 20 % loss)"
                ),
                x_desc: "p95 detection + takeover (ms)".to_owned(),
                y_desc: "false host changes and drops".to_owned(),
                x_range: 0.0..xmax,
                x_log: false,
                y_range: 0.0..ymax,
                series: vec![series, Series::new("fixed 1 s timeout", RED, fixed)],
                style: ChartStyle::FIGURE,
            }],
        )?;
    }
    for (label, phi, p95, alarms, stall_alarms) in &rows {
        let default = *phi == Some(9.0);
        if phi.is_none() || default {
            println!(
                "{}",
                ResultLine::new("wild.migration")
                    .field("detector", if default { "default" } else { "fixed" })
                    .field("where", "harness")
                    .fixed("p95_ms", *p95, 0)
                    .field("false_alarms", alarms)
                    .field("stall_false_alarms", stall_alarms)
                    .field("minutes", minutes)
                    .field("label", label.replace(' ', "_"))
            );
        }
    }
    Ok(())
}
