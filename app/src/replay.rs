//! `softsync replay` and `softsync store`: recorded sessions played back, exported, listed,
//! deleted and pruned (`softsync_store::record`).
//!
//! Playback is headless (`--serve ROOM` plays it as a room instead: [`crate::replay_room`]):
//! the recording's events are printed at their times (`replay t=… kind=…`,
//! `t` in seconds from the recording's start), scaled by `--speed`, and `--dump` writes every
//! object's state (between its recorded states, interpolated) at `--dump-hz` recorded times —
//! the same lines at any speed. `--from` seeks: the room at that time is read in one go
//! (`seek t=… objects=… ms=…`), then playback goes on from there. `--as PEER` adds that
//! peer's head and hands to every dump line: the session from its point of view.

// The I/O layer: playback is paced on this machine's clock.
#![allow(clippy::disallowed_methods)]

use std::io::Write as _;
use std::process::ExitCode;
use std::time::Duration;

use softsync_store::record::{RecState, RecordingInfo};
use softsync_store::RoomStore;

use crate::cli::{ReplayArgs, StoreAction};
use crate::Failure;

fn open(target: &str) -> Result<Box<dyn RoomStore>, Failure> {
    softsync_store::open(target).map_err(|e| Failure::usage(e.to_string()))
}

fn describe(r: &RecordingInfo) -> String {
    format!(
        "recording {} started_unix_ms={} seconds={:.3} events={} states={} host={}",
        r.id,
        r.started_unix_ms,
        (r.end_us.saturating_sub(r.start_us)) as f64 / 1e6,
        r.events,
        r.states,
        r.host
    )
}

