//! `softsync-bench`: the framework's benchmarks that are not product code.
//!
//! ```text
//! softsync-bench frame [--quick] [--out DIR] [--assets DIR]
//! softsync-bench join [--joins N] [--build LABEL=PATH]... [--out DIR]
//! ```
//! `frame`: the frame-budget room ([`softsync_bench::frame`]); writes `frame.csv`, `frame.svg`,
//! `spikes.md` and `RESULT.txt` under `docs/results/frame/` (or `--out`) and prints the RESULT
//! lines.
//!
//! `join`: where a join's time goes ([`softsync_bench::join`]), for each `--build` (default:
//! the `softsync` binary beside this one, labelled `this`); writes `join.csv`, `join.md` and
//! `join.txt` under `docs/results/live/` (or `--out`). Run it in a network namespace
//! (`scripts/bench-net-live --join`).
#![allow(clippy::print_stdout)]

use std::path::PathBuf;
use std::process::ExitCode;

use softsync_bench::frame::{self, FramePlan};

const USAGE: &str = "usage: softsync-bench frame [--quick] [--out DIR] [--assets DIR]\n\
       softsync-bench join [--joins N] [--build LABEL=PATH]... [--out DIR]\n\
  frame    the frame-budget room: 4 peers in one process, 11 soft bodies, two hands on one,\n\
           a tear every 2 s, a cut every 10 s, the host stopped at 30 s; 60 s measured\n\
           (--quick: 8 s, every kind of event in it)\n\
  join     where a join's time goes: one `softsync host`, N joiners in turn (default 20), each\n\
           to its first state; per build (default: the softsync binary beside this one)";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("softsync-bench: {e}\n{USAGE}");
            ExitCode::from(2)
        }
    }
}

fn run(args: &[String]) -> Result<(), String> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut assets = root.join("assets");
    let mut out = root.join("docs/results/frame");
    let mut quick = false;
    let mut it = args.iter();
    match it.next().map(String::as_str) {
        Some("frame") => {}
        Some("join") => return run_join(&root, it.as_slice()),
        Some("-h" | "--help") => {
            println!("{USAGE}");
            return Ok(());
        }
        Some(other) => return Err(format!("unknown bench `{other}`")),
        None => return Err("which bench?".into()),
    }
    while let Some(a) = it.next() {
        match a.as_str() {
            "--quick" => quick = true,
            "--out" => out = it.next().ok_or("--out needs a directory")?.into(),
            "--assets" => assets = it.next().ok_or("--assets needs a directory")?.into(),
            other => return Err(format!("unknown option `{other}`")),
        }
    }
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
    Ok(())
}

fn run_join(root: &std::path::Path, args: &[String]) -> Result<(), String> {
    use softsync_bench::join::{self, JoinPlan};
    let mut out = root.join("docs/results/live");
    let mut joins = 20usize;
    let mut builds: Vec<(String, PathBuf)> = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--out" => out = it.next().ok_or("--out needs a directory")?.into(),
            "--joins" => {
                joins = it
                    .next()
                    .and_then(|v| v.parse().ok())
                    .filter(|n| (1..=1000).contains(n))
                    .ok_or("--joins needs a count, 1-1000")?
            }
            "--build" => {
                let b = it.next().ok_or("--build needs LABEL=PATH")?;
                let (label, path) = b.split_once('=').ok_or("--build needs LABEL=PATH")?;
                builds.push((label.to_owned(), path.into()));
            }
            other => return Err(format!("unknown option `{other}`")),
        }
    }
    if builds.is_empty() {
        let exe = std::env::current_exe().map_err(|e| e.to_string())?;
        let beside = exe.with_file_name("softsync");
        builds.push(("this".to_owned(), beside));
    }
    let scratch = std::env::temp_dir().join(format!("softsync-bench-join-{}", std::process::id()));
    let mut reports = Vec::new();
    for (label, softsync) in builds {
        if !softsync.is_file() {
            return Err(format!("{}: no such binary (build it: cargo build -p softsync)", softsync.display()));
        }
        let plan = JoinPlan {
            softsync,
            joins,
            label: label.clone(),
            scratch: scratch.join(&label),
        };
        let r = join::run(&plan)?;
        eprintln!("{label}: {} joins in {:.1} s", r.joins.len(), r.took.as_secs_f64());
        reports.push(r);
    }
    let lines = join::write(&reports, &out)?;
    let _ = std::fs::remove_dir_all(&scratch);
    for l in lines {
        println!("{l}");
    }
    Ok(())
}
