//! Recorded sessions: what happened in a room and how everything looked, for review.
//!
//! A recording (schema v2) is its start — the room as it was then ([`RoomImage`], as JSON) —
//! then its events in order, each stamped with the room time (joins, leaves, migrations,
//! authority, tears and cuts, messages, who holds what, objects gone), and every object's
//! shown state each time it changed, at the replication rate (20 Hz). Written by the host
//! with the room (`Keeper`, `--record`), in the same transactions.
//!
//! Reading: [`crate::RoomStore::recording_state_at`] is the room at any time — each object's state
//! interpolated between its recorded states around it (none past the time it was gone) — in
//! two indexed queries per object, so a seek costs the same at minute 1 and minute 10.

use std::collections::BTreeMap;

use glam::{Quat, Vec3};
use softsync_net::{ClassId, NetId, ObjectState, RoomImage};

use crate::codec::{decode_particles, encode_particles, image_from_json, image_to_json};
use crate::db::{Sql, V};
use crate::StoreError;

/// One thing that happened.
#[derive(Clone, Debug, PartialEq)]
pub struct RecEvent {
    /// Room time, µs.
    pub room_us: u64,
    /// What: `join`, `leave`, `migration`, `authority`, `tear`, `lift`, `cut`, `resolution`,
    /// `message`, `holders`, `gone`.
    pub kind: String,
    /// The peer it is about.
    pub peer: Option<u64>,
    /// The object it is about.
    pub object: Option<u32>,
    /// Its details (JSON).
    pub data: String,
}

/// An object's shown state at a room time.
#[derive(Clone, Debug, PartialEq)]
pub struct RecState {
    /// Room time, µs.
    pub room_us: u64,
    /// Object.
    pub object: NetId,
    /// Its class.
    pub class: ClassId,
    /// The state.
    pub state: ObjectState,
}

/// A recording's start.
#[derive(Clone, Debug, PartialEq)]
pub struct RecStart {
    /// Its id (the Unix time it started, ms).
    pub id: i64,
    /// The room time it started at, µs.
    pub room_us: u64,
    /// The recording host.
    pub host: u64,
    /// The room then.
    pub image: RoomImage,
}

/// What one write adds to a recording.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RecordBatch {
    /// The recording (the keeper's id for it).
    pub recording: i64,
    /// Its start, in its first batch.
    pub start: Option<RecStart>,
    /// Events, in order, numbered from `first_n`.
    pub events: Vec<RecEvent>,
    /// The number of the first event.
    pub first_n: u64,
    /// States.
    pub states: Vec<RecState>,
    /// The room time the recording reaches.
    pub end_us: u64,
}

impl RecordBatch {
    /// Nothing to write.
    pub fn is_empty(&self) -> bool {
        self.start.is_none() && self.events.is_empty() && self.states.is_empty()
    }

    /// Bytes of values.
    pub fn payload_bytes(&self) -> usize {
        self.events
            .iter()
            .map(|e| 40 + e.kind.len() + e.data.len())
            .sum::<usize>()
            + self
                .states
                .iter()
                .map(|s| 24 + 56 + 12 * s.state.particles.len())
                .sum::<usize>()
    }

    /// `other` after this one (a batch the writer could not take, kept for the next).
    pub fn append(&mut self, other: RecordBatch) {
        if self.start.is_none() {
            self.start = other.start;
        }
        self.events.extend(other.events);
        self.states.extend(other.states);
        self.end_us = self.end_us.max(other.end_us);
    }
}

/// What a store says about one recording.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingInfo {
    /// Id.
    pub id: i64,
    /// When it started, Unix ms.
    pub started_unix_ms: i64,
    /// Room time at its start and end, µs.
    pub start_us: u64,
    /// End.
    pub end_us: u64,
    /// The host that recorded it.
    pub host: u64,
    /// Events.
    pub events: u64,
    /// State rows.
    pub states: u64,
}

fn us(v: &V, what: &str) -> Result<u64, StoreError> {
    u64::try_from(v.int(what)?).map_err(|_| StoreError::Row(format!("{what} negative")))
}

