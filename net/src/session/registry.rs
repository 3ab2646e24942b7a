//! The room's objects as this peer knows them (`Registry`): each one's spawn record, its
//! state on the quantization grid (what replication compares and sends), what its owner last
//! published, and the snapshot buffer remote peers interpolate; object ids and the per-peer
//! limits the host enforces.

use std::collections::BTreeMap;

use std::time::Duration;

use glam::{Quat, Vec3};

use super::delta::PartQ;
use crate::error::NetError;
use crate::ids::{NetId, PeerId, Term};
use crate::interp::{Snapshot, SnapshotBuffer};
use crate::policy::{ClassConfig, SoftBodyMode};
use crate::quant::{dequantize_quat, quantize_quat, QuatQ};
use crate::time::Instant;
use crate::wire::SpawnInfo;

/// An object's state as the application sees it: center transform and world-space particles.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct ObjectState {
    /// Center position.
    pub pos: Vec3,
    /// Center rotation.
    pub rot: Quat,
    /// Particle positions in world space (empty for rigid objects).
    pub particles: Vec<Vec3>,
}

impl ObjectState {
    /// A rigid pose.
    pub fn rigid(pos: Vec3, rot: Quat) -> Self {
        ObjectState {
            pos,
            rot,
            particles: Vec::new(),
        }
    }

    fn is_finite(&self) -> bool {
        self.pos.is_finite() && self.rot.is_finite() && self.particles.iter().all(|p| p.is_finite())
    }

    /// The state's rotation, normalized, if the state is finite and the rotation is a unit
    /// quaternion up to rounding (|q|² within [0.98, 1.02]; a zero quaternion is refused).
    pub(crate) fn checked_rotation(&self) -> Result<Quat, NetError> {
        if !self.is_finite() {
            return Err(NetError::InvalidState("non-finite state"));
        }
        if !(0.98..=1.02).contains(&self.rot.length_squared()) {
            return Err(NetError::InvalidState("rotation is not a unit quaternion"));
        }
        Ok(self.rot.normalize())
    }
}

/// What a remote peer displays for an object.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayedState {
    /// The interpolated state.
    pub state: ObjectState,
    /// The time, in the sending peer's clock, that this state represents.
    pub source_time: Instant,
    /// Interpolation delay applied.
    pub delay: Duration,
}

/// One object.
#[derive(Debug)]
pub(crate) struct Object {
    /// Its spawn record (class, owner, epoch, held, policy, particle count, request).
    pub info: SpawnInfo,
    /// Center position on the class grid.
    pub pos: [u32; 3],
    /// Center rotation, smallest-three.
    pub rot: QuatQ,
    /// Particle offsets in the center's frame on the particle grid.
    pub particles: Vec<[u32; 3]>,
    /// At rest (rest sync: thresholds are dropped, the exact pose goes out).
    pub rest: bool,
    /// When the grid state last changed.
    pub last_change: Instant,
    /// What the owner (us) last published, unquantized.
    pub published: Option<ObjectState>,
    /// When.
    pub published_at: Instant,
    /// Received snapshots (remote objects).
    pub buffer: SnapshotBuffer,
    /// The peer whose updates we apply (its owner, or the host relaying them).
    pub source: Option<PeerId>,
    /// Its topology log (tears and cuts), see `topology`.
    pub topology: super::topology::TopologyLog,
    /// Let go of since the last send tick (the budget's release boost starts at the tick).
    pub released: bool,
    /// Until when a released or thrown object goes before resting ones (`session::budget`).
    pub boost_until: Option<Instant>,
    /// Its own interpolation settings, if it has any (a speaking avatar's head, shown with
    /// less delay so that lips and voice line up: [`crate::Session::set_object_interpolation`]).
    pub interp: Option<crate::interp::InterpolationConfig>,
}

impl Object {
    /// Whether `local` may claim this object from a new host of `term` (`Resync`): it owns
    /// it at an epoch of an older term (a grant of `term` itself came from a rival host of
    /// that term, which the new host's record overrides).
    pub fn claimable(&self, local: PeerId, term: Term) -> bool {
        self.info.owner == local && self.info.epoch.term < term.0
    }

