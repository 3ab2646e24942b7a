//! Entry points shared by the cargo-fuzz targets (`net/fuzz`) and the stable tests
//! (`net/tests/fuzz_sessions.rs`): arbitrary bytes fed to every decoder and to a joined pair
//! ([`decode_all`]), and bytes read as a script that plays a whole room of sessions over
//! virtual time with a hostile peer in it ([`play_session`]). Every broken invariant panics,
//! so libFuzzer reports it with its input.

//!
//! Laid out as: this file (the decoders' entry point), `script.rs` (the script: setup, steps,
//! checks and the entry points that play it), `room.rs` (the room of sessions a script plays
//! in), `checks.rs` (the invariants checked after each step, the hostile peer's forgeries),
//! `seeds.rs` (the seed scripts), `corpus.rs` (the committed corpora and the known issues'
//! scripts).

mod checks;
mod corpus;
mod room;
mod script;
mod seeds;

pub use corpus::{fixed_issue_scripts, known_issue_scripts, seed_corpus};
pub use script::*;
pub use seeds::seed_scripts;
#[allow(unused_imports)] // what the submodules share, through `use super::*`
use {checks::*, corpus::*, room::*, seeds::*};

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use glam::{Quat, Vec3};

use crate::ids::{AuthorityEpoch, ClassId, NetId, PeerId, Term};
use crate::policy::{
    AuthorityPolicy, ClassConfig, MessageConfig, SendPolicy, SessionConfig, SoftBodyMode,
    StateRoute,
};
use crate::rng::SeededRng;
use crate::session::{Event, ObjectState, RoomKey, Session};
use crate::time::Instant;
use crate::wire::{
    decode_packet, decode_state_block, encode_beacon, AppMessage, Control, Delivery, DenyReason,
    EntryLayout, MessageKind, MessageRefusal, MessageTarget, PacketHeader, PacketWriter,
    RoomSummary, RoomToken, Section, SpawnInfo, TopologyEvent, PROTOCOL_VERSION,
};

/// Decode `data` every way we can; asserts that decoded state stays finite.
pub fn decode_all(data: &[u8]) {
    let class = ClassConfig::soft_body("fuzz", SendPolicy::default(), SoftBodyMode::Particles);
    let layout = EntryLayout {
        class: &class,
        particles: 300,
        generation: 0,
    };
    let _ = Control::decode(data);
    let _ = decode_state_block(64, data, |_| Some(layout));
    // The scene-sharing datagrams: the decoder, a server and a fetch fed the bytes as they
    // are and behind the share marker.
    let mut shared = vec![crate::share::SHARE_MARKER];
    shared.extend_from_slice(data);
    for bytes in [data, &shared[..]] {
        let _ = crate::share::ShareMsg::decode(bytes);
        let mut server = crate::share::BlobServer::new(vec![7; 3000]);
        let _ = server.handle(Instant::ZERO, PeerId(2), bytes);
        let mut fetch = crate::share::BlobFetch::new(
            Instant::ZERO,
            PeerId(1),
            1 << 16,
            std::time::Duration::from_secs(1),
        );
        let _ = fetch.poll_transmit(Instant::ZERO);
        fetch.handle(PeerId(1), bytes);
        let _ = fetch.outcome();
    }
    // voice datagrams: as they are and behind the voice marker; what decodes re-encodes to
    // itself
    let mut voice = vec![crate::voice::VOICE_MARKER];
    voice.extend_from_slice(data);
    for bytes in [data, &voice[..]] {
        if let Ok(d) = crate::voice::VoiceDatagram::decode(bytes) {
            assert_eq!(crate::voice::VoiceDatagram::decode(&d.encode()), Ok(d));
        }
    }
    if let Ok((_, sections)) = decode_packet(data) {
        for s in sections {
            match s {
                Section::State { count, bits } => {
                    let _ = decode_state_block(count, bits, |_| Some(layout));
                }
                Section::Reliable { bytes, .. } => {
                    let _ = Control::decode(bytes);
                }
                _ => {}
            }
        }
    }
    // a joined host/client pair with a soft body, each fed the bytes from the other
    let (mut host, mut client, id) = joined_pair(class);
    let now = Instant::from_millis(100);
    host.handle_packet(now, PeerId(2), data);
    client.handle_packet(now, PeerId(1), data);
    for s in [&mut host, &mut client] {
        s.handle_timeout(now);
        while s.poll_transmit(now).is_some() {}
        if let Some(st) = id.and_then(|id| s.latest_state(id)) {
            assert!(st.pos.is_finite() && st.rot.is_finite());
            assert!(st.particles.iter().all(|p| p.is_finite()));
        }
    }
}

fn joined_pair(class: ClassConfig) -> (Session, Session, Option<crate::ids::NetId>) {
    let cfg = SessionConfig {
        classes: vec![class],
        ..SessionConfig::default()
    };
    let now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    let mut client = Session::join(PeerId(2), PeerId(1), cfg, now);
    let particles = (0..60)
        .map(|i| Vec3::new(i as f32 * 0.01, 1.0, 0.0))
        .collect();
    let st = ObjectState {
        pos: Vec3::Y,
        rot: Quat::IDENTITY,
        particles,
    };
    let id = host.spawn(now, ClassId(0), st).map(|x| x.0).ok();
    for _ in 0..8 {
        while let Some(t) = host.poll_transmit(now) {
            client.handle_packet(now, PeerId(1), &t.payload);
        }
        while let Some(t) = client.poll_transmit(now) {
            host.handle_packet(now, PeerId(2), &t.payload);
        }
    }
    (host, client, id)
}

// ================================================================ sessions played
