//! Objects built off the frame. A soft object that arrives with a topology history — each
//! piece of a cut (its log is its parent's plus the `Cut` that made it), a torn body in a late
//! joiner's snapshot — is its class's body replayed through that history, and planning a
//! piece clusters its mesh (~6 ms for half the thesis's bunny): in the frame, a cut stalls
//! every peer's frame for as long as its pieces take. Here the replay runs on a worker thread
//! ([`softsync_softbody::BodyBuild`]) while the frame goes on; the object is
//! [`LocalBody::Building`] until its body lands, which costs the frame only the copy of its
//! rapier bodies into the world. A build lands [`BUILD_LANDS_AFTER`] (30 ms) after it starts,
//! whenever the worker finished (waiting for it if it has not): the frame it lands in
//! depends on the peer's clock alone, so runs on virtual time stay deterministic. A peer on
//! the wall clock (the app: `PeerConfig::land_when_ready`) lands it at the first frame after
//! that once the worker is done instead, so no frame waits for a worker on a slow machine.
//!
//! Consistency: the worker replays the same log entries from the same class plan placed at the
//! same pose with the same arithmetic as the frame would, so every peer ends with the same
//! mesh and particles whenever its build lands. Entries the log gains meanwhile are applied
//! in order when it lands; an entry that rewrites one the build replays (a migration's new
//! host) restarts it. Until it lands the object has nothing to show or publish: the owner
//! publishes a piece from its first step after landing, and the others show the owner's state
//! from theirs. The body a cut replaced stays shown (`Mirror::leaving`) until every build
//! running has landed, so the cut never blinks: old body, then its pieces, in one frame.

use softsync_net::wire::TopologyEvent;
use softsync_net::{Instant, NetId, ObjectState, PeerId};
use softsync_softbody::BodyBuild;

use super::Peer;
use crate::events::{Event, PeerError};
use crate::mirror::{build_step, Build, LocalBody, BUILD_LANDS_AFTER};
use crate::scene::Kind;

/// The longest a despawned body stays shown waiting for builds to land, seconds.
const LEAVING_MAX_S: f64 = 1.0;

impl Peer {
    /// A `kind` object `id` was spawned at `s` (at `now`): if it is a soft body whose log has entries
    /// already, starts building it off the frame and makes it a [`LocalBody::Building`]
    /// object. False when the frame should build it (not soft, no history, off-frame builds
    /// off, or an entry the scene cannot turn into a step: the frame's replay reports it).
    pub(super) fn build_off_frame(
        &mut self,
        now: Instant,
        id: NetId,
        kind: Kind,
        avatar_of: Option<PeerId>,
        s: &ObjectState,
    ) -> Result<bool, PeerError> {
        if !self.config.build_off_frame || self.scene.soft_config(kind).is_none() {
            return Ok(false);
        }
        let log = self.session.topology_log(id).unwrap_or(&[]).to_vec();
        if log.is_empty() {
            return Ok(false);
        }
        let Ok(steps) = log
            .iter()
            .map(|e| build_step(&self.scene, kind, e, true))
            .collect::<Result<Vec<_>, _>>()
        else {
            return Ok(false);
        };
        let plan = self.scene.soft_plan(kind).map_err(PeerError::Build)?;
        let job = BodyBuild::start(plan, s.pos, s.rot, steps);
        self.mirror.insert(id, kind, LocalBody::Building, avatar_of);
        let started = now;
        self.mirror.builds.insert(
            id,
            Build {
                job,
                entries: log,
                started,
            },
        );
        Ok(true)
    }

    /// Entry `seq` of the log of `id`, which is being built: nothing to do if the build
    /// replays it or it comes after (applied on landing); a different entry where the build
    /// has one (the log was rewritten) restarts the build from the log as it is now. False
    /// if `id` is not being built.
    pub(super) fn topology_while_building(
        &mut self,
        now: Instant,
        id: NetId,
        seq: u32,
        event: &TopologyEvent,
    ) -> bool {
        let Some(b) = self.mirror.builds.get(&id) else {
            return false;
        };
        match b.entries.get(seq as usize) {
            Some(e) if e != event => {}
            _ => return true,
        }
        let Some(kind) = self.mirror.objects.get(&id).map(|o| o.kind) else {
            return true;
        };
        let avatar_of = self.mirror.objects.get(&id).and_then(|o| o.avatar_of);
        let s = self
            .session
            .latest_state(id)
            .unwrap_or_else(|| ObjectState::rigid(glam::Vec3::ZERO, glam::Quat::IDENTITY));
        self.mirror.remove(id);
        self.counters.builds_restarted += 1;
        match self.build_off_frame(now, id, kind, avatar_of, &s) {
            Ok(true) => {}
            Ok(false) | Err(_) => {
                // the frame builds it and replays the whole log
                if let Ok(body) = self.mirror.build(&self.scene, kind, s.pos, s.rot) {
                    self.mirror.insert(id, kind, body, avatar_of);
                    let log = self.session.topology_log(id).unwrap_or(&[]).to_vec();
                    for e in &log {
                        if let Err(e) = self.mirror.apply_topology(&self.scene, id, e) {
                            self.counters.apply_errors += 1;
                            self.events.push_back(Event::Warning(format!(
                                "object {}: history not replayed: {e}",
                                id.0
                            )));
                            break;
                        }
                    }
                }
            }
        }
        true
    }