    /// A replica of `info` (particles at the center until state arrives).
    fn new(now: Instant, info: SpawnInfo, class: &ClassConfig) -> Self {
        let pos = class
            .position_quantizer()
            .quantize(Vec3::from_array(info.pos));
        let rot = quantize_quat(Quat::from_array(info.rot), class.rot_bits());
        let particles =
            vec![class.particle_quantizer().quantize(Vec3::ZERO); info.particles as usize];
        Object {
            info,
            pos,
            rot,
            particles,
            rest: false,
            last_change: now,
            published: None,
            published_at: now,
            buffer: SnapshotBuffer::default(),
            source: None,
            topology: Default::default(),
            released: false,
            boost_until: None,
            interp: None,
        }
    }

    /// The grid state as world-space values.
    pub fn compose(&self, class: &ClassConfig) -> ObjectState {
        let pos = class.position_quantizer().dequantize(self.pos);
        let rot = dequantize_quat(self.rot, class.rot_bits());
        let pq = class.particle_quantizer();
        let particles = if class.soft_body_mode == SoftBodyMode::Particles {
            self.particles
                .iter()
                .map(|q| pos + rot * pq.dequantize(*q))
                .collect()
        } else {
            Vec::new()
        };
        ObjectState {
            pos,
            rot,
            particles,
        }
    }

    /// The owner publishes `state` (checked by the caller; `unit` its normalized rotation):
    /// put it on the grid, note a change (which ends rest), keep the exact values.
    pub fn publish(&mut self, now: Instant, state: &ObjectState, unit: Quat, class: &ClassConfig) {
        let pos = class.position_quantizer().quantize(state.pos);
        let rot = quantize_quat(unit, class.rot_bits());
        let pq = class.particle_quantizer();
        let inv = unit.inverse();
        let particles: Vec<[u32; 3]> = state
            .particles
            .iter()
            .map(|p| pq.quantize(inv * (*p - state.pos)))
            .collect();
        if self.pos != pos || self.rot != rot || self.particles != particles {
            self.pos = pos;
            self.rot = rot;
            self.particles = particles;
            self.last_change = now;
            self.rest = false;
        }
        self.published = Some(ObjectState {
            pos: state.pos,
            rot: unit,
            particles: state.particles.clone(),
        });
        self.published_at = now;
    }

    /// Take over from the replica: what we show becomes what we publish (after a grant or a
    /// migration), unless we published already.
    pub fn adopt_replica(&mut self, class: &ClassConfig) {
        if self.published.is_none() {
            self.published = Some(self.compose(class));
        }
    }

    /// Apply a received part state to the grid state.
    pub fn apply_part(&mut self, part: u32, state: PartQ, chunk_len: usize) {
        match state {
            PartQ::Transform { pos, rot } => {
                self.pos = pos;
                self.rot = rot;
            }
            PartQ::Chunk(v) => {
                let start = (part as usize - 1) * chunk_len;
                for (i, x) in v.into_iter().enumerate() {
                    if let Some(d) = self.particles.get_mut(start + i) {
                        *d = x;
                    }
                }
            }
        }
    }

    /// The grid state as a snapshot at `time`, for the interpolation buffer.
    pub fn snapshot(&self, time: Instant, class: &ClassConfig) -> Snapshot {
        let pq = class.particle_quantizer();
        Snapshot {
            time,
            pos: class.position_quantizer().dequantize(self.pos),
            rot: dequantize_quat(self.rot, class.rot_bits()),
            offsets: self.particles.iter().map(|q| pq.dequantize(*q)).collect(),
            rest: self.rest,
        }
    }
}

/// The objects, and the ids to give new ones.
#[derive(Debug)]
pub(crate) struct Registry {
    objects: BTreeMap<NetId, Object>,
    next_id: u32,
    /// After we took over as host: ids `lo..hi` the old host may have spawned unseen by us.
    lost_ids: Option<(u32, u32)>,
}

impl Default for Registry {
    fn default() -> Self {
        Registry {
            objects: BTreeMap::new(),
            next_id: 1,
            lost_ids: None,
        }
    }
}

impl Registry {
    /// An object.
    pub fn get(&self, id: NetId) -> Option<&Object> {
        self.objects.get(&id)
    }

    /// An object, mutably.
    pub fn get_mut(&mut self, id: NetId) -> Option<&mut Object> {
        self.objects.get_mut(&id)
    }

