//! Cross-crate tests live in `tests/tests/`: the interaction, soft-body and network crates
//! wired together in-process as the app will wire them (the multi-process WebRTC tests of the
//! `softsync` binary will join them here).
