//! Cuts and tears by a peer that does not own the body (co-manipulation: one holds the tissue,
//! another cuts it). The non-owner's blade actions ([`Blade`], room frame) go to the body's
//! owner as [`BladeRequest`]s — reliable and in order, relayed by the host to whoever owns
//! the body when it relays — batched (a scalpel samples every 5 mm: at most one message per
//! [`BLADE_BATCH`], a lift or a cut at once). The owner applies them as its own scalpel's:
//! in its rest frame, through the host's topology log, so every peer applies the same events.
//! Strokes of two authors on one body never run into one another: a segment of another author
//! than the open stroke's ends that stroke first (a lift), and a lift ends only its author's
//! stroke.

use std::collections::BTreeMap;
use std::time::Duration;

use glam::Vec3;
use softsync_net::{Delivery, Instant, MessageTarget, NetId, PeerId};

use super::Peer;
use crate::events::{Event, TopologyError};
use crate::messages::{Blade, BladeRequest, MAX_BLADE_ACTIONS};

/// A non-owner's blade actions wait at most this long to be sent together.
pub const BLADE_BATCH: Duration = Duration::from_millis(50);

/// The blade requests of a peer, both ways.
#[derive(Debug, Default)]
pub(crate) struct Blades {
    /// Ours, not sent yet: per object, the actions and when the first was queued.
    out: BTreeMap<NetId, (Vec<Blade>, Instant)>,
    /// Owner: per object, the author of the open stroke.
    strokes: BTreeMap<NetId, PeerId>,
}

impl Blades {
    pub(crate) fn clear(&mut self) {
        *self = Blades::default();
    }
}

fn finite(v: &[f32; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl Peer {
    /// A blade action on `id`, which another peer owns: queued for its owner.
    pub(super) fn request_blade(
        &mut self,
        now: Instant,
        id: NetId,
        action: Blade,
    ) -> Result<(), TopologyError> {
        if !self.may_share(id) {
            return Err(TopologyError(format!(
                "object {} is not ours and its class does not let others cut it",
                id.0
            )));
        }
        let urgent = !matches!(action, Blade::Tear { .. });
        let (queue, _) = self.blades.out.entry(id).or_insert((Vec::new(), now));
        queue.push(action);
        if urgent || queue.len() >= MAX_BLADE_ACTIONS {
            self.send_blades(now, id);
        }
        Ok(())
    }

    /// Each step: what waited long enough goes.
    pub(super) fn flush_blades(&mut self, now: Instant) {
        let due: Vec<NetId> = self
            .blades
            .out
            .iter()
            .filter(|(_, (_, since))| now.saturating_since(*since) >= BLADE_BATCH)
            .map(|(id, _)| *id)
            .collect();
        for id in due {
            self.send_blades(now, id);
        }
    }

    fn send_blades(&mut self, now: Instant, id: NetId) {
        let Some((actions, _)) = self.blades.out.remove(&id) else {
            return;
        };
        let msg = BladeRequest {
            object: id,
            actions,
        };
        let sent = self.session.send(
            now,
            &self.message_types,
            MessageTarget::OwnerOf(id),
            Delivery::Reliable,
            &msg,
        );
        match sent {
            Ok(_) => self.counters.blade_requests_sent += 1,
            Err(e) => self.events.push_back(Event::Warning(format!(
                "blade on object {} not sent: {e}",
                id.0
            ))),
        }
    }

    /// Owner: another peer's blade on one of our bodies.
    pub(super) fn on_blade_request(&mut self, now: Instant, from: PeerId, m: BladeRequest) {
        let ok = m.actions.len() <= MAX_BLADE_ACTIONS
            && m.actions.iter().all(|a| match a {
                Blade::Tear { from, to, blade } => finite(from) && finite(to) && finite(blade),
                Blade::Lift => true,
                Blade::Cut { point, normal } => finite(point) && finite(normal),
            })
            && self.session.owner(m.object) == Some(self.me())
            && self.may_share(m.object)
            && !self.replaying;
        if !ok {
            self.counters.blade_requests_refused += 1;
            return;
        }
        self.counters.blade_requests_applied += 1;
        for a in m.actions {
            let r = match a {
                Blade::Tear { from: a, to, blade } => self.tear_by(
                    now,
                    m.object,
                    Vec3::from(a),
                    Vec3::from(to),
                    Vec3::from(blade),
                    from,
                ),
                Blade::Lift => self.lift_by(now, m.object, from),
                Blade::Cut { point, normal } => {
                    self.cut(now, m.object, Vec3::from(point), Vec3::from(normal))
                }
            };
            if let Err(e) = r {
                self.events.push_back(Event::Warning(format!(
                    "blade of peer {} on object {}: {e}",
                    from.0, m.object.0
                )));
            }
        }
    }

    /// Owner: a tear segment of `author`'s stroke is about to go to the host: if another
    /// author's stroke is open on `id`, end it first.
    pub(super) fn stroke_of(&mut self, now: Instant, id: NetId, author: PeerId) {
        match self.blades.strokes.insert(id, author) {
            Some(open) if open != author => {
                let _ = self.ask_lift(now, id);
            }
            _ => {}
        }
    }

    /// Owner: `author` lifts its blade from `id`: its stroke ends (another's is left open).
    pub(super) fn lift_by(
        &mut self,
        now: Instant,
        id: NetId,
        author: PeerId,
    ) -> Result<(), TopologyError> {
        match self.blades.strokes.get(&id) {
            Some(open) if *open != author => Ok(()),
            _ => {
                self.blades.strokes.remove(&id);
                self.ask_lift(now, id)
            }
        }
    }
}
