//! Tears and cuts on a peer. The owner turns a scalpel's path in the room into topology
//! events in the object's rest frame, quantised as the wire carries them, and asks the host
//! ([`Peer::tear`], [`Peer::lift`], [`Peer::cut`]). Nobody applies an event until it is in the
//! host's log ([`softsync_net::Event::Topology`]): then every mirror applies the same
//! quantised events in the same order and ends with the identical mesh. An entry that is not
//! the next one (after a migration the new host's log replaced ours from there) rebuilds the
//! body from its class and replays the whole log.

use glam::Vec3;
use softsync_net::wire::TopologyEvent;
use softsync_net::{Instant, NetId, PeerId};
use softsync_softbody::cut::{CutPlane, TearSegment};

use super::Peer;
use crate::events::{Event, TopologyError};
use crate::messages::Blade;
use crate::mirror::LocalBody;

/// Distance the hand moves between two samples of a scalpel's path (the paper samples "by time
/// or distance"; distance keeps segments the same length at any hand speed).
pub const SCALPEL_SAMPLE_M: f32 = 0.005;

/// Trigger value above which a hand holds its scalpel to the body.
pub const SCALPEL_TRIGGER: f32 = 0.5;

/// Length of the scalpel's blade above its tip, along the hand's local +y, metres.
pub const SCALPEL_BLADE_M: f32 = 0.04;

/// A turn of the scalpel's path sharper than this (degrees) is sampled where it turns, before
/// the next [`SCALPEL_SAMPLE_M`] (tear paper §3.1: extra samples on abrupt motion), so a
/// corner of the stroke is not cut off.
pub const SCALPEL_TURN_DEG: f32 = 30.0;

/// Where a scalpel's stroke is sampled this frame: the stroke's last sample is `last`, the
/// tip was at `prev` a frame ago and is at `tip` now. A sample every [`SCALPEL_SAMPLE_M`] of
/// the way from `last` (the tip itself when it has gone that far), and the previous tip when
/// the path turned there by more than [`SCALPEL_TURN_DEG`] (at least 1 mm from `last`).
pub fn scalpel_samples(last: Vec3, prev: Vec3, tip: Vec3) -> Vec<Vec3> {
    let mut out = Vec::new();
    let mut from = last;
    let (before, after) = (prev - last, tip - prev);
    let turned = before.length() > 1e-3
        && after.length() > 1e-4
        && before.angle_between(after).to_degrees() > SCALPEL_TURN_DEG;
    if turned {
        out.push(prev);
        from = prev;
    }
    if from.distance(tip) >= SCALPEL_SAMPLE_M {
        out.push(tip);
    }
    out
}

/// A hand's scalpel: while its trigger is held, the hand's path through a soft body tears it
/// (VR controllers and the desktop's mouse hand alike: both give a trigger). A hand whose
/// tool is the cutter cuts instead (`peer/cutter.rs`).
#[derive(Clone, Debug, Default)]
pub(crate) struct Scalpel {
    /// The hand's last input: position, rotation, trigger.
    pub input: Option<(Vec3, glam::Quat, f32)>,
    /// The object being torn, and whether we asked for it already.
    target: Option<NetId>,
    asked: bool,
    /// The tip where the last segment ended.
    last: Option<Vec3>,
    /// The tip a frame ago.
    prev: Option<Vec3>,
}

