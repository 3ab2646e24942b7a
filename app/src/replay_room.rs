//! `softsync replay STORE --serve ROOM`: a recorded session played back as a room that
//! spectators join, like any room (a desktop or VR peer, a bot; in a keyed room with the key
//! or a token).
//!
//! The host here is a puppeteer ([`softsync_peer::Peer::set_replaying`]): the room opens
//! empty, from the scene the store keeps, with its clock at the recording's time played;
//! then, 20 times a second, the room at the moment played ([`Playback::room_at`]) is made
//! the room's: objects the recording has and the room does not appear (built through their
//! logs, under fresh ids, locked), a tear the recording reaches is appended to its object's
//! log, a cut's pieces appear and their parent goes, and every object shows its recorded
//! state. A seek backwards rebuilds what changed since. Spectators steer it with a
//! [`ReplayControl`] message (pause, seek, speed); a retained [`ReplayClock`] says where it
//! stands.

// The I/O layer: playback is paced on this machine's clock.
#![allow(clippy::disallowed_methods)]

use std::collections::BTreeMap;
use std::process::ExitCode;
use std::time::Duration;

use softsync_bevy::{Room, RoomOptions};
use softsync_net::wire::TopologyEvent;
use softsync_net::{Delivery, Instant, KeptObject, MessageTarget, NetId};
use softsync_peer::messages::{ReplayClock, ReplayControl};
use softsync_peer::scene::{Kind, Scene};
use softsync_store::playback::Playback;
use softsync_store::RoomStore;

use crate::cli::ReplayArgs;
use crate::Failure;

/// How often the room is set to the recording (its replication rate).
const TICK: Duration = Duration::from_millis(50);

/// A recorded object as the room has it.
struct Live {
    id: NetId,
    log: Vec<TopologyEvent>,
}

/// Where playback stands: the recorded time shown, on this machine's clock.
struct Position {
    /// Recorded time (µs) at `since`.
    at_us: u64,
    since: std::time::Instant,
    speed: f64,
    paused: bool,
}

impl Position {
    fn now_us(&self, end_us: u64) -> u64 {
        if self.paused {
            return self.at_us.min(end_us);
        }
        let gone = self.since.elapsed().as_secs_f64() * self.speed * 1e6;
        (self.at_us + gone as u64).min(end_us)
    }

    fn rebase(&mut self, end_us: u64) {
        self.at_us = self.now_us(end_us);
        self.since = std::time::Instant::now();
    }
}