/// Writes `b` (inside the caller's transaction).
pub(crate) fn write(db: &mut dyn Sql, b: &RecordBatch) -> Result<(), StoreError> {
    if let Some(s) = &b.start {
        db.exec(
            "INSERT INTO recordings (id, started_unix_ms, start_room_us, end_room_us, host, image)
             VALUES (?1, ?2, ?3, ?3, ?4, ?5) ON CONFLICT (id) DO NOTHING",
            &[
                V::I(s.id),
                V::I(s.id),
                V::I(s.room_us as i64),
                V::I(s.host as i64),
                V::T(image_to_json(&s.image)),
            ],
        )?;
    }
    for (k, e) in b.events.iter().enumerate() {
        db.exec(
            "INSERT INTO record_events (recording, n, room_us, kind, peer, object, data)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7) ON CONFLICT (recording, n) DO NOTHING",
            &[
                V::I(b.recording),
                V::I((b.first_n + k as u64) as i64),
                V::I(e.room_us as i64),
                V::T(e.kind.clone()),
                e.peer.map_or(V::N, |p| V::I(p as i64)),
                e.object.map_or(V::N, |o| V::I(i64::from(o))),
                V::T(e.data.clone()),
            ],
        )?;
    }
    for s in &b.states {
        let (p, q) = (s.state.pos, s.state.rot);
        db.exec(
            "INSERT INTO record_states (recording, object, room_us, class, px, py, pz, qx, qy, qz, qw, particles)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)
             ON CONFLICT (recording, object, room_us) DO NOTHING",
            &[
                V::I(b.recording),
                V::I(i64::from(s.object.0)),
                V::I(s.room_us as i64),
                V::I(i64::from(s.class.0)),
                V::R(f64::from(p.x)),
                V::R(f64::from(p.y)),
                V::R(f64::from(p.z)),
                V::R(f64::from(q.x)),
                V::R(f64::from(q.y)),
                V::R(f64::from(q.z)),
                V::R(f64::from(q.w)),
                V::B(encode_particles(&s.state.particles)),
            ],
        )?;
    }
    if b.end_us > 0 {
        db.exec(
            "UPDATE recordings SET end_room_us = ?2 WHERE id = ?1 AND end_room_us < ?2",
            &[V::I(b.recording), V::I(b.end_us as i64)],
        )?;
    }
    Ok(())
}

/// Every recording, oldest first.
pub(crate) fn list(db: &mut dyn Sql) -> Result<Vec<RecordingInfo>, StoreError> {
    let rows = db.rows(
        "SELECT r.id, r.started_unix_ms, r.start_room_us, r.end_room_us, r.host,
           (SELECT count(*) FROM record_events e WHERE e.recording = r.id),
           (SELECT count(*) FROM record_states s WHERE s.recording = r.id)
         FROM recordings r ORDER BY r.id",
        &[],
    )?;
    rows.iter()
        .map(|r| {
            Ok(RecordingInfo {
                id: r[0].int("id")?,
                started_unix_ms: r[1].int("started_unix_ms")?,
                start_us: us(&r[2], "start_room_us")?,
                end_us: us(&r[3], "end_room_us")?,
                host: r[4].int("host")? as u64,
                events: us(&r[5], "events")?,
                states: us(&r[6], "states")?,
            })
        })
        .collect()
}

/// Deletes recording `id` (its events and states); false if there is none. The room's
/// state is untouched.
pub(crate) fn delete(db: &mut dyn Sql, id: i64) -> Result<bool, StoreError> {
    db.exec(
        "DELETE FROM record_events WHERE recording = ?1",
        &[V::I(id)],
    )?;
    db.exec(
        "DELETE FROM record_states WHERE recording = ?1",
        &[V::I(id)],
    )?;
    Ok(db.exec("DELETE FROM recordings WHERE id = ?1", &[V::I(id)])? > 0)
}

/// A recording, for reading.
#[derive(Clone, Debug)]
pub struct Recording {
    /// What the store says about it.
    pub info: RecordingInfo,
    /// The room at its start.
    pub image: RoomImage,
}

fn state_row(r: &[V], room_us: u64) -> Result<RecState, StoreError> {
    let f = |i: usize, w: &str| r[i].real(w).map(|x| x as f32);
    let object =
        u32::try_from(r[0].int("object")?).map_err(|_| StoreError::Row("object".into()))?;
    let class = u16::try_from(r[1].int("class")?).map_err(|_| StoreError::Row("class".into()))?;
    let pos = Vec3::new(f(2, "px")?, f(3, "py")?, f(4, "pz")?);
    let rot = Quat::from_xyzw(f(5, "qx")?, f(6, "qy")?, f(7, "qz")?, f(8, "qw")?);
    if !pos.is_finite() || !rot.is_finite() {
        return Err(StoreError::Row(format!(
            "object {object}: a recorded pose is not finite"
        )));
    }
    Ok(RecState {
        room_us,
        object: NetId(object),
        class: ClassId(class),
        state: ObjectState {
            pos,
            rot,
            particles: decode_particles(r[9].bytes("particles")?)?,
        },
    })
}

/// Recording `id`'s info and start.
pub(crate) fn open(db: &mut dyn Sql, id: i64) -> Result<Option<Recording>, StoreError> {
    let Some(info) = list(db)?.into_iter().find(|r| r.id == id) else {
        return Ok(None);
    };
    let rows = db.rows("SELECT image FROM recordings WHERE id = ?1", &[V::I(id)])?;
    let image = image_from_json(rows[0][0].text("image")?)?;
    Ok(Some(Recording { info, image }))
}

