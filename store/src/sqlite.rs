//! The embedded back end: one SQLite file (rusqlite, SQLite built in). Write-ahead log,
//! `synchronous = FULL` (a write that returned survives a power cut), and the file locked for
//! as long as the store is open (`locking_mode = EXCLUSIVE`, taken at open): a second host
//! given the same file is refused at once instead of interleaving its writes.

use std::path::{Path, PathBuf};
use std::time::Duration;

use rusqlite::{params, Connection, OptionalExtension, Transaction};
use softsync_net::{NetId, RoomImage};

use crate::codec::{encode_event, encode_particles, EVENT_FORMAT};
use crate::rows;
use crate::schema::{migration_sql, SCHEMA_VERSION};
use crate::sql;
use crate::{Batch, LogChange, RoomIdentity, RoomStore, StoreError, StoreInfo};

/// How long an open waits for a lock another process holds before it says so.
const LOCK_WAIT: Duration = Duration::from_millis(300);

/// A room kept in a SQLite file.
pub struct SqliteStore {
    conn: Connection,
    path: PathBuf,
    migrated_from: u32,
}

impl std::fmt::Debug for SqliteStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SqliteStore")
            .field("path", &self.path)
            .finish()
    }
}

pub(crate) fn db_err(path: &Path) -> impl Fn(rusqlite::Error) -> StoreError + '_ {
    move |e| {
        let what = match &e {
            rusqlite::Error::SqliteFailure(f, _) if f.code == rusqlite::ErrorCode::DatabaseBusy => {
                format!("in use by another host ({e})")
            }
            rusqlite::Error::SqliteFailure(f, _) if f.code == rusqlite::ErrorCode::NotADatabase => {
                format!("corrupt or not a database ({e})")
            }
            rusqlite::Error::SqliteFailure(f, _) if f.code == rusqlite::ErrorCode::DiskFull => {
                format!("disk full ({e})")
            }
            _ => e.to_string(),
        };
        StoreError::Database {
            backend: "sqlite",
            target: path.display().to_string(),
            what,
        }
    }
}

impl SqliteStore {
    /// Open (or create) the store at `path`, lock it, and migrate it to [`SCHEMA_VERSION`].
    pub fn open(path: &Path) -> Result<Self, StoreError> {
        let err = db_err(path);
        if path.is_dir() {
            return Err(StoreError::Database {
                backend: "sqlite",
                target: path.display().to_string(),
                what: "is a folder, not a file".into(),
            });
        }
        let conn = Connection::open(path).map_err(&err)?;
        conn.busy_timeout(LOCK_WAIT).map_err(&err)?;
        conn.pragma_update(None, "locking_mode", "EXCLUSIVE")
            .map_err(&err)?;
        conn.pragma_update(None, "journal_mode", "WAL")
            .map_err(&err)?;
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(&err)?;
        // take the lock now (EXCLUSIVE keeps it until the connection closes), and read the
        // whole schema: a corrupt file fails here, not mid-room
        conn.execute_batch("BEGIN EXCLUSIVE; COMMIT;")
            .map_err(&err)?;
        let check: String = conn
            .query_row("PRAGMA quick_check", [], |r| r.get(0))
            .map_err(&err)?;
        if check != "ok" {
            return Err(StoreError::Database {
                backend: "sqlite",
                target: path.display().to_string(),
                what: format!("corrupt: {check}"),
            });
        }
        let mut s = SqliteStore {
            conn,
            path: path.to_path_buf(),
            migrated_from: 0,
        };
        s.migrate()?;
        Ok(s)
    }

