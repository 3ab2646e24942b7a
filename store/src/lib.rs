//! Rooms that remember. A room's lasting state — every object (class, pose, particles), each
//! object's topology log (tears, cuts, resolution changes: the pieces are objects whose logs
//! end in their `Cut`), the retained messages and the room time — kept in a database by the
//! host while the room runs, so a room every peer left, or whose every process died, opens
//! again as it was ([`softsync_net::Session::restore_object`]).
//!
//! - [`RoomStore`]: one trait, two back ends on one schema and one set of statements:
//!   [`SqliteStore`] (embedded, a file beside the scene: the default) and [`PgStore`]
//!   (PostgreSQL, for rooms whose peers are on different machines). The schema is versioned
//!   ([`schema`]); migrations run at open, a store of a newer version is refused.
//! - [`Tracker`]: what changed since the last write, as a [`Batch`] (one transaction: a cut's
//!   parent leaves and its pieces arrive together, so nothing is ever half-applied).
//! - [`StoreWriter`]: the writes on their own thread; the frame only hands batches over.
//!
//! - [`keeper::Keeper`]: a running [`softsync_peer::Peer`]'s room into its store (what the
//!   `softsync` binary's `--store` runs): looks every 0.1 s, checkpoints every second.
//!
//! What is not kept: who owned what, who was in the room, avatars (they belong to their
//! peers), state in flight.

pub mod codec;
mod db;
pub mod keeper;
pub mod playback;
mod postgres;
pub mod record;
mod recorder;
mod room;
mod rows;
pub mod schema;
mod sql;
mod sqlite;
#[cfg(feature = "testing")]
pub mod testing;
mod tracker;
mod writer;

use std::time::Duration;

use softsync_net::wire::TopologyEvent;
use softsync_net::{ClassId, NetId, ObjectState, RoomImage};

pub use postgres::PgStore;
pub use sqlite::SqliteStore;
pub use tracker::Tracker;
pub use writer::{StoreWriter, WriterStatus};

/// What a room is made from: a store kept for one scene refuses another.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RoomIdentity {
    /// SHA-256 (hex) of the scene's bundle (the scene file and the files it reads): the
    /// scene is kept in the store under it.
    pub scene_sha256: String,
    /// A digest of the room's message table, the names in order ([`RoomIdentity::messages`]):
    /// a retained message names its type by its index there.
    pub messages_digest: u64,
}

impl RoomIdentity {
    /// The identity of the room made from the scene bundle `bundle` with message table
    /// digest `messages_digest`.
    pub fn of(bundle: &[u8], messages_digest: u64) -> Self {
        RoomIdentity {
            scene_sha256: sha256_hex(bundle),
            messages_digest,
        }
    }

    /// The digest of a message table (FNV-1a of the names, one per line): stable across
    /// builds, unlike the handshake's digest.
    pub fn messages(names: &[String]) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in names.join("\n").bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        h
    }
}

/// SHA-256 of `bytes`, lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let d = ring::digest::digest(&ring::digest::SHA256, bytes);
    d.as_ref().iter().map(|b| format!("{b:02x}")).collect()
}

/// How one object's log changed since the last write.
#[derive(Clone, Debug, PartialEq)]
pub enum LogChange {
    /// Entries `from..` are these (the entries before stay).
    Append {
        /// Position of the first.
        from: u32,
        /// The entries.
        events: Vec<TopologyEvent>,
    },
    /// The whole log is this (a new object, or a log a new host rewrote).
    Replace(Vec<TopologyEvent>),
}

/// One object's row: class and state.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectRow {
    /// Id.
    pub id: NetId,
    /// Class.
    pub class: ClassId,
    /// State.
    pub state: ObjectState,
}

/// Everything one write changes, applied in one transaction, in this order: `full` empties
/// the room first; removals; object rows; log changes; retained messages; the room time.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// The batch is the whole room: what the store had is dropped first.
    pub full: bool,
    /// Objects gone (their logs go with them).
    pub remove: Vec<NetId>,
    /// Objects written (new, or their state changed).
    pub objects: Vec<ObjectRow>,
    /// Log changes, per object.
    pub logs: Vec<(NetId, LogChange)>,
    /// The retained messages, all of them, when they changed.
    pub retained: Option<Vec<softsync_net::wire::AppMessage>>,
    /// The room time of this write.
    pub room_time: Duration,
    /// A checkpoint: every object's state is written as of `room_time`.
    pub checkpoint: bool,
    /// What this write adds to a recording of the session (`--record`).
    pub record: Option<record::RecordBatch>,
}

impl Batch {
    /// The bytes of values this batch writes (particles, poses, events, messages): what the
    /// room costs its store, before the database's own overhead.
    pub fn payload_bytes(&self) -> usize {
        let objects: usize = self
            .objects
            .iter()
            .map(|o| 8 + 2 + 7 * 8 + 12 * o.state.particles.len())
            .sum();
        let events: usize = self
            .logs
            .iter()
            .map(|(_, c)| match c {
                LogChange::Append { events, .. } | LogChange::Replace(events) => events
                    .iter()
                    .map(|e| {
                        let (k, j) = codec::encode_event(e);
                        16 + k.len() + j.len()
                    })
                    .sum::<usize>(),
            })
            .sum();
        let retained: usize = self
            .retained
            .iter()
            .flatten()
            .map(|m| 40 + m.payload.len())
            .sum();
        objects
            + events
            + retained
            + 8 * self.remove.len()
            + self
                .record
                .as_ref()
                .map_or(0, record::RecordBatch::payload_bytes)
    }

