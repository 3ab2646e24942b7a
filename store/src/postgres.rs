//! PostgreSQL, for rooms whose peers are on different machines: the same schema and
//! statements as SQLite ([`crate::schema`], `sql.rs`), one room per database. The store is
//! held with a session advisory lock taken at open (a second host is refused at once; the
//! lock goes with the connection, so a host that died frees it). A connection the server
//! dropped is opened again at the next write (and the lock taken again): a server that went
//! away and came back costs the writes in between, and the keeper's next batch brings the
//! whole room.

use std::str::FromStr;
use std::time::Duration;

use postgres::{Client, Config, NoTls};
use softsync_net::RoomImage;

use crate::codec::EVENT_FORMAT;
use crate::db::Pg;
use crate::room;
use crate::schema::{migration_sql, SCHEMA_VERSION};
use crate::{Batch, RoomIdentity, RoomStore, StoreError, StoreInfo};

/// The advisory lock key that marks a database as held by a host ("softsync" in ASCII).
const LOCK_KEY: i64 = 0x736f_6674_7379_6e63;

/// How long a connection may take.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(3);

/// A room kept in a PostgreSQL database.
pub struct PgStore {
    client: Client,
    config: Config,
    /// The URL without its password, for messages.
    target: String,
    migrated_from: u32,
}

impl std::fmt::Debug for PgStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PgStore")
            .field("target", &self.target)
            .finish()
    }
}

impl Drop for PgStore {
    /// The lock is given back before the connection closes: the server ends a closed
    /// connection's backend (and frees its locks) a moment later, and a host reopening the
    /// store at once (a restart, the next test) found it still held.
    fn drop(&mut self) {
        let _ = self
            .client
            .execute("SELECT pg_advisory_unlock($1)", &[&LOCK_KEY]);
    }
}

pub(crate) fn db_err(target: &str) -> impl Fn(postgres::Error) -> StoreError + '_ {
    move |e| {
        let what = match e.as_db_error() {
            Some(d) => format!("{} ({})", d.message(), d.code().code()),
            None if e.is_closed() => format!("the server closed the connection ({e})"),
            None => e.to_string(),
        };
        StoreError::Database {
            backend: "postgres",
            target: target.to_string(),
            what,
        }
    }
}

/// `url` with any password replaced by `***`.
fn redacted(url: &str) -> String {
    match (url.find("://"), url.find('@')) {
        (Some(s), Some(at)) if at > s => {
            let userinfo = &url[s + 3..at];
            match userinfo.split_once(':') {
                Some((user, _)) => format!("{}{user}:***{}", &url[..s + 3], &url[at..]),
                None => url.to_string(),
            }
        }
        _ => url.to_string(),
    }
}

fn connect(config: &Config, target: &str) -> Result<Client, StoreError> {
    let mut client = config.connect(NoTls).map_err(db_err(target))?;
    let locked: bool = client
        .query_one("SELECT pg_try_advisory_lock($1)", &[&LOCK_KEY])
        .and_then(|r| r.try_get(0))
        .map_err(db_err(target))?;
    if !locked {
        return Err(StoreError::Database {
            backend: "postgres",
            target: target.to_string(),
            what: "in use by another host (its advisory lock is held)".into(),
        });
    }
    Ok(client)
}

impl PgStore {
    /// Connect to `url` (`postgres://user[:password]@host[:port]/database`, or a unix socket:
    /// `postgresql://user@/database?host=/run/postgresql`), lock the database and migrate it
    /// to [`SCHEMA_VERSION`].
    pub fn open(url: &str) -> Result<Self, StoreError> {
        let target = redacted(url);
        let mut config = Config::from_str(url).map_err(db_err(&target))?;
        config.connect_timeout(CONNECT_TIMEOUT);
        let client = connect(&config, &target)?;
        let mut s = PgStore {
            client,
            config,
            target,
            migrated_from: 0,
        };
        s.migrate()?;
        Ok(s)
    }

    fn version(&mut self) -> Result<u32, StoreError> {
        let target = self.target.clone();
        let err = db_err(&target);
        let tables: i64 = self
            .client
            .query_one(
                "SELECT count(*) FROM information_schema.tables WHERE table_schema = current_schema()",
                &[],
            )
            .and_then(|r| r.try_get(0))
            .map_err(&err)?;
        if tables == 0 {
            return Ok(0);
        }
        let meta: i64 = self
            .client
            .query_one(
                "SELECT count(*) FROM information_schema.tables
                 WHERE table_schema = current_schema() AND table_name = 'meta'",
                &[],
            )
            .and_then(|r| r.try_get(0))
            .map_err(&err)?;
        if meta == 0 {
            return Err(StoreError::Foreign(format!(
                "{} has {tables} tables and no `meta`",
                self.target
            )));
        }
        let v = self.meta("schema_version")?;
        v.ok_or_else(|| StoreError::Foreign("no schema_version in meta".into()))?
            .parse()
            .map_err(|_| StoreError::Foreign("schema_version is not a number".into()))
    }

