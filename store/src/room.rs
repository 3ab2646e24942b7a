//! The room's rows, read and written the same way on every back end (through `db::Sql`,
//! inside the transaction the back end opens): its identity, the scene, the kept image and
//! each batch.

use std::time::Duration;

use softsync_net::RoomImage;

use crate::codec::{encode_event, encode_particles, EVENT_FORMAT};
use crate::db::{Sql, V};
use crate::{rows, sql, Batch, LogChange, RoomIdentity, StoreError};

/// One `meta` value.
pub(crate) fn get_meta(db: &mut dyn Sql, key: &str) -> Result<Option<String>, StoreError> {
    match db.rows(sql::GET_META, &[V::T(key.to_owned())])?.first() {
        Some(r) => Ok(Some(r[0].text("meta value")?.to_owned())),
        None => Ok(None),
    }
}

/// Sets one `meta` value.
pub(crate) fn set_meta(db: &mut dyn Sql, key: &str, value: &str) -> Result<(), StoreError> {
    db.exec(
        sql::SET_META,
        &[V::T(key.to_owned()), V::T(value.to_owned())],
    )
    .map(|_| ())
}

/// The identity of the room kept, if any.
pub(crate) fn identity(db: &mut dyn Sql) -> Result<Option<RoomIdentity>, StoreError> {
    let scene = get_meta(db, "scene_sha256")?;
    let messages = get_meta(db, "messages_digest")?;
    match (scene, messages) {
        (Some(scene_sha256), Some(m)) => Ok(Some(RoomIdentity {
            scene_sha256,
            messages_digest: u64::from_str_radix(&m, 16)
                .map_err(|_| StoreError::Row(format!("messages_digest {m:?}")))?,
        })),
        _ => Ok(None),
    }
}

/// [`crate::RoomStore::begin`].
pub(crate) fn begin(
    db: &mut dyn Sql,
    identity: &RoomIdentity,
    bundle: &[u8],
    reset: bool,
) -> Result<(), StoreError> {
    if let Some(kept) = self::identity(db)? {
        if kept != *identity && !reset {
            return Err(StoreError::OtherScene {
                stored_scene: kept.scene_sha256,
                stored_messages: kept.messages_digest,
                given_scene: identity.scene_sha256.clone(),
                given_messages: identity.messages_digest,
            });
        }
    }
    if reset {
        for s in sql::EMPTY_ROOM {
            db.exec(s, &[])?;
        }
        db.exec(sql::FORGET_TIMES, &[])?;
    }
    db.exec(
        sql::PUT_SCENE,
        &[V::T(identity.scene_sha256.clone()), V::B(bundle.to_vec())],
    )?;
    set_meta(db, "scene_sha256", &identity.scene_sha256)?;
    set_meta(
        db,
        "messages_digest",
        &format!("{:016x}", identity.messages_digest),
    )
}

/// The scene bundle kept under `sha256`.
pub(crate) fn scene(db: &mut dyn Sql, sha256: &str) -> Result<Option<Vec<u8>>, StoreError> {
    match db.rows(sql::GET_SCENE, &[V::T(sha256.to_owned())])?.first() {
        Some(r) => Ok(Some(r[0].bytes("bundle")?.to_vec())),
        None => Ok(None),
    }
}