/// `softsync replay STORE --serve ROOM …`.
pub fn serve(
    a: &ReplayArgs,
    room_name: &str,
    mut store: Box<dyn RoomStore>,
    info: &softsync_store::record::RecordingInfo,
    from_us: u64,
) -> Result<ExitCode, Failure> {
    let fail = |e: softsync_store::StoreError| Failure::runtime(e.to_string());
    let playback = Playback::open(store.as_mut(), info.id).map_err(fail)?;
    let info = playback.info().clone();
    // `--as PEER`: the recorded id of that peer's head, which a spectator's view follows
    let follow_head = match a.as_peer {
        Some(p) => crate::replay::avatar_of(store.as_mut(), &info, p)?
            .into_iter()
            .find(|(_, class)| Kind::of_class(softsync_net::ClassId(*class)) == Kind::HEAD)
            .map(|(id, _)| NetId(id)),
        None => None,
    };
    let scene = stored_scene(store.as_mut())?;
    let mut opts = RoomOptions::host(room_name.to_owned());
    opts.bind = if a.desktop && a.serve.is_none() {
        std::net::SocketAddr::from(([127, 0, 0, 1], 0))
    } else {
        a.bind
    };
    opts.room_key = crate::room_key(a.room_key_file.as_deref())?;
    opts.spawn_scene = false;
    opts.peer.avatar = false;
    let mut room = Room::open(scene, opts).map_err(|e| Failure::runtime(e.to_string()))?;
    room.peer.set_replaying(true);
    let now = room.now();
    room.peer
        .replay_room_time(now, Duration::from_micros(from_us))
        .map_err(|e| Failure::runtime(e.to_string()))?;
    println!(
        "serving recording {} as room {room_name} at {} ({:.3} s from {:.3} s)",
        info.id,
        room.signal_url(),
        (info.end_us.saturating_sub(info.start_us)) as f64 / 1e6,
        from_us.saturating_sub(info.start_us) as f64 / 1e6
    );
    // `--desktop`: a desktop peer of ours joins and shows it; serving ends with its window
    let mut viewer = if a.desktop {
        let exe =
            std::env::current_exe().map_err(|e| Failure::runtime(format!("--desktop: {e}")))?;
        let mut cmd = std::process::Command::new(exe);
        cmd.args(["join", "--desktop", "--room", room_name, "--signal"])
            .arg(room.signal_url())
            .args(["--no-avatar", "--quiet"])
            .args(&a.viewer_arg);
        if let Some(k) = &a.room_key_file {
            cmd.arg("--room-key-file").arg(k);
        }
        Some(
            cmd.spawn()
                .map_err(|e| Failure::runtime(format!("--desktop: the viewer: {e}")))?,
        )
    } else {
        None
    };
    let mut pos = Position {
        at_us: from_us,
        since: std::time::Instant::now(),
        speed: a.speed.clamp(0.1, 16.0),
        paused: false,
    };
    let mut live: BTreeMap<NetId, Live> = BTreeMap::new();
    let (mut next_tick, mut next_clock) = (std::time::Instant::now(), std::time::Instant::now());
    let mut ended_at: Option<std::time::Instant> = None;
    let mut clock_dirty = true;
    loop {
        room.network_in()
            .map_err(|e| Failure::runtime(e.to_string()))?;
        let now = room.now();
        for e in room.drain_events().collect::<Vec<_>>() {
            if let softsync_peer::Event::Room(softsync_net::Event::Message(m)) = &e {
                if let Some(Ok(c)) = room.peer.decode::<ReplayControl>(m) {
                    control(&mut pos, &c, &info, m.from.0);
                    clock_dirty = true;
                }
                continue;
            }
            if let Some(line) = room_line(&e) {
                println!("replay-room {line}");
            }
        }
        if std::time::Instant::now() >= next_tick {
            next_tick += TICK;
            let t = pos.now_us(info.end_us);
            let want = playback.room_at(store.as_mut(), t).map_err(fail)?;
            sync(&mut room, now, &mut live, want);
            if let Some(v) = viewer.as_mut() {
                if let Ok(Some(status)) = v.try_wait() {
                    println!("replay-room the viewer closed ({status})");
                    break;
                }
            }
            if t >= info.end_us && !pos.paused && viewer.is_none() {
                let end = *ended_at.get_or_insert_with(|| {
                    println!("replay-room ended t={:.3}", rel(&info, t));
                    std::time::Instant::now()
                });
                if end.elapsed().as_secs_f64() >= a.linger {
                    break;
                }
            } else {
                ended_at = None;
            }
        }
        if clock_dirty || std::time::Instant::now() >= next_clock {
            next_clock = std::time::Instant::now() + Duration::from_secs(1);
            clock_dirty = false;
            let clock = ReplayClock {
                t_s: rel(&info, pos.now_us(info.end_us)),
                length_s: rel(&info, info.end_us),
                paused: pos.paused,
                speed: pos.speed,
                follow: follow_head.and_then(|h| live.get(&h)).map(|l| l.id),
            };
            if let Err(e) = room.send(MessageTarget::Everyone, Delivery::Retained, &clock) {
                eprintln!("replay clock not sent: {e}");
            }
        }
        room.flush();
        std::thread::sleep(Duration::from_millis(4));
    }
    room.leave();
    println!("replay-room done");
    Ok(ExitCode::SUCCESS)
}

fn rel(info: &softsync_store::record::RecordingInfo, t_us: u64) -> f64 {
    t_us.saturating_sub(info.start_us) as f64 / 1e6
}

