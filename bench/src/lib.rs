//! `softsync-bench`: benchmarks of the softsync framework that users' binaries do not carry.
//!
//! - [`frame`]: the frame-budget room — four peers in one process, eleven soft bodies, two
//!   hands on one body, a tear stroke every 2 s, a cut every 10 s, a host migration —
//!   and where each frame's time goes.
//! - [`join`]: where a join's time goes, on real WebRTC between `softsync` processes.
//! - [`live`]: rooms of real `softsync` processes on real WebRTC: the thesis's tables, rooms of
//!   growing size, several hands on one body, a room under attack, signaling behind a load
//!   balancer, the churn soak; and `method: auto` in one process.
//! - [`store`]: the room store — reopening a torn room, and what writing it costs the frame,
//!   SQLite and PostgreSQL side by side.
//! - [`cli`]: the command line.

pub mod cli;
pub mod frame;
pub mod join;
pub mod live;
pub mod store;

/// The repository's `assets/` (the shipped scenes and meshes the benches load).
pub fn assets_dir() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("assets")
}

/// Wall-clock seconds since the first call: the one clock the in-process benches read (the
/// frame bench lends it to its peers as their stopwatch; `method: auto` probes with it).
#[allow(clippy::disallowed_methods)]
pub fn wall_s() -> f64 {
    static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_secs_f64()
}
