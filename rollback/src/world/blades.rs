//! A rollback world's blades and topology (see the parent module's "Cuts and tears"): each
//! hand's scalpel stroke and cutter sweep worked from its input, the changes they make to the
//! soft bodies, and the topology log that save, load and snapshots carry.

use std::sync::Arc;

use glam::Vec3;
use softsync_net::wire::TopologyEvent;
use softsync_peer::peer::cutter::sweep_plane;
use softsync_peer::peer::topology::{
    plane_of, scalpel_samples, segment_of, SCALPEL_BLADE_M, SCALPEL_TRIGGER,
};
use softsync_peer::{HandTool, LocalBody};
use softsync_softbody::BuildStep;

use super::{LogEntry, RollbackWorld, WorldObject, MAX_LOG_ENTRIES};

/// The topology log as a persistent list: a save shares it (one pointer), an append adds a
/// node, a load takes the saved list back, whatever happened since.
#[derive(Clone, Debug, Default)]
pub(super) struct TopologyLog {
    head: Option<Arc<LogNode>>,
}

#[derive(Debug)]
struct LogNode {
    entry: LogEntry,
    prev: Option<Arc<LogNode>>,
    len: usize,
}

impl TopologyLog {
    pub(super) fn len(&self) -> usize {
        self.head.as_ref().map_or(0, |n| n.len)
    }

    pub(super) fn push(&mut self, entry: LogEntry) {
        let prev = self.head.take();
        let len = prev.as_ref().map_or(0, |n| n.len) + 1;
        self.head = Some(Arc::new(LogNode { entry, prev, len }));
    }

    pub(super) fn to_vec(&self) -> Vec<LogEntry> {
        let mut out = Vec::with_capacity(self.len());
        let mut at = self.head.as_deref();
        while let Some(n) = at {
            out.push(n.entry.clone());
            at = n.prev.as_deref();
        }
        out.reverse();
        out
    }
}

impl Drop for TopologyLog {
    /// Iteratively: a long log dropped node by node would recurse once per entry.
    fn drop(&mut self) {
        let mut at = self.head.take();
        while let Some(n) = at {
            at = match Arc::try_unwrap(n) {
                Ok(mut node) => node.prev.take(),
                Err(_) => None,
            };
        }
    }
}

/// A hand's blade between steps: its scalpel's stroke and its cutter's sweep.
#[derive(Clone, Debug, Default)]
pub(super) struct Blade {
    /// The object the scalpel is in.
    target: Option<usize>,
    /// The tip where the stroke's last segment ended.
    last: Option<Vec3>,
    /// The tip a step ago.
    prev: Option<Vec3>,
    /// The object the cutter entered and where its tip was then.
    entered: Option<(usize, Vec3)>,
    /// This press of the cutter cut already (or gave up).
    done: bool,
}

impl RollbackWorld {
    /// Player `p`'s hand `h` works its blade this step (see the module docs): the same rules
    /// as a state-sync peer's scalpel and cutter, on the world's own bodies.
    pub(super) fn work_blade(&mut self, p: usize, h: usize, d: &softsync_peer::DeviceFrame) {
        let Some((tip, rot)) = d.hands[h] else {
            self.lift_blade(p, h);
            return;
        };
        let blade = rot * Vec3::Y * SCALPEL_BLADE_M;
        let cutter = d.tool[h] == HandTool::Cutter;
        // the cutter: one cut per press, once the tip has swept far enough through a body
        if cutter && d.trigger[h] >= SCALPEL_TRIGGER {
            let b = &self.players[p].blades[h];
            if !b.done {
                match b.entered {
                    None => {
                        let at = self.soft_object_at(tip);
                        self.players[p].blades[h].entered = at.map(|i| (i, tip));
                    }
                    Some((i, entry)) => {
                        if let Some((point, normal)) = sweep_plane(entry, tip, blade) {
                            self.players[p].blades[h].done = true;
                            if self.cut(i, point, normal).is_err() {
                                self.refused += 1;
                            }
                        }
                    }
                }
            }
        } else {
            let b = &mut self.players[p].blades[h];
            (b.entered, b.done) = (None, false);
        }
        // the scalpel
        let trigger = if cutter { 0.0 } else { d.trigger[h] };
        if trigger < SCALPEL_TRIGGER {
            self.lift_blade(p, h);
            return;
        }
        let target = match self.players[p].blades[h].target {
            Some(i) if i < self.objects.len() => i,
            _ => match self.soft_object_at(tip) {
                Some(i) => {
                    let b = &mut self.players[p].blades[h];
                    (b.target, b.last, b.prev) = (Some(i), None, None);
                    i
                }
                None => return,
            },
        };
        let b = &mut self.players[p].blades[h];
        let prev = b.prev.replace(tip);
        let Some(mut last) = b.last else {
            b.last = Some(tip);
            return;
        };
        for s in scalpel_samples(last, prev.unwrap_or(last), tip) {
            if self.tear(target, last, s, blade).is_err() {
                self.refused += 1;
            }
            last = s;
        }
        self.players[p].blades[h].last = Some(last);
    }

    /// The scalpel of player `p`'s hand `h` leaves the body: its stroke ends.
    fn lift_blade(&mut self, p: usize, h: usize) {
        let b = &mut self.players[p].blades[h];
        let stroke = (b.target.take(), b.last.take());
        b.prev = None;
        if let (Some(i), Some(_)) = stroke {
            if self.record(i, TopologyEvent::Lift).is_err() {
                self.refused += 1;
            }
        }
    }