    /// Known.
    pub fn contains(&self, id: NetId) -> bool {
        self.objects.contains_key(&id)
    }

    /// Every object in id order.
    pub fn iter(&self) -> impl Iterator<Item = &Object> {
        self.objects.values()
    }

    /// Every object in id order, mutably.
    pub fn iter_mut(&mut self) -> impl Iterator<Item = &mut Object> {
        self.objects.values_mut()
    }

    /// Every id in order.
    pub fn ids(&self) -> Vec<NetId> {
        self.objects.keys().copied().collect()
    }

    /// Owner of an object.
    pub fn owner(&self, id: NetId) -> Option<PeerId> {
        self.objects.get(&id).map(|o| o.info.owner)
    }

    /// The ids `p` owns, in order.
    pub fn owned_by(&self, p: PeerId) -> Vec<NetId> {
        self.objects
            .values()
            .filter(|o| o.info.owner == p)
            .map(|o| o.info.id)
            .collect()
    }

    /// Add a replica of `info` (replacing one with its id).
    pub fn insert(&mut self, now: Instant, info: SpawnInfo, class: &ClassConfig) {
        let id = info.id;
        self.objects.insert(id, Object::new(now, info, class));
    }

    /// Remove an object; false if unknown.
    pub fn remove(&mut self, id: NetId) -> bool {
        self.objects.remove(&id).is_some()
    }

    /// A fresh object id (never 0), or `None` once the id space is used up.
    pub fn alloc_id(&mut self) -> Option<NetId> {
        let id = self.next_id.max(1);
        self.next_id = id.checked_add(1)?;
        Some(NetId(id))
    }

    /// Ids up to `id` are taken (an object restored under its old id): fresh ones start after.
    pub fn skip_ids_through(&mut self, id: NetId) {
        self.next_id = self.next_id.max(id.0.saturating_add(1));
    }

    /// On taking over as host: skip `window` ids past the highest known, and remember them as
    /// ids the old host may have spawned without our hearing of it (claims may create those).
    pub fn reserve_lost_ids(&mut self, window: u32) {
        let lo = self
            .objects
            .keys()
            .max()
            .map_or(1, |m| m.0.saturating_add(1));
        let hi = lo.saturating_add(window);
        self.next_id = self.next_id.max(hi);
        self.lost_ids = Some((lo, hi));
    }

    /// Whether `id` is one the old host may have spawned unseen ([`Registry::reserve_lost_ids`]).
    pub fn is_lost_id(&self, id: NetId) -> bool {
        self.lost_ids
            .is_some_and(|(lo, hi)| (lo..hi).contains(&id.0))
    }