impl Peer {
    /// Each hand with its trigger held over a soft body tears it along the hand's path, one
    /// segment per [`SCALPEL_SAMPLE_M`] moved and one more where the path turns sharply
    /// ([`scalpel_samples`]); letting go lifts the scalpel. A body another peer owns is torn
    /// through its owner (`peer/blade.rs`), or, for a `Locked` class, asked for first.
    pub(super) fn use_scalpels(&mut self, now: Instant) {
        for h in 0..self.scalpels.len() {
            let Some((tip, rot, trigger)) = self.scalpels[h].input else {
                continue;
            };
            // a hand whose tool is the cutter sweeps a plane (`peer/cutter.rs`); its
            // scalpel sees the trigger released (a stroke in progress is lifted)
            let cutter = self.hand_tool(h) == super::cutter::HandTool::Cutter;
            self.use_cutter(
                now,
                h,
                tip,
                Self::blade_of(rot),
                if cutter { trigger } else { 0.0 },
            );
            let trigger = if cutter { 0.0 } else { trigger };
            if trigger < SCALPEL_TRIGGER {
                let s = &mut self.scalpels[h];
                let stroke = (s.target.take(), s.last.take());
                s.prev = None;
                s.asked = false;
                if let (Some(id), Some(_)) = stroke {
                    let _ = self.lift(now, id);
                }
                continue;
            }
            let target = match self.scalpels[h].target {
                Some(id) if self.mirror.objects.contains_key(&id) => id,
                _ => match self.soft_body_at(tip) {
                    Some(id) => {
                        self.scalpels[h].target = Some(id);
                        self.scalpels[h].last = None;
                        self.scalpels[h].prev = None;
                        id
                    }
                    None => continue,
                },
            };
            // a body another peer owns: its owner takes our blade as a request, if the class
            // lets others act on it (else we ask for it, and start once it is ours)
            if self.session.owner(target) != Some(self.me()) && !self.may_share(target) {
                if !self.scalpels[h].asked {
                    self.scalpels[h].asked = true;
                    self.ask_authority(now, target);
                }
                continue;
            }
            let prev = self.scalpels[h].prev.replace(tip);
            let Some(mut last) = self.scalpels[h].last else {
                self.scalpels[h].last = Some(tip);
                continue;
            };
            let blade = Self::blade_of(rot);
            for p in scalpel_samples(last, prev.unwrap_or(last), tip) {
                if let Err(e) = self.tear(now, target, last, p, blade) {
                    self.events
                        .push_back(Event::Warning(format!("scalpel: {e}")));
                }
                last = p;
            }
            self.scalpels[h].last = Some(last);
        }
    }

    /// The soft body whose shown surface's bounds (1 cm wider) hold `p`, nearest center first.
    pub(super) fn soft_body_at(&self, p: Vec3) -> Option<NetId> {
        self.mirror
            .objects
            .iter()
            .filter_map(|(id, o)| {
                let LocalBody::Soft(h) = o.body else {
                    return None;
                };
                let b = self.mirror.soft.get(h)?;
                let (lo, hi) = softsync_softbody::mesh::bounds(b.render_positions());
                let pad = Vec3::splat(0.01);
                let inside = p.cmpge(lo - pad).all() && p.cmple(hi + pad).all();
                inside.then(|| (p.distance((lo + hi) * 0.5), *id))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, id)| id)
    }

    /// The rest frame of our soft object `id`: (center position, rotation) in the room.
    fn rest_frame(&self, id: NetId) -> Result<(Vec3, glam::Quat), TopologyError> {
        if self.session.owner(id) != Some(self.me()) {
            return Err(TopologyError(format!("object {} is not ours", id.0)));
        }
        match self.mirror.objects.get(&id).map(|o| o.body) {
            Some(LocalBody::Soft(h)) => self
                .mirror
                .soft
                .get(h)
                .map(|b| b.center_pose(&self.mirror.world))
                .ok_or_else(|| TopologyError(format!("object {} has no body", id.0))),
            Some(_) => Err(TopologyError(format!("object {} is not a soft body", id.0))),
            None => Err(TopologyError(format!("no object {}", id.0))),
        }
    }

    /// Hash of soft object `id`'s rest mesh (welded rest vertices and triangles, 10 µm): two
    /// peers that applied the same topology log have equal hashes.
    pub fn topology_hash(&self, id: NetId) -> Option<u64> {
        let LocalBody::Soft(h) = self.mirror.objects.get(&id)?.body else {
            return None;
        };
        let b = self.mirror.soft.get(h)?;
        let mesh = softsync_softbody::Mesh {
            positions: b.rest_vertices().to_vec(),
            normals: None,
            triangles: b.welded().triangles.clone(),
        };
        Some(softsync_softbody::cut::topology_hash(&mesh, 1e-5))
    }

    /// Asks to tear soft object `id` along one segment of a scalpel (room frame): the
    /// blade's tip moved from `from` to `to`; `blade` runs from the tip to its back end. Ours:
    /// asked of the host; another peer's: sent to its owner, which applies it as its own
    /// (`peer/blade.rs`; not for a `Locked` class).
    pub fn tear(
        &mut self,
        now: Instant,
        id: NetId,
        from: Vec3,
        to: Vec3,
        blade: Vec3,
    ) -> Result<(), TopologyError> {
        if self.session.owner(id) != Some(self.me()) {
            let (from, to, blade) = (from.to_array(), to.to_array(), blade.to_array());
            return self.request_blade(now, id, Blade::Tear { from, to, blade });
        }
        let me = self.me();
        self.tear_by(now, id, from, to, blade, me)
    }

