//! Co-manipulation: hands of several peers on one soft body at once (the thesis's own
//! limitation, §6.3: a user could not touch an object another user owned).
//!
//! **The rule.** Authority does not move while anyone holds the body: the owner keeps
//! simulating, and another peer's hand on it becomes a *remote hand*. A hand reaching for a
//! soft body another peer owns asks for authority as before when nobody holds the body (a lone
//! user then simulates what they hold, with no lag at all); when the owner says someone holds
//! it (its [`Holders`], retained per object, so a late joiner knows too), or the host denies
//! the request because someone does (two reached at once), the hand holds it as a remote hand
//! instead — no grab is refused for being second. `Locked` classes refuse remote hands as they
//! refuse authority; under `OwnerMustAgree` the owner's peer agrees or not
//! ([`crate::PeerConfig::agree_to_hands`]).
//!
//! **What travels.** The grabbing peer sends the hand's position and velocity, the particle
//! and a grab number ([`RemoteHand`]) every step it holds, unreliably, to whoever owns the
//! body ([`MessageTarget::OwnerOf`]): relayed by the host, which resolves the owner at the
//! moment it relays — so hands keep holding through a migration or an owner's death (the
//! new owner gets the next sample) — and which checks and rate-limits every sender (a
//! bucket of its own for unreliable messages). Direct would save one hop (one-way latency);
//! the room's state route is relayed by default for the same reasons, and a direct hand
//! would need the owner to check membership and rates itself. A release goes three times
//! with the throw; an owner that hears nothing of a hand for [`REMOTE_HAND_TIMEOUT_S`] lets
//! go (its peer died).
//!
//! **The owner** drives the particle exactly as its own hands drive theirs
//! ([`drive_particle`]: the same velocity hold, the same limits), toward the hand's position
//! extrapolated by its velocity over the sample's age (at most [`MAX_EXTRAPOLATE_S`]); two
//! pulls stretch the body between them, a squeeze from each side compresses it.
//!
//! **The grabbing peer sees its hand act at once** (local prediction): each frame, the body it
//! shows is the replicated one plus a correction `c = hand − particle` (capped at
//! [`MAX_CORRECTION_M`]) on the held particle, spread to its neighbours with the body's own
//! neighbour weights `clamp(1 − d/δ, 0, 1)`. It is reconciled by construction: `c` is taken
//! against the newest replicated shape every frame, so as the owner's state (which includes
//! the hand) arrives, `c` shrinks to what the hand moved since; after a release it fades out
//! over [`FADE_S`].

use std::collections::BTreeMap;

use glam::Vec3;
use softsync_interaction::{drive_particle, release_particle, ObjectRef, Target};
use softsync_net::wire::DenyReason;
use softsync_net::{AuthorityPolicy, Delivery, Instant, MessageTarget, NetId, PeerId};
use softsync_net::{ObjectState, ReceivedMessage};

use super::Peer;
use crate::events::Event;
use crate::messages::{HandAnswer, Holder, Holders, RemoteHand, REMOTE_HAND_TIMEOUT_S};
use crate::mirror::LocalBody;

/// How long a released hand's local correction takes to fade, seconds.
pub const FADE_S: f32 = 0.15;
/// The largest correction shown: beyond it the owner is evidently not following the hand.
pub const MAX_CORRECTION_M: f32 = 0.15;
/// A remote hand's goal is extrapolated by its velocity over at most this long.
pub const MAX_EXTRAPOLATE_S: f32 = 0.05;
/// A release is sent this many times, one per step (unreliable).
const RELEASE_REPEATS: u8 = 3;
/// Hands a peer has (what a remote hand's index may be).
const HANDS: u8 = 2;
/// One hand of one peer starts a new grab at most this often (a person cannot grab faster; a
/// flood of new grab numbers is dropped, counted).
const MIN_GRAB_INTERVAL_S: f64 = 0.1;

/// A remote hand the owner applies.
#[derive(Clone, Debug)]
struct Applied {
    object: NetId,
    particle: u32,
    grab: u32,
    goal: Vec3,
    vel: Vec3,
    heard: Instant,
    /// The owner agreed (always, but under `OwnerMustAgree`).
    agreed: bool,
}

/// One of our hands holding a body another peer simulates.
#[derive(Clone, Debug)]
struct Sending {
    object: NetId,
    particle: u32,
    grab: u32,
    /// The last correction shown for it.
    correction: Vec3,
}