/// The room as kept.
pub(crate) fn load(db: &mut dyn Sql) -> Result<RoomImage, StoreError> {
    let format: u32 = get_meta(db, "event_format")?
        .and_then(|v| v.parse().ok())
        .unwrap_or(EVENT_FORMAT);
    if format > EVENT_FORMAT {
        return Err(StoreError::Newer {
            found: format,
            known: EVENT_FORMAT,
        });
    }
    let room_us: u64 = get_meta(db, "room_time_us")?
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    let mut objects = Vec::new();
    for r in db.rows(sql::LOAD_OBJECTS, &[])? {
        let f = |i: usize, w: &str| r[i].real(w);
        objects.push(rows::object(
            r[0].int("id")?,
            r[1].int("class")?,
            [f(2, "px")?, f(3, "py")?, f(4, "pz")?],
            [f(5, "qx")?, f(6, "qy")?, f(7, "qz")?, f(8, "qw")?],
            r[9].bytes("particles")?,
        )?);
    }
    for r in db.rows(sql::LOAD_TOPOLOGY, &[])? {
        rows::push_event(
            &mut objects,
            r[0].int("object")?,
            r[1].int("seq")?,
            r[2].text("kind")?,
            r[3].text("event")?,
        )?;
    }
    let mut retained = Vec::new();
    for r in db.rows(sql::LOAD_RETAINED, &[])? {
        retained.push(rows::retained(
            r[0].int("kind")?,
            r[1].int("object")?,
            r[2].int("origin")?,
            r[3].int("seq")?,
            r[4].text("delivery")?,
            r[5].bytes("payload")?.to_vec(),
        )?);
    }
    Ok(RoomImage {
        room_time: Duration::from_micros(room_us),
        objects,
        retained,
    })
}

fn write_events(
    db: &mut dyn Sql,
    id: softsync_net::NetId,
    from: u32,
    events: &[softsync_net::wire::TopologyEvent],
) -> Result<(), StoreError> {
    let object = i64::from(id.0);
    db.exec(sql::CUT_LOG, &[V::I(object), V::I(i64::from(from))])?;
    for (k, e) in events.iter().enumerate() {
        let (kind, json) = encode_event(e);
        db.exec(
            sql::PUT_EVENT,
            &[
                V::I(object),
                V::I(i64::from(from) + k as i64),
                V::T(kind.to_owned()),
                V::T(json),
            ],
        )?;
    }
    Ok(())
}

/// [`crate::RoomStore::write`], inside the caller's transaction.
pub(crate) fn write(db: &mut dyn Sql, b: &Batch) -> Result<(), StoreError> {
    let room_us = i64::try_from(b.room_time.as_micros()).unwrap_or(i64::MAX);
    if b.full {
        for s in sql::EMPTY_ROOM {
            db.exec(s, &[])?;
        }
    }
    for id in &b.remove {
        for s in sql::DROP_OBJECT {
            db.exec(s, &[V::I(i64::from(id.0))])?;
        }
    }
    for row in &b.objects {
        let (p, q) = (row.state.pos, row.state.rot);
        db.exec(
            sql::PUT_OBJECT,
            &[
                V::I(i64::from(row.id.0)),
                V::I(i64::from(row.class.0)),
                V::R(f64::from(p.x)),
                V::R(f64::from(p.y)),
                V::R(f64::from(p.z)),
                V::R(f64::from(q.x)),
                V::R(f64::from(q.y)),
                V::R(f64::from(q.z)),
                V::R(f64::from(q.w)),
                V::B(encode_particles(&row.state.particles)),
                V::I(room_us),
            ],
        )?;
    }
    for (id, change) in &b.logs {
        match change {
            LogChange::Append { from, events } => write_events(db, *id, *from, events)?,
            LogChange::Replace(events) => write_events(db, *id, 0, events)?,
        }
    }
    if let Some(msgs) = &b.retained {
        db.exec(sql::EMPTY_RETAINED, &[])?;
        for m in msgs {
            db.exec(
                sql::PUT_RETAINED,
                &[
                    V::I(i64::from(m.kind.0)),
                    V::I(rows::retained_object(m)),
                    V::I(m.origin.0 as i64),
                    V::I(i64::from(m.seq)),
                    V::T(rows::delivery_text(m.delivery).to_owned()),
                    V::B(m.payload.clone()),
                ],
            )?;
        }
    }
    if let Some(r) = &b.record {
        crate::record::write(db, r)?;
    }
    // a batch with no room time (a recording's alone) leaves the room's
    if room_us > 0 {
        set_meta(db, "room_time_us", &room_us.to_string())?;
    }
    if b.checkpoint {
        set_meta(db, "checkpoint_room_time_us", &room_us.to_string())?;
    }
    Ok(())
}
