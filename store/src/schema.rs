//! The store's schema and its versions. [`MIGRATIONS`]`[k]` takes a store from version `k` to
//! `k + 1` (version 0: empty); a store is migrated step by step at open, inside one
//! transaction, and one of a version above [`SCHEMA_VERSION`] is refused. The SQL keeps to
//! what SQLite and PostgreSQL both read (`BIGINT`, `DOUBLE PRECISION`, `TEXT`; blobs are the
//! one type named per back end, [`BLOB_TYPE`]).
//!
//! | table | rows |
//! |---|---|
//! | `meta` | `key`/`value` text: `schema_version`, `event_format`, `scene_sha256`, `messages_digest` (hex), `room_time_us`, `checkpoint_room_time_us` |
//! | `scenes` | `sha256`, `bundle`: each scene the room was made from, content-addressed |
//! | `objects` | `id`, `class`, pose (`px py pz qx qy qz qw`), `particles` (blob of f32 triples), `state_room_us` (room time of the state) |
//! | `topology` | `object`, `seq`, `kind`, `event` (JSON; [`crate::codec`]) |
//! | `retained` | `kind`, `object` (-1: room-wide), `origin`, `seq`, `delivery`, `payload` |
//! | `recordings` (v2) | `id` (its start, Unix ms), `started_unix_ms`, `start_room_us`, `end_room_us`, `host`, `image` (the room at the start, JSON: [`crate::codec::image_to_json`]) |
//! | `record_events` (v2) | `recording`, `n` (order), `room_us`, `kind`, `peer`, `object`, `data` (JSON) |
//! | `record_states` (v2) | `recording`, `object`, `room_us`, `class`, pose, `particles`: the shown state when it changed, at the replication rate |

/// The schema this build writes.
pub const SCHEMA_VERSION: u32 = 2;

/// The placeholder for the blob type in [`MIGRATIONS`].
pub const BLOB_TYPE: &str = "{BLOB}";

/// Step `k` takes version `k` to `k + 1`.
pub const MIGRATIONS: &[&str] = &[
    // 0 → 1: the room's objects, logs, retained messages and scenes
    "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
     CREATE TABLE scenes (sha256 TEXT PRIMARY KEY, bundle {BLOB} NOT NULL);
     CREATE TABLE objects (
        id BIGINT PRIMARY KEY, class BIGINT NOT NULL,
        px DOUBLE PRECISION NOT NULL, py DOUBLE PRECISION NOT NULL, pz DOUBLE PRECISION NOT NULL,
        qx DOUBLE PRECISION NOT NULL, qy DOUBLE PRECISION NOT NULL, qz DOUBLE PRECISION NOT NULL,
        qw DOUBLE PRECISION NOT NULL,
        particles {BLOB} NOT NULL, state_room_us BIGINT NOT NULL);
     CREATE TABLE topology (
        object BIGINT NOT NULL, seq BIGINT NOT NULL, kind TEXT NOT NULL, event TEXT NOT NULL,
        PRIMARY KEY (object, seq));
     CREATE TABLE retained (
        kind BIGINT NOT NULL, object BIGINT NOT NULL, origin BIGINT NOT NULL, seq BIGINT NOT NULL,
        delivery TEXT NOT NULL, payload {BLOB} NOT NULL,
        PRIMARY KEY (kind, object));",
    // 1 → 2: recorded sessions (`record.rs`): each recording's start (the room then, as
    // JSON), its events in order, the objects' shown states over time
    "CREATE TABLE recordings (
        id BIGINT PRIMARY KEY, started_unix_ms BIGINT NOT NULL, start_room_us BIGINT NOT NULL,
        end_room_us BIGINT NOT NULL, host BIGINT NOT NULL, image TEXT NOT NULL);
     CREATE TABLE record_events (
        recording BIGINT NOT NULL, n BIGINT NOT NULL, room_us BIGINT NOT NULL,
        kind TEXT NOT NULL, peer BIGINT, object BIGINT, data TEXT NOT NULL,
        PRIMARY KEY (recording, n));
     CREATE INDEX record_events_time ON record_events (recording, room_us);
     CREATE TABLE record_states (
        recording BIGINT NOT NULL, object BIGINT NOT NULL, room_us BIGINT NOT NULL,
        class BIGINT NOT NULL,
        px DOUBLE PRECISION NOT NULL, py DOUBLE PRECISION NOT NULL, pz DOUBLE PRECISION NOT NULL,
        qx DOUBLE PRECISION NOT NULL, qy DOUBLE PRECISION NOT NULL, qz DOUBLE PRECISION NOT NULL,
        qw DOUBLE PRECISION NOT NULL, particles {BLOB} NOT NULL,
        PRIMARY KEY (recording, object, room_us));",
];

/// Migration `k`'s SQL with the back end's blob type.
pub fn migration_sql(k: usize, blob: &str) -> Option<String> {
    MIGRATIONS.get(k).map(|s| s.replace(BLOB_TYPE, blob))
}