/// A correction fading out after a release.
#[derive(Clone, Debug)]
struct Fade {
    object: NetId,
    particle: u32,
    correction: Vec3,
    left_s: f32,
}

/// The peer's co-manipulation state (a part of [`Peer`]).
#[derive(Debug, Default)]
pub(crate) struct Comanip {
    /// Owner: remote hands on bodies we simulate, by (sender, hand).
    applied: BTreeMap<(PeerId, u8), Applied>,
    /// Owner: per (sender, hand), the newest grab number that ended; older samples are late.
    ended: BTreeMap<(PeerId, u8), u32>,
    /// Owner: per (sender, hand), when its last new grab was taken or refused.
    last_grab_at: BTreeMap<(PeerId, u8), Instant>,
    /// Per hand of ours: what it holds remotely.
    sending: [Option<Sending>; 2],
    /// Per hand of ours: its last grab number.
    grabs: [u32; 2],
    /// Releases still to repeat.
    releasing: Vec<(RemoteHand, u8)>,
    fades: Vec<Fade>,
    /// Who holds what, as each object's owner said (or, for ours, as we apply it).
    holders: BTreeMap<NetId, Holders>,
    /// Owner: what we published last per object.
    published: BTreeMap<NetId, Holders>,
    /// Hands on a body that went (a cut replaced it by pieces), waiting for the pieces.
    pub(super) orphans: Vec<super::orphans::Orphan>,
}

impl Comanip {
    /// Everything goes (we rejoin: the objects are about to).
    pub(crate) fn clear(&mut self) {
        *self = Comanip {
            grabs: self.grabs,
            ..Comanip::default()
        };
    }
}

/// A hand sample a hostile or broken peer could send: what is wrong with it.
fn malformed(m: &RemoteHand) -> Option<&'static str> {
    let finite = m.pos.iter().chain(&m.vel).all(|v| v.is_finite());
    if !finite {
        Some("not finite")
    } else if m.hand >= HANDS {
        Some("no such hand")
    } else if m.grab == 0 {
        Some("grab number 0")
    } else if Vec3::from(m.vel).length() > 100.0 || Vec3::from(m.pos).length() > 1e4 {
        Some("out of range")
    } else {
        None
    }
}

impl Peer {
    /// Who holds object `id` (its owner's word; ours for what we simulate).
    pub fn holders(&self, id: NetId) -> &[Holder] {
        self.comanip
            .holders
            .get(&id)
            .map_or(&[], |h| h.hands.as_slice())
    }

    /// Remote hands we apply now, as owner (across all our objects).
    pub fn remote_hands_applied(&self) -> usize {
        self.comanip.applied.values().filter(|a| a.agreed).count()
    }

    /// The correction our remote hand `hand` shows on its particle now (zero if none).
    pub fn remote_correction(&self, hand: usize) -> Option<Vec3> {
        self.comanip
            .sending
            .get(hand)?
            .as_ref()
            .map(|s| s.correction)
    }

    pub(super) fn may_share(&self, id: NetId) -> bool {
        let Some(o) = self.mirror.objects.get(&id) else {
            return false;
        };
        let policy = self.scene.class(o.kind).map(|c| c.authority);
        matches!(o.body, LocalBody::Soft(_))
            && matches!(
                policy,
                Some(AuthorityPolicy::Free | AuthorityPolicy::OwnerMustAgree)
            )
    }

    /// A hand reaches for `object`, which another peer owns: hold it as a remote hand if
    /// someone holds it already (true), else the caller asks for authority.
    pub(super) fn grab_as_remote_if_held(&mut self, object: ObjectRef) -> bool {
        let Some(id) = self.mirror.id_of(object) else {
            return false;
        };
        if self.holders(id).is_empty() || !self.may_share(id) || !self.waits_on_particle(object) {
            return false;
        }
        self.hands.hold_remote(object);
        true
    }

    /// The host denied our request for `id`: someone holds it. Hands waiting for it hold it as
    /// remote hands (true), if the class lets them.
    pub(super) fn grab_as_remote_on_denial(&mut self, id: NetId, reason: DenyReason) -> bool {
        let held = matches!(reason, DenyReason::Held(_) | DenyReason::OwnerRefused);
        let Some(r) = self.mirror.object_ref(id) else {
            return false;
        };
        if !held || !self.may_share(id) || !self.waits_on_particle(r) {
            return false;
        }
        self.hands.hold_remote(r);
        true
    }