/// Events of recording `id` with `from_us <= room_us < to_us`, in order.
pub(crate) fn events(
    db: &mut dyn Sql,
    id: i64,
    from_us: u64,
    to_us: u64,
) -> Result<Vec<RecEvent>, StoreError> {
    db.rows(
        "SELECT room_us, kind, peer, object, data FROM record_events
         WHERE recording = ?1 AND room_us >= ?2 AND room_us < ?3 ORDER BY n",
        &[
            V::I(id),
            V::I(from_us as i64),
            V::I(to_us.min(i64::MAX as u64) as i64),
        ],
    )?
    .iter()
    .map(|r| {
        Ok(RecEvent {
            room_us: us(&r[0], "room_us")?,
            kind: r[1].text("kind")?.to_owned(),
            peer: r[2].opt_int("peer")?.map(|p| p as u64),
            object: r[3]
                .opt_int("object")?
                .map(|o| u32::try_from(o).map_err(|_| StoreError::Row("object".into())))
                .transpose()?,
            data: r[4].text("data")?.to_owned(),
        })
    })
    .collect()
}

/// Recording `id`'s recorded states with `from_us <= room_us < to_us`, by time then object.
pub(crate) fn states(
    db: &mut dyn Sql,
    id: i64,
    from_us: u64,
    to_us: u64,
) -> Result<Vec<RecState>, StoreError> {
    db.rows(
        "SELECT object, class, px, py, pz, qx, qy, qz, qw, particles, room_us FROM record_states
         WHERE recording = ?1 AND room_us >= ?2 AND room_us < ?3 ORDER BY room_us, object",
        &[
            V::I(id),
            V::I(from_us as i64),
            V::I(to_us.min(i64::MAX as u64) as i64),
        ],
    )?
    .iter()
    .map(|r| state_row(r, us(&r[10], "room_us")?))
    .collect()
}

/// Every object's state at room time `t_us` in recording `id`: between its last recorded
/// state at or before `t_us` and its next one, interpolated (positions and particles
/// linearly, rotations by slerp); an object gone (a `gone` event) before `t_us` after its
/// last state is not in it.
pub(crate) fn state_at(db: &mut dyn Sql, id: i64, t_us: u64) -> Result<Vec<RecState>, StoreError> {
    let t = t_us.min(i64::MAX as u64) as i64;
    let objects = db.rows(
        "SELECT DISTINCT object FROM record_states WHERE recording = ?1 AND room_us <= ?2",
        &[V::I(id), V::I(t)],
    )?;
    let gone: BTreeMap<i64, i64> = db
        .rows(
            "SELECT object, max(room_us) FROM record_events
             WHERE recording = ?1 AND kind = 'gone' AND room_us <= ?2 GROUP BY object",
            &[V::I(id), V::I(t)],
        )?
        .iter()
        .filter_map(|r| Some((r[0].int("object").ok()?, r[1].int("room_us").ok()?)))
        .collect();
    const COLS: &str = "object, class, px, py, pz, qx, qy, qz, qw, particles, room_us";
    let mut out = Vec::new();
    for o in objects {
        let object = o[0].int("object")?;
        let before = db.rows(
            &format!(
                "SELECT {COLS} FROM record_states WHERE recording = ?1 AND object = ?2
                 AND room_us <= ?3 ORDER BY room_us DESC LIMIT 1"
            ),
            &[V::I(id), V::I(object), V::I(t)],
        )?;
        let Some(b) = before.first() else { continue };
        let b_us = us(&b[10], "room_us")?;
        if gone.get(&object).is_some_and(|g| *g >= b_us as i64) {
            continue;
        }
        let mut s = state_row(b, t_us)?;
        let after = db.rows(
            &format!(
                "SELECT {COLS} FROM record_states WHERE recording = ?1 AND object = ?2
                 AND room_us > ?3 ORDER BY room_us ASC LIMIT 1"
            ),
            &[V::I(id), V::I(object), V::I(t)],
        )?;
        if let Some(a) = after.first() {
            let a_us = us(&a[10], "room_us")?;
            let n = state_row(a, a_us)?;
            if n.state.particles.len() == s.state.particles.len() && a_us > b_us {
                let f = (t_us - b_us) as f32 / (a_us - b_us) as f32;
                s.state.pos = s.state.pos.lerp(n.state.pos, f);
                s.state.rot = s.state.rot.slerp(n.state.rot, f);
                for (p, q) in s.state.particles.iter_mut().zip(&n.state.particles) {
                    *p = p.lerp(*q, f);
                }
            }
        }
        out.push(s);
    }
    Ok(out)
}
