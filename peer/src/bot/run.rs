//! The bot's interpreter: runs a parsed script ([`Cmd`]s) step by step against a
//! [`BotWorld`], moving the avatar and the hands and saying what it does.

use std::collections::VecDeque;

use glam::{Quat, Vec3};
use softsync_interaction::{HandInput, HandSample};
use softsync_net::{Instant, NetId, PeerId};

use super::parse::Cmd;
use super::world::BotWorld;
use crate::device::{clamp01, DeviceFrame};
use crate::scene::Scene;

#[derive(Clone, Debug)]
enum Active {
    Wait(f64),
    Motion {
        part: usize,
        from: Vec3,
        to: Vec3,
        t0: f64,
        dur: f64,
    },
    Wave {
        part: usize,
        center: [Vec3; 3],
        amp: f32,
        period: f64,
        t0: f64,
        dur: f64,
    },
    Grab {
        hand: usize,
        t0: f64,
        until: f64,
    },
    Own {
        id: NetId,
        until: f64,
    },
    Tear {
        hand: usize,
        id: NetId,
        points: Vec<Vec3>,
        /// The point the hand is going to.
        k: usize,
        t0: f64,
        step: f64,
    },
    Slice {
        hand: usize,
        name: String,
        from: Vec3,
        to: Vec3,
        t0: f64,
        dur: f64,
        /// The peer's cut gestures before the sweep.
        cuts: u64,
    },
}

/// A running bot: drives the avatar (head and hands) and the grips.
#[derive(Clone, Debug)]
pub struct Bot {
    cmds: Vec<Cmd>,
    pc: usize,
    active: Option<Active>,
    /// Head, left, right: where the script puts them (its own frame).
    pos: [Vec3; 3],
    /// Added to `pos` to get the room position: zero for a bot alone; the tracked pose minus
    /// the script's start point when a device drives the avatar (a script on a VR peer moves
    /// the hands relative to the controllers).
    base: [Vec3; 3],
    /// Where the script started each part.
    start: [Vec3; 3],
    /// Tracked rotations (a device), else the bot's own.
    rots: [Option<Quat>; 3],
    /// Tracked grip values (a device): the grip is the larger of the script's and the device's.
    device_grip: [f32; 3],
    rot: Quat,
    grip: [f32; 3],
    /// The script's trigger per part (a slice holds it); the hand's is the larger of it and
    /// the device's.
    trigger: [f32; 3],
    started: bool,
    /// Finished the script.
    pub done: bool,
    /// Grabs that took hold, with the time from grip to hold (s).
    pub grabs: Vec<f64>,
    /// Grabs that gave up.
    pub failed_grabs: u64,
    /// What the bot said, not yet taken by the driver.
    said: VecDeque<String>,
}

impl Bot {
    /// A bot running `cmds`.
    pub fn new(cmds: Vec<Cmd>) -> Self {
        Bot {
            cmds,
            pc: 0,
            active: None,
            pos: [Vec3::ZERO; 3],
            base: [Vec3::ZERO; 3],
            start: [Vec3::ZERO; 3],
            rots: [None; 3],
            device_grip: [0.0; 3],
            rot: Quat::IDENTITY,
            grip: [0.0; 3],
            trigger: [0.0; 3],
            started: false,
            done: false,
            grabs: Vec::new(),
            failed_grabs: 0,
            said: VecDeque::new(),
        }
    }

    /// Whether every class the script names is one of `scene`'s (not the avatar's): the
    /// error lists the unknown ones and the scene's classes.
    pub fn check(&self, scene: &Scene) -> Result<(), String> {
        let mut unknown: Vec<&str> = self
            .cmds
            .iter()
            .filter_map(|c| match c {
                Cmd::Reach(_, k, _, _)
                | Cmd::Own(k, _)
                | Cmd::Tear(_, k, _, _)
                | Cmd::Slice(_, k, ..)
                | Cmd::Cut(k, _) => k.as_deref(),
                _ => None,
            })
            .filter(|k| scene.kind(k).is_none())
            .collect();
        unknown.sort_unstable();
        unknown.dedup();
        if unknown.is_empty() {
            return Ok(());
        }
        let classes: Vec<&str> = scene
            .object_classes()
            .map(|(_, c)| c.name.as_str())
            .collect();
        Err(format!(
            "the bot script names {} not in scene {} (its classes: {}, or nearest)",
            unknown.join(", "),
            scene.name,
            classes.join(", ")
        ))
    }

