//! `softsync-bench`: benchmarks of the softsync framework that users' binaries do not carry.
//!
//! - [`frame`]: the frame-budget room — four peers in one process, eleven soft bodies, two
//!   hands on one body, a tear stroke every 2 s, a cut every 10 s, a host migration —
//!   and where each frame's time goes.

//! - [`join`]: where a join's time goes, on real WebRTC between `softsync` processes.

pub mod frame;
pub mod join;
