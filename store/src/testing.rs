//! A PostgreSQL server of its own, for a test or a bench (feature `testing`): Debian's package (`.ci/run` installs it), a cluster made
//! by `initdb` in a scratch folder, listening on a unix socket only (no TCP), run as the
//! `postgres` user (PostgreSQL refuses to run as root, and CI runs as root), stopped and
//! removed when the guard goes.

#![allow(clippy::disallowed_methods)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running server and the database `room` in it.
#[derive(Debug)]
pub struct PgCluster {
    dir: PathBuf,
    bin: PathBuf,
    child: Option<Child>,
    /// `postgresql://postgres@/room?host=SOCKET_DIR`.
    pub url: String,
}

fn bin_dir() -> Result<PathBuf, String> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .map(|r| {
            r.filter_map(|e| e.ok())
                .map(|e| e.path().join("bin"))
                .collect()
        })
        .unwrap_or_default();
    dirs.retain(|d| d.join("initdb").exists());
    dirs.sort();
    dirs.pop().ok_or_else(|| {
        "PostgreSQL is not installed (Debian's postgresql package; .ci/run installs it)".into()
    })
}

fn as_postgres(bin: &Path, program: &str) -> Command {
    let mut c = Command::new("runuser");
    c.args(["-u", "postgres", "--"]).arg(bin.join(program));
    c
}

impl PgCluster {
    /// initdb, start, wait for the socket, create the database `room`; the reason if
    /// PostgreSQL is not installed or will not start.
    pub fn start(name: &str) -> Result<PgCluster, String> {
        let bin = bin_dir()?;
        let dir = std::env::temp_dir().join(format!("softsync-pg-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let io = |what: &str| {
            let what = what.to_owned();
            move |e: std::io::Error| format!("{what}: {e}")
        };
        std::fs::create_dir_all(dir.join("sock")).map_err(io("the cluster's folder"))?;
        let ok = Command::new("chown")
            .args(["-R", "postgres:postgres"])
            .arg(&dir)
            .status()
            .map_err(io("chown"))?
            .success();
        if !ok {
            return Err(format!("chown {} to postgres failed", dir.display()));
        }
        let out = as_postgres(&bin, "initdb")
            .args(["-A", "trust", "-U", "postgres", "--no-sync", "-D"])
            .arg(dir.join("data"))
            .output()
            .map_err(io("initdb"))?;
        if !out.status.success() {
            return Err(format!("initdb: {}", String::from_utf8_lossy(&out.stderr)));
        }
        let mut s = PgCluster {
            url: format!(
                "postgresql://postgres@/room?host={}",
                dir.join("sock").display()
            ),
            dir,
            bin,
            child: None,
        };
        s.run()?;
        let admin = format!(
            "postgresql://postgres@/postgres?host={}",
            s.dir.join("sock").display()
        );
        postgres::Client::connect(&admin, postgres::NoTls)
            .and_then(|mut c| c.batch_execute("CREATE DATABASE room"))
            .map_err(|e| format!("creating the database: {e}"))?;
        Ok(s)
    }

    /// Start (again) on the same cluster and wait until it takes connections.
    pub fn run(&mut self) -> Result<(), String> {
        let log = std::fs::File::create(self.dir.join("server.log"))
            .map_err(|e| format!("server.log: {e}"))?;
        let child = as_postgres(&self.bin, "postgres")
            .arg("-D")
            .arg(self.dir.join("data"))
            .arg("-k")
            .arg(self.dir.join("sock"))
            .args(["-c", "listen_addresses=", "-c", "fsync=off"])
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .map_err(|e| format!("postgres: {e}"))?;
        self.child = Some(child);
        let admin = format!(
            "postgresql://postgres@/postgres?host={}",
            self.dir.join("sock").display()
        );
        let t0 = Instant::now();
        loop {
            if postgres::Client::connect(&admin, postgres::NoTls).is_ok() {
                return Ok(());
            }
            if t0.elapsed() > Duration::from_secs(30) {
                return Err(format!(
                    "PostgreSQL did not start: {}",
                    std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default()
                ));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Stop the server (fast shutdown: open connections are closed) and wait for it.
    pub fn stop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = as_postgres(&self.bin, "pg_ctl")
                .args(["stop", "-m", "fast", "-w", "-D"])
                .arg(self.dir.join("data"))
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status();
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

impl Drop for PgCluster {
    fn drop(&mut self) {
        self.stop();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