    fn say(&mut self, msg: String) {
        self.said.push_back(msg);
    }

    /// The next thing the bot said (oldest first), for the driver's log.
    pub fn poll_message(&mut self) -> Option<String> {
        self.said.pop_front()
    }

    /// Room position of part `part` now.
    fn at(&self, part: usize) -> Vec3 {
        self.pos[part] + self.base[part]
    }

    /// A room position as a point in the script's frame for `part`.
    fn to_script(&self, part: usize, room_pos: Vec3) -> Vec3 {
        room_pos - self.base[part]
    }

    /// One fixed step at `now`, before the world's (a state-sync peer's
    /// [`fixed_step`](crate::Peer::fixed_step)): set the hands' inputs and the avatar's pose.
    /// With a tracked device under the script, tracked parts follow the device, offset by
    /// what the script moved them.
    pub fn step(&mut self, now: Instant, peer: &mut dyn BotWorld, device: Option<&DeviceFrame>) {
        let t = peer.sim_time();
        if !self.started {
            let (home, rot) = peer.home();
            self.rot = rot;
            self.pos = [
                home,
                home + rot * Vec3::new(-0.2, -0.45, -0.25),
                home + rot * Vec3::new(0.2, -0.45, -0.25),
            ];
            self.start = self.pos;
            self.started = true;
        }
        // The device's poses are the base the script's motion adds to.
        for part in 0..3 {
            match device.and_then(|d| d.part(part)) {
                Some((p, r)) => {
                    // Room position = tracked + (script position - script start).
                    self.base[part] = p - self.start[part];
                    self.rots[part] = Some(r);
                }
                None => {
                    self.base[part] = Vec3::ZERO;
                    self.rots[part] = None;
                }
            }
            if part > 0 {
                self.device_grip[part] = device.map_or(0.0, |d| clamp01(d.grip[part - 1]));
            }
        }
        // Run commands until one takes time.
        for _ in 0..64 {
            if self.active.is_none() && !self.next(now, peer, t) {
                break;
            }
            if !self.advance(now, peer, t) {
                break;
            }
        }
        for part in 0..3 {
            peer.set_avatar_pose(part, self.at(part), self.rots[part].unwrap_or(self.rot));
        }
        for h in 0..2 {
            let input = HandInput {
                sample: HandSample {
                    position_m: self.at(h + 1),
                    rotation: self.rots[h + 1].unwrap_or(self.rot),
                    time_s: t,
                },
                grip: self.grip[h + 1].max(self.device_grip[h + 1]),
                trigger: self.trigger[h + 1].max(device.map_or(0.0, |d| clamp01(d.trigger[h]))),
            };
            peer.set_hand_input(h, input);
        }
    }

