//! `SOFTSYNC_LOG=LEVEL[,PREFIX…]`: the `log` records of the libraries under us (the WebRTC
//! stack: ICE candidates and pairs, TURN allocations, DTLS) on stderr, for a connection that
//! will not come up. `SOFTSYNC_LOG=debug,rtc_ice,webrtc` keeps those crates' records at debug
//! and above; without prefixes every crate's. Unset: nothing is installed (the desktop front
//! end's bevy logger may take `log` instead).

use log::{Level, Log, Metadata, Record};

struct StderrLog {
    level: Level,
    prefixes: Vec<String>,
}

impl Log for StderrLog {
    fn enabled(&self, m: &Metadata<'_>) -> bool {
        m.level() <= self.level
            && (self.prefixes.is_empty() || self.prefixes.iter().any(|p| m.target().starts_with(p)))
    }

    fn log(&self, r: &Record<'_>) {
        if self.enabled(r.metadata()) {
            eprintln!("log {} {}: {}", r.level(), r.target(), r.args());
        }
    }

    fn flush(&self) {}
}

/// Installs the logger if SOFTSYNC_LOG names a level (error, warn, info, debug, trace).
pub fn install() {
    let Ok(spec) = std::env::var("SOFTSYNC_LOG") else {
        return;
    };
    let mut parts = spec.split(',').map(str::trim);
    let Some(level) = parts.next().and_then(|l| l.parse::<Level>().ok()) else {
        eprintln!("SOFTSYNC_LOG={spec:?}: expected LEVEL[,PREFIX…] with LEVEL error…trace");
        return;
    };
    let prefixes = parts.filter(|p| !p.is_empty()).map(str::to_owned).collect();
    if log::set_boxed_logger(Box::new(StderrLog { level, prefixes })).is_ok() {
        log::set_max_level(level.to_level_filter());
    }
}
