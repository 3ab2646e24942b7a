//! `softsync-bench`: benchmarks of the softsync framework that users' binaries do not carry.
//!
//! - [`frame`]: the frame-budget room — four peers in one process, eleven soft bodies, two
//!   hands on one body, a tear stroke every 2 s, a cut every 10 s, a host migration —
//!   and where each frame's time goes.

pub mod frame;
