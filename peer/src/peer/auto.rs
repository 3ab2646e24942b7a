//! `method: auto` on the owner's side: after each step, every soft body we own of a class
//! with `auto` feeds its activity to its controller (`softbody::methods::auto`); a body that
//! comes to rest is put to sleep here, and a body that needs another resolution level asks
//! the host for it as a topology event ([`TopologyEvent::Resolution`]). Nothing changes until
//! the host puts the change in the object's log; then every peer, this one included,
//! rebuilds the body at that level ([`Mirror::apply_topology`]) — remote replicas follow
//! because the log is the room's, late joiners replay it, and the net layer lays the
//! object's particles out anew.
//!
//! [`Mirror::apply_topology`]: crate::mirror::Mirror::apply_topology

use std::collections::BTreeMap;

use glam::Vec3;
use softsync_net::wire::TopologyEvent;
use softsync_net::{Instant, NetId};
use softsync_softbody::methods::auto::{AutoController, AutoMode};
use softsync_softbody::SoftBodyHandle;

use super::Peer;
use crate::mirror::LocalBody;

/// A request for a level is asked again after this long without an answer (a refusal is
/// silent).
const RETRY_S: f64 = 2.0;

/// One auto body we own.
#[derive(Clone, Debug)]
pub(crate) struct AutoBody {
    controller: AutoController,
    /// The level we asked for, and when (sim seconds).
    asked: Option<(u8, f64)>,
}

/// The auto bodies we own.
pub(crate) type AutoBodies = BTreeMap<NetId, AutoBody>;

impl Peer {
    /// After the step: run every owned auto body's controller; sleep, or ask for a level.
    pub(super) fn run_auto(&mut self, now: Instant) {
        let me = self.me();
        let t = self.sim_time_s;
        let ours: Vec<(NetId, SoftBodyHandle)> = self
            .mirror
            .objects
            .iter()
            .filter(|(id, o)| {
                self.session.owner(**id) == Some(me) && self.scene.auto(o.kind).is_some()
            })
            .filter_map(|(id, o)| match o.body {
                LocalBody::Soft(h) => Some((*id, h)),
                _ => None,
            })
            .collect();
        self.auto.retain(|id, _| ours.iter().any(|(o, _)| o == id));
        for (id, h) in ours {
            let Some(o) = self.mirror.objects.get(&id) else {
                continue;
            };
            let (kind, current) = (o.kind, o.level);
            let Some(auto) = self.scene.auto(kind) else {
                continue;
            };
            let held = self.is_held(softsync_interaction::ObjectRef::Soft(h));
            let Some(body) = self.mirror.soft.get(h) else {
                continue;
            };
            let torn = !body.tear_boxes().is_empty();
            let mut activity = body.activity(&self.mirror.world);
            activity.driven |= held;
            let state = self.auto.entry(id).or_insert_with(|| AutoBody {
                controller: AutoController::new(t),
                asked: None,
            });
            if let Some(mode) = state.controller.update(t, &activity, &auto.settings) {
                self.counters.auto_mode_changes += 1;
                if mode == AutoMode::Asleep {
                    if let Some(b) = self.mirror.soft.get_mut(h) {
                        b.sleep(&mut self.mirror.world);
                    }
                }
            }
            let want = auto.level(state.controller.mode());
            let have = current.map_or(auto.base, usize::from);
            if want == have || torn {
                state.asked = None;
                continue;
            }
            let level = want as u8;
            if state
                .asked
                .is_some_and(|(l, at)| l == level && t - at < RETRY_S)
            {
                continue;
            }
            // this body's own count at that level: a cut's piece is not its class's mesh
            let Some(config) = auto.ladder.configs.get(want).cloned() else {
                continue;
            };
            let Ok(particles) = self
                .mirror
                .soft
                .particles_with(h, &self.mirror.world, config)
            else {
                state.asked = Some((level, t));
                continue;
            };
            let event = TopologyEvent::Resolution {
                level,
                particles: particles as u32,
            };
            if self
                .session
                .request_topology(now, id, event, Vec::new())
                .is_ok()
            {
                state.asked = Some((level, t));
                self.counters.resolution_requests += 1;
            }
        }
    }

    /// Soft body `old` of `id` became `new` (a resolution change): hands on it move over, a
    /// held particle to the new particle nearest it.
    pub(super) fn hands_follow(
        &mut self,
        old: SoftBodyHandle,
        new: SoftBodyHandle,
        before: &[Vec3],
    ) {
        let Some(body) = self.mirror.soft.get(new) else {
            return;
        };
        let after = body.particle_positions(&self.mirror.world);
        self.hands.replace_soft(old, new, |i| {
            let p = before.get(i as usize)?;
            after
                .iter()
                .enumerate()
                .min_by(|a, b| {
                    a.1.distance_squared(*p)
                        .total_cmp(&b.1.distance_squared(*p))
                })
                .map(|(j, _)| j as u32)
        });
    }
}