/// A spectator's [`ReplayControl`]: applied and said.
fn control(
    pos: &mut Position,
    c: &ReplayControl,
    info: &softsync_store::record::RecordingInfo,
    from: u64,
) {
    pos.rebase(info.end_us);
    if let Some(p) = c.pause {
        pos.paused = p;
    }
    if let Some(s) = c.speed.filter(|s| s.is_finite()) {
        pos.speed = s.clamp(0.1, 16.0);
    }
    if let Some(s) = c.seek_s.filter(|s| s.is_finite()) {
        let length = info.end_us.saturating_sub(info.start_us);
        pos.at_us = info.start_us + ((s.max(0.0) * 1e6) as u64).min(length);
    }
    println!(
        "replay-room control from={from} t={:.3} paused={} speed={}",
        rel(info, pos.at_us),
        pos.paused,
        pos.speed
    );
}

/// The room made the recording's at one moment: what is gone goes, what is new appears,
/// logs grow (or, where the recording's log is not the room's plus entries, the object is
/// built again), and every object shows its recorded state.
fn sync(room: &mut Room, now: Instant, live: &mut BTreeMap<NetId, Live>, want: Vec<KeptObject>) {
    let wanted: BTreeMap<NetId, KeptObject> = want.into_iter().map(|o| (o.id, o)).collect();
    let gone: Vec<NetId> = live
        .keys()
        .filter(|id| !wanted.contains_key(id))
        .copied()
        .collect();
    for rec in gone {
        if let Some(l) = live.remove(&rec) {
            room.peer.replay_remove(now, l.id);
        }
    }
    for (rec, o) in &wanted {
        let grows = live.get(rec).map(|l| {
            o.topology.starts_with(&l.log)
                && o.topology[l.log.len()..]
                    .iter()
                    .all(|e| !matches!(e, TopologyEvent::Cut { .. }))
        });
        match grows {
            Some(true) => {
                if let Some(l) = live.get_mut(rec) {
                    for e in o.topology[l.log.len()..].iter().copied() {
                        if let Err(err) = room.peer.replay_entry(now, l.id, e) {
                            eprintln!("{err}");
                        }
                        l.log.push(e);
                    }
                }
            }
            Some(false) => {
                if let Some(l) = live.remove(rec) {
                    room.peer.replay_remove(now, l.id);
                }
            }
            None => {}
        }
        if !live.contains_key(rec) {
            match room.peer.replay_spawn(now, o) {
                Ok(id) => {
                    live.insert(
                        *rec,
                        Live {
                            id,
                            log: o.topology.clone(),
                        },
                    );
                }
                Err(e) => {
                    eprintln!("{e}");
                    continue;
                }
            }
        }
        if let Some(l) = live.get(rec) {
            room.peer.replay_show(now, l.id, &o.state);
        }
    }
}

/// The scene the store keeps for its room.
fn stored_scene(store: &mut dyn RoomStore) -> Result<Scene, Failure> {
    let fail = |e: softsync_store::StoreError| Failure::runtime(e.to_string());
    let id = store
        .identity()
        .map_err(fail)?
        .ok_or_else(|| Failure::usage("the store keeps no room (and so no scene to replay in)"))?;
    let bundle = store
        .scene(&id.scene_sha256)
        .map_err(fail)?
        .ok_or_else(|| Failure::runtime("the store names a scene it does not keep"))?;
    let cache = softsync_peer::scene::cache::default_scene_cache();
    Scene::from_bundle(&bundle, &cache).map_err(Failure::runtime)
}

/// A line for a room event worth saying (who came and went).
fn room_line(e: &softsync_peer::Event) -> Option<String> {
    use softsync_net::Event as Net;
    match e {
        softsync_peer::Event::Room(Net::PeerJoined(p)) => Some(format!("spectator-joined {}", p.0)),
        softsync_peer::Event::Room(Net::PeerLeft(p)) => Some(format!("spectator-left {}", p.0)),
        softsync_peer::Event::Warning(w) => Some(format!("warning {w}")),
        _ => None,
    }
}