    fn migrate(&mut self) -> Result<(), StoreError> {
        let found = self.version()?;
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
        let err = db_err(&self.target);
        let mut tx = self.client.transaction().map_err(&err)?;
        for k in found..SCHEMA_VERSION {
            let sql = migration_sql(k as usize, "BYTEA")
                .ok_or_else(|| StoreError::Foreign(format!("no migration from version {k}")))?;
            tx.batch_execute(&sql).map_err(&err)?;
        }
        let target = self.target.clone();
        let mut db = Pg(&mut tx, &target);
        room::set_meta(&mut db, "schema_version", &SCHEMA_VERSION.to_string())?;
        room::set_meta(&mut db, "event_format", &EVENT_FORMAT.to_string())?;
        tx.commit().map_err(&err)
    }

    fn meta(&mut self, key: &str) -> Result<Option<String>, StoreError> {
        room::get_meta(&mut Pg(&mut self.client, &self.target), key)
    }

    /// Run `sql` on the database directly (tests: an older schema, a forged version).
    pub fn execute_raw(&mut self, sql: &str) -> Result<(), StoreError> {
        self.client.batch_execute(sql).map_err(db_err(&self.target))
    }

    /// A connection the server dropped is opened again (and the lock taken again).
    fn reconnect_if_closed(&mut self) -> Result<(), StoreError> {
        if self.client.is_closed() {
            self.client = connect(&self.config, &self.target)?;
        }
        Ok(())
    }
}

impl RoomStore for PgStore {
    fn info(&self) -> StoreInfo {
        StoreInfo {
            backend: "postgres",
            schema_version: SCHEMA_VERSION,
            migrated_from: self.migrated_from,
        }
    }

    fn identity(&mut self) -> Result<Option<RoomIdentity>, StoreError> {
        room::identity(&mut Pg(&mut self.client, &self.target))
    }

    fn begin(
        &mut self,
        identity: &RoomIdentity,
        bundle: &[u8],
        reset: bool,
    ) -> Result<(), StoreError> {
        let err = db_err(&self.target);
        let mut tx = self.client.transaction().map_err(&err)?;
        room::begin(&mut Pg(&mut tx, &self.target), identity, bundle, reset)?;
        tx.commit().map_err(&err)
    }

    fn load(&mut self) -> Result<RoomImage, StoreError> {
        let err = db_err(&self.target);
        let mut tx = self.client.transaction().map_err(&err)?;
        let image = room::load(&mut Pg(&mut tx, &self.target))?;
        tx.commit().map_err(&err)?;
        Ok(image)
    }

    fn write(&mut self, b: &Batch) -> Result<(), StoreError> {
        self.reconnect_if_closed()?;
        let err = db_err(&self.target);
        let mut tx = self.client.transaction().map_err(&err)?;
        room::write(&mut Pg(&mut tx, &self.target), b)?;
        tx.commit().map_err(&err)
    }

    fn scene(&mut self, sha256: &str) -> Result<Option<Vec<u8>>, StoreError> {
        room::scene(&mut Pg(&mut self.client, &self.target), sha256)
    }

    fn recordings(&mut self) -> Result<Vec<crate::record::RecordingInfo>, StoreError> {
        crate::record::list(&mut Pg(&mut self.client, &self.target))
    }

    fn recording(&mut self, id: i64) -> Result<Option<crate::record::Recording>, StoreError> {
        crate::record::open(&mut Pg(&mut self.client, &self.target), id)
    }

    fn recording_events(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecEvent>, StoreError> {
        crate::record::events(&mut Pg(&mut self.client, &self.target), id, from_us, to_us)
    }

    fn recording_state_at(
        &mut self,
        id: i64,
        t_us: u64,
    ) -> Result<Vec<crate::record::RecState>, StoreError> {
        crate::record::state_at(&mut Pg(&mut self.client, &self.target), id, t_us)
    }

    fn recording_states(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecState>, StoreError> {
        crate::record::states(&mut Pg(&mut self.client, &self.target), id, from_us, to_us)
    }

    fn delete_recording(&mut self, id: i64) -> Result<bool, StoreError> {
        crate::record::delete(&mut Pg(&mut self.client, &self.target), id)
    }
}

#[cfg(test)]
mod tests {
    use super::redacted;

    #[test]
    fn passwords_never_reach_messages() {
        assert_eq!(
            redacted("postgres://room:s3cret@db.example:5432/rooms"),
            "postgres://room:***@db.example:5432/rooms"
        );
        assert_eq!(
            redacted("postgresql://room@/rooms?host=/run/pg"),
            "postgresql://room@/rooms?host=/run/pg"
        );
    }
}