    /// The schema version the file says it is at (0: empty).
    fn version(conn: &Connection, path: &Path) -> Result<u32, StoreError> {
        let tables: i64 = conn
            .query_row(
                "SELECT count(*) FROM sqlite_master WHERE type = 'table'",
                [],
                |r| r.get(0),
            )
            .map_err(db_err(path))?;
        if tables == 0 {
            return Ok(0);
        }
        let has_meta: i64 = conn
            .query_row(
                "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'meta'",
                [],
                |r| r.get(0),
            )
            .map_err(db_err(path))?;
        if has_meta == 0 {
            return Err(StoreError::Foreign(format!(
                "{} has {tables} tables and no `meta`",
                path.display()
            )));
        }
        let v: Option<String> = conn
            .query_row(
                "SELECT value FROM meta WHERE key = 'schema_version'",
                [],
                |r| r.get(0),
            )
            .optional()
            .map_err(db_err(path))?;
        v.ok_or_else(|| StoreError::Foreign("no schema_version in meta".into()))?
            .parse()
            .map_err(|_| StoreError::Foreign("schema_version is not a number".into()))
    }

    fn migrate(&mut self) -> Result<(), StoreError> {
        let path = self.path.clone();
        let err = db_err(&path);
        let found = Self::version(&self.conn, &path)?;
        self.migrated_from = found;
        if found > SCHEMA_VERSION {
            return Err(StoreError::Newer {
                found,
                known: SCHEMA_VERSION,
            });
        }
        if found == SCHEMA_VERSION {
            return Ok(());
        }
        let tx = self.conn.transaction().map_err(&err)?;
        for k in found..SCHEMA_VERSION {
            let sql = migration_sql(k as usize, "BLOB")
                .ok_or_else(|| StoreError::Foreign(format!("no migration from version {k}")))?;
            tx.execute_batch(&sql).map_err(&err)?;
        }
        set_meta(&tx, "schema_version", &SCHEMA_VERSION.to_string()).map_err(&err)?;
        set_meta(&tx, "event_format", &EVENT_FORMAT.to_string()).map_err(&err)?;
        tx.commit().map_err(&err)
    }

    /// Run `sql` on the file directly (tests: an older schema, a forged version).
    pub fn execute_raw(&mut self, sql: &str) -> Result<(), StoreError> {
        self.conn.execute_batch(sql).map_err(db_err(&self.path))
    }
}

fn set_meta(tx: &Transaction<'_>, key: &str, value: &str) -> rusqlite::Result<usize> {
    tx.execute(sql::SET_META, params![key, value])
}

fn get_meta(conn: &Connection, key: &str) -> rusqlite::Result<Option<String>> {
    conn.query_row(sql::GET_META, [key], |r| r.get(0))
        .optional()
}

fn write_object(
    tx: &Transaction<'_>,
    row: &crate::ObjectRow,
    room_us: i64,
) -> rusqlite::Result<usize> {
    let (p, q) = (row.state.pos, row.state.rot);
    tx.execute(
        sql::PUT_OBJECT,
        params![
            i64::from(row.id.0),
            i64::from(row.class.0),
            f64::from(p.x),
            f64::from(p.y),
            f64::from(p.z),
            f64::from(q.x),
            f64::from(q.y),
            f64::from(q.z),
            f64::from(q.w),
            encode_particles(&row.state.particles),
            room_us
        ],
    )
}

fn write_events(
    tx: &Transaction<'_>,
    id: NetId,
    from: u32,
    events: &[softsync_net::wire::TopologyEvent],
) -> rusqlite::Result<()> {
    tx.execute(sql::CUT_LOG, params![i64::from(id.0), i64::from(from)])?;
    let mut st = tx.prepare_cached(sql::PUT_EVENT)?;
    for (k, e) in events.iter().enumerate() {
        let (kind, json) = encode_event(e);
        st.execute(params![
            i64::from(id.0),
            i64::from(from) + k as i64,
            kind,
            json
        ])?;
    }
    Ok(())
}

impl RoomStore for SqliteStore {
    fn info(&self) -> StoreInfo {
        StoreInfo {
            backend: "sqlite",
            schema_version: SCHEMA_VERSION,
            migrated_from: self.migrated_from,
        }
    }

