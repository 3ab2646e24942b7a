//! The statements every back end runs, in the SQL SQLite and PostgreSQL both read, with
//! `?N` parameters (PostgreSQL's back end turns them into `$N`: [`numbered`]).

/// Upsert one `meta` row: key, value.
pub const SET_META: &str = "INSERT INTO meta (key, value) VALUES (?1, ?2)
     ON CONFLICT (key) DO UPDATE SET value = excluded.value";
/// One `meta` value: key.
pub const GET_META: &str = "SELECT value FROM meta WHERE key = ?1";
/// Upsert one object row: id, class, px, py, pz, qx, qy, qz, qw, particles, state_room_us.
pub const PUT_OBJECT: &str =
    "INSERT INTO objects (id, class, px, py, pz, qx, qy, qz, qw, particles, state_room_us)
     VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)
     ON CONFLICT (id) DO UPDATE SET class = excluded.class, px = excluded.px,
       py = excluded.py, pz = excluded.pz, qx = excluded.qx, qy = excluded.qy,
       qz = excluded.qz, qw = excluded.qw, particles = excluded.particles,
       state_room_us = excluded.state_room_us";
/// Drop an object's log entries from a position on: object, seq.
pub const CUT_LOG: &str = "DELETE FROM topology WHERE object = ?1 AND seq >= ?2";
/// One log entry: object, seq, kind, event.
pub const PUT_EVENT: &str =
    "INSERT INTO topology (object, seq, kind, event) VALUES (?1, ?2, ?3, ?4)";
/// An object gone: id (three statements: its row, its log, its retained messages).
pub const DROP_OBJECT: [&str; 3] = [
    "DELETE FROM objects WHERE id = ?1",
    "DELETE FROM topology WHERE object = ?1",
    "DELETE FROM retained WHERE object = ?1",
];
/// The whole room goes (a full batch, a reset).
pub const EMPTY_ROOM: [&str; 3] = [
    "DELETE FROM objects",
    "DELETE FROM topology",
    "DELETE FROM retained",
];
/// The room's times go too (a reset).
pub const FORGET_TIMES: &str =
    "DELETE FROM meta WHERE key IN ('room_time_us', 'checkpoint_room_time_us')";
/// Every retained message goes (they are written whole).
pub const EMPTY_RETAINED: &str = "DELETE FROM retained";
/// One retained message: kind, object, origin, seq, delivery, payload.
pub const PUT_RETAINED: &str = "INSERT INTO retained (kind, object, origin, seq, delivery, payload)
     VALUES (?1, ?2, ?3, ?4, ?5, ?6)
     ON CONFLICT (kind, object) DO UPDATE SET origin = excluded.origin,
       seq = excluded.seq, delivery = excluded.delivery, payload = excluded.payload";
/// A scene bundle, kept once: sha256, bundle.
pub const PUT_SCENE: &str =
    "INSERT INTO scenes (sha256, bundle) VALUES (?1, ?2) ON CONFLICT (sha256) DO NOTHING";
/// A scene bundle: sha256.
pub const GET_SCENE: &str = "SELECT bundle FROM scenes WHERE sha256 = ?1";
/// Every object row, by id.
pub const LOAD_OBJECTS: &str =
    "SELECT id, class, px, py, pz, qx, qy, qz, qw, particles FROM objects ORDER BY id";
/// Every log entry, by object and position.
pub const LOAD_TOPOLOGY: &str =
    "SELECT object, seq, kind, event FROM topology ORDER BY object, seq";
/// Every retained message.
pub const LOAD_RETAINED: &str =
    "SELECT kind, object, origin, seq, delivery, payload FROM retained ORDER BY kind, object";

/// `sql` with `?N` parameters written `$N` (PostgreSQL).
pub fn numbered(sql: &str) -> String {
    sql.replace('?', "$")
}
