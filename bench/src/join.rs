//! `softsync-bench join`: where a join's time goes, on real WebRTC between real `softsync`
//! processes (issue 34, point 4).
//!
//! One host (`softsync host`, its embedded signaling server) and `joins` joiners, one after
//! another, each a fresh `softsync join` without a scene of its own: it fetches the room's
//! scene, says Hello, is welcomed and shows the room's first state, then leaves. Each joiner
//! runs with `SOFTSYNC_LOG` naming the WebRTC stack's few records that mark its steps; records
//! and the joiner's own `join timeline ms:` line carry milliseconds since the process started,
//! so one clock lines them up:
//!
//! | phase | from → to |
//! |---|---|
//! | `signaling` | connecting starts → the signaling server assigns our id |
//! | `offer` | id → the room's offer arrives (the host's turn: it offers to each new socket) |
//! | `ice` | offer → ICE connected (answer, candidates, connectivity checks, nomination) |
//! | `dtls` | ICE connected → DTLS handshake complete |
//! | `channel` | DTLS → our first data channel open and identified (SCTP, channel open) |
//! | `scene` | channel → the room's scene fetched and verified |
//! | `welcome` | scene → the Welcome taken (room built, Hello, the host's answer) |
//! | `first_state` | Welcome → the first frame that shows an object of the room |
//!
//! Run it inside a network namespace (`scripts/bench-net-live --join`): on a namespace with only
//! loopback, the way the tests run.

#![allow(clippy::disallowed_methods)] // real processes on the wall clock: clocks, sleeps

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use softsync_benchkit::output::{Csv, ResultLine};
use softsync_benchkit::stats::median;

/// The WebRTC stack's records that mark a join's steps (debug level, these targets only).
const LOG_SPEC: &str = "debug,matchbox_socket::webrtc_socket,rtc_ice::agent,rtc_dtls::handshaker";

/// The phases, in order (see the module's table).
pub const PHASES: [&str; 8] = [
    "signaling",
    "offer",
    "ice",
    "dtls",
    "channel",
    "scene",
    "welcome",
    "first_state",
];

/// What to run.
#[derive(Clone, Debug)]
pub struct JoinPlan {
    /// The `softsync` binary under test.
    pub softsync: PathBuf,
    /// Joins measured (one after another).
    pub joins: usize,
    /// A name for the build, written into the RESULT line (`build=`).
    pub label: String,
    /// Scratch directory: the peers' output and the joiners' scene cache.
    pub scratch: PathBuf,
}

/// One join, phase by phase (ms).
#[derive(Clone, Debug, PartialEq)]
pub struct Breakdown {
    /// Each phase of [`PHASES`], in order.
    pub phases: [f64; 8],
    /// Start to first state.
    pub total: f64,
}

/// The marks of one joiner's output, in ms since its start; `None` for a missing mark.
fn parse(stdout: &str, stderr: &str) -> Result<Breakdown, String> {
    let timeline = stdout
        .lines()
        .find_map(|l| l.strip_prefix("join timeline ms:"))
        .ok_or("the joiner printed no `join timeline ms:` line (a build before the timeline?)")?;
    let mark = |name: &str| -> Option<f64> {
        timeline.split_whitespace().find_map(|kv| {
            let (k, v) = kv.split_once('=')?;
            (k == name).then(|| v.parse().ok()).flatten()
        })
    };
    // `log <ms> LEVEL target: message`: the first record whose message holds `needle`
    let record = |needle: &str| -> Option<f64> {
        stderr.lines().find_map(|l| {
            let rest = l.strip_prefix("log ")?;
            if !rest.contains(needle) {
                return None;
            }
            rest.split_whitespace().next()?.parse().ok()
        })
    };
    let need =
        |what: &str, v: Option<f64>| v.ok_or(format!("no {what} mark in the joiner's output"));
    let start = need("start", mark("start"))?;
    // matchbox's own record of the id, when there: the room's `registered` mark is taken
    // when `connect` next polls for it (every 5 ms), sometimes after the offer came
    let registered = need("registered", record("IdAssigned(").or(mark("registered")))?;
    let offer = need("offer", record("received offer"))?;
    let ice = need(
        "ICE connected",
        record("Setting new connection state: Connected"),
    )?;
    let dtls = need("DTLS", record("] is completed"))?;
    let contact = need("contact", mark("contact"))?;
    let scene = mark("scene").unwrap_or(contact);
    let welcome = need("welcome", mark("welcome"))?;
    let first = need("first_state", mark("first_state"))?;
    let marks = [
        start, registered, offer, ice, dtls, contact, scene, welcome, first,
    ];
    let mut phases = [0.0; 8];
    for (i, p) in phases.iter_mut().enumerate() {
        *p = marks[i + 1] - marks[i];
    }
    Ok(Breakdown {
        phases,
        total: first - start,
    })
}