    fn identity(&mut self) -> Result<Option<RoomIdentity>, StoreError> {
        let err = db_err(&self.path);
        let scene = get_meta(&self.conn, "scene_sha256").map_err(&err)?;
        let config = get_meta(&self.conn, "messages_digest").map_err(&err)?;
        match (scene, config) {
            (Some(scene_sha256), Some(c)) => Ok(Some(RoomIdentity {
                scene_sha256,
                messages_digest: u64::from_str_radix(&c, 16)
                    .map_err(|_| StoreError::Row(format!("messages_digest {c:?}")))?,
            })),
            _ => Ok(None),
        }
    }

    fn begin(
        &mut self,
        identity: &RoomIdentity,
        bundle: &[u8],
        reset: bool,
    ) -> Result<(), StoreError> {
        if let Some(kept) = self.identity()? {
            if kept != *identity && !reset {
                return Err(StoreError::OtherScene {
                    stored_scene: kept.scene_sha256,
                    stored_messages: kept.messages_digest,
                    given_scene: identity.scene_sha256.clone(),
                    given_messages: identity.messages_digest,
                });
            }
        }
        let err = db_err(&self.path);
        let tx = self.conn.transaction().map_err(&err)?;
        if reset {
            tx.execute_batch(&format!(
                "{}; {};",
                sql::EMPTY_ROOM.join("; "),
                sql::FORGET_TIMES
            ))
            .map_err(&err)?;
        }
        tx.execute(sql::PUT_SCENE, params![identity.scene_sha256, bundle])
            .map_err(&err)?;
        set_meta(&tx, "scene_sha256", &identity.scene_sha256).map_err(&err)?;
        set_meta(
            &tx,
            "messages_digest",
            &format!("{:016x}", identity.messages_digest),
        )
        .map_err(&err)?;
        tx.commit().map_err(&err)
    }

    fn load(&mut self) -> Result<RoomImage, StoreError> {
        let err = db_err(&self.path);
        let format: u32 = get_meta(&self.conn, "event_format")
            .map_err(&err)?
            .and_then(|v| v.parse().ok())
            .unwrap_or(EVENT_FORMAT);
        if format > EVENT_FORMAT {
            return Err(StoreError::Newer {
                found: format,
                known: EVENT_FORMAT,
            });
        }
        let room_us: u64 = get_meta(&self.conn, "room_time_us")
            .map_err(&err)?
            .and_then(|v| v.parse().ok())
            .unwrap_or(0);
        let mut objects = Vec::new();
        let mut st = self.conn.prepare(sql::LOAD_OBJECTS).map_err(&err)?;
        let mut rows = st.query([]).map_err(&err)?;
        while let Some(r) = rows.next().map_err(&err)? {
            let p = [
                r.get(2).map_err(&err)?,
                r.get(3).map_err(&err)?,
                r.get(4).map_err(&err)?,
            ];
            let q = [
                r.get(5).map_err(&err)?,
                r.get(6).map_err(&err)?,
                r.get(7).map_err(&err)?,
                r.get(8).map_err(&err)?,
            ];
            let particles: Vec<u8> = r.get(9).map_err(&err)?;
            objects.push(rows::object(
                r.get(0).map_err(&err)?,
                r.get(1).map_err(&err)?,
                p,
                q,
                &particles,
            )?);
        }
        drop(rows);
        drop(st);
        let mut st = self.conn.prepare(sql::LOAD_TOPOLOGY).map_err(&err)?;
        let mut rows = st.query([]).map_err(&err)?;
        while let Some(r) = rows.next().map_err(&err)? {
            let (kind, json): (String, String) = (r.get(2).map_err(&err)?, r.get(3).map_err(&err)?);
            rows::push_event(
                &mut objects,
                r.get(0).map_err(&err)?,
                r.get(1).map_err(&err)?,
                &kind,
                &json,
            )?;
        }
        drop(rows);
        drop(st);
        let mut retained = Vec::new();
        let mut st = self.conn.prepare(sql::LOAD_RETAINED).map_err(&err)?;
        let mut rows = st.query([]).map_err(&err)?;
        while let Some(r) = rows.next().map_err(&err)? {
            let delivery: String = r.get(4).map_err(&err)?;
            retained.push(rows::retained(
                r.get(0).map_err(&err)?,
                r.get(1).map_err(&err)?,
                r.get(2).map_err(&err)?,
                r.get(3).map_err(&err)?,
                &delivery,
                r.get(5).map_err(&err)?,
            )?);
        }
        Ok(RoomImage {
            room_time: Duration::from_micros(room_us),
            objects,
            retained,
        })
    }

