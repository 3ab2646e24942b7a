//! `softsync-benchkit`: what softsync's benchmarks share.