    /// May one more object of `particles` particles be created for `p`, which may own at most
    /// `max_objects` objects of `max_particles` particles in all?
    pub fn may_create_for(
        &self,
        p: PeerId,
        particles: u32,
        max_objects: usize,
        max_particles: usize,
    ) -> bool {
        let (count, total) = self
            .objects
            .values()
            .filter(|o| o.info.owner == p)
            .fold((0usize, 0usize), |(n, t), o| {
                (n + 1, t.saturating_add(o.info.particles as usize))
            });
        count < max_objects && total.saturating_add(particles as usize) <= max_particles
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::ids::{AuthorityEpoch, ClassId};
    use crate::policy::{AuthorityPolicy, SendPolicy};

    fn info(id: u32, owner: u64, particles: u32) -> SpawnInfo {
        SpawnInfo {
            id: NetId(id),
            class: ClassId(0),
            owner: PeerId(owner),
            epoch: AuthorityEpoch::default(),
            held: false,
            policy: AuthorityPolicy::Free,
            particles,
            pos: [0.5, 1.0, -0.25],
            rot: [0.0, 0.0, 0.0, 1.0],
            request: None,
            topology: 0,
        }
    }

    fn soft() -> ClassConfig {
        ClassConfig::soft_body("s", SendPolicy::default(), SoftBodyMode::Particles)
    }

    #[test]
    fn a_published_state_is_kept_exactly_and_on_the_grid_within_half_a_step() {
        let class = soft();
        let mut reg = Registry::default();
        let t0 = Instant::from_millis(1);
        reg.insert(t0, info(1, 7, 2), &class);
        let o = reg.get_mut(NetId(1)).unwrap();
        o.rest = true;
        let rot = Quat::from_rotation_y(0.3);
        let st = ObjectState {
            pos: Vec3::new(0.1, 1.2, 0.3),
            rot,
            particles: vec![Vec3::new(0.15, 1.2, 0.3), Vec3::new(0.1, 1.25, 0.3)],
        };
        let t1 = Instant::from_millis(2);
        o.publish(t1, &st, rot, &class);
        assert_eq!(o.published.as_ref(), Some(&st));
        assert!(!o.rest, "a change ends rest");
        assert_eq!(o.last_change, t1);
        let back = o.compose(&class);
        let step = class.position_resolution_m;
        assert!(back.pos.distance(st.pos) <= step);
        for (a, b) in back.particles.iter().zip(&st.particles) {
            assert!(a.distance(*b) <= 2.0 * step, "{a} vs {b}");
        }
        // the same state again is no change
        o.rest = true;
        o.publish(Instant::from_millis(3), &st, rot, &class);
        assert!(o.rest);
        assert_eq!(o.last_change, t1);
    }

    #[test]
    fn a_replica_starts_at_its_spawn_pose_and_center_only_classes_show_no_particles() {
        let mut class = soft();
        let mut reg = Registry::default();
        reg.insert(Instant::ZERO, info(3, 1, 4), &class);
        let st = reg.get(NetId(3)).unwrap().compose(&class);
        assert!(st.pos.distance(Vec3::new(0.5, 1.0, -0.25)) < 1e-3);
        assert_eq!(st.particles.len(), 4);
        class.soft_body_mode = SoftBodyMode::CenterOnly;
        assert!(reg
            .get(NetId(3))
            .unwrap()
            .compose(&class)
            .particles
            .is_empty());
    }

    #[test]
    fn ids_are_never_zero_and_run_out_cleanly() {
        let mut reg = Registry::default();
        assert_eq!(reg.alloc_id(), Some(NetId(1)));
        reg.next_id = u32::MAX;
        assert_eq!(reg.alloc_id(), None, "u32::MAX would leave no next id");
    }

    #[test]
    fn a_new_host_reserves_the_ids_the_old_one_may_have_used() {
        let class = soft();
        let mut reg = Registry::default();
        for id in [1, 2, 9] {
            reg.insert(Instant::ZERO, info(id, 1, 0), &class);
        }
        reg.reserve_lost_ids(1024);
        assert!(!reg.is_lost_id(NetId(9)));
        assert!(reg.is_lost_id(NetId(10)) && reg.is_lost_id(NetId(1033)));
        assert!(!reg.is_lost_id(NetId(1034)));
        assert_eq!(reg.alloc_id(), Some(NetId(1034)));
    }

    #[test]
    fn per_peer_limits_count_objects_and_particles() {
        let class = soft();
        let mut reg = Registry::default();
        reg.insert(Instant::ZERO, info(1, 5, 100), &class);
        reg.insert(Instant::ZERO, info(2, 5, 100), &class);
        reg.insert(Instant::ZERO, info(3, 6, 100), &class);
        assert!(reg.may_create_for(PeerId(5), 50, 3, 250));
        assert!(!reg.may_create_for(PeerId(5), 51, 3, 250), "particles");
        assert!(!reg.may_create_for(PeerId(5), 0, 2, 250), "objects");
        assert_eq!(reg.owned_by(PeerId(5)), vec![NetId(1), NetId(2)]);
    }

    #[test]
    fn received_parts_land_in_their_particle_range() {
        let mut class = soft();
        class.particles_per_chunk = 2;
        let mut reg = Registry::default();
        reg.insert(Instant::ZERO, info(1, 5, 5), &class);
        let o = reg.get_mut(NetId(1)).unwrap();
        o.apply_part(2, PartQ::Chunk(vec![[7, 7, 7], [8, 8, 8]]), 2);
        o.apply_part(3, PartQ::Chunk(vec![[9, 9, 9], [10, 10, 10]]), 2);
        assert_eq!(o.particles[2], [7, 7, 7]);
        assert_eq!(
            o.particles[4],
            [9, 9, 9],
            "the rest of a short chunk is dropped"
        );
        assert_eq!(o.particles.len(), 5);
    }
}
