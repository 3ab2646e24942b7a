//! Over 800 lines: the script language (parse) and its interpreter (run) share the command
//! type and its validation; issue 40 splits them into `bot/parse.rs` and `bot/run.rs`.
//!
//! Bots: a small script language for avatar motion and actions, so that tests and load runs
//! are reproducible.
//!
//! One command per line or separated by `;`, `#` starts a comment. HAND is `left`, `right` or
//! `head`; times are seconds; positions metres in the room (y up, table top at 0.75 m).
//!
//! ```text
//! wait S                        do nothing for S
//! move HAND X Y Z [in S]        go to a point (straight line over S, default 0.5)
//! offset HAND DX DY DZ [in S]   go by an offset
//! reach HAND TARGET [at DX DY DZ] [in S]
//!                               go to an object: a class of the scene (the thesis room's:
//!                               bunny, softball, softbox, plate, block, can, ball) or
//!                               `nearest`; soft bodies are reached at their particle nearest
//!                               to the hand, or with `at` nearest to the object's center +
//!                               (DX DY DZ) (room axes: two bots take opposite sides)
//! grab HAND [timeout S]         close the grip; waits until held (through the authority
//!                               request if another peer owns it), or gives up (default 3 s)
//! squeeze HAND DEPTH [in S]     push the held point DEPTH metres toward the body's center
//! pull HAND DX DY DZ [in S]     move the held point by an offset (as `offset`, but says so
//!                               when the hand holds nothing); on a body another peer
//!                               simulates the hand is a remote hand (co-manipulation)
//! release HAND                  open the grip
//! wave HAND AMPLITUDE PERIOD S  move sinusoidally (load runs); HAND may be `all` (head
//!                               and both hands at once, out of phase)
//! own TARGET [timeout S]        ask for authority over the object (nearest of its kind to
//!                               the right hand) and wait until ours (default 3 s)
//! tear HAND TARGET DX DY DZ [DX DY DZ]… [in S]
//!                               a scalpel in HAND goes through the points (offsets from
//!                               TARGET's center when the stroke starts, room axes), S per
//!                               step (default 0.15); each step tears TARGET from the
//!                               last point to this one, the blade upright 4 cm above the
//!                               tip; the stroke ends with a lift (TARGET ours, or another
//!                               peer's: its owner applies the stroke as its own)
//! cut TARGET NX NY NZ           cut TARGET through its center, plane normal N (room; ours, or
//!                               another peer's through its owner)
//! slice HAND TARGET DX DY DZ DX DY DZ [in S]
//!                               the cut gesture: HAND's tool becomes the cutter and sweeps,
//!                               trigger held, from TARGET's center + the first offset to
//!                               its center + the second over S (default 0.5), the blade
//!                               upright; the body is cut by the plane of the sweep (tear
//!                               paper §3.2, `peer/cutter.rs`); then the tool is the
//!                               scalpel again
//! say TEXT                      send TEXT to everyone in the room (a reliable
//!                               [`Say`](crate::messages::Say) message; at most 200 bytes)
//! note TEXT                     as `say`, retained: the room keeps the latest note (a late
//!                               joiner gets it; a kept room keeps it between sessions)
//! replay pause|play|seek S|speed X   a spectator of a played-back recording steers it
//!                               (`softsync replay --serve`: a `ReplayControl` to the host)
//! kick PEER [REASON]            the host kicks PEER out and bans it for the room's life
//!                               (`Session::kick`); PEER is an id as the peer printed it
//!                               (decimal, or hex with 0x) or `newest` (the member that
//!                               joined last); REASON at most 120 bytes
//! loop                          start again from the top (last line)
//! ```
//!
//! On a peer with a tracked device (`--vr`, `--desktop`), a script runs on top of it: tracked
//! parts follow the device, displaced by the script's motion (`move` and `reach` still go to
//! room positions), and the grip is the larger of the script's and the device's.
//!
//! Built-in scripts by name: `squeeze` (reach the soft ball, grab, squeeze, release, back),
//! `idle` (stand still), `wave` (both hands waving, forever).
//!
//! A bot says what it does (`reach softbox (object 5)`, `grabbed object 5 after 120 ms`, …);
//! the driver takes those lines with [`Bot::poll_message`] after each step and logs them.