    fn waits_on_particle(&self, object: ObjectRef) -> bool {
        self.hand_ids.iter().any(|h| {
            matches!(self.hands.waiting(*h), Some(t @ Target::SoftParticle(..)) if t.object() == object)
        })
    }

    /// After the hands' update: each hand holding remotely tells the owner where it is;
    /// releases are repeated.
    pub(super) fn send_remote_hands(&mut self, now: Instant) {
        for (m, left) in &mut self.comanip.releasing {
            let _ = self.session.send(
                now,
                &self.message_types,
                MessageTarget::OwnerOf(m.object),
                Delivery::Unreliable,
                &*m,
            );
            *left = left.saturating_sub(1);
        }
        self.comanip.releasing.retain(|(_, left)| *left > 0);
        for h in 0..self.hand_ids.len() {
            let hid = self.hand_ids[h];
            let Some(target) = self.hands.remote(hid) else {
                self.comanip.sending[h] = None;
                continue;
            };
            let holding = match target {
                Target::SoftParticle(_, p) => self.mirror.id_of(target.object()).map(|id| (id, p)),
                _ => None,
            };
            let waiting = self
                .comanip
                .orphans
                .iter()
                .any(|o| o.hands.iter().any(|x| x.0 == h));
            if holding.is_none() && waiting {
                continue; // its body was cut: it waits for the pieces
            }
            let Some((id, particle)) = holding else {
                // the body is gone (despawned, or replaced by a cut's pieces): the hand lets
                // go; its owner lets go of it when it goes silent
                self.hands.deny(target.object());
                self.comanip.sending[h] = None;
                continue;
            };
            let same = self.comanip.sending[h]
                .as_ref()
                .is_some_and(|s| s.object == id && s.particle == particle);
            if !same {
                self.comanip.grabs[h] = self.comanip.grabs[h].wrapping_add(1).max(1);
                self.comanip.sending[h] = Some(Sending {
                    object: id,
                    particle,
                    grab: self.comanip.grabs[h],
                    correction: Vec3::ZERO,
                });
                self.counters.remote_grabs += 1;
            }
            let (Some(sample), Some(s)) = (self.hands.sample(hid), &self.comanip.sending[h]) else {
                continue;
            };
            let msg = RemoteHand {
                object: id,
                hand: h as u8,
                grab: s.grab,
                particle,
                pos: sample.position_m.to_array(),
                vel: self.hands.throw_velocity(hid).to_array(),
                release: false,
            };
            let to = MessageTarget::OwnerOf(id);
            if let Err(e) =
                self.session
                    .send(now, &self.message_types, to, Delivery::Unreliable, &msg)
            {
                self.events
                    .push_back(Event::Warning(format!("remote hand not sent: {e}")));
            }
        }
    }

    /// Our remote hand `hand` let go: tell the owner (three times), fade its correction.
    pub(super) fn remote_released(&mut self, hand: usize, velocity: Vec3) {
        let Some(s) = self.comanip.sending.get_mut(hand).and_then(Option::take) else {
            return;
        };
        let msg = RemoteHand {
            object: s.object,
            hand: hand as u8,
            grab: s.grab,
            particle: s.particle,
            pos: [0.0; 3],
            vel: velocity.to_array(),
            release: true,
        };
        self.comanip.releasing.push((msg, RELEASE_REPEATS));
        self.comanip.fades.push(Fade {
            object: s.object,
            particle: s.particle,
            correction: s.correction,
            left_s: FADE_S,
        });
    }

