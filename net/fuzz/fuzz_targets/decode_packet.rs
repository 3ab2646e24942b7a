//! Fuzz the datagram decoder and a live session with arbitrary bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    softsync_net::fuzzing::decode_all(data);
});