/// `softsync store …`.
pub fn store(action: StoreAction) -> Result<ExitCode, Failure> {
    match action {
        StoreAction::List { store } => {
            let mut s = open(&store)?;
            let list = s
                .recordings()
                .map_err(|e| Failure::runtime(e.to_string()))?;
            if list.is_empty() {
                println!("no recordings in {store}");
            }
            for r in &list {
                println!("{}", describe(r));
            }
        }
        StoreAction::Delete { store, session } => {
            let mut s = open(&store)?;
            if !s
                .delete_recording(session)
                .map_err(|e| Failure::runtime(e.to_string()))?
            {
                return Err(Failure::usage(format!("no recording {session} in {store}")));
            }
            println!("deleted recording {session} (the room's state is kept)");
        }
        StoreAction::Prune { store, older_than } => {
            let mut s = open(&store)?;
            let now_ms = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_millis() as i64);
            let gone = softsync_store::prune_recordings(
                s.as_mut(),
                now_ms - older_than.as_millis() as i64,
            )
            .map_err(|e| Failure::runtime(e.to_string()))?;
            println!(
                "pruned {} recordings (the room's state is kept)",
                gone.len()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The avatar parts (object ids and classes) of peer `p` in a recording, from its `appear`
/// events; an error names the peers it has avatars of.
pub(crate) fn avatar_of(
    s: &mut dyn RoomStore,
    info: &RecordingInfo,
    p: u64,
) -> Result<Vec<(u32, u16)>, Failure> {
    let events = s
        .recording_events(info.id, info.start_us, info.end_us.saturating_add(1))
        .map_err(|e| Failure::runtime(e.to_string()))?;
    let mut parts: std::collections::BTreeMap<u64, Vec<(u32, u16)>> = Default::default();
    for e in events.iter().filter(|e| e.kind == "appear") {
        let class = serde_json::from_str::<serde_json::Value>(&e.data)
            .ok()
            .and_then(|v| v.get("class").and_then(serde_json::Value::as_u64))
            .and_then(|c| u16::try_from(c).ok());
        let avatar = class.filter(|c| {
            softsync_peer::scene::Kind::of_class(softsync_net::ClassId(*c)).is_avatar()
        });
        if let (Some(class), Some(peer), Some(object)) = (avatar, e.peer, e.object) {
            parts.entry(peer).or_default().push((object, class));
        }
    }
    match parts.remove(&p) {
        Some(v) => Ok(v),
        None => Err(Failure::usage(format!(
            "--as {p}: recording {} has no avatar of that peer (it has avatars of {})",
            info.id,
            if parts.is_empty() {
                "nobody: recorded before avatars were named, or with none".to_owned()
            } else {
                parts
                    .keys()
                    .map(u64::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        ))),
    }
}

/// One recorded object of a dump line (its particles too, or only its pose).
fn object_json(s: &RecState, particles: bool) -> serde_json::Value {
    let mut v = serde_json::json!({
        "id": s.object.0,
        "class": s.class.0,
        "pos": s.state.pos.to_array(),
        "rot": s.state.rot.to_array(),
    });
    if particles {
        let ps: Vec<[f32; 3]> = s.state.particles.iter().map(|p| p.to_array()).collect();
        v["particles"] = serde_json::json!(ps);
    }
    v
}

fn dump_line(t_s: f64, room_us: u64, states: &[RecState], view: Option<(u64, &[u32])>) -> String {
    let objects: Vec<serde_json::Value> = states.iter().map(|s| object_json(s, true)).collect();
    let mut line =
        serde_json::json!({"t": t_s, "room_s": room_us as f64 / 1e6, "objects": objects});
    if let Some((peer, parts)) = view {
        // the point of view: that peer's head and hands, as recorded at this moment
        let parts: Vec<serde_json::Value> = states
            .iter()
            .filter(|s| parts.contains(&s.object.0))
            .map(|s| object_json(s, false))
            .collect();
        line["as"] = serde_json::json!({"peer": peer, "parts": parts});
    }
    line.to_string()
}

fn csv_field(s: &str) -> String {
    format!("\"{}\"", s.replace('"', "\"\""))
}

/// `softsync replay …`.
pub fn replay(a: ReplayArgs) -> Result<ExitCode, Failure> {
    let mut s = open(&a.store)?;
    let fail = |e: softsync_store::StoreError| Failure::runtime(e.to_string());
    let list = s.recordings().map_err(fail)?;
    if a.list {
        if list.is_empty() {
            println!("no recordings in {}", a.store);
        }
        for r in &list {
            println!("{}", describe(r));
        }
        return Ok(ExitCode::SUCCESS);
    }
    let info = match a.recording {
        Some(id) => list.iter().find(|r| r.id == id).cloned().ok_or_else(|| {
            Failure::usage(format!(
                "no recording {id} in {} (softsync replay --list)",
                a.store
            ))
        })?,
        None => list
            .last()
            .cloned()
            .ok_or_else(|| Failure::usage(format!("no recordings in {}", a.store)))?,
    };
    let us = |secs: f64| info.start_us + (secs * 1e6) as u64;
    let from = us(a.from).min(info.end_us);
    let to = a.to.map_or(info.end_us, us).min(info.end_us);
    let rel = |t: u64| t.saturating_sub(info.start_us) as f64 / 1e6;
    if a.serve.is_some() || a.desktop {
        let room = a.serve.clone().unwrap_or_else(|| "replay".to_owned());
        return crate::replay_room::serve(&a, &room, s, &info, from);
    }
    if let Some(dir) = &a.export {
        std::fs::create_dir_all(dir)
            .map_err(|e| Failure::usage(format!("--export {}: {e}", dir.display())))?;
        let mut ev = String::from("t_s,kind,peer,object,data\n");
        for e in s.recording_events(info.id, from, to + 1).map_err(fail)? {
            ev += &format!(
                "{:.6},{},{},{},{}\n",
                rel(e.room_us),
                e.kind,
                e.peer.map_or(String::new(), |p| p.to_string()),
                e.object.map_or(String::new(), |o| o.to_string()),
                csv_field(&e.data)
            );
        }
        let mut tr = String::from("t_s,object,class,px,py,pz,qx,qy,qz,qw,particles\n");
        for st in s.recording_states(info.id, from, to + 1).map_err(fail)? {
            let (p, q) = (st.state.pos, st.state.rot);
            tr += &format!(
                "{:.6},{},{},{},{},{},{},{},{},{},{}\n",
                rel(st.room_us),
                st.object.0,
                st.class.0,
                p.x,
                p.y,
                p.z,
                q.x,
                q.y,
                q.z,
                q.w,
                st.state.particles.len()
            );
        }
        for (name, text) in [("events.csv", ev), ("tracks.csv", tr)] {
            std::fs::write(dir.join(name), text)
                .map_err(|e| Failure::runtime(format!("{name}: {e}")))?;
        }
        println!("exported recording {} to {}", info.id, dir.display());
        return Ok(ExitCode::SUCCESS);
    }
    let mut dump = match &a.dump {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p)
                .map_err(|e| Failure::usage(format!("--dump {}: {e}", p.display())))?,
        )),
        None => None,
    };
    println!("{}", describe(&info));
    let view = match a.as_peer {
        Some(p) => {
            let parts: Vec<u32> = avatar_of(s.as_mut(), &info, p)?
                .into_iter()
                .map(|(id, _)| id)
                .collect();
            println!(
                "as peer {p}: avatar objects {}",
                parts
                    .iter()
                    .map(u32::to_string)
                    .collect::<Vec<_>>()
                    .join(",")
            );
            Some((p, parts))
        }
        None => None,
    };
    let t0 = std::time::Instant::now();
    let at_start = s.recording_state_at(info.id, from).map_err(fail)?;
    println!(
        "seek t={:.3} objects={} ms={:.1}",
        rel(from),
        at_start.len(),
        t0.elapsed().as_secs_f64() * 1e3
    );
    let events = s.recording_events(info.id, from, to + 1).map_err(fail)?;
    let step_us = (1e6 / a.dump_hz) as u64;
    let mut next_dump = from;
    let mut next_event = 0;
    let (mut dumps, wall) = (0u64, std::time::Instant::now());
    loop {
        // the recorded time this moment of playback shows
        let shown = if a.speed == 0.0 {
            to
        } else {
            from + (wall.elapsed().as_secs_f64() * a.speed * 1e6) as u64
        };
        // events and dumps in recorded-time order up to it
        loop {
            let ev = events
                .get(next_event)
                .filter(|e| e.room_us <= shown.min(to));
            let dump_due = dump.is_some() && next_dump <= shown.min(to);
            match (ev, dump_due) {
                (Some(e), d) if !d || e.room_us <= next_dump => {
                    println!(
                        "replay t={:.3} kind={} peer={} object={} data={}",
                        rel(e.room_us),
                        e.kind,
                        e.peer.map_or("-".into(), |p| p.to_string()),
                        e.object.map_or("-".into(), |o| o.to_string()),
                        e.data
                    );
                    next_event += 1;
                }
                (_, true) => {
                    let states = s.recording_state_at(info.id, next_dump).map_err(fail)?;
                    if let Some(f) = &mut dump {
                        let v = view.as_ref().map(|(p, parts)| (*p, parts.as_slice()));
                        writeln!(f, "{}", dump_line(rel(next_dump), next_dump, &states, v))
                            .map_err(|e| Failure::runtime(format!("--dump: {e}")))?;
                    }
                    dumps += 1;
                    next_dump += step_us;
                }
                _ => break,
            }
        }
        if shown >= to {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if let Some(mut f) = dump {
        f.flush()
            .map_err(|e| Failure::runtime(format!("--dump: {e}")))?;
    }
    println!(
        "replay done: events={} dumps={} seconds={:.3} wall_s={:.3}",
        next_event,
        dumps,
        rel(to) - rel(from),
        wall.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}