    /// Owner: a tear segment of `author`'s stroke (ours, or a request's).
    pub(super) fn tear_by(
        &mut self,
        now: Instant,
        id: NetId,
        from: Vec3,
        to: Vec3,
        blade: Vec3,
        author: PeerId,
    ) -> Result<(), TopologyError> {
        self.rest_frame(id)?;
        // through the body's deformation as it is now: the slit opens where the blade passes
        // through the squeezed tissue, not where that tissue was at rest
        let Some(LocalBody::Soft(h)) = self.mirror.objects.get(&id).map(|o| o.body) else {
            return Err(TopologyError(format!("no soft object {}", id.0)));
        };
        let b = self
            .mirror
            .soft
            .get(h)
            .ok_or_else(|| TopologyError(format!("object {} has no body", id.0)))?;
        let map = |x: Vec3| b.rest_point(&self.mirror.world, x);
        let (from_r, to_r) = (map(from), map(to));
        let blade_r = map(to + blade) - to_r;
        let q = |v: Vec3| {
            TopologyEvent::quantise(v.to_array())
                .ok_or_else(|| TopologyError(format!("tear point {v} out of range")))
        };
        let event = TopologyEvent::Tear {
            from: q(from_r)?,
            to: q(to_r)?,
            blade: q(blade_r)?,
        };
        // as every peer will read it (quantised, in the rest frame): refused here, not by all
        if let Some(seg) = segment_of(&event) {
            seg.validate().map_err(|e| TopologyError(e.to_string()))?;
        }
        self.stroke_of(now, id, author);
        self.ask_topology(now, id, event, Vec::new())
    }

    /// Ends a stroke on `id`: the next tear starts a new one (another peer's body: sent to its
    /// owner, as [`Peer::tear`]).
    pub fn lift(&mut self, now: Instant, id: NetId) -> Result<(), TopologyError> {
        if self.session.owner(id) != Some(self.me()) {
            return self.request_blade(now, id, Blade::Lift);
        }
        let me = self.me();
        self.lift_by(now, id, me)
    }

    /// Owner: asks the host to end `id`'s stroke.
    pub(super) fn ask_lift(&mut self, now: Instant, id: NetId) -> Result<(), TopologyError> {
        self.rest_frame(id)?;
        self.ask_topology(now, id, TopologyEvent::Lift, Vec::new())
    }

    /// Asks to cut soft object `id` by the plane through `point` with normal `normal` (room
    /// frame). Ours: the pieces become objects of their own, ours. Another peer's: sent to its
    /// owner, which cuts it as its own (the pieces are the owner's).
    pub fn cut(
        &mut self,
        now: Instant,
        id: NetId,
        point: Vec3,
        normal: Vec3,
    ) -> Result<(), TopologyError> {
        if self.session.owner(id) != Some(self.me()) {
            let (point, normal) = (point.to_array(), normal.to_array());
            return self.request_blade(now, id, Blade::Cut { point, normal });
        }
        let (pos, rot) = self.rest_frame(id)?;
        let inv = rot.inverse();
        let event = TopologyEvent::Cut {
            point: TopologyEvent::quantise((inv * (point - pos)).to_array())
                .ok_or_else(|| TopologyError("cut point out of range".into()))?,
            normal: TopologyEvent::quantise_normal((inv * normal).to_array())
                .ok_or_else(|| TopologyError("cut normal is zero".into()))?,
            keep: 0,
        };
        // The particle count of every piece, from the same quantised plane every peer uses.
        let plane = plane_of(&event)?;
        let Some(LocalBody::Soft(h)) = self.mirror.objects.get(&id).map(|o| o.body) else {
            return Err(TopologyError(format!("no soft object {}", id.0)));
        };
        let pieces = self
            .mirror
            .soft
            .cut_piece_particles(h, &self.mirror.world, &plane)
            .map_err(|e| TopologyError(e.to_string()))?;
        let pieces = pieces.into_iter().map(|n| n as u32).collect();
        self.ask_topology(now, id, event, pieces)
    }

    fn ask_topology(
        &mut self,
        now: Instant,
        id: NetId,
        event: TopologyEvent,
        pieces: Vec<u32>,
    ) -> Result<(), TopologyError> {
        self.session
            .request_topology(now, id, event, pieces)
            .map_err(|e| TopologyError(e.to_string()))
    }