    /// The soft object whose drawn surface's bounds (1 cm wider) hold `p`, nearest center
    /// first (ties: the lower index).
    fn soft_object_at(&self, p: Vec3) -> Option<usize> {
        let mut best: Option<(f32, usize)> = None;
        for (i, o) in self.objects.iter().enumerate() {
            let LocalBody::Soft(h) = o.body else { continue };
            let Some(b) = self.soft.get(h) else { continue };
            let (lo, hi) = softsync_softbody::mesh::bounds(b.render_positions());
            let pad = Vec3::splat(0.01);
            if !(p.cmpge(lo - pad).all() && p.cmple(hi + pad).all()) {
                continue;
            }
            let d = p.distance((lo + hi) * 0.5);
            if best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, i));
            }
        }
        best.map(|(_, i)| i)
    }

    /// Tears object `i` along the tip's move `from → to` (room frame), through its
    /// deformation now, quantised into its rest frame as the wire's events are.
    fn tear(&mut self, i: usize, from: Vec3, to: Vec3, blade: Vec3) -> Result<(), String> {
        let LocalBody::Soft(h) = self.objects.get(i).ok_or("no such object")?.body else {
            return Err("not a soft body".into());
        };
        let b = self.soft.get(h).ok_or("no body")?;
        let map = |x: Vec3| b.rest_point(&self.world, x);
        let (from_r, to_r) = (map(from), map(to));
        let blade_r = map(to + blade) - to_r;
        let q = |v: Vec3| TopologyEvent::quantise(v.to_array()).ok_or("out of range");
        let event = TopologyEvent::Tear {
            from: q(from_r)?,
            to: q(to_r)?,
            blade: q(blade_r)?,
        };
        self.record(i, event)
    }

    /// Cuts object `i` by the plane through `point` with `normal` (room frame).
    fn cut(&mut self, i: usize, point: Vec3, normal: Vec3) -> Result<(), String> {
        let LocalBody::Soft(h) = self.objects.get(i).ok_or("no such object")?.body else {
            return Err("not a soft body".into());
        };
        let (pos, rot) = self.soft.get(h).ok_or("no body")?.center_pose(&self.world);
        let inv = rot.inverse();
        let event = TopologyEvent::Cut {
            point: TopologyEvent::quantise((inv * (point - pos)).to_array())
                .ok_or("cut point out of range")?,
            normal: TopologyEvent::quantise_normal((inv * normal).to_array())
                .ok_or("cut normal is zero")?,
            keep: 0,
        };
        self.record(i, event)
    }

    /// Applies `event` to object `i` and logs it.
    /// Refused once the log holds [`MAX_LOG_ENTRIES`] (the same on every peer): a snapshot
    /// must stay loadable for joiners, whatever a player does with its blade.
    pub(super) fn record(&mut self, i: usize, event: TopologyEvent) -> Result<(), String> {
        if self.log.len() >= MAX_LOG_ENTRIES {
            return Err(format!(
                "the topology log is full ({MAX_LOG_ENTRIES} entries)"
            ));
        }
        self.apply(i, &event)?;
        self.log.push(LogEntry {
            object: u32::try_from(i).map_err(|e| e.to_string())?,
            event,
        });
        Ok(())
    }

    /// Applies a topology event to object `i` (live, or replaying a snapshot's log): a cut
    /// replaces the body by its first piece and appends the others as new objects of its
    /// class. Refused with why, changing nothing.
    fn apply(&mut self, i: usize, event: &TopologyEvent) -> Result<(), String> {
        let o = self.objects.get(i).ok_or("no such object")?;
        let (kind, LocalBody::Soft(h)) = (o.kind, o.body) else {
            return Err("not a soft body".into());
        };
        match event {
            TopologyEvent::Tear { .. } => {
                let seg = segment_of(event).ok_or("not a tear")?;
                seg.validate().map_err(|e| e.to_string())?;
                BuildStep::Tear(seg).apply(&mut self.soft, &mut self.world, h)?;
                self.refresh_handles(i);
            }
            TopologyEvent::Lift => {
                BuildStep::Lift.apply(&mut self.soft, &mut self.world, h)?;
            }
            TopologyEvent::Cut { .. } => {
                let plane = plane_of(event).map_err(|e| e.0)?;
                let pieces = self
                    .soft
                    .cut(h, &mut self.world, &plane)
                    .map_err(|e| e.to_string())?;
                let mut pieces = pieces.into_iter();
                if let Some(first) = pieces.next() {
                    self.objects[i].body = LocalBody::Soft(first);
                    self.refresh_handles(i);
                }
                for piece in pieces {
                    self.objects.push(WorldObject {
                        kind,
                        body: LocalBody::Soft(piece),
                        handles: Vec::new(),
                    });
                    self.refresh_handles(self.objects.len() - 1);
                }
            }
            TopologyEvent::Resolution { .. } => {
                return Err("a rollback world has no resolution changes".into())
            }
        }
        Ok(())
    }

    /// Object `i`'s rapier bodies again (a tear adds particles, a cut makes new bodies).
    fn refresh_handles(&mut self, i: usize) {
        let Some(o) = self.objects.get(i) else { return };
        if let LocalBody::Soft(h) = o.body {
            let handles = self
                .soft
                .get(h)
                .map(|b| {
                    std::iter::once(b.center())
                        .chain(b.particles().iter().copied())
                        .collect()
                })
                .unwrap_or_default();
            self.objects[i].handles = handles;
        }
    }
}
