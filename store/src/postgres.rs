//! PostgreSQL, for rooms whose peers are on different machines: the same schema and
//! statements as SQLite ([`crate::schema`], `sql.rs`), one room per database. The store is
//! held with a session advisory lock taken at open (a second host is refused at once; the
//! lock goes with the connection, so a host that died frees it). A connection the server
//! dropped is opened again at the next write (and the lock taken again): a server that went
//! away and came back costs the writes in between, and the keeper's next batch brings the
//! whole room.

use std::str::FromStr;
use std::time::Duration;

use postgres::types::ToSql;
use postgres::{Client, Config, NoTls, Transaction};
use softsync_net::{NetId, RoomImage};

use crate::codec::{encode_event, encode_particles, EVENT_FORMAT};
use crate::schema::{migration_sql, SCHEMA_VERSION};
use crate::sql::{self, numbered};
use crate::{rows, Batch, LogChange, ObjectRow, RoomIdentity, RoomStore, StoreError, StoreInfo};

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
        set_meta(&mut tx, "schema_version", &SCHEMA_VERSION.to_string()).map_err(&err)?;
        set_meta(&mut tx, "event_format", &EVENT_FORMAT.to_string()).map_err(&err)?;
        tx.commit().map_err(&err)
    }

    fn meta(&mut self, key: &str) -> Result<Option<String>, StoreError> {
        self.client
            .query_opt(&numbered(sql::GET_META), &[&key])
            .and_then(|r| r.map(|r| r.try_get(0)).transpose())
            .map_err(db_err(&self.target))
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

fn set_meta(tx: &mut Transaction<'_>, key: &str, value: &str) -> Result<u64, postgres::Error> {
    tx.execute(&numbered(sql::SET_META), &[&key, &value])
}

fn write_object(
    tx: &mut Transaction<'_>,
    row: &ObjectRow,
    room_us: i64,
) -> Result<u64, postgres::Error> {
    let (p, q) = (row.state.pos, row.state.rot);
    let params: [&(dyn ToSql + Sync); 11] = [
        &i64::from(row.id.0),
        &i64::from(row.class.0),
        &f64::from(p.x),
        &f64::from(p.y),
        &f64::from(p.z),
        &f64::from(q.x),
        &f64::from(q.y),
        &f64::from(q.z),
        &f64::from(q.w),
        &encode_particles(&row.state.particles),
        &room_us,
    ];
    tx.execute(&numbered(sql::PUT_OBJECT), &params)
}

fn write_events(
    tx: &mut Transaction<'_>,
    id: NetId,
    from: u32,
    events: &[softsync_net::wire::TopologyEvent],
) -> Result<(), postgres::Error> {
    let object = i64::from(id.0);
    tx.execute(&numbered(sql::CUT_LOG), &[&object, &i64::from(from)])?;
    let st = tx.prepare(&numbered(sql::PUT_EVENT))?;
    for (k, e) in events.iter().enumerate() {
        let (kind, json) = encode_event(e);
        tx.execute(&st, &[&object, &(i64::from(from) + k as i64), &kind, &json])?;
    }
    Ok(())
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
        let scene = self.meta("scene_sha256")?;
        let messages = self.meta("messages_digest")?;
        match (scene, messages) {
            (Some(scene_sha256), Some(m)) => Ok(Some(RoomIdentity {
                scene_sha256,
                messages_digest: u64::from_str_radix(&m, 16)
                    .map_err(|_| StoreError::Row(format!("messages_digest {m:?}")))?,
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
        let err = db_err(&self.target);
        let mut tx = self.client.transaction().map_err(&err)?;
        if reset {
            for s in sql::EMPTY_ROOM {
                tx.execute(s, &[]).map_err(&err)?;
            }
            tx.execute(sql::FORGET_TIMES, &[]).map_err(&err)?;
        }
        tx.execute(
            &numbered(sql::PUT_SCENE),
            &[&identity.scene_sha256, &bundle],
        )
        .map_err(&err)?;
        set_meta(&mut tx, "scene_sha256", &identity.scene_sha256).map_err(&err)?;
        set_meta(
            &mut tx,
            "messages_digest",
            &format!("{:016x}", identity.messages_digest),
        )
        .map_err(&err)?;
        tx.commit().map_err(&err)
    }

    fn load(&mut self) -> Result<RoomImage, StoreError> {
        let format: u32 = self
            .meta("event_format")?
            .and_then(|v| v.parse().ok())
            .unwrap_or(EVENT_FORMAT);
        if format > EVENT_FORMAT {
            return Err(StoreError::Newer {
                found: format,
                known: EVENT_FORMAT,
            });
        }
        let room_us: u64 = self
            .meta("room_time_us")?
            .and_then(|v| v.parse().ok())
            .unwrap_or(0);
        let err = db_err(&self.target);
        let mut tx = self.client.transaction().map_err(&err)?;
        let mut objects = Vec::new();
        for r in tx.query(sql::LOAD_OBJECTS, &[]).map_err(&err)? {
            let p = [
                r.try_get(2).map_err(&err)?,
                r.try_get(3).map_err(&err)?,
                r.try_get(4).map_err(&err)?,
            ];
            let q = [
                r.try_get(5).map_err(&err)?,
                r.try_get(6).map_err(&err)?,
                r.try_get(7).map_err(&err)?,
                r.try_get(8).map_err(&err)?,
            ];
            let particles: Vec<u8> = r.try_get(9).map_err(&err)?;
            objects.push(rows::object(
                r.try_get(0).map_err(&err)?,
                r.try_get(1).map_err(&err)?,
                p,
                q,
                &particles,
            )?);
        }
        for r in tx.query(sql::LOAD_TOPOLOGY, &[]).map_err(&err)? {
            let (kind, json): (String, String) =
                (r.try_get(2).map_err(&err)?, r.try_get(3).map_err(&err)?);
            rows::push_event(
                &mut objects,
                r.try_get(0).map_err(&err)?,
                r.try_get(1).map_err(&err)?,
                &kind,
                &json,
            )?;
        }
        let mut retained = Vec::new();
        for r in tx.query(sql::LOAD_RETAINED, &[]).map_err(&err)? {
            let delivery: String = r.try_get(4).map_err(&err)?;
            retained.push(rows::retained(
                r.try_get(0).map_err(&err)?,
                r.try_get(1).map_err(&err)?,
                r.try_get(2).map_err(&err)?,
                r.try_get(3).map_err(&err)?,
                &delivery,
                r.try_get(5).map_err(&err)?,
            )?);
        }
        tx.commit().map_err(&err)?;
        Ok(RoomImage {
            room_time: Duration::from_micros(room_us),
            objects,
            retained,
        })
    }

    fn write(&mut self, b: &Batch) -> Result<(), StoreError> {
        self.reconnect_if_closed()?;
        let err = db_err(&self.target);
        let room_us = i64::try_from(b.room_time.as_micros()).unwrap_or(i64::MAX);
        let mut tx = self.client.transaction().map_err(&err)?;
        if b.full {
            for s in sql::EMPTY_ROOM {
                tx.execute(s, &[]).map_err(&err)?;
            }
        }
        for id in &b.remove {
            for s in sql::DROP_OBJECT {
                tx.execute(&numbered(s), &[&i64::from(id.0)])
                    .map_err(&err)?;
            }
        }
        for row in &b.objects {
            write_object(&mut tx, row, room_us).map_err(&err)?;
        }
        for (id, change) in &b.logs {
            match change {
                LogChange::Append { from, events } => write_events(&mut tx, *id, *from, events),
                LogChange::Replace(events) => write_events(&mut tx, *id, 0, events),
            }
            .map_err(&err)?;
        }
        if let Some(msgs) = &b.retained {
            tx.execute(sql::EMPTY_RETAINED, &[]).map_err(&err)?;
            for m in msgs {
                let params: [&(dyn ToSql + Sync); 6] = [
                    &i64::from(m.kind.0),
                    &rows::retained_object(m),
                    &(m.origin.0 as i64),
                    &i64::from(m.seq),
                    &rows::delivery_text(m.delivery),
                    &m.payload,
                ];
                tx.execute(&numbered(sql::PUT_RETAINED), &params)
                    .map_err(&err)?;
            }
        }
        if let Some(r) = &b.record {
            crate::record::write(&mut crate::db::Pg(&mut tx, &self.target), r)?;
        }
        // a batch with no room time (a recording's alone) leaves the room's
        if room_us > 0 {
            set_meta(&mut tx, "room_time_us", &room_us.to_string()).map_err(&err)?;
        }
        if b.checkpoint {
            set_meta(&mut tx, "checkpoint_room_time_us", &room_us.to_string()).map_err(&err)?;
        }
        tx.commit().map_err(&err)
    }

    fn scene(&mut self, sha256: &str) -> Result<Option<Vec<u8>>, StoreError> {
        self.client
            .query_opt(&numbered(sql::GET_SCENE), &[&sha256])
            .and_then(|r| r.map(|r| r.try_get(0)).transpose())
            .map_err(db_err(&self.target))
    }

    fn recordings(&mut self) -> Result<Vec<crate::record::RecordingInfo>, StoreError> {
        crate::record::list(&mut crate::db::Pg(&mut self.client, &self.target))
    }

    fn recording(&mut self, id: i64) -> Result<Option<crate::record::Recording>, StoreError> {
        crate::record::open(&mut crate::db::Pg(&mut self.client, &self.target), id)
    }

    fn recording_events(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecEvent>, StoreError> {
        crate::record::events(
            &mut crate::db::Pg(&mut self.client, &self.target),
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
        crate::record::state_at(&mut crate::db::Pg(&mut self.client, &self.target), id, t_us)
    }

    fn recording_states(
        &mut self,
        id: i64,
        from_us: u64,
        to_us: u64,
    ) -> Result<Vec<crate::record::RecState>, StoreError> {
        crate::record::states(
            &mut crate::db::Pg(&mut self.client, &self.target),
            id,
            from_us,
            to_us,
        )
    }

    fn delete_recording(&mut self, id: i64) -> Result<bool, StoreError> {
        crate::record::delete(&mut crate::db::Pg(&mut self.client, &self.target), id)
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