    /// Entry `seq` of `id`'s log arrived: apply it, or rebuild and replay if it is not the
    /// next one. A failure is a warning: the body keeps its last shape.
    pub(super) fn on_topology(&mut self, now: Instant, id: NetId, seq: u32, event: TopologyEvent) {
        if self.topology_while_building(now, id, seq, &event) {
            return; // its build replays it, or it is applied when the build lands
        }
        let applied = self.mirror.topology_applied(id);
        let body_before = self.mirror.objects.get(&id).map(|o| o.body);
        let particles_before = match body_before {
            Some(LocalBody::Soft(h)) => self
                .mirror
                .soft
                .get(h)
                .map(|b| b.particle_positions(&self.mirror.world))
                .unwrap_or_default(),
            _ => Vec::new(),
        };
        let result = if seq == applied {
            self.mirror.apply_topology(&self.scene, id, &event)
        } else {
            let log = self.session.topology_log(id).unwrap_or(&[]).to_vec();
            self.rebuild(now, id).and_then(|()| {
                log.iter()
                    .try_for_each(|e| self.mirror.apply_topology(&self.scene, id, e))
            })
        };
        if let (
            TopologyEvent::Resolution { .. },
            Some(LocalBody::Soft(old)),
            Some(LocalBody::Soft(new)),
        ) = (
            event,
            body_before,
            self.mirror.objects.get(&id).map(|o| o.body),
        ) {
            if old != new {
                self.hands_follow(old, new, &particles_before);
            }
        }
        match result {
            Ok(()) => self.counters.topology_events += 1,
            Err(e) => {
                self.counters.apply_errors += 1;
                self.events.push_back(Event::Warning(format!(
                    "object {}: topology entry {seq} not applied: {e}",
                    id.0
                )));
            }
        }
    }

    /// Replaces `id`'s body by a fresh one of its class at its current pose.
    fn rebuild(&mut self, _now: Instant, id: NetId) -> Result<(), TopologyError> {
        let Some(o) = self.mirror.objects.get(&id).cloned() else {
            return Ok(());
        };
        let s = self.mirror.body_state(o.body, o.pose);
        let body = self
            .mirror
            .build(&self.scene, o.kind, s.pos, s.rot)
            .map_err(|e| TopologyError(e.to_string()))?;
        self.mirror.remove(id);
        self.mirror.insert(id, o.kind, body, o.avatar_of);
        let ours = self.session.owner(id) == Some(self.me());
        self.mirror.set_simulated(id, ours);
        Ok(())
    }
}

/// The plane a cut event names, in metres.
pub fn plane_of(event: &TopologyEvent) -> Result<CutPlane, TopologyError> {
    let TopologyEvent::Cut { point, normal, .. } = event else {
        return Err(TopologyError("not a cut".into()));
    };
    CutPlane::new(
        Vec3::from_array(TopologyEvent::metres(*point)),
        Vec3::new(
            f32::from(normal[0]),
            f32::from(normal[1]),
            f32::from(normal[2]),
        ),
    )
    .map_err(|e| TopologyError(e.to_string()))
}

/// A tear event's segment, in metres.
pub fn segment_of(event: &TopologyEvent) -> Option<TearSegment> {
    let TopologyEvent::Tear { from, to, blade } = event else {
        return None;
    };
    let m = |q: &[i32; 3]| Vec3::from_array(TopologyEvent::metres(*q));
    Some(TearSegment {
        from: m(from),
        to: m(to),
        blade: m(blade),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scalpel_samples_every_5_mm_and_where_its_path_turns() {
        let o = Vec3::ZERO;
        // straight on: nothing until 5 mm, then the tip
        assert!(scalpel_samples(o, Vec3::X * 0.002, Vec3::X * 0.004).is_empty());
        assert_eq!(
            scalpel_samples(o, Vec3::X * 0.004, Vec3::X * 0.006),
            [Vec3::X * 0.006]
        );
        // a right angle at 3 mm: the corner is sampled, then the tip once 5 mm past it
        let corner = Vec3::X * 0.003;
        assert_eq!(
            scalpel_samples(o, corner, corner + Vec3::Z * 0.002),
            [corner]
        );
        let far = corner + Vec3::Z * 0.006;
        assert_eq!(scalpel_samples(o, corner, far), [corner, far]);
        // a gentle bend is not a corner
        let bend = Vec3::new(0.0045, 0.0, 0.0005);
        assert!(scalpel_samples(o, Vec3::X * 0.003, bend).is_empty());
        // a turn within 1 mm of the last sample is noise
        let tiny = Vec3::X * 0.0005;
        assert!(scalpel_samples(o, tiny, tiny + Vec3::Z * 0.002).is_empty());
    }
}
