//! A room kept between sessions: [`Peer::room_image`] is the room as a store keeps it (every
//! networked object but the avatars, with its log and state, the retained messages, the room
//! time), and [`Peer::reopen`] is how a host opens a room from such an image instead of from
//! its scene's objects: each body is its class replayed through its log, placed in the kept
//! state, under its old id.

use softsync_net::{Instant, KeptObject, RoomImage};

use super::Peer;
use crate::events::{Event, PeerError};
use crate::scene::Kind;

/// What a reopen did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Reopened {
    /// Objects put back.
    pub objects: usize,
    /// Topology entries replayed.
    pub entries: usize,
    /// Soft bodies whose kept particles did not fit the rebuilt body (they start at rest in
    /// their kept pose).
    pub states_not_applied: usize,
    /// Retained messages put back.
    pub messages: usize,
}

impl Peer {
    /// The room as it is now, to keep: every networked object but the avatars, each with its
    /// class, latest state and topology log; the retained messages but the built-in
    /// [`Holders`](crate::messages::Holders) (who holds what is about the people present); the room time (zero
    /// before the room clock is known).
    pub fn room_image(&self, now: Instant) -> RoomImage {
        let objects = self
            .session
            .object_ids()
            .into_iter()
            .filter_map(|id| {
                let class = self.session.class_of(id)?;
                if Kind::of_class(class).is_avatar() {
                    return None;
                }
                Some(KeptObject {
                    id,
                    class,
                    state: self.session.latest_state(id)?,
                    topology: self.session.topology_log(id)?.to_vec(),
                })
            })
            .collect();
        // who holds what is about the people in the room now, not the room's state
        let holders = self.message_types.kind::<crate::messages::Holders>();
        let retained = self
            .session
            .retained_for_keeping()
            .into_iter()
            .filter(|m| Some(m.kind) != holders)
            .collect();
        RoomImage {
            room_time: self.session.room_time(now).unwrap_or_default(),
            objects,
            retained,
        }
    }

    /// The host opens the room from `image` (instead of [`Peer::open`]): every kept object is
    /// rebuilt (its class replayed through its log, in the frame: a reopen is not a frame of
    /// a running room), placed in its kept state and restored under its old id; then the
    /// retained messages, the room clock and our avatar. An object whose log does not replay,
    /// or whose class the scene lacks, fails the reopen with the reason (nothing is dropped
    /// silently: the store keeps it).
    pub fn reopen(&mut self, now: Instant, image: &RoomImage) -> Result<Reopened, PeerError> {
        let mut done = Reopened::default();
        self.session
            .resume_room_time(now, image.room_time)
            .map_err(|e| PeerError::Build(format!("reopening: {e}")))?;
        for o in &image.objects {
            let kind = Kind::of_class(o.class);
            if kind.is_avatar() || self.scene.class(kind).is_none() {
                return Err(PeerError::Build(format!(
                    "reopening: object {} is of class {}, which the scene has no object class for",
                    o.id.0, o.class.0
                )));
            }
            let body = self
                .mirror
                .build(&self.scene, kind, o.state.pos, o.state.rot)?;
            self.mirror.insert(o.id, kind, body, None);
            self.mirror.set_pose(o.id, o.state.pos, o.state.rot);
            for (seq, e) in o.topology.iter().enumerate() {
                if let Err(err) = self.mirror.apply_topology(&self.scene, o.id, e) {
                    self.mirror.remove(o.id);
                    return Err(PeerError::Build(format!(
                        "reopening: entry {seq} of object {}'s log ({e:?}) does not replay: {err}",
                        o.id.0
                    )));
                }
                done.entries += 1;
            }
            if !self.mirror.apply_shown(o.id, &o.state) {
                done.states_not_applied += 1;
                self.counters.apply_errors += 1;
                self.events.push_back(Event::Warning(format!(
                    "reopening: object {}'s kept state ({} particles) does not fit its rebuilt body: it starts at rest",
                    o.id.0,
                    o.state.particles.len()
                )));
            }
            let state = self.mirror.state(o.id).unwrap_or_else(|| o.state.clone());
            self.session
                .restore_object(now, KeptObject { state, ..o.clone() })
                .map_err(|e| PeerError::Build(format!("reopening object {}: {e}", o.id.0)))?;
            done.objects += 1;
        }
        for m in &image.retained {
            match self.session.restore_retained(m.clone()) {
                Ok(()) => done.messages += 1,
                Err(e) => self.events.push_back(Event::Warning(format!(
                    "reopening: a retained message of kind {} not restored: {e}",
                    m.kind.0
                ))),
            }
        }
        self.spawn_avatar(now);
        Ok(done)
    }
}
