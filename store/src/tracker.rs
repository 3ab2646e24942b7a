//! What changed in a room since the last write. The keeper hands the tracker the room as it
//! is now ([`RoomImage`]) and gets back the [`Batch`] that brings the store there: objects
//! that came and went, log entries appended (or a log a new host rewrote), retained messages,
//! and, at a checkpoint, every state that moved. An object whose log changed is written whole
//! in the same batch (its state as of that log), so a reopened body is never placed with a
//! state of another layout.

use std::collections::BTreeMap;

use softsync_net::wire::{AppMessage, TopologyEvent};
use softsync_net::{ClassId, NetId, ObjectState, RoomImage};

use crate::{Batch, LogChange, ObjectRow};

/// What the store has, as far as the batches handed out say.
#[derive(Debug, Default)]
pub struct Tracker {
    written: BTreeMap<NetId, (ClassId, Vec<TopologyEvent>, ObjectState)>,
    retained: Vec<AppMessage>,
    /// The next batch must be the whole room (first write, or a write that failed).
    full: bool,
}

impl Tracker {
    /// A tracker whose first batch is the whole room.
    pub fn new() -> Self {
        Tracker {
            full: true,
            ..Default::default()
        }
    }

    /// The store may have missed batches (a write failed): the next one is the whole room.
    pub fn resync(&mut self) {
        self.full = true;
    }

    /// The batch taking the store from what it has to `now`; with `checkpoint`, every state
    /// that changed is written too. `None` when nothing is to be written.
    pub fn diff(&mut self, now: &RoomImage, checkpoint: bool) -> Option<Batch> {
        let full = std::mem::take(&mut self.full);
        if full {
            self.written.clear();
            self.retained.clear();
        }
        let mut b = Batch {
            full,
            room_time: now.room_time,
            checkpoint: checkpoint || full,
            ..Default::default()
        };
        let live: std::collections::BTreeSet<NetId> = now.objects.iter().map(|o| o.id).collect();
        b.remove = self
            .written
            .keys()
            .filter(|id| !live.contains(id))
            .copied()
            .collect();
        for id in &b.remove {
            self.written.remove(id);
        }
        for o in &now.objects {
            let change = match self.written.get(&o.id) {
                None => Some(LogChange::Replace(o.topology.clone())),
                Some((class, _, _)) if *class != o.class => {
                    Some(LogChange::Replace(o.topology.clone()))
                }
                Some((_, log, _)) if o.topology.starts_with(log) => (o.topology.len() > log.len())
                    .then(|| LogChange::Append {
                        from: log.len() as u32,
                        events: o.topology[log.len()..].to_vec(),
                    }),
                Some(_) => Some(LogChange::Replace(o.topology.clone())),
            };
            let moved = self
                .written
                .get(&o.id)
                .is_none_or(|(_, _, s)| *s != o.state);
            if change.is_some() || (b.checkpoint && moved) {
                b.objects.push(ObjectRow {
                    id: o.id,
                    class: o.class,
                    state: o.state.clone(),
                });
                self.written
                    .insert(o.id, (o.class, o.topology.clone(), o.state.clone()));
            }
            if let Some(c) = change {
                // a new object with an empty log still clears any rows of an id reused
                if !matches!(&c, LogChange::Replace(v) if v.is_empty()) || !full {
                    b.logs.push((o.id, c));
                }
            }
        }
        if full || now.retained != self.retained {
            b.retained = Some(now.retained.clone());
            self.retained = now.retained.clone();
        }
        let empty = b.remove.is_empty()
            && b.objects.is_empty()
            && b.logs.is_empty()
            && b.retained.is_none();
        (!empty || b.checkpoint).then_some(b)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use std::time::Duration;

    use glam::{Quat, Vec3};
    use softsync_net::KeptObject;

    use super::*;

    fn obj(id: u32, x: f32, log: Vec<TopologyEvent>) -> KeptObject {
        KeptObject {
            id: NetId(id),
            class: ClassId(1),
            state: ObjectState::rigid(Vec3::new(x, 0.0, 0.0), Quat::IDENTITY),
            topology: log,
        }
    }

    fn room(objects: Vec<KeptObject>) -> RoomImage {
        RoomImage {
            room_time: Duration::from_secs(1),
            objects,
            retained: vec![],
        }
    }

    #[test]
    fn appends_removals_rewrites_and_states_only_at_checkpoints() {
        let tear = TopologyEvent::Lift;
        let mut t = Tracker::new();
        let b = t
            .diff(
                &room(vec![obj(1, 0.0, vec![]), obj(2, 0.0, vec![tear])]),
                false,
            )
            .unwrap();
        assert!(b.full && b.checkpoint && b.objects.len() == 2);
        // nothing changed, no checkpoint: nothing to write
        assert!(t
            .diff(
                &room(vec![obj(1, 0.0, vec![]), obj(2, 0.0, vec![tear])]),
                false
            )
            .is_none());
        // a state moved: only at a checkpoint
        let moved = room(vec![obj(1, 0.5, vec![]), obj(2, 0.0, vec![tear])]);
        assert!(t.diff(&moved, false).is_none());
        let b = t.diff(&moved, true).unwrap();
        assert_eq!(b.objects.len(), 1);
        assert_eq!(b.objects[0].id, NetId(1));
        // an entry appended: written with the object's state, without waiting
        let b = t
            .diff(
                &room(vec![obj(1, 0.5, vec![]), obj(2, 0.1, vec![tear, tear])]),
                false,
            )
            .unwrap();
        assert_eq!(
            b.logs,
            vec![(
                NetId(2),
                LogChange::Append {
                    from: 1,
                    events: vec![tear]
                }
            )]
        );
        assert_eq!(b.objects.len(), 1);
        // a rewritten log (a new host's) replaces; a removed object goes
        let other = TopologyEvent::Resolution {
            level: 1,
            particles: 9,
        };
        let b = t
            .diff(&room(vec![obj(2, 0.1, vec![other])]), false)
            .unwrap();
        assert_eq!(b.remove, vec![NetId(1)]);
        assert_eq!(b.logs, vec![(NetId(2), LogChange::Replace(vec![other]))]);
        // after a failed write, the whole room again
        t.resync();
        assert!(
            t.diff(&room(vec![obj(2, 0.1, vec![other])]), false)
                .unwrap()
                .full
        );
    }
}