struct Host {
    child: Child,
    url: String,
}

impl Drop for Host {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_host(plan: &JoinPlan, room: &str) -> Result<Host, String> {
    let mut child = Command::new(&plan.softsync)
        .args(["host", "--room", room, "--bind", "127.0.0.1:0", "--quiet"])
        .args(["--duration", "900"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("{}: {e}", plan.softsync.display()))?;
    let out = child.stdout.take().ok_or("no host stdout")?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut sent = false;
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if let (false, Some(url)) = (sent, line.strip_prefix("signaling on ")) {
                let _ = tx.send(url.trim().to_owned());
                sent = true;
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(60))
        .map_err(|_| "the host printed no `signaling on` line within 60 s".to_owned())?;
    Ok(Host { child, url })
}

fn one_join(plan: &JoinPlan, host: &Host, room: &str, i: usize) -> Result<Breakdown, String> {
    let cache = plan.scratch.join(format!("cache{i}"));
    let out = Command::new(&plan.softsync)
        .args(["join", "--room", room, "--signal", &host.url, "--quiet"])
        .args(["--duration", "0.5", "--connect-timeout", "20"])
        .env("SOFTSYNC_LOG", LOG_SPEC)
        .env("XDG_CACHE_HOME", &cache)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("{}: {e}", plan.softsync.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let _ = std::fs::write(plan.scratch.join(format!("join{i}.out")), stdout.as_bytes());
    let _ = std::fs::write(plan.scratch.join(format!("join{i}.err")), stderr.as_bytes());
    let _ = std::fs::remove_dir_all(&cache);
    if !out.status.success() {
        return Err(format!(
            "join {i} exited with {}: {}",
            out.status,
            stderr.lines().rev().take(3).collect::<Vec<_>>().join(" / ")
        ));
    }
    parse(&stdout, &stderr).map_err(|e| format!("join {i}: {e}"))
}

/// What a run measured.
#[derive(Clone, Debug)]
pub struct JoinReport {
    /// The build's name.
    pub label: String,
    /// The `softsync` binary measured.
    pub binary: PathBuf,
    /// Every join.
    pub joins: Vec<Breakdown>,
    /// Wall time of the run.
    pub took: Duration,
}

/// Run `plan`: one host, `plan.joins` joiners in turn.
pub fn run(plan: &JoinPlan) -> Result<JoinReport, String> {
    std::fs::create_dir_all(&plan.scratch).map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let room = "joinbench";
    let host = start_host(plan, room)?;
    // the host's own start (scene, signaling) is not a join's
    std::thread::sleep(Duration::from_millis(500));
    let mut joins = Vec::new();
    for i in 0..plan.joins {
        joins.push(one_join(plan, &host, room, i)?);
        // the host times the leaver out of its books before the next one comes
        std::thread::sleep(Duration::from_millis(100));
    }
    drop(host);
    Ok(JoinReport {
        label: plan.label.clone(),
        binary: plan.softsync.clone(),
        joins,
        took: t0.elapsed(),
    })
}

impl JoinReport {
    /// The median of each phase and of the total.
    pub fn medians(&self) -> ([f64; 8], f64) {
        let mut m = [0.0; 8];
        for (k, v) in m.iter_mut().enumerate() {
            *v = median(&self.joins.iter().map(|j| j.phases[k]).collect::<Vec<_>>());
        }
        (
            m,
            median(&self.joins.iter().map(|j| j.total).collect::<Vec<_>>()),
        )
    }

    /// `RESULT join.breakdown build=… joins=… signaling_ms=… … first_state_ms=… total_ms=…`
    /// (medians; `first_state_ms` the phase, `total_ms` start to first state).
    pub fn result_line(&self) -> ResultLine {
        let (m, total) = self.medians();
        let mut l = ResultLine::new("join.breakdown")
            .field("build", &self.label)
            .field("joins", self.joins.len());
        for (name, v) in PHASES.iter().zip(m) {
            l = l.fixed(&format!("{name}_ms"), v, 1);
        }
        l.fixed("total_ms", total, 1)
    }

    /// Every join's row (appended to `csv`, whose header is [`csv_header`]).
    pub fn rows(&self, csv: &mut Csv) {
        for (i, j) in self.joins.iter().enumerate() {
            let mut row = vec![self.label.clone(), i.to_string()];
            row.extend(j.phases.iter().map(|v| format!("{v:.1}")));
            row.push(format!("{:.1}", j.total));
            csv.row(row);
        }
    }
}

/// The CSV's columns: build, join, each phase, total.
pub fn csv_header() -> Vec<String> {
    let mut h = vec!["build".to_owned(), "join".to_owned()];
    h.extend(PHASES.iter().map(|p| format!("{p}_ms")));
    h.push("total_ms".to_owned());
    h
}

/// Writes `join.csv`, `join.md` and `join.txt` (the RESULT lines) under `out`; returns the
/// lines.
pub fn write(reports: &[JoinReport], out: &Path) -> Result<Vec<String>, String> {
    std::fs::create_dir_all(out).map_err(|e| e.to_string())?;
    let header = csv_header();
    let mut csv = Csv::new(&header.iter().map(String::as_str).collect::<Vec<_>>());
    let mut md = String::from(
        "# Where a join's time goes (issue 34, point 4)\n\n\
         Generated by `scripts/bench-net-live --join` (= `softsync-bench join` in a network \
         namespace with only loopback): one `softsync host`, then joiners one after another, \
         each without a scene (it fetches the room's), to the first frame that shows the \
         room's state. Phases from the joiner's `join timeline ms:` line and the WebRTC \
         stack's records (`SOFTSYNC_LOG`), on one clock; medians, ms. The phases are defined \
         in `bench/src/join.rs`.\n\n| build | joins |",
    );
    for p in PHASES {
        md += &format!(" {p} |");
    }
    md += " total |\n|---|---:|";
    for _ in PHASES {
        md += "---:|";
    }
    md += "---:|\n";
    let mut lines = Vec::new();
    for r in reports {
        r.rows(&mut csv);
        let (m, total) = r.medians();
        md += &format!("| {} | {} |", r.label, r.joins.len());
        for v in m {
            md += &format!(" {v:.1} |");
        }
        md += &format!(" **{total:.1}** |\n");
        lines.push(r.result_line().to_string());
    }
    md += "\nBuilds: ";
    md += &reports
        .iter()
        .map(|r| format!("`{}` = `{}`", r.label, r.binary.display()))
        .collect::<Vec<_>>()
        .join(", ");
    md += ".\n";
    md += "\nRESULT lines (`join.txt`):\n\n```text\n";
    for l in &lines {
        md += l;
        md += "\n";
    }
    md += "```\n";
    csv.write(out.join("join.csv")).map_err(|e| e.to_string())?;
    std::fs::write(out.join("join.md"), md).map_err(|e| e.to_string())?;
    std::fs::write(out.join("join.txt"), lines.join("\n") + "\n").map_err(|e| e.to_string())?;
    Ok(lines)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    const STDOUT: &str = "scene thesis-room from peer 1: 113633 bytes in 24 ms\n\
        join timeline ms: start=0.8 registered=6.4 contact=21.6 scene=81.6 opened=81.8 welcome=103.6 first_state=110.0\n";
    const STDERR: &str = "log 2.2 DEBUG matchbox_socket::webrtc_socket: IdAssigned(x)\n\
        log 8.6 DEBUG matchbox_socket::webrtc_socket::native: received offer\n\
        log 13.1 INFO rtc_ice::agent: [controlled]: Setting new connection state: Checking\n\
        log 13.1 INFO rtc_ice::agent: [controlled]: Setting new connection state: Connected\n\
        log 16.1 DEBUG rtc_dtls::handshaker: [handshake:client] is completed\n";

    #[test]
    fn phases_follow_the_marks() {
        let b = parse(STDOUT, STDERR).unwrap();
        let want = [1.4, 6.4, 4.5, 3.0, 5.5, 60.0, 22.0, 6.4];
        for (got, want) in b.phases.iter().zip(want) {
            assert!((got - want).abs() < 1e-9, "{:?}", b.phases);
        }
        assert!((b.total - 109.2).abs() < 1e-9);
        assert!((b.phases.iter().sum::<f64>() - b.total).abs() < 1e-9);
    }

    #[test]
    fn a_missing_mark_is_named() {
        let e = parse(STDOUT, "log 2.2 DEBUG x: received offer\n").unwrap_err();
        assert!(e.contains("ICE connected"), "{e}");
        let e = parse("connected to peer 1 after 1500 ms\n", STDERR).unwrap_err();
        assert!(e.contains("join timeline"), "{e}");
    }
}
