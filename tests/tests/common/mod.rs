//! Helpers shared by the multi-process tests: the `softsync` binary, scratch folders, child
//! processes killed when dropped, bounded waits on their output.
#![allow(
    dead_code,
    clippy::unwrap_used,
    clippy::disallowed_methods,
    missing_docs
)]

pub mod dump;
pub mod hub;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub fn binary() -> PathBuf {
    // target/<profile>/deps/live_rooms-… → target/<profile>/softsync
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().unwrap().parent().unwrap();
    let bin = dir.join("softsync");
    assert!(
        bin.exists(),
        "{} is missing: build it first (`cargo build -p softsync`; scripts/test does)",
        bin.display()
    );
    bin
}

/// The built `softsync-bench` (`target/<profile>/softsync-bench`): the benches' binary, which
/// runs rooms of [`binary`]'s processes.
pub fn bench_binary() -> PathBuf {
    let bin = binary().with_file_name("softsync-bench");
    assert!(
        bin.exists(),
        "{} is missing: build it first (`cargo build -p softsync-bench`; scripts/test does)",
        bin.display()
    );
    bin
}

/// A built example program of `softsync-bevy` (`target/<profile>/examples/NAME`).
pub fn example(name: &str) -> PathBuf {
    let bin = binary().parent().unwrap().join("examples").join(name);
    assert!(
        bin.exists(),
        "{} is missing: build it first (`cargo build -p softsync-bevy --example {name}`; \
         scripts/test does)",
        bin.display()
    );
    bin
}