    /// Start the next command; false when there is none.
    fn next(&mut self, now: Instant, peer: &mut dyn BotWorld, t: f64) -> bool {
        let Some(cmd) = self.cmds.get(self.pc).cloned() else {
            if !self.done {
                self.done = true;
                self.say("script done".into());
            }
            return false;
        };
        self.pc += 1;
        self.active = match cmd {
            Cmd::Wait(s) => Some(Active::Wait(t + s)),
            Cmd::Move(part, to, dur) => Some(Active::Motion {
                part,
                from: self.pos[part],
                to: self.to_script(part, to),
                t0: t,
                dur,
            }),
            Cmd::Offset(part, d, dur) => Some(Active::Motion {
                part,
                from: self.pos[part],
                to: self.pos[part] + d,
                t0: t,
                dur,
            }),
            Cmd::Pull(hand, d, dur) => {
                if peer.held(hand - 1).is_none() {
                    self.say("pull: the hand holds nothing".into());
                }
                Some(Active::Motion {
                    part: hand,
                    from: self.pos[hand],
                    to: self.pos[hand] + d,
                    t0: t,
                    dur,
                })
            }
            Cmd::Reach(part, kind, at, dur) => {
                match self.target(now, peer, part, kind.as_deref(), at) {
                    Some((to, name)) => {
                        self.say(format!("reach {name}"));
                        Some(Active::Motion {
                            part,
                            from: self.pos[part],
                            to: self.to_script(part, to),
                            t0: t,
                            dur,
                        })
                    }
                    None => {
                        self.say(format!(
                            "reach: no {} in the room",
                            kind.as_deref().unwrap_or("object")
                        ));
                        None
                    }
                }
            }
            Cmd::Grab(hand, timeout) => {
                self.grip[hand] = 1.0;
                Some(Active::Grab {
                    hand,
                    t0: t,
                    until: t + timeout,
                })
            }
            Cmd::Squeeze(hand, depth, dur) => {
                let center = peer
                    .held(hand - 1)
                    .and_then(|id| peer.shown(now, id))
                    .map(|s| s.0);
                match center {
                    Some(c) => {
                        let dir = (c - self.at(hand)).normalize_or_zero();
                        Some(Active::Motion {
                            part: hand,
                            from: self.pos[hand],
                            to: self.pos[hand] + dir * depth,
                            t0: t,
                            dur,
                        })
                    }
                    None => {
                        self.say("squeeze: the hand holds nothing".into());
                        None
                    }
                }
            }
            Cmd::Release(hand) => {
                self.grip[hand] = 0.0;
                if let Some(id) = peer.held(hand - 1) {
                    self.say(format!("release object {}", id.0));
                }
                None
            }
            Cmd::Wave(part, amp, period, dur) => Some(Active::Wave {
                part,
                center: self.pos,
                amp,
                period,
                t0: t,
                dur,
            }),
            Cmd::Own(kind, timeout) => match self.object(now, peer, 2, kind.as_deref()) {
                Some((id, name)) => {
                    if !peer.owns(id) {
                        peer.ask_authority(now, id);
                    }
                    self.say(format!("own {name}"));
                    Some(Active::Own {
                        id,
                        until: t + timeout,
                    })
                }
                None => {
                    self.say("own: no such object in the room".into());
                    None
                }
            },
            Cmd::Tear(hand, kind, offsets, step) => {
                match self.object(now, peer, hand, kind.as_deref()) {
                    Some((id, name)) => {
                        self.say(format!("tear {name} along {} points", offsets.len()));
                        let c = peer.shown(now, id).map_or(Vec3::ZERO, |s| s.0);
                        let points: Vec<Vec3> = offsets.iter().map(|o| c + *o).collect();
                        self.pos[hand] = self.to_script(hand, points[0]);
                        if peer.blades_are_inputs() {
                            // the stroke is the hand's input: the trigger held along it
                            self.trigger[hand] = 1.0;
                        }
                        Some(Active::Tear {
                            hand,
                            id,
                            points,
                            k: 1,
                            t0: t,
                            step,
                        })
                    }
                    None => {
                        self.say("tear: no such object in the room".into());
                        None
                    }
                }
            }
            Cmd::Slice(hand, kind, a, b, dur) => {
                match self.object(now, peer, hand, kind.as_deref()) {
                    Some((id, name)) => {
                        let c = peer.shown(now, id).map_or(Vec3::ZERO, |s| s.0);
                        self.say(format!("slice {name}"));
                        self.pos[hand] = self.to_script(hand, c + a);
                        self.trigger[hand] = 1.0;
                        peer.set_hand_tool(hand - 1, crate::HandTool::Cutter);
                        Some(Active::Slice {
                            hand,
                            name,
                            from: self.to_script(hand, c + a),
                            to: self.to_script(hand, c + b),
                            t0: t,
                            dur,
                            cuts: peer.cut_gestures(),
                        })
                    }
                    None => {
                        self.say("slice: no such object in the room".into());
                        None
                    }
                }
            }
            Cmd::Cut(kind, normal) => {
                let center = self.at(2);
                match self.object(now, peer, 2, kind.as_deref()) {
                    Some((id, name)) => {
                        let point = peer.shown(now, id).map_or(center, |s| s.0);
                        match peer.cut(now, id, point, normal) {
                            Ok(()) => self.say(format!("cut {name}")),
                            Err(e) => self.say(format!("cut {name}: {e}")),
                        }
                    }
                    None => self.say("cut: no such object in the room".into()),
                }
                None
            }
            Cmd::Say(text, retained) => {
                match peer.say(now, &text, retained) {
                    Ok(seq) => self.say(format!("said {text:?} (message {seq})")),
                    Err(e) => self.say(format!("say: {e}")),
                }
                None
            }
            Cmd::Replay(c) => {
                match peer.replay(now, &c) {
                    Ok(seq) => self.say(format!("replay control sent (message {seq})")),
                    Err(e) => self.say(format!("replay: {e}")),
                }
                None
            }
            Cmd::Kick(who, reason) => {
                match peer.kick(now, who.map(PeerId), &reason) {
                    Ok(p) => self.say(format!("kicked peer {} ({reason:?})", p.0)),
                    Err(e) => self.say(format!("kick: {e}")),
                }
                None
            }
            Cmd::Loop => {
                self.pc = 0;
                None
            }
        };
        true
    }

