//! `softsync-bench`: the framework's benchmarks that are not product code.
//!
//! ```text
//! softsync-bench frame [--quick] [--out DIR] [--assets DIR]
//! ```
//! `frame`: the frame-budget room ([`softsync_bench::frame`]); writes `frame.csv`, `frame.svg`,
//! `spikes.md` and `RESULT.txt` under `docs/results/frame/` (or `--out`) and prints the RESULT
//! lines.
#![allow(clippy::print_stdout)]

use std::path::PathBuf;
use std::process::ExitCode;

use softsync_bench::frame::{self, FramePlan};

const USAGE: &str = "usage: softsync-bench frame [--quick] [--out DIR] [--assets DIR]\n\
  frame    the frame-budget room: 4 peers in one process, 11 soft bodies, two hands on one,\n\
           a tear every 2 s, a cut every 10 s, the host stopped at 30 s; 60 s measured\n\
           (--quick: 8 s, every kind of event in it)";

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
