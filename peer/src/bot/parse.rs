//! The bot script language: commands ([`Cmd`]) parsed from text, each checked as it is read
//! (the reference is in the module above).

use glam::Vec3;

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
