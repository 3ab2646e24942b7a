//! Fuzz whole sessions: the bytes are a script of steps played by a room of honest sessions
//! and a hostile peer on virtual time (`softsync_net::fuzzing::play_session`); every broken
//! invariant (two owners, a footprint over its cap, a non-finite state, a panic) is a crash.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    softsync_net::fuzzing::play_session(data);
});