    /// Progress the active command; true when it finished.
    fn advance(&mut self, now: Instant, peer: &mut dyn BotWorld, t: f64) -> bool {
        let Some(a) = self.active.clone() else {
            return true;
        };
        let finished = match a {
            Active::Wait(until) => t >= until,
            Active::Motion {
                part,
                from,
                to,
                t0,
                dur,
            } => {
                let f = if dur <= 0.0 {
                    1.0
                } else {
                    ((t - t0) / dur).clamp(0.0, 1.0) as f32
                };
                self.pos[part] = from.lerp(to, f);
                f >= 1.0
            }
            Active::Wave {
                part,
                center,
                amp,
                period,
                t0,
                dur,
            } => {
                // Continuous: starts where the part is, and stays where it ends.
                let ph = ((t.min(t0 + dur) - t0) / period * std::f64::consts::TAU) as f32;
                let parts = if part == 3 { 0..3 } else { part..part + 1 };
                for p in parts {
                    let (a, shift) = if p == 0 {
                        (amp * 0.4, 0.0)
                    } else {
                        (amp, p as f32 * 1.3)
                    };
                    let f = |q: f32| {
                        Vec3::new(q.sin() * a, (q * 2.0).sin() * a * 0.3, q.cos() * a * 0.5)
                    };
                    self.pos[p] = center[p] + f(ph + shift) - f(shift);
                }
                t - t0 >= dur
            }
            Active::Slice {
                hand,
                name,
                from,
                to,
                t0,
                dur,
                cuts,
            } => {
                let f = if dur <= 0.0 {
                    1.0
                } else {
                    ((t - t0) / dur).clamp(0.0, 1.0) as f32
                };
                self.pos[hand] = from.lerp(to, f);
                let cut = peer.cut_gestures() > cuts;
                if f >= 1.0 || cut {
                    if cut {
                        self.say(format!("sliced {name}"));
                    } else {
                        self.say(format!("slice {name}: the sweep made no cut"));
                    }
                    self.trigger[hand] = 0.0;
                    peer.set_hand_tool(hand - 1, crate::HandTool::Scalpel);
                }
                f >= 1.0 || cut
            }
            Active::Grab { hand, t0, until } => {
                if let Some(id) = peer.held(hand - 1) {
                    self.grabs.push(t - t0);
                    self.say(format!(
                        "grabbed object {} after {:.0} ms",
                        id.0,
                        (t - t0) * 1e3
                    ));
                    true
                } else if t >= until {
                    self.failed_grabs += 1;
                    self.grip[hand] = 0.0;
                    self.say("grab: nothing taken".into());
                    true
                } else {
                    false
                }
            }
            Active::Own { id, until } => {
                if peer.owns(id) {
                    self.say(format!("own object {}", id.0));
                    true
                } else if t >= until {
                    self.say(format!("own: object {} not granted", id.0));
                    true
                } else {
                    false
                }
            }
            Active::Tear {
                hand,
                id,
                points,
                k,
                t0,
                step,
            } => {
                let f = if step <= 0.0 {
                    1.0
                } else {
                    ((t - t0) / step).clamp(0.0, 1.0) as f32
                };
                let (a, b) = (points[k - 1], points[k]);
                self.pos[hand] = self.to_script(hand, a.lerp(b, f));
                if f < 1.0 {
                    false
                } else {
                    let blade = Vec3::Y * 0.04;
                    if !peer.blades_are_inputs() {
                        if let Err(e) = peer.tear(now, id, a, b, blade) {
                            self.say(format!("tear object {}: {e}", id.0));
                        }
                    }
                    if k + 1 < points.len() {
                        self.active = Some(Active::Tear {
                            hand,
                            id,
                            points,
                            k: k + 1,
                            t0: t,
                            step,
                        });
                        return false;
                    }
                    if peer.blades_are_inputs() {
                        self.trigger[hand] = 0.0;
                    } else if let Err(e) = peer.lift(now, id) {
                        self.say(format!("lift object {}: {e}", id.0));
                    }
                    self.say(format!(
                        "tore object {} in {} segments",
                        id.0,
                        points.len() - 1
                    ));
                    true
                }
            }
        };
        if finished {
            self.active = None;
        }
        finished
    }