    /// A built-in co-manipulation message: true if it was one (the peer keeps it).
    pub(super) fn on_comanip_message(&mut self, now: Instant, m: &ReceivedMessage) -> bool {
        if let Some(r) = self.message_types.decode::<RemoteHand>(m) {
            match r {
                Ok(hand) => self.on_remote_hand(now, m.from, hand),
                Err(_) => self.counters.remote_hands_malformed += 1,
            }
            return true;
        }
        if let Some(r) = self
            .message_types
            .decode::<crate::messages::BladeRequest>(m)
        {
            match r {
                Ok(req) => self.on_blade_request(now, m.from, req),
                Err(_) => self.counters.blade_requests_refused += 1,
            }
            return true;
        }
        if let Some(r) = self.message_types.decode::<HandAnswer>(m) {
            if let Ok(a) = r {
                self.on_hand_answer(m.from, a);
            }
            return true;
        }
        if let Some(r) = self.message_types.decode::<Holders>(m) {
            let Delivery::ObjectState(id) = m.delivery else {
                return true;
            };
            match r {
                Ok(h) if self.session.owner(id) == Some(m.from) && h.hands.len() <= 64 => {
                    if self.comanip.holders.get(&id) != Some(&h) {
                        self.events.push_back(Event::Holders {
                            id,
                            hands: h.hands.clone(),
                        });
                        self.comanip.holders.insert(id, h);
                    }
                }
                _ => self.counters.holders_refused += 1,
            }
            return true;
        }
        false
    }

    /// Owner: a sample of another peer's hand on one of our bodies.
    fn on_remote_hand(&mut self, now: Instant, from: PeerId, m: RemoteHand) {
        if malformed(&m).is_some() {
            self.counters.remote_hands_malformed += 1;
            return;
        }
        let key = (from, m.hand);
        if self.comanip.ended.get(&key).is_some_and(|g| m.grab <= *g) {
            return; // a late sample of a grab that ended
        }
        if self.session.owner(m.object) != Some(self.me()) {
            return; // routed to us before authority moved; the new owner gets the next one
        }
        let body = match self.mirror.objects.get(&m.object).map(|o| o.body) {
            Some(LocalBody::Soft(h)) => h,
            _ => {
                self.counters.remote_hands_malformed += 1;
                return;
            }
        };
        let particles = self.mirror.soft.get(body).map_or(0, |b| b.num_particles());
        if m.particle as usize >= particles {
            self.counters.remote_hands_malformed += 1;
            return;
        }
        let new_grab = self
            .comanip
            .applied
            .get(&key)
            .is_none_or(|a| a.grab != m.grab || a.object != m.object);
        if m.release {
            if !new_grab {
                self.end_remote_hand(key, Vec3::from(m.vel));
            }
            self.comanip.ended.insert(key, m.grab);
            return;
        }
        if new_grab {
            let interval = std::time::Duration::from_secs_f64(MIN_GRAB_INTERVAL_S);
            let last = self.comanip.last_grab_at.get(&key).copied();
            if last.is_some_and(|at| now.saturating_since(at) < interval) {
                self.counters.remote_hands_too_fast += 1;
                return;
            }
            self.comanip.last_grab_at.insert(key, now);
            if let Some(old) = self.comanip.applied.get(&key).map(|a| a.grab) {
                // that hand's previous grab ended without a release we heard
                self.end_remote_hand(key, Vec3::ZERO);
                self.comanip.ended.insert(key, old);
            }
            let agreed = self.may_share(m.object)
                && match self.class_policy(m.object) {
                    Some(AuthorityPolicy::OwnerMustAgree) => self.config.agree_to_hands,
                    _ => true,
                };
            // a refusal is answered, and an agreement the sender waits for; a plain take is not
            // (each answer is a reliable message: a flood of grabs must not become one of them)
            let asked = self.class_policy(m.object) == Some(AuthorityPolicy::OwnerMustAgree);
            if !agreed || asked {
                let answer = HandAnswer {
                    object: m.object,
                    hand: m.hand,
                    grab: m.grab,
                    accepted: agreed,
                };
                let to = MessageTarget::Peer(from);
                let _ =
                    self.session
                        .send(now, &self.message_types, to, Delivery::Reliable, &answer);
            }
            if !agreed {
                self.counters.remote_hands_refused += 1;
                self.comanip.ended.insert(key, m.grab);
                return;
            }
            self.counters.remote_hands_taken += 1;
        }
        self.comanip.applied.insert(
            key,
            Applied {
                object: m.object,
                particle: m.particle,
                grab: m.grab,
                goal: Vec3::from(m.pos),
                vel: Vec3::from(m.vel),
                heard: now,
                agreed: true,
            },
        );
    }

    fn class_policy(&self, id: NetId) -> Option<AuthorityPolicy> {
        let o = self.mirror.objects.get(&id)?;
        self.scene.class(o.kind).map(|c| c.authority)
    }