use std::collections::VecDeque;

use glam::{Quat, Vec3};
use softsync_interaction::{HandInput, HandSample};
use softsync_net::{Delivery, Instant, MessageTarget, NetId, PeerId};

use crate::device::{clamp01, DeviceFrame};
use crate::peer::Peer;
use crate::scene::Scene;

/// A bot script command.
#[derive(Clone, Debug, PartialEq)]
pub enum Cmd {
    /// Pause.
    Wait(f64),
    /// Absolute move.
    Move(usize, Vec3, f64),
    /// Relative move.
    Offset(usize, Vec3, f64),
    /// Move to an object (None: nearest), at its particle nearest to its center + the offset
    /// if one is given (else nearest to the hand).
    Reach(usize, Option<String>, Option<Vec3>, f64),
    /// Move the held point by an offset.
    Pull(usize, Vec3, f64),
    /// Close the grip.
    Grab(usize, f64),
    /// Push toward the held body's center.
    Squeeze(usize, f32, f64),
    /// Open the grip.
    Release(usize),
    /// Sinusoidal motion.
    Wave(usize, f32, f64, f64),
    /// Ask for authority over an object and wait.
    Own(Option<String>, f64),
    /// Tear along points (offsets from the target's center, room axes), seconds per step.
    Tear(usize, Option<String>, Vec<Vec3>, f64),
    /// Cut through the center with a normal (room frame).
    Cut(Option<String>, Vec3),
    /// Sweep a hand's cutter from one offset of the target's center to another (seconds).
    Slice(usize, Option<String>, Vec3, Vec3, f64),
    /// Send a line of text to the room (retained: a note the room keeps).
    Say(String, bool),
    /// A spectator of a played-back recording steers it (`softsync replay --serve`).
    Replay(crate::messages::ReplayControl),
    /// Host: kick a peer (`None`: the member that joined last) and ban it, with a reason.
    Kick(Option<u64>, String),
    /// Restart.
    Loop,
}

/// A parse error with its line.
#[derive(Debug, thiserror::Error)]
#[error("bot script, command {index} ({text:?}): {msg}")]
pub struct ScriptError {
    /// 1-based command number.
    pub index: usize,
    /// The command.
    pub text: String,
    /// What is wrong.
    pub msg: String,
}

/// Built-in scripts.
pub fn builtin(name: &str) -> Option<&'static str> {
    match name {
        "squeeze" => Some(
            "wait 1; reach right softbox in 1; grab right; squeeze right 0.02 in 0.6; wait 0.6; \
             release right; offset right 0 0.15 0 in 0.5",
        ),
        "idle" => Some("wait 1"),
        "wave" => Some("wave all 0.15 1.2 6; loop"),
        _ => None,
    }
}

fn hand(s: &str) -> Result<usize, String> {
    match s {
        "head" => Ok(0),
        "left" => Ok(1),
        "right" => Ok(2),
        _ => Err(format!("{s:?} is not a hand: use left, right or head")),
    }
}

fn num(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("{s:?} is not a number"))?;
    if !v.is_finite() || v.abs() > 1e4 {
        return Err(format!("{s} is out of range"));
    }
    Ok(v)
}

fn dur(w: &[&str], at: usize, default: f64) -> Result<f64, String> {
    match (w.get(at), w.get(at + 1)) {
        (None, _) => Ok(default),
        (Some(&"in"), Some(v)) | (Some(&"timeout"), Some(v)) => {
            let d = num(v)?;
            if d < 0.0 {
                Err("a duration cannot be negative".into())
            } else {
                Ok(d)
            }
        }
        _ => Err(format!("unexpected {:?}", w[at..].join(" "))),
    }
}

