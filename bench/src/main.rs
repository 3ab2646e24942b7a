//! `softsync-bench`: the framework's benchmarks, out of the product binary.
//!
//! ```text
//! softsync-bench frame [--quick]            the frame-budget room, in one process
//! softsync-bench join [--build L=PATH]...   where a join's time goes
//! softsync-bench store [--postgres URL]      the room store: reopen, and writing as it runs
//! softsync-bench net-live | room-load | comanip | abuse | signal-lb | soak | auto
//! ```
//! Each writes its CSV, charts and `RESULT` lines under `docs/results/` (or `--out`); the
//! live ones run rooms of the `softsync` binary beside this one (or `SOFTSYNC_BIN`) on real
//! WebRTC, so run them in a network namespace (the `scripts/bench-*` do). `--help` on each
//! says more.
#![allow(clippy::print_stdout)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Parser;
use softsync_bench::cli::{Cli, Route, Sub};
use softsync_bench::frame::{self, FramePlan};
use softsync_bench::join::{self, JoinPlan};
use softsync_bench::live;

/// `store`: reopen and write, SQLite and PostgreSQL side by side.
fn run_store(
    out: &Path,
    postgres: Option<String>,
    rounds: usize,
    seconds: f64,
    runs: usize,
    assets: Option<PathBuf>,
) -> Result<(), String> {
    use softsync_bench::store;
    let assets = assets.unwrap_or_else(softsync_bench::assets_dir);
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let cluster = match postgres {
        Some(_) => None,
        None => Some(softsync_store::testing::PgCluster::start("bench")?),
    };
    let pg =
        postgres.unwrap_or_else(|| cluster.as_ref().map(|c| c.url.clone()).unwrap_or_default());
    let sqlite = store::scratch_sqlite("store");
    let backends: store::Backends =
        vec![("sqlite", sqlite.display().to_string()), ("postgres", pg)];
    let mut lines = store::reopen(&assets, &backends, runs, out)?;
    lines.extend(store::seek(&assets, &backends, 10.0, 200, out)?);
    lines.extend(store::write(&assets, &backends, rounds, seconds, out)?);
    let text: Vec<String> = lines.iter().map(ToString::to_string).collect();
    for l in &text {
        println!("{l}");
    }
    std::fs::write(out.join("RESULT.txt"), text.join("\n") + "\n")
        .map_err(|e| format!("RESULT.txt: {e}"))?;
    drop(cluster);
    let _ = std::fs::remove_file(&sqlite);
    Ok(())
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    match run(cli.bench) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("softsync-bench: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Runs one bench; false when it ran and found a failure (a soak's violation, a room the load
/// balancer lost).
fn run(bench: Sub) -> Result<bool, String> {
    match bench {
        Sub::Frame { out, quick, assets } => {
            let assets = assets.unwrap_or_else(softsync_bench::assets_dir);
            let plan = if quick {
                FramePlan::quick(&assets)
            } else {
                FramePlan::full(&assets)
            };
            let report = frame::run(&plan)?;
            for w in report.warnings.iter().take(20) {
                eprintln!("warning: {w}");
            }
            let lines = report.write(&out)?;
            println!("{}", report.spikes_md(10));
            for l in lines {
                println!("{l}");
            }
        }
        Sub::Join { out, joins, builds } => run_join(&out, usize::from(joins), builds)?,
        Sub::NetLive {
            out,
            seconds,
            quick,
            centre_only,
        } => {
            if centre_only {
                live::centre_only_live(&out, seconds)?;
            } else {
                live::net_live(&out, seconds, quick)?;
            }
        }
        Sub::Auto {
            out,
            seconds,
            assets,
        } => {
            let assets = assets.unwrap_or_else(softsync_bench::assets_dir);
            live::auto(&out, seconds, &assets)?;
        }
        Sub::Comanip { out, quick } => live::comanip(&out, quick)?,
        Sub::Store {
            out,
            postgres,
            rounds,
            seconds,
            runs,
            assets,
        } => run_store(&out, postgres, rounds.into(), seconds, runs.into(), assets)?,
        Sub::RoomClock { out, seconds } => live::room_clock(&out, seconds)?,
        Sub::Voice { out, quick } => live::voice(&out, quick)?,
        Sub::VoiceProcessing { out } => live::voice_processing(&out)?,
        Sub::Abuse {
            out,
            seconds,
            attacks,
            hostile,
        } => {
            let attacks = attacks.map_or_else(
                || live::ATTACKS.iter().map(|a| a.to_string()).collect(),
                |a| a.0,
            );
            let hostile = hostile.unwrap_or_else(|| beside("softsync-hostile"));
            live::abuse(&out, seconds, &attacks, &hostile)?;
        }
        Sub::RoomLoad {
            out,
            seconds,
            peers,
            state_route,
            builds,
            rounds,
        } => live::room_load(
            &out,
            seconds,
            &peers.0,
            state_route == Route::Direct,
            &builds,
            usize::from(rounds),
        )?,
        Sub::SignalLb {
            out,
            rooms,
            real_rooms,
            parallel,
            config,
        } => {
            let plan = live::LbPlan {
                rooms: usize::from(rooms),
                real_rooms: usize::from(real_rooms),
                config,
                parallel: usize::from(parallel),
            };
            return live::signal_lb(&out, &plan);
        }
        Sub::Soak {
            out,
            minutes,
            seed,
            peers,
            max_peers,
            busy_loops,
        } => {
            if max_peers < peers {
                return Err(format!(
                    "--max-peers {max_peers} is less than --peers {peers}"
                ));
            }
            let plan = live::SoakPlan {
                seconds: minutes * 60.0,
                seed,
                start_peers: usize::from(peers),
                max_peers: usize::from(max_peers),
                min_running: 3.min(usize::from(peers)),
                busy_loops: usize::from(busy_loops),
            };
            return Ok(live::soak(&out, &plan)? == 0);
        }
    }
    Ok(true)
}

/// A binary beside this one (cargo builds every binary of the workspace into one directory).
fn beside(name: &str) -> PathBuf {
    std::env::current_exe()
        .map(|e| e.with_file_name(name))
        .unwrap_or_else(|_| PathBuf::from(name))
}

fn run_join(out: &Path, joins: usize, mut builds: Vec<(String, PathBuf)>) -> Result<(), String> {
    if builds.is_empty() {
        builds.push(("this".to_owned(), live::softsync_binary()?));
    }
    let scratch = std::env::temp_dir().join(format!("softsync-bench-join-{}", std::process::id()));
    let mut reports = Vec::new();
    for (label, softsync) in builds {
        if !softsync.is_file() {
            return Err(format!(
                "{}: no such binary (build it: cargo build -p softsync)",
                softsync.display()
            ));
        }
        let plan = JoinPlan {
            softsync,
            joins,
            label: label.clone(),
            scratch: scratch.join(&label),
        };
        let r = join::run(&plan)?;
        eprintln!(
            "{label}: {} joins in {:.1} s",
            r.joins.len(),
            r.took.as_secs_f64()
        );
        reports.push(r);
    }
    let lines = join::write(&reports, out)?;
    let _ = std::fs::remove_dir_all(&scratch);
    for l in lines {
        println!("{l}");
    }
    Ok(())
}