    /// Owner: a remote hand lets go (`throw` given to its particle).
    fn end_remote_hand(&mut self, key: (PeerId, u8), throw: Vec3) {
        let Some(a) = self.comanip.applied.remove(&key) else {
            return;
        };
        if let Some(LocalBody::Soft(h)) = self.mirror.objects.get(&a.object).map(|o| o.body) {
            release_particle(
                &mut self.mirror.world,
                &mut self.mirror.soft,
                h,
                a.particle,
                throw,
            );
        }
        let still_held = self.comanip.applied.values().any(|b| b.object == a.object);
        if let (false, Some(r)) = (still_held, self.mirror.object_ref(a.object)) {
            if !self.is_held(r) {
                self.hands.watch_until_rest(r);
            }
        }
    }

    /// Sender: the owner answered one of our remote hands.
    fn on_hand_answer(&mut self, from: PeerId, a: HandAnswer) {
        if a.accepted || self.session.owner(a.object) != Some(from) {
            return;
        }
        let ours = self
            .comanip
            .sending
            .get(usize::from(a.hand))
            .and_then(|s| s.as_ref());
        if !ours.is_some_and(|s| s.object == a.object && s.grab == a.grab) {
            return;
        }
        self.counters.remote_hands_denied += 1;
        self.events.push_back(Event::AuthorityDenied(a.object));
        if let Some(r) = self.mirror.object_ref(a.object) {
            self.hands.deny(r);
        }
    }

    /// Owner, before the soft bodies step: silent hands go; the others drive their particles.
    pub(super) fn apply_remote_hands(&mut self, now: Instant) {
        let me = self.me();
        let timeout = std::time::Duration::from_secs_f64(REMOTE_HAND_TIMEOUT_S);
        let mut gone = Vec::new();
        for (key, a) in &self.comanip.applied {
            let ours = self.session.owner(a.object) == Some(me);
            if !ours || now.saturating_since(a.heard) > timeout {
                gone.push((*key, ours));
            }
        }
        for (key, ours) in gone {
            if ours {
                self.counters.remote_hands_expired += 1;
                self.end_remote_hand(key, Vec3::ZERO);
            } else {
                // authority moved: the new owner applies the hand now, nothing to let go here
                self.comanip.applied.remove(&key);
            }
        }
        let dt = self.config.dt_s;
        let cfg = self.config.hand.clone();
        for a in self.comanip.applied.values() {
            let Some(LocalBody::Soft(h)) = self.mirror.objects.get(&a.object).map(|o| o.body)
            else {
                continue;
            };
            let age = now
                .saturating_since(a.heard)
                .as_secs_f32()
                .min(MAX_EXTRAPOLATE_S);
            let goal = a.goal + a.vel * age;
            drive_particle(
                &mut self.mirror.world,
                &mut self.mirror.soft,
                h,
                a.particle,
                goal,
                &cfg,
                dt,
            );
        }
    }

    /// A peer left: its hands let go (no throw).
    pub(super) fn forget_hands_of(&mut self, p: PeerId) {
        let keys: Vec<(PeerId, u8)> = self
            .comanip
            .applied
            .keys()
            .filter(|k| k.0 == p)
            .copied()
            .collect();
        for k in keys {
            self.end_remote_hand(k, Vec3::ZERO);
        }
        self.comanip.ended.retain(|k, _| k.0 != p);
        self.comanip.last_grab_at.retain(|k, _| k.0 != p);
    }