fn target_kind(t: &str) -> Result<Option<String>, String> {
    if t == "nearest" {
        return Ok(None);
    }
    // Checked against the scene when the bot meets it (`Bot::check`).
    if t.is_empty()
        || t.len() > 64
        || !t
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(format!("{t:?} is not a class name or `nearest`"));
    }
    Ok(Some(t.to_owned()))
}

/// `X Y Z [X Y Z]… [in S]` from `at`: at least two points.
fn path(w: &[&str], at: usize) -> Result<(Vec<Vec3>, f64), String> {
    let end = w.iter().position(|x| *x == "in").unwrap_or(w.len());
    let coords = &w[at.min(end)..end];
    if coords.len() < 6 || coords.len() % 3 != 0 {
        return Err("expected two or more points X Y Z".into());
    }
    if coords.len() / 3 > 256 {
        return Err("at most 256 points".into());
    }
    let pts = (0..coords.len() / 3)
        .map(|k| vec3(coords, 3 * k))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((pts, dur(w, end, 0.15)?))
}

fn vec3(w: &[&str], at: usize) -> Result<Vec3, String> {
    if w.len() < at + 3 {
        return Err("expected X Y Z".into());
    }
    Ok(Vec3::new(
        num(w[at])? as f32,
        num(w[at + 1])? as f32,
        num(w[at + 2])? as f32,
    ))
}