    /// Topology entries and objects added or removed (the "events" of a write).
    pub fn events(&self) -> usize {
        self.remove.len()
            + self
                .logs
                .iter()
                .map(|(_, c)| match c {
                    LogChange::Append { events, .. } | LogChange::Replace(events) => events.len(),
                })
                .sum::<usize>()
    }
}

/// What a store says about itself.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoreInfo {
    /// Back end (`sqlite`, `postgres`).
    pub backend: &'static str,
    /// Schema version of the store as opened (after migrations).
    pub schema_version: u32,
    /// Schema version the store was at before this open migrated it (equal if none ran).
    pub migrated_from: u32,
}

/// Why a store could not be opened, read or written.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The database said no (locked, corrupt, full disk, server gone): its words.
    #[error("{backend} store {target}: {what}")]
    Database {
        /// Back end.
        backend: &'static str,
        /// The file or server.
        target: String,
        /// The database's error.
        what: String,
    },
    /// The store was written by a newer softsync (schema `found`, this build knows up to
    /// `known`): refused rather than misread.
    #[error("the store's schema is version {found}, newer than this build's {known}: open it with a newer softsync")]
    Newer {
        /// The store's version.
        found: u32,
        /// Ours.
        known: u32,
    },
    /// The store is not one of ours (tables missing or of another shape).
    #[error("not a softsync room store: {0}")]
    Foreign(String),
    /// The store keeps a room made from another scene or configuration.
    #[error("the store keeps a room of another scene (store: scene {stored_scene}, messages {stored_messages:016x}; given: scene {given_scene}, messages {given_messages:016x}): give the scene it was made from, or start afresh with --store-reset")]
    OtherScene {
        /// The store's scene hash.
        stored_scene: String,
        /// The store's config digest.
        stored_messages: u64,
        /// The given scene's hash.
        given_scene: String,
        /// The given config digest.
        given_messages: u64,
    },
    /// A row could not be read back (a value out of range, an unknown event kind).
    #[error("store row unreadable: {0}")]
    Row(String),
}

/// A place a room is kept. One writer at a time (the host); every call is one transaction.
pub trait RoomStore: Send {
    /// Back end and schema.
    fn info(&self) -> StoreInfo;

    /// The identity of the room kept, if any room is.
    fn identity(&mut self) -> Result<Option<RoomIdentity>, StoreError>;

    /// Keep a room of `identity` from now on: the scene bundle is stored under its hash; a
    /// store that kept another room is emptied first only if `reset` (otherwise
    /// [`StoreError::OtherScene`]).
    fn begin(
        &mut self,
        identity: &RoomIdentity,
        bundle: &[u8],
        reset: bool,
    ) -> Result<(), StoreError>;

    /// The room as kept: every object with its log, the retained messages, the room time.
    fn load(&mut self) -> Result<RoomImage, StoreError>;

    /// Apply `batch` in one transaction (all of it or none).
    fn write(&mut self, batch: &Batch) -> Result<(), StoreError>;

    /// The scene bundle kept under `sha256`.
    fn scene(&mut self, sha256: &str) -> Result<Option<Vec<u8>>, StoreError>;

    /// Every recorded session, oldest first.
    fn recordings(&mut self) -> Result<Vec<record::RecordingInfo>, StoreError>;

    /// Recording `id`: what it is and the room at its start.
    fn recording(&mut self, id: i64) -> Result<Option<record::Recording>, StoreError>;

    /// Recording `id`'s events with `from_us <= room time < to_us`, in order.
    fn recording_events(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<record::RecEvent>, StoreError>;

    /// Every object's state at room time `t_us` of recording `id` (interpolated between the
    /// recorded states around it).
    fn recording_state_at(
        &mut self,
        id: i64,
        t_us: u64,
    ) -> Result<Vec<record::RecState>, StoreError>;

    /// Recording `id`'s recorded states with `from_us <= room time < to_us` (an export).
    fn recording_states(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<record::RecState>, StoreError>;

    /// Delete recording `id`; false if there was none. The room's state stays.
    fn delete_recording(&mut self, id: i64) -> Result<bool, StoreError>;
}

/// Delete every recording that started before `before_unix_ms`; their ids.
pub fn prune_recordings(
    store: &mut dyn RoomStore,
    before_unix_ms: i64,
) -> Result<Vec<i64>, StoreError> {
    let mut gone = Vec::new();
    for r in store.recordings()? {
        if r.started_unix_ms < before_unix_ms && store.delete_recording(r.id)? {
            gone.push(r.id);
        }
    }
    Ok(gone)
}

/// Open the store `target`: a `postgres://` or `postgresql://` URL ([`PgStore`]), or else a
/// path ([`SqliteStore`]; created if missing).
pub fn open(target: &str) -> Result<Box<dyn RoomStore>, StoreError> {
    if target.starts_with("postgres://") || target.starts_with("postgresql://") {
        return Ok(Box::new(PgStore::open(target)?));
    }
    Ok(Box::new(SqliteStore::open(std::path::Path::new(target))?))
}
