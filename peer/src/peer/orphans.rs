//! Hands on a body that a cut replaces: the room despawns the body and spawns each piece as
//! an object of its own, built by every peer from the log. Our hands on the body (here or
//! remote) wait for the pieces, then take the nearest particle of the piece nearest to where
//! their particle was — each hand keeps holding the right piece, as a remote hand if the
//! piece is another peer's (pieces belong to the cutter: the body's owner, which asks for the
//! cut, also for a non-owner's blade). Hands whose pieces do not come within a second let go.

use glam::Vec3;
use softsync_interaction::{ObjectRef, Target};
use softsync_net::{Instant, NetId};

use super::Peer;
use crate::mirror::LocalBody;

/// Our hands on a body that was despawned, waiting for the pieces of its cut.
#[derive(Clone, Debug)]
pub(crate) struct Orphan {
    pub(super) parent: NetId,
    pub(super) since: Instant,
    /// Per hand: where its particle was.
    pub(super) hands: Vec<(usize, Vec3)>,
}

/// How long hands on a cut body wait for its pieces before they let go, seconds.
const ORPHAN_WAIT_S: f64 = 1.0;

impl Peer {
    /// Object `id` is about to be despawned: our hands on it (here or remote) wait for the
    /// pieces of a cut to take it over ([`Peer::adopt_orphans`]).
    pub(super) fn orphan_hands_of(&mut self, now: Instant, id: NetId) {
        let Some(LocalBody::Soft(h)) = self.mirror.objects.get(&id).map(|o| o.body) else {
            return;
        };
        let Some(body) = self.mirror.soft.get(h) else {
            return;
        };
        let at = body.particle_positions(&self.mirror.world);
        let hands: Vec<(usize, Vec3)> = self
            .hand_ids
            .iter()
            .enumerate()
            .filter_map(|(i, hid)| {
                let t = self.hands.held(*hid).or_else(|| self.hands.remote(*hid))?;
                match t {
                    Target::SoftParticle(b, p) if b == h => Some((i, *at.get(p as usize)?)),
                    _ => None,
                }
            })
            .collect();
        if !hands.is_empty() {
            self.comanip.orphans.push(Orphan {
                parent: id,
                since: now,
                hands,
            });
        }
    }

    /// Hands waiting on a cut body take the nearest particle of its pieces once they are
    /// built (objects spawned after it whose log ends with the cut, fully applied; none still
    /// building off the frame): each
    /// hand keeps holding the right piece, as a remote hand if the piece is another peer's.
    /// Past [`ORPHAN_WAIT_S`] they let go.
    pub(super) fn adopt_orphans(&mut self, now: Instant) {
        if self.comanip.orphans.is_empty() {
            return;
        }
        let me = self.me();
        let orphans = std::mem::take(&mut self.comanip.orphans);
        for o in orphans {
            let pieces: Vec<(NetId, softsync_softbody::SoftBodyHandle)> = self
                .mirror
                .objects
                .iter()
                .filter(|(id, _)| **id > o.parent)
                .filter_map(|(id, m)| {
                    let LocalBody::Soft(h) = m.body else {
                        return None;
                    };
                    let log = self.session.topology_log(*id)?;
                    let cut = matches!(
                        log.last(),
                        Some(softsync_net::wire::TopologyEvent::Cut { .. })
                    );
                    (cut && m.topology as usize == log.len()).then_some((*id, h))
                })
                .collect();
            // all the pieces first: some may still be building off the frame
            let waited = now.saturating_since(o.since).as_secs_f64();
            if (pieces.is_empty() || !self.mirror.builds.is_empty()) && waited < ORPHAN_WAIT_S {
                self.comanip.orphans.push(o);
                continue;
            }
            if pieces.is_empty() {
                // no pieces came: the hands let go (a remote one is told it was refused)
                for (hand, _) in &o.hands {
                    if let Some(t) = self.hands.remote(self.hand_ids[*hand]) {
                        self.hands.deny(t.object());
                    }
                }
                continue;
            }
            for (hand, at) in o.hands {
                let mut best: Option<(f32, NetId, softsync_softbody::SoftBodyHandle, u32)> = None;
                for (id, h) in &pieces {
                    let Some(b) = self.mirror.soft.get(*h) else {
                        continue;
                    };
                    for (j, p) in b.particle_positions(&self.mirror.world).iter().enumerate() {
                        let d = p.distance_squared(at);
                        if best.is_none_or(|(bd, ..)| d < bd) {
                            best = Some((d, *id, *h, j as u32));
                        }
                    }
                }
                let Some((_, id, h, j)) = best else { continue };
                let hid = self.hand_ids[hand];
                if self.hands.retarget(hid, Target::SoftParticle(h, j)) {
                    self.counters.holds_kept_through_cuts += 1;
                    if self.session.owner(id) != Some(me) {
                        self.hands.hold_as_remote(ObjectRef::Soft(h));
                    }
                }
            }
        }
    }
}