    /// Builds that finished land in the world (then the entries their log gained meanwhile
    /// are applied); once none is running, the bodies despawned meanwhile go.
    ///
    /// While a despawned body is still shown, builds land together (all of a cut's pieces in
    /// one frame: never the body and one of its pieces in the world at once, overlapping).
    pub(super) fn land_builds(&mut self, now: Instant) {
        // due, not merely done: when a build lands depends on the clock alone — unless the
        // peer lands builds once they are done (`land_when_ready`: then a due build whose
        // worker is still busy waits for a later frame, up to `LEAVING_MAX_S`)
        let when_ready = self.config.land_when_ready;
        let mut ready: Vec<NetId> = self
            .mirror
            .builds
            .iter_mut()
            .filter_map(|(id, b)| {
                let age = now.saturating_since(b.started);
                let due = age >= BUILD_LANDS_AFTER
                    && (!when_ready || age.as_secs_f64() > LEAVING_MAX_S || b.job.is_ready());
                due.then_some(*id)
            })
            .collect();
        ready.sort();
        let overdue = |since: &Instant| now.saturating_since(*since).as_secs_f64() > LEAVING_MAX_S;
        let waiting_for_all = self.mirror.leaving.iter().any(|(_, t)| !overdue(t));
        if !waiting_for_all || ready.len() == self.mirror.builds.len() {
            for id in ready {
                self.land(id);
            }
        }
        let running = !self.mirror.builds.is_empty();
        let gone: Vec<NetId> = self
            .mirror
            .leaving
            .iter()
            .filter(|(_, since)| !running || overdue(since))
            .map(|(id, _)| *id)
            .collect();
        for id in gone {
            self.mirror.remove(id);
        }
    }

    /// Lands object `id`'s finished build.
    fn land(&mut self, id: NetId) {
        let Some(b) = self.mirror.builds.remove(&id) else {
            return;
        };
        let landed = b.job.land(&mut self.mirror.soft, &mut self.mirror.world);
        let Some(o) = self.mirror.objects.get_mut(&id) else {
            return;
        };
        let kind = o.kind;
        match landed {
            Ok(h) => {
                o.body = LocalBody::Soft(h);
                o.topology = b.entries.len() as u32;
                o.level = b.entries.iter().rev().find_map(|e| match e {
                    TopologyEvent::Resolution { level, .. } => Some(*level),
                    _ => None,
                });
                self.mirror
                    .by_ref
                    .insert(softsync_interaction::ObjectRef::Soft(h), id);
                self.counters.bodies_built_off_frame += 1;
                self.counters.topology_events += b.entries.len() as u64;
            }
            Err(e) => {
                // the class's body, at the first entry it could not take (as the frame's
                // replay would leave it): a warning, and the room's state shows on it
                self.counters.apply_errors += 1;
                self.events.push_back(Event::Warning(format!(
                    "object {}: history not replayed: {e}",
                    id.0
                )));
                let (pos, rot) = self
                    .session
                    .latest_state(id)
                    .map_or((glam::Vec3::ZERO, glam::Quat::IDENTITY), |s| (s.pos, s.rot));
                let avatar_of = o.avatar_of;
                self.mirror.remove(id);
                if let Ok(body) = self.mirror.build(&self.scene, kind, pos, rot) {
                    self.mirror.insert(id, kind, body, avatar_of);
                }
                return;
            }
        }
        // what the log gained while it was built
        let log = self.session.topology_log(id).unwrap_or(&[]).to_vec();
        for e in log.iter().skip(b.entries.len()) {
            match self.mirror.apply_topology(&self.scene, id, e) {
                Ok(()) => self.counters.topology_events += 1,
                Err(e) => {
                    self.counters.apply_errors += 1;
                    self.events.push_back(Event::Warning(format!(
                        "object {}: topology entry not applied: {e}",
                        id.0
                    )));
                    break;
                }
            }
        }
        let ours = self.session.owner(id) == Some(self.me());
        self.mirror.set_simulated(id, ours);
    }

    /// The room despawned `id`: it goes now, or, if it is a soft body and builds are running
    /// (a cut's pieces), once they land.
    pub(super) fn despawn_shown(&mut self, now: Instant, id: NetId) {
        let soft = matches!(
            self.mirror.objects.get(&id).map(|o| o.body),
            Some(LocalBody::Soft(_))
        );
        if soft && self.config.build_off_frame {
            self.mirror.leaving.push((id, now));
        } else {
            self.mirror.remove(id);
        }
    }
}
