//! `SOFTSYNC_LOG=LEVEL[,PREFIX…]`: the `log` records of the libraries under us (the WebRTC
//! stack: ICE candidates and pairs, TURN allocations, DTLS) on stderr, for a connection that
//! will not come up. `SOFTSYNC_LOG=debug,rtc_ice,webrtc` keeps those crates' records at debug
//! and above; without prefixes every crate's. Unset: nothing is installed (the desktop front
//! end's bevy logger may take `log` instead).
//!
//! Each record carries the milliseconds since the process started ([`since_start_ms`]), the
//! clock the join timeline is printed on too: `softsync bench join` lines the two up to say
//! where a join's time goes (ICE, DTLS) inside the WebRTC stack.

use std::sync::OnceLock;
use std::time::Instant;

use log::{Level, Log, Metadata, Record};

static START: OnceLock<Instant> = OnceLock::new();

/// Milliseconds since the process started (since [`install`], which `main` calls first).
pub fn since_start_ms() -> f64 {
    START.get_or_init(Instant::now).elapsed().as_secs_f64() * 1e3
}

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
            eprintln!(
                "log {:.1} {} {}: {}",
                since_start_ms(),
                r.level(),
                r.target(),
                r.args()
            );
        }
    }

    fn flush(&self) {}
}

/// Installs the logger if SOFTSYNC_LOG names a level (error, warn, info, debug, trace).
pub fn install() {
    START.get_or_init(Instant::now);
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
