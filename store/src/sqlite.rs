//! The embedded back end: one SQLite file (rusqlite, SQLite built in). Write-ahead log,
//! `synchronous = FULL` (a write that returned survives a power cut), and the file locked for
//! as long as the store is open (`locking_mode = EXCLUSIVE`, taken at open): a second host
//! given the same file is refused at once instead of interleaving its writes.

use std::path::{Path, PathBuf};
use std::time::Duration;

use rusqlite::{Connection, OptionalExtension};
use softsync_net::RoomImage;

use crate::codec::EVENT_FORMAT;
use crate::db::Lite;
use crate::room;
use crate::schema::{migration_sql, SCHEMA_VERSION};
use crate::{Batch, RoomIdentity, RoomStore, StoreError, StoreInfo};

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
        let mut db = Lite(&tx, &path);
        room::set_meta(&mut db, "schema_version", &SCHEMA_VERSION.to_string())?;
        room::set_meta(&mut db, "event_format", &EVENT_FORMAT.to_string())?;
        tx.commit().map_err(&err)
    }

    /// Run `sql` on the file directly (tests: an older schema, a forged version).
    pub fn execute_raw(&mut self, sql: &str) -> Result<(), StoreError> {
        self.conn.execute_batch(sql).map_err(db_err(&self.path))
    }
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
        room::identity(&mut Lite(&self.conn, &self.path))
    }

    fn begin(
        &mut self,
        identity: &RoomIdentity,
        bundle: &[u8],
        reset: bool,
    ) -> Result<(), StoreError> {
        let tx = self.conn.transaction().map_err(db_err(&self.path))?;
        room::begin(&mut Lite(&tx, &self.path), identity, bundle, reset)?;
        tx.commit().map_err(db_err(&self.path))
    }

    fn load(&mut self) -> Result<RoomImage, StoreError> {
        let tx = self.conn.transaction().map_err(db_err(&self.path))?;
        let image = room::load(&mut Lite(&tx, &self.path))?;
        tx.commit().map_err(db_err(&self.path))?;
        Ok(image)
    }

    fn write(&mut self, b: &Batch) -> Result<(), StoreError> {
        let tx = self.conn.transaction().map_err(db_err(&self.path))?;
        room::write(&mut Lite(&tx, &self.path), b)?;
        tx.commit().map_err(db_err(&self.path))
    }

    fn scene(&mut self, sha256: &str) -> Result<Option<Vec<u8>>, StoreError> {
        room::scene(&mut Lite(&self.conn, &self.path), sha256)
    }

    fn recordings(&mut self) -> Result<Vec<crate::record::RecordingInfo>, StoreError> {
        crate::record::list(&mut Lite(&self.conn, &self.path))
    }

    fn recording(&mut self, id: i64) -> Result<Option<crate::record::Recording>, StoreError> {
        crate::record::open(&mut Lite(&self.conn, &self.path), id)
    }

    fn recording_events(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecEvent>, StoreError> {
        crate::record::events(&mut Lite(&self.conn, &self.path), id, from_us, to_us)
    }

    fn recording_state_at(
        &mut self,
        id: i64,
        t_us: u64,
    ) -> Result<Vec<crate::record::RecState>, StoreError> {
        crate::record::state_at(&mut Lite(&self.conn, &self.path), id, t_us)
    }

    fn recording_states(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecState>, StoreError> {
        crate::record::states(&mut Lite(&self.conn, &self.path), id, from_us, to_us)
    }

    fn delete_recording(&mut self, id: i64) -> Result<bool, StoreError> {
        crate::record::delete(&mut Lite(&self.conn, &self.path), id)
    }
}