/// Parse a script (inline text or a file's contents).
pub fn parse(text: &str) -> Result<Vec<Cmd>, ScriptError> {
    let mut out = Vec::new();
    let pieces = text
        .lines()
        .flat_map(|l| l.split('#').next().unwrap_or("").split(';'))
        .map(str::trim)
        .filter(|s| !s.is_empty());
    for (i, piece) in pieces.enumerate() {
        let w: Vec<&str> = piece.split_whitespace().collect();
        let cmd = (|| -> Result<Cmd, String> {
            let arg = |k: usize| {
                w.get(k)
                    .copied()
                    .ok_or_else(|| "missing argument".to_string())
            };
            Ok(match w[0] {
                "wait" => Cmd::Wait(num(arg(1)?)?.max(0.0)),
                "move" => Cmd::Move(hand(arg(1)?)?, vec3(&w, 2)?, dur(&w, 5, 0.5)?),
                "offset" => Cmd::Offset(hand(arg(1)?)?, vec3(&w, 2)?, dur(&w, 5, 0.5)?),
                "reach" if w.get(3) == Some(&"at") => Cmd::Reach(
                    hand(arg(1)?)?,
                    target_kind(arg(2)?)?,
                    Some(vec3(&w, 4)?),
                    dur(&w, 7, 0.5)?,
                ),
                "reach" => Cmd::Reach(
                    hand(arg(1)?)?,
                    target_kind(arg(2)?)?,
                    None,
                    dur(&w, 3, 0.5)?,
                ),
                "pull" => Cmd::Pull(hand(arg(1)?)?, vec3(&w, 2)?, dur(&w, 5, 0.5)?),
                "own" => Cmd::Own(target_kind(arg(1)?)?, dur(&w, 2, 3.0)?),
                "tear" => {
                    let (pts, step) = path(&w, 3)?;
                    Cmd::Tear(hand(arg(1)?)?, target_kind(arg(2)?)?, pts, step)
                }
                "cut" => {
                    let n = vec3(&w, 2)?;
                    if n.length() < 1e-6 {
                        return Err("the normal is zero".into());
                    }
                    Cmd::Cut(target_kind(arg(1)?)?, n)
                }
                "slice" => Cmd::Slice(
                    hand(arg(1)?)?,
                    target_kind(arg(2)?)?,
                    vec3(&w, 3)?,
                    vec3(&w, 6)?,
                    dur(&w, 9, 0.5)?,
                ),
                "say" | "note" => {
                    let text = piece[w[0].len()..].trim();
                    if text.is_empty() || text.len() > 200 {
                        return Err(format!("{} needs a text of 1 to 200 bytes", w[0]));
                    }
                    Cmd::Say(text.to_owned(), w[0] == "note")
                }
                "replay" => {
                    let num = |i: usize| -> Result<f64, String> {
                        arg(i)?
                            .parse::<f64>()
                            .ok()
                            .filter(|v| v.is_finite() && *v >= 0.0)
                            .ok_or_else(|| format!("replay {}: a number of 0 or more", w[1]))
                    };
                    let mut c = crate::messages::ReplayControl {
                        pause: None,
                        seek_s: None,
                        speed: None,
                    };
                    match arg(1)? {
                        "pause" => c.pause = Some(true),
                        "play" => c.pause = Some(false),
                        "seek" => c.seek_s = Some(num(2)?),
                        "speed" => c.speed = Some(num(2)?),
                        other => {
                            return Err(format!(
                                "replay {other}: pause, play, seek SECONDS or speed X"
                            ))
                        }
                    }
                    Cmd::Replay(c)
                }
                "kick" => {
                    let who = match arg(1)? {
                        "newest" => None,
                        id => Some(
                            id.strip_prefix("0x")
                                .map_or_else(|| id.parse::<u64>(), |h| u64::from_str_radix(h, 16))
                                .map_err(|_| {
                                    format!("kick: {id:?} is not a peer id or `newest`")
                                })?,
                        ),
                    };
                    let reason = w[2..].join(" ");
                    if reason.len() > 120 {
                        return Err("kick: the reason is at most 120 bytes".into());
                    }
                    Cmd::Kick(who, reason)
                }
                "grab" => Cmd::Grab(hand(arg(1)?)?, dur(&w, 2, 3.0)?),
                "squeeze" => Cmd::Squeeze(hand(arg(1)?)?, num(arg(2)?)? as f32, dur(&w, 3, 0.5)?),
                "release" => Cmd::Release(hand(arg(1)?)?),
                "wave" => Cmd::Wave(
                    if arg(1)? == "all" { 3 } else { hand(arg(1)?)? },
                    num(arg(2)?)? as f32,
                    num(arg(3)?)?.max(0.05),
                    num(arg(4)?)?.max(0.0),
                ),
                "loop" => Cmd::Loop,
                other => return Err(format!("unknown command {other:?}")),
            })
        })()
        .map_err(|msg| ScriptError {
            index: i + 1,
            text: piece.to_owned(),
            msg,
        })?;
        if matches!(
            cmd,
            Cmd::Grab(0, _)
                | Cmd::Squeeze(0, ..)
                | Cmd::Release(0)
                | Cmd::Tear(0, ..)
                | Cmd::Slice(0, ..)
                | Cmd::Pull(0, ..)
        ) {
            return Err(ScriptError {
                index: i + 1,
                text: piece.to_owned(),
                msg: "the head cannot grab".into(),
            });
        }
        out.push(cmd);
    }
    Ok(out)
}

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

    /// One fixed step at `now` (before [`Peer::fixed_step`]): set the hands' inputs and the
    /// avatar's pose. With a tracked device under the script, tracked parts follow the device,
    /// offset by what the script moved them.
    pub fn step(&mut self, now: Instant, peer: &mut Peer, device: Option<&DeviceFrame>) {
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
    fn next(&mut self, now: Instant, peer: &mut Peer, t: f64) -> bool {
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
                    .and_then(|(id, _)| peer.shown_state(now, id))
                    .map(|s| s.pos);
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
                if let Some((id, _)) = peer.held(hand - 1) {
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
                    if peer.session().owner(id) != Some(peer.me()) {
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
                        let c = peer.shown_state(now, id).map_or(Vec3::ZERO, |s| s.pos);
                        let points: Vec<Vec3> = offsets.iter().map(|o| c + *o).collect();
                        self.pos[hand] = self.to_script(hand, points[0]);
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
                        let c = peer.shown_state(now, id).map_or(Vec3::ZERO, |s| s.pos);
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
                            cuts: peer.counters().cut_gestures,
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
                        let point = peer.shown_state(now, id).map_or(center, |s| s.pos);
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
                let msg = crate::messages::Say { text: text.clone() };
                let how = if retained {
                    Delivery::Retained
                } else {
                    Delivery::Reliable
                };
                match peer.send(now, MessageTarget::Everyone, how, &msg) {
                    Ok(seq) => self.say(format!("said {text:?} (message {seq})")),
                    Err(e) => self.say(format!("say: {e}")),
                }
                None
            }
            Cmd::Replay(c) => {
                match peer.send(now, MessageTarget::Host, Delivery::Reliable, &c) {
                    Ok(seq) => self.say(format!("replay control sent (message {seq})")),
                    Err(e) => self.say(format!("replay: {e}")),
                }
                None
            }
            Cmd::Kick(who, reason) => {
                let me = peer.me();
                let target = who.map(PeerId).or_else(|| {
                    let members = peer.session().members();
                    members
                        .iter()
                        .filter(|(p, _)| **p != me)
                        .max_by_key(|(_, seq)| **seq)
                        .map(|(p, _)| *p)
                });
                match target {
                    Some(p) => match peer.kick(now, p, &reason) {
                        Ok(()) => self.say(format!("kicked peer {} ({reason:?})", p.0)),
                        Err(e) => self.say(format!("kick: {e}")),
                    },
                    None => self.say("kick: nobody else in the room".into()),
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
    fn advance(&mut self, now: Instant, peer: &mut Peer, t: f64) -> bool {
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
                let cut = peer.counters().cut_gestures > cuts;
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
                if let Some((id, _)) = peer.held(hand - 1) {
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
                if peer.session().owner(id) == Some(peer.me()) {
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
                    if let Err(e) = peer.tear(now, id, a, b, blade) {
                        self.say(format!("tear object {}: {e}", id.0));
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
                    if let Err(e) = peer.lift(now, id) {
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
        peer: &mut Peer,
        part: usize,
        kind: Option<&str>,
    ) -> Option<(NetId, String)> {
        let from = self.at(part);
        let ids: Vec<_> = peer
            .objects()
            .iter()
            .filter(|(_, o)| {
                !o.kind.is_avatar() && kind.is_none_or(|k| peer.scene().name_of(o.kind) == k)
            })
            .map(|(id, o)| (*id, peer.scene().name_of(o.kind).to_owned()))
            .collect();
        ids.into_iter()
            .filter_map(|(id, k)| {
                let d = peer.shown_state(now, id)?.pos.distance(from);
                Some((d, id, format!("{k} (object {})", id.0)))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, id, n)| (id, n))
    }

    /// A point to reach: the object's particle nearest to the hand, or its center.
    fn target(
        &self,
        now: Instant,
        peer: &mut Peer,
        part: usize,
        kind: Option<&str>,
        at: Option<Vec3>,
    ) -> Option<(Vec3, String)> {
        let hand = self.at(part);
        let ids: Vec<_> = peer
            .objects()
            .iter()
            .filter(|(_, o)| {
                !o.kind.is_avatar() && kind.is_none_or(|k| peer.scene().name_of(o.kind) == k)
            })
            .map(|(id, o)| (*id, peer.scene().name_of(o.kind).to_owned()))
            .collect();
        let mut best: Option<(f32, Vec3, String)> = None;
        for (id, k) in ids {
            let Some(s) = peer.shown_state(now, id) else {
                continue;
            };
            let from = at.map_or(hand, |d| s.pos + d);
            let p = if s.particles.is_empty() {
                s.pos
            } else {
                s.particles
                    .iter()
                    .copied()
                    .min_by(|a, b| a.distance(from).total_cmp(&b.distance(from)))
                    .unwrap_or(s.pos)
            };
            // which object: the one nearest the hand
            let d = if at.is_some() {
                s.pos.distance(hand)
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn scripts_parse_and_errors_name_the_command() {
        let c = parse("wait 1; reach right softball in 1\n# comment\ngrab right; squeeze right 0.03 in 0.6; release right; loop").unwrap();
        assert_eq!(c.len(), 6);
        assert_eq!(c[1], Cmd::Reach(2, Some("softball".into()), None, 1.0));
        assert_eq!(c[2], Cmd::Grab(2, 3.0));
        let c = parse("reach left bunny at -0.1 0 0 in 0.8; pull left -0.05 0 0.01 in 1").unwrap();
        assert_eq!(
            c,
            [
                Cmd::Reach(
                    1,
                    Some("bunny".into()),
                    Some(Vec3::new(-0.1, 0.0, 0.0)),
                    0.8
                ),
                Cmd::Pull(1, Vec3::new(-0.05, 0.0, 0.01), 1.0)
            ]
        );
        assert!(parse("reach left bunny at 1 2").is_err());
        assert!(parse("pull head 0 0 1").is_err());
        for name in ["squeeze", "idle", "wave"] {
            parse(builtin(name).unwrap()).unwrap();
        }
        let e = parse("wait 1; jump right").unwrap_err();
        assert_eq!(e.index, 2);
        assert!(e.to_string().contains("unknown command"), "{e}");
        assert!(parse("reach right tea/pot")
            .unwrap_err()
            .msg
            .contains("not a class name"));
        // A name the scene does not have: refused when the bot meets the scene.
        let scene = Scene::by_name(
            "thesis-room",
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets")),
        )
        .unwrap();
        let teapot = Bot::new(parse("reach right teapot; own bunny").unwrap());
        let e = teapot.check(&scene).unwrap_err();
        assert!(e.contains("teapot") && e.contains("softbox"), "{e}");
        Bot::new(parse("reach right softball; cut softbox 0 1 0").unwrap())
            .check(&scene)
            .unwrap();
        assert_eq!(
            parse("say  the valve is open ").unwrap(),
            [Cmd::Say("the valve is open".into(), false)]
        );
        assert!(parse("say").is_err());
        assert_eq!(
            parse("kick newest spam in the chat; kick 0x1f; kick 42 x").unwrap(),
            [
                Cmd::Kick(None, "spam in the chat".into()),
                Cmd::Kick(Some(31), String::new()),
                Cmd::Kick(Some(42), "x".into())
            ]
        );
        assert!(parse("kick").is_err());
        assert!(parse("kick someone").is_err());
        assert!(parse(&format!("kick newest {}", "x".repeat(121))).is_err());
        assert!(parse(&format!("say {}", "x".repeat(201))).is_err());
        assert!(parse("move left 1 2").is_err());
        assert!(parse("move left 1 2 NaN").is_err());
        assert!(parse("grab head").is_err());
        assert!(
            parse("wait 1 2").is_ok(),
            "extra words after wait are ignored"
        );
        assert!(parse("move left 0 1 0 in -1").is_err());
        let c =
            parse("own bunny; tear right bunny 0 1 0 0.01 1 0 0.02 1 0 in 0.1; cut softbox 0 1 0")
                .unwrap();
        assert_eq!(c[0], Cmd::Own(Some("bunny".into()), 3.0));
        assert!(
            matches!(&c[1], Cmd::Tear(2, Some(k), p, s) if k == "bunny" && p.len() == 3 && *s == 0.1)
        );
        assert_eq!(c[2], Cmd::Cut(Some("softbox".into()), Vec3::Y));
        assert!(
            parse("tear right bunny 0 1 0").is_err(),
            "one point is no segment"
        );
        assert!(parse("tear right bunny 0 1 0 1 1").is_err());
        assert!(parse("tear head bunny 0 1 0 1 1 1").is_err());
        assert!(parse("cut bunny 0 0 0").is_err());
        assert!(parse("cut bunny 0 NaN 1").is_err());
    }
}