    fn write(&mut self, b: &Batch) -> Result<(), StoreError> {
        let err = db_err(&self.path);
        let room_us = i64::try_from(b.room_time.as_micros()).unwrap_or(i64::MAX);
        let tx = self.conn.transaction().map_err(&err)?;
        if b.full {
            tx.execute_batch(&sql::EMPTY_ROOM.join("; "))
                .map_err(&err)?;
        }
        for id in &b.remove {
            tx.execute(sql::DROP_OBJECT[0], [i64::from(id.0)])
                .map_err(&err)?;
            tx.execute(sql::DROP_OBJECT[1], [i64::from(id.0)])
                .map_err(&err)?;
            tx.execute(sql::DROP_OBJECT[2], [i64::from(id.0)])
                .map_err(&err)?;
        }
        for row in &b.objects {
            write_object(&tx, row, room_us).map_err(&err)?;
        }
        for (id, change) in &b.logs {
            match change {
                LogChange::Append { from, events } => write_events(&tx, *id, *from, events),
                LogChange::Replace(events) => write_events(&tx, *id, 0, events),
            }
            .map_err(&err)?;
        }
        if let Some(msgs) = &b.retained {
            tx.execute(sql::EMPTY_RETAINED, []).map_err(&err)?;
            for m in msgs {
                let object = rows::retained_object(m);
                tx.execute(
                    sql::PUT_RETAINED,
                    params![
                        i64::from(m.kind.0),
                        object,
                        m.origin.0 as i64,
                        i64::from(m.seq),
                        rows::delivery_text(m.delivery),
                        m.payload
                    ],
                )
                .map_err(&err)?;
            }
        }
        if let Some(r) = &b.record {
            crate::record::write(&mut crate::db::Lite(&tx, &self.path), r)?;
        }
        // a batch with no room time (a recording's alone) leaves the room's
        if room_us > 0 {
            set_meta(&tx, "room_time_us", &room_us.to_string()).map_err(&err)?;
        }
        if b.checkpoint {
            set_meta(&tx, "checkpoint_room_time_us", &room_us.to_string()).map_err(&err)?;
        }
        tx.commit().map_err(&err)
    }

    fn scene(&mut self, sha256: &str) -> Result<Option<Vec<u8>>, StoreError> {
        self.conn
            .query_row(sql::GET_SCENE, [sha256], |r| r.get(0))
            .optional()
            .map_err(db_err(&self.path))
    }

    fn recordings(&mut self) -> Result<Vec<crate::record::RecordingInfo>, StoreError> {
        crate::record::list(&mut crate::db::Lite(&self.conn, &self.path))
    }

    fn recording(&mut self, id: i64) -> Result<Option<crate::record::Recording>, StoreError> {
        crate::record::open(&mut crate::db::Lite(&self.conn, &self.path), id)
    }

    fn recording_events(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecEvent>, StoreError> {
        crate::record::events(
            &mut crate::db::Lite(&self.conn, &self.path),
            id,
            from_us,
            to_us,
        )
    }

    fn recording_state_at(
        &mut self,
        id: i64,
        t_us: u64,
    ) -> Result<Vec<crate::record::RecState>, StoreError> {
        crate::record::state_at(&mut crate::db::Lite(&self.conn, &self.path), id, t_us)
    }

    fn recording_states(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecState>, StoreError> {
        crate::record::states(
            &mut crate::db::Lite(&self.conn, &self.path),
            id,
            from_us,
            to_us,
        )
    }

    fn delete_recording(&mut self, id: i64) -> Result<bool, StoreError> {
        crate::record::delete(&mut crate::db::Lite(&self.conn, &self.path), id)
    }
}