    /// Owner, after the step: who holds each of our objects; published when it changed.
    pub(super) fn publish_holders(&mut self, now: Instant) {
        let me = self.me();
        let mut now_held: BTreeMap<NetId, Vec<Holder>> = BTreeMap::new();
        for (h, hid) in self.hand_ids.iter().enumerate() {
            let Some(t) = self.hands.held(*hid) else {
                continue;
            };
            let Some(id) = self.mirror.id_of(t.object()) else {
                continue;
            };
            let particle = match t {
                Target::SoftParticle(_, p) => p,
                _ => u32::MAX,
            };
            now_held.entry(id).or_default().push(Holder {
                peer: me,
                hand: h as u8,
                particle,
            });
        }
        for ((peer, hand), a) in &self.comanip.applied {
            now_held.entry(a.object).or_default().push(Holder {
                peer: *peer,
                hand: *hand,
                particle: a.particle,
            });
        }
        let owned: Vec<NetId> = self
            .mirror
            .objects
            .iter()
            .filter(|(id, o)| !o.kind.is_avatar() && self.session.owner(**id) == Some(me))
            .map(|(id, _)| *id)
            .collect();
        self.comanip.published.retain(|id, _| owned.contains(id));
        for id in owned {
            let mut hands = now_held.remove(&id).unwrap_or_default();
            hands.sort();
            let h = Holders { hands };
            let told = self
                .comanip
                .published
                .get(&id)
                .or_else(|| self.comanip.holders.get(&id));
            if told.map_or(h.hands.is_empty(), |t| *t == h) {
                self.comanip.published.entry(id).or_insert(h);
                continue;
            }
            let sent = self.session.send(
                now,
                &self.message_types,
                MessageTarget::Everyone,
                Delivery::ObjectState(id),
                &h,
            );
            if sent.is_ok() {
                self.events.push_back(Event::Holders {
                    id,
                    hands: h.hands.clone(),
                });
                self.comanip.holders.insert(id, h.clone());
                self.comanip.published.insert(id, h);
            }
        }
    }

    /// What a body we do not simulate shows, with our remote hands' corrections (see the
    /// module's doc): the held particle at the hand, its neighbours by their weights.
    pub(super) fn predict_shown(&mut self, id: NetId, s: &mut ObjectState) {
        let Some(LocalBody::Soft(h)) = self.mirror.objects.get(&id).map(|o| o.body) else {
            return;
        };
        let Some(body) = self.mirror.soft.get(h) else {
            return;
        };
        if s.particles.len() != body.num_particles() {
            return;
        }
        let rows = &body.particle_map().neighbours;
        let add = |particle: u32, c: Vec3, particles: &mut [Vec3]| {
            let p = particle as usize;
            if p >= particles.len() {
                return;
            }
            particles[p] += c;
            let (a, b) = (rows.offsets[p] as usize, rows.offsets[p + 1] as usize);
            for k in a..b {
                let j = rows.ids[k] as usize;
                if j != p && j < particles.len() {
                    particles[j] += c * rows.weights[k].clamp(0.0, 1.0);
                }
            }
        };
        for (h, hid) in self.hand_ids.iter().enumerate() {
            let Some(send) = self.comanip.sending[h].as_mut() else {
                continue;
            };
            if send.object != id {
                continue;
            }
            let Some(sample) = self.hands.sample(*hid) else {
                continue;
            };
            let Some(x) = s.particles.get(send.particle as usize).copied() else {
                continue;
            };
            let mut c = sample.position_m - x;
            if c.length() > MAX_CORRECTION_M {
                c = c.normalize() * MAX_CORRECTION_M;
            }
            send.correction = c;
            add(send.particle, c, &mut s.particles);
        }
        for f in self.comanip.fades.iter().filter(|f| f.object == id) {
            let k = (f.left_s / FADE_S).clamp(0.0, 1.0);
            add(f.particle, f.correction * k, &mut s.particles);
        }
    }

    /// Fades advance by one step.
    pub(super) fn age_fades(&mut self) {
        let dt = self.config.dt_s;
        for f in &mut self.comanip.fades {
            f.left_s -= dt;
        }
        self.comanip.fades.retain(|f| f.left_s > 0.0);
    }

    /// Authority over `id` came to us: our remote hands on it hold it here now; or went to
    /// another peer: the hands we applied go with it (its owner hears them next).
    pub(super) fn on_owner_changed(&mut self, id: NetId, ours: bool) {
        if ours {
            for s in &mut self.comanip.sending {
                if s.as_ref().is_some_and(|s| s.object == id) {
                    *s = None;
                }
            }
            self.comanip.fades.retain(|f| f.object != id);
            // what the room believes, so we publish when it differs from what we apply
            if let Some(h) = self.comanip.holders.get(&id).cloned() {
                self.comanip.published.insert(id, h);
            }
        } else {
            self.comanip.applied.retain(|_, a| a.object != id);
            self.comanip.published.remove(&id);
        }
    }

    /// The held-by-a-remote-hand check for a body we own (it must not go back to the host).
    pub(super) fn remote_hands_on(&self, id: NetId) -> bool {
        self.comanip.applied.values().any(|a| a.object == id)
    }
}