    /// The object of `kind` nearest to `part` (any non-avatar object for `None`).
    fn object(
        &self,
        now: Instant,
        peer: &mut dyn BotWorld,
        part: usize,
        kind: Option<&str>,
    ) -> Option<(NetId, String)> {
        let from = self.at(part);
        peer.object_list()
            .into_iter()
            .filter(|(_, k)| kind.is_none_or(|want| k == want))
            .filter_map(|(id, k)| {
                let d = peer.shown(now, id)?.0.distance(from);
                Some((d, id, format!("{k} (object {})", id.0)))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, id, n)| (id, n))
    }

    /// A point to reach: the object's particle nearest to the hand, or its center.
    fn target(
        &self,
        now: Instant,
        peer: &mut dyn BotWorld,
        part: usize,
        kind: Option<&str>,
        at: Option<Vec3>,
    ) -> Option<(Vec3, String)> {
        let hand = self.at(part);
        let ids: Vec<_> = peer
            .object_list()
            .into_iter()
            .filter(|(_, k)| kind.is_none_or(|want| k == want))
            .collect();
        let mut best: Option<(f32, Vec3, String)> = None;
        for (id, k) in ids {
            let Some((pos, particles)) = peer.shown(now, id) else {
                continue;
            };
            let from = at.map_or(hand, |d| pos + d);
            let p = particles
                .iter()
                .copied()
                .min_by(|a, b| a.distance(from).total_cmp(&b.distance(from)))
                .unwrap_or(pos);
            // which object: the one nearest the hand
            let d = if at.is_some() {
                pos.distance(hand)
            } else {
                p.distance(from)
            };
            if best.as_ref().is_none_or(|b| d < b.0) {
                best = Some((d, p, format!("{k} (object {})", id.0)));
            }
        }
        best.map(|(_, p, n)| (p, n))
    }
}