/// A file of the repository, by its path from the root.
pub fn repo_file(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

pub fn require_netns() {
    assert_eq!(
        std::env::var("SOFTSYNC_IN_NETNS").as_deref(),
        Ok("1"),
        "these tests open WebRTC and must run inside scripts/netns-run (scripts/test does this)"
    );
}

/// Milliseconds on the wall clock (`Scene::probe_auto`'s timer).
pub fn wall_ms() -> f64 {
    static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_secs_f64() * 1e3
}

/// Runs `scripts/NAME ARGS` with the built binary (inside the test's own namespace): whether
/// it succeeded, and what it printed.
pub fn run_script(name: &str, args: &[&str], env: &[(&str, &str)]) -> (bool, String) {
    let out = Command::new("bash")
        .arg(repo_file(&format!("scripts/{name}")))
        .args(args)
        .env("SOFTSYNC_BIN", binary())
        .envs(env.iter().copied())
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

pub fn scratch(test: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("softsync-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A child process, killed (SIGKILL) when dropped.
pub struct Proc {
    /// For messages.
    pub name: String,
    /// The process.
    pub child: Child,
    /// Its stdout file.
    pub out: PathBuf,
    /// Its stderr file.
    pub err: PathBuf,
}

impl Proc {
    pub fn spawn(dir: &Path, name: &str, args: &[&str]) -> Proc {
        Self::spawn_env(dir, name, args, &[])
    }

    /// Spawn with extra environment variables.
    pub fn spawn_env(dir: &Path, name: &str, args: &[&str], env: &[(&str, &str)]) -> Proc {
        Self::spawn_program(dir, name, &binary(), args, env)
    }

    /// Spawn any program (a wrapper script around the binary, say).
    pub fn spawn_program(
        dir: &Path,
        name: &str,
        program: &Path,
        args: &[&str],
        env: &[(&str, &str)],
    ) -> Proc {
        let out = dir.join(format!("{name}.out"));
        let err = dir.join(format!("{name}.err"));
        let child = Command::new(program)
            .args(args)
            .envs(env.iter().copied())
            .stdout(Stdio::from(std::fs::File::create(&out).unwrap()))
            .stderr(Stdio::from(std::fs::File::create(&err).unwrap()))
            .spawn()
            .unwrap();
        Proc {
            name: name.to_owned(),
            child,
            out,
            err,
        }
    }

    pub fn stdout(&self) -> String {
        std::fs::read_to_string(&self.out).unwrap_or_default()
    }

    /// Its stdout and the tail of its stderr, for a failure message. A desktop peer's
    /// `screenshot` lines (one every half second) are cut to the last four, so that what a
    /// CI log keeps of a failure shows its events.
    pub fn logs(&self) -> String {
        let out = self.stdout();
        let shots = out.lines().filter(|l| l.starts_with("screenshot ")).count();
        let mut seen = 0;
        let kept: Vec<&str> = out
            .lines()
            .filter(|l| {
                if !l.starts_with("screenshot ") {
                    return true;
                }
                seen += 1;
                seen + 4 > shots
            })
            .collect();
        let cut = if shots > 4 {
            format!(" ({} earlier screenshot lines left out)", shots - 4)
        } else {
            String::new()
        };
        format!(
            "--- {} stdout{cut}\n{}\n--- {} stderr (tail)\n{}",
            self.name,
            kept.join("\n"),
            self.name,
            std::fs::read_to_string(&self.err)
                .unwrap_or_default()
                .lines()
                .rev()
                .take(15)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect::<Vec<_>>()
                .join("\n")
        )
    }

    /// Wait (bounded) until stdout has a line containing `needle`; return that line.
    pub fn wait_line(&self, needle: &str, within: Duration) -> String {
        let start = Instant::now();
        loop {
            if let Some(l) = self.stdout().lines().find(|l| l.contains(needle)) {
                return l.to_owned();
            }
            assert!(
                start.elapsed() < within,
                "{} printed no {needle:?} within {within:?}\n{}",
                self.name,
                self.logs()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Wait (bounded) for the process to exit; its exit code.
    pub fn wait_exit(&mut self, within: Duration) -> i32 {
        let start = Instant::now();
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s.code().unwrap_or(-1);
            }
            assert!(
                start.elapsed() < within,
                "{} did not exit within {within:?}\n{}",
                self.name,
                self.logs()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// The peer id it printed (`hosting …` / `joining …`).
    pub fn peer_id(&self) -> u64 {
        // 40 s: a debug binary starting beside other rooms' processes on a loaded 2-core
        // machine once took more than 20 s to print it
        let l = self.wait_line("peer=", Duration::from_secs(40));
        field(&l, "peer").parse().unwrap()
    }
}

impl Drop for Proc {
    /// A process still running when its test ends is asked to stop (SIGTERM), so that what it
    /// started stops too (`scripts/vr-sim` stops Monado on TERM, which a SIGKILL left running
    /// orphaned after every VR test), and killed if it is not gone within 8 s. A test that
    /// means a crash calls [`Proc::kill`].
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = Command::new("kill")
                .args(["-TERM", &self.child.id().to_string()])
                .status();
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(8) {
                if !matches!(self.child.try_wait(), Ok(None)) {
                    return;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        self.kill();
    }
}

/// A rollback peer's `rollback.check` lines: (epoch, frame) → checksum.
pub fn rollback_checks(p: &Proc) -> std::collections::BTreeMap<(u32, i64), String> {
    p.stdout()
        .lines()
        .filter(|l| l.starts_with("rollback.check "))
        .map(|l| {
            (
                (
                    field(l, "epoch").parse().unwrap(),
                    field(l, "frame").parse().unwrap(),
                ),
                field(l, "checksum").to_owned(),
            )
        })
        .collect()
}

pub fn field<'a>(line: &'a str, key: &str) -> &'a str {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{key}=")))
        .unwrap_or_else(|| panic!("no {key}= in {line:?}"))
}

/// A standalone signaling server on a free port, and its URL.
pub fn standalone_signal(dir: &Path) -> (Proc, String) {
    let p = Proc::spawn(dir, "signal", &["signal", "--bind", "127.0.0.1:0"]);
    let url = signal_url(&p);
    (p, url)
}

/// The signaling URL a process printed.
pub fn signal_url(p: &Proc) -> String {
    let l = p.wait_line("signaling on ", Duration::from_secs(10));
    l.trim_start_matches("signaling on ").trim().to_owned()
}

/// `softsync host --room ROOM --bind 127.0.0.1:0 --quiet EXTRA…` (signaling embedded), named
/// "host", and the signaling URL it prints.
pub fn embedded_host(dir: &Path, room: &str, extra: &[&str]) -> (Proc, String) {
    let mut args = vec!["host", "--room", room, "--bind", "127.0.0.1:0", "--quiet"];
    args.extend_from_slice(extra);
    let p = Proc::spawn(dir, "host", &args);
    let url = signal_url(&p);
    (p, url)
}

/// `softsync host|join --room ROOM --signal URL --quiet EXTRA…`, named `name`.
pub fn peer_on(
    dir: &Path,
    name: &str,
    command: &str,
    url: &str,
    room: &str,
    extra: &[&str],
) -> Proc {
    let mut args = vec![command, "--room", room, "--signal", url, "--quiet"];
    args.extend_from_slice(extra);
    Proc::spawn(dir, name, &args)
}

/// Send `sig` (`-TERM`, `-STOP`, …) to a child process.
pub fn send_signal(sig: &str, p: &Proc) {
    let status = Command::new("kill")
        .args([sig, &p.child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success(), "kill {sig}");
}
