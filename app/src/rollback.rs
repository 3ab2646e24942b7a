//! `softsync host|join --sync rollback`: a headless peer of a rollback room on the real path
//! (signaling, WebRTC data channels, the optional seeded conditioner), its loop at the fixed
//! rate, its lines for people and tests:
//! - `epoch n=N frame=F players=A,B,…` when an epoch starts here;
//! - `grab object=K` / `release object=K` when our right hand takes or lets go of the scene's
//!   object K (in our own view);
//! - `rollback.check epoch=N frame=F checksum=X` for every confirmed frame that is a multiple
//!   of 60 (two processes agree when their lines for an epoch and frame are equal: a new
//!   epoch restarts the world at its frame, so a frame past that one has another state in
//!   each epoch, and a peer may have confirmed it in the old one before it switched);
//! - a stats line a second, and `rollback.summary …` at the end;
//! - with `--dump FILE`, a dump line at `--dump-hz` and one at the end, in the state-sync
//!   peer's format (`softsync_peer::dump`): the world as this peer shows it (its newest,
//!   possibly predicted, frame), objects numbered in the scene's order, owned by nobody, then
//!   every player's head and hands (`head`, `hand`, owned by their player) where its last
//!   input put them.

use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant as WallInstant};

use softsync_bevy::{RollbackHooks, RollbackRoom, RoomOptions, TickInfo};
use softsync_net::Event;
use softsync_peer::dump::{Dump, DumpLine, DumpObject};
use softsync_peer::Scene;
use softsync_rollback::script::{ScriptedPlayer, SqueezeThrow};
use softsync_rollback::{PlayerInput, RollbackConfig, RollbackEvent, RollbackPeer};

use crate::cli::{FrontEnd, PeerArgs};
use crate::Failure;

/// What a rollback bot does.
enum Script {
    Idle,
    /// The squeeze-and-throw motion, starting with this object (default: from our id).
    Squeeze(Option<usize>),
    /// A script of the bot language (over the front end's device, if any).
    Language(Box<softsync_peer::Bot>),
}

/// Flags a rollback peer cannot honour: refused with the reason, never ignored.
fn refuse_unhonoured(a: &PeerArgs) -> Result<(), Failure> {
    let why = if a.voice.is_some() {
        Some("--voice…: a rollback room has no voice yet (it is the state-sync room's)")
    } else if a.presence.is_some() {
        Some("--name/--colour: a rollback room announces no presence yet")
    } else if a.uplink_bytes_per_s.is_some() {
        Some("--uplink-kbps: ggrs sends every input to every player; nothing to budget")
    } else {
        None
    };
    match why {
        Some(w) => Err(Failure::usage(format!("--sync rollback: {w}"))),
        None => Ok(()),
    }
}

/// One dump line of what a rollback peer shows at `now`.
fn dump_line(peer: &RollbackPeer, now: softsync_net::Instant) -> Option<DumpLine> {
    let world = peer.world()?;
    let session = peer.session();
    let scene = peer.scene();
    let log = world.topology_log();
    let mut objects: Vec<DumpObject> = world
        .objects()
        .iter()
        .enumerate()
        .filter_map(|(i, o)| {
            let (pos, rot) = world.object_pose(i)?;
            // soft bodies: the log entries that changed it and its rest mesh's hash, as a
            // state-sync dump has them (equal hashes: the identical torn or cut mesh)
            let soft = match o.body {
                softsync_peer::LocalBody::Soft(h) => world.soft_bodies().get(h),
                _ => None,
            };
            let topology = soft.map(|b| {
                let mesh = softsync_softbody::Mesh {
                    positions: b.rest_vertices().to_vec(),
                    normals: None,
                    triangles: b.welded().triangles.clone(),
                };
                format!(
                    "{:016x}",
                    softsync_softbody::cut::topology_hash(&mesh, 1e-5)
                )
            });
            let entries = log.iter().filter(|e| e.object as usize == i).count();
            Some(DumpObject {
                id: u32::try_from(i).ok()?,
                kind: scene.name_of(o.kind).to_owned(),
                owner: 0,
                pos: pos.to_array(),
                rot: rot.to_array(),
                particles: world
                    .particles(i)
                    .unwrap_or_default()
                    .iter()
                    .map(|p| p.to_array())
                    .collect(),
                src: None,
                src_from: None,
                log: soft.map(|_| entries as u32),
                topology,
                holders: Vec::new(),
            })
        })
        .collect();
    // every player's head and hands where its last input put them, as a state-sync dump
    // lists avatar parts: kind `head`/`hand`, owned by their player
    let first = objects.len();
    for (i, who) in world.players().iter().enumerate() {
        let Some(d) = world.player_input(i).map(|p| p.to_device()) else {
            continue;
        };
        for (k, (part, pose)) in [("head", d.head), ("hand", d.hands[0]), ("hand", d.hands[1])]
            .into_iter()
            .enumerate()
        {
            let Some((pos, rot)) = pose else { continue };
            objects.push(DumpObject {
                id: u32::try_from(first + 3 * i + k).unwrap_or(u32::MAX),
                kind: part.to_owned(),
                owner: who.0,
                pos: pos.to_array(),
                rot: rot.to_array(),
                particles: Vec::new(),
                src: None,
                src_from: None,
                log: None,
                topology: None,
                holders: Vec::new(),
            });
        }
    }
    let t = now.as_secs_f64();
    Some(DumpLine {
        t,
        state_t: t,
        wall_ms: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64),
        room_s: session.room_time(now).map(|d| d.as_secs_f64()),
        peer: session.local_id().0,
        host: session.host_id().map(|h| h.0),
        term: session.term().0,
        members: session.members().keys().map(|p| p.0).collect(),
        up_bytes: session.stats().up.bytes,
        down_bytes: session.stats().down.bytes,
        objects,
        hands: Vec::new(),
    })
}

/// The lines a rollback peer prints and its dump, after each tick (on the room's thread).
struct Reporter {
    quiet: bool,
    /// The time of the last tick.
    now: softsync_net::Instant,
    checked: i32,
    checked_epoch: u32,
    holding: Option<usize>,
    last_line: WallInstant,
    last_up: (WallInstant, u64),
    dump: Option<Dump>,
    dump_every: Duration,
    next_dump: WallInstant,
    /// Why the peer cannot go on, for the main thread.
    failure: Arc<Mutex<Option<Failure>>>,
    /// Welcomed (or hosting).
    joined: Arc<AtomicBool>,
}

impl Reporter {
    fn write_dump(&mut self, peer: &RollbackPeer) {
        let Some(d) = self.dump.as_mut() else { return };
        // nothing to show before the first epoch's world
        let Some(line) = dump_line(peer, self.now) else {
            return;
        };
        if let Err(e) = d.write(&line) {
            eprintln!("warning: --dump: {e}; no more dump lines");
            self.dump = None;
        }
    }

    fn after_tick(&mut self, peer: &RollbackPeer, info: &TickInfo<'_>) {
        self.now = info.now;
        // our right hand's grabs and releases, in our own (predicted) view
        let me = peer.me();
        let held = peer.epoch().and_then(|e| {
            let i = e.players.iter().position(|p| *p == me)?;
            peer.world()?.held(i, 1)
        });
        if held != self.holding {
            match (self.holding, held) {
                (_, Some(k)) => println!("grab object={k}"),
                (Some(k), None) => println!("release object={k}"),
                (None, None) => {}
            }
            self.holding = held;
        }
        for e in info.events {
            match e {
                RollbackEvent::EpochStarted { n, frame, players } => {
                    let p: Vec<String> = players.iter().map(|p| p.0.to_string()).collect();
                    println!("epoch n={n} frame={frame} players={}", p.join(","));
                }
                RollbackEvent::Desync { frame, peer } => {
                    println!("desync frame={frame} peer={}", peer.0)
                }
                RollbackEvent::Repaired { epoch, ms } => {
                    println!("desync repaired epoch={epoch} ms={ms:.0}")
                }
                RollbackEvent::PlayerDisconnected(p) => println!("player {} disconnected", p.0),
                RollbackEvent::Warning(w) => eprintln!("warning: {w}"),
                RollbackEvent::Room(Event::Joined { host, .. }) => {
                    self.joined.store(true, Ordering::SeqCst);
                    println!("joined: host is peer {}", host.0)
                }
                RollbackEvent::Room(Event::Refused { reason }) => {
                    self.fail(Failure::connect(refusal(reason)));
                }
                RollbackEvent::Room(Event::Dropped { reason, .. }) => {
                    self.fail(Failure::runtime(format!("dropped from the room: {reason}")));
                }
                RollbackEvent::Room(Event::PeerJoined(p)) => println!("peer {} joined", p.0),
                RollbackEvent::Room(Event::PeerLeft(p)) => println!("peer {} left", p.0),
                RollbackEvent::Room(Event::HostChanged { host, .. }) => {
                    println!("host is now peer {}", host.0)
                }
                RollbackEvent::Room(_) => {}
            }
        }
        if let (Some(c), Some((n, start))) =
            (peer.confirmed_frame(), peer.epoch().map(|e| (e.n, e.frame)))
        {
            if n != self.checked_epoch {
                // the new epoch's timeline from its frame on: checked again, under its number
                self.checked_epoch = n;
                self.checked = self.checked.min(start);
            }
            let mut f = (self.checked + 1).max(c - 120);
            f = (f + 59) / 60 * 60;
            while f <= c {
                if let Some(sum) = peer.checksum_at(f) {
                    println!("rollback.check epoch={n} frame={f} checksum={sum:032x}");
                }
                self.checked = f;
                f += 60;
            }
        }
        if !self.quiet && self.last_line.elapsed() >= Duration::from_secs(1) {
            self.last_line = WallInstant::now();
            let s = peer.stats();
            let up = (info.up_bytes - self.last_up.1) as f64
                / self.last_up.0.elapsed().as_secs_f64().max(1e-3);
            self.last_up = (WallInstant::now(), info.up_bytes);
            println!(
                "stats up={up:.0}B/s frame={} confirmed={} epoch={} players={} rollbacks={} resimulated={} stalled={} desyncs={} ggrs_bytes={}",
                peer.world().map_or(-1, |w| w.frame()),
                peer.confirmed_frame().unwrap_or(-1),
                peer.epoch().map_or(0, |e| e.n),
                peer.epoch().map_or(0, |e| e.players.len()),
                s.rollbacks,
                s.resimulated,
                s.stalled_ticks,
                s.desyncs,
                s.ggrs_bytes
            );
        }
        if self.dump.is_some() && WallInstant::now() >= self.next_dump {
            self.next_dump = WallInstant::now() + self.dump_every;
            self.write_dump(peer);
        }
    }

    fn fail(&self, f: Failure) {
        let mut slot = self.failure.lock().unwrap_or_else(|e| e.into_inner());
        slot.get_or_insert(f);
    }

    /// After leaving: the last dump line and the summary.
    fn at_end(mut self, peer: &RollbackPeer) {
        self.write_dump(peer);
        let s = peer.stats();
        let p95 = |v: &[f32]| {
            let mut v = v.to_vec();
            v.sort_by(f32::total_cmp);
            v.get(v.len() * 95 / 100).copied().unwrap_or(0.0)
        };
        let p99 = {
            let mut v = s.frame_ms.clone();
            v.sort_by(f32::total_cmp);
            v.get(v.len() * 99 / 100).copied().unwrap_or(0.0)
        };
        println!(
            "rollback.summary frames={} resimulated={} rollbacks={} desyncs={} epochs={} epochs_refused={} switch_ms_max={:.0} frame_ms_p95={:.2} frame_ms_p99={p99:.2} save_us={:.1} load_us={:.1} ggrs_bytes={} repairs={} repair_ms_max={:.0} corrections={} correction_mm_p95={:.1}",
            s.frames,
            s.resimulated,
            s.rollbacks,
            s.desyncs,
            s.epochs,
            s.epochs_refused,
            s.switch_ms_max,
            p95(&s.frame_ms),
            s.save_ns as f64 / s.saves.max(1) as f64 / 1e3,
            s.load_ns as f64 / s.rollbacks.max(1) as f64 / 1e3,
            s.ggrs_bytes,
            s.repairs,
            s.repair_ms_max,
            s.correction_mm.len(),
            p95(&s.correction_mm),
        );
    }
}

/// Run a rollback peer until `--duration`, a signal, or a refusal: headless, or drawn on the
/// desktop or in a headset (the same room on its own thread; the front end's device is the
/// input unless a bot drives it).
pub fn run(
    a: &PeerArgs,
    front: FrontEnd,
    scene: Scene,
    opts: RoomOptions,
    dump: Option<Dump>,
    bot: Option<softsync_peer::Bot>,
) -> Result<ExitCode, Failure> {
    refuse_unhonoured(a)?;
    let rcfg = RollbackConfig {
        dt_s: (1.0 / a.sim_hz) as f32,
        ..RollbackConfig::default()
    };
    let script = match a.bot.as_deref() {
        None => None,
        Some("idle") => Some(Script::Idle),
        Some(b) if b == "squeeze" || crate::throw_slot(b).is_some() => {
            Some(Script::Squeeze(crate::throw_slot(b).flatten()))
        }
        Some(other) => match bot {
            Some(b) => Some(Script::Language(Box::new(b))),
            None => {
                return Err(Failure::usage(format!(
                    "--bot {other:?}: not a script, a built-in or a file"
                )))
            }
        },
    };
    let failure = Arc::new(Mutex::new(None));
    let joined = Arc::new(AtomicBool::new(a.host));
    let reporter = Arc::new(Mutex::new(None::<Reporter>));
    *reporter.lock().unwrap_or_else(|e| e.into_inner()) = Some(Reporter {
        quiet: a.quiet,
        now: softsync_net::Instant::ZERO,
        checked: -1,
        checked_epoch: 0,
        holding: None,
        last_line: WallInstant::now(),
        last_up: (WallInstant::now(), 0),
        dump,
        dump_every: Duration::from_secs_f64(1.0 / a.dump_hz.max(0.01)),
        next_dump: WallInstant::now(),
        failure: failure.clone(),
        joined: joined.clone(),
    });
    let mut hooks = RollbackHooks::default();
    {
        let r1 = reporter.clone();
        hooks.after_tick = Some(Box::new(move |peer, info| {
            if let Some(r) = r1.lock().unwrap_or_else(|e| e.into_inner()).as_mut() {
                r.after_tick(peer, info);
            }
        }));
        let reporter = reporter.clone();
        hooks.at_end = Some(Box::new(move |peer| {
            if let Some(r) = reporter.lock().unwrap_or_else(|e| e.into_inner()).take() {
                r.at_end(peer);
            }
        }));
    }
    // the bot's hands (else: the front end's device, or none)
    let mut squeeze: Option<SqueezeThrow> = None;
    let idle =
        matches!(script, Some(Script::Idle)) || (script.is_none() && front == FrontEnd::Headless);
    if idle {
        hooks.input = Some(Box::new(|_, _, _| PlayerInput::default()));
    } else if let Some(Script::Squeeze(slot)) = script {
        let slot_cell = Arc::new(Mutex::new(slot));
        hooks.input = Some(Box::new(move |peer, _, _| {
            let (Some(w), me) = (peer.world(), peer.me()) else {
                return PlayerInput::default();
            };
            let s = squeeze.get_or_insert_with(|| {
                let slot = *slot_cell.lock().unwrap_or_else(|e| e.into_inner());
                SqueezeThrow::new(me, slot.unwrap_or((me.0 % 5) as usize))
            });
            s.input(w)
        }));
    } else if let Some(Script::Language(b)) = script {
        let mut player = ScriptedPlayer::new(*b);
        hooks.input = Some(Box::new(move |peer, device, now| {
            let input = player.input(now, peer, device);
            let me = peer.me().0;
            while let Some(msg) = player.poll_message() {
                println!("bot peer={me} t={:.2} {msg}", now.as_secs_f64());
            }
            input
        }));
    }
    let mut room = RollbackRoom::open(scene, opts, rcfg, hooks).map_err(|e| Failure {
        code: e.exit_code(),
        msg: e.to_string(),
    })?;
    let me = room.me();
    if let Some((c, after)) = room.contact() {
        println!(
            "connected to peer {} after {:.0} ms",
            c.0,
            after.as_secs_f64() * 1e3
        );
    }
    if room.runs_signaling() {
        println!("signaling on {}", room.signal_url());
    }
    println!(
        "{} room={} peer={} signal={} sync=rollback",
        if a.host { "hosting" } else { "joining" },
        a.room,
        me.0,
        room.signal_url()
    );
    let started = WallInstant::now();
    let outcome = match front {
        FrontEnd::Headless => {
            let stop = Arc::new(AtomicBool::new(false));
            {
                let stop = stop.clone();
                if let Err(e) = ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)) {
                    eprintln!("warning: no signal handler ({e})");
                }
            }
            while !stop.load(Ordering::SeqCst)
                && a.duration.is_none_or(|d| started.elapsed() < d)
                && room.running()
                && failure.lock().unwrap_or_else(|e| e.into_inner()).is_none()
            {
                if !joined.load(Ordering::SeqCst) && started.elapsed() > a.connect_timeout {
                    let f = Failure::connect("no welcome from the room's host in time");
                    failure
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .get_or_insert(f);
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            room.leave();
            Ok(ExitCode::SUCCESS)
        }
        #[cfg(feature = "desktop")]
        front => run_front(a, front, room, failure.clone(), joined.clone()),
        #[cfg(not(feature = "desktop"))]
        _ => Err(Failure::usage("this front end is not in this build")),
    };
    let failed = failure.lock().unwrap_or_else(|e| e.into_inner()).take();
    match failed {
        Some(f) => Err(f),
        None => outcome,
    }
}

/// A desktop or VR peer of a rollback room: bevy draws the room's newest frame, the front end
/// writes its device to `LocalDevice`, the plugin passes it to the room's thread.
#[cfg(feature = "desktop")]
fn run_front(
    a: &PeerArgs,
    front: FrontEnd,
    room: RollbackRoom,
    failure: Arc<Mutex<Option<Failure>>>,
    joined: Arc<AtomicBool>,
) -> Result<ExitCode, Failure> {
    use bevy::app::{App, AppExit, Last, TerminalCtrlCHandlerPlugin};
    use bevy::ecs::message::MessageWriter;
    use bevy::time::{Fixed, Time};

    if let Err(e) = ctrlc::set_handler(TerminalCtrlCHandlerPlugin::gracefully_exit) {
        eprintln!("warning: no signal handler ({e})");
    }
    let home = softsync_peer::avatar::home(room.me());
    let mut app = App::new();
    match front {
        FrontEnd::Desktop => {
            let focus = a.view.focus.as_deref().and_then(|f| room.scene().kind(f));
            app.add_plugins(crate::desktop_plugins(a))
                .add_plugins(crate::view::ViewPlugin(crate::view_config(a, true)))
                .add_plugins(crate::desktop::DesktopPlugin(
                    crate::desktop::OrbitCamera::at_home(home, focus),
                ));
            crate::rollback_view::add_systems(&mut app);
        }
        #[cfg(feature = "vr")]
        FrontEnd::Vr => {
            app.add_plugins(crate::vr::plugins())
                .add_plugins(crate::view::ViewPlugin(crate::view_config(a, false)))
                .add_plugins(crate::vr::VrPlugin(crate::vr::StageOrigin {
                    pos: softsync_bevy::glue::to_bevy(glam::Vec3::new(home.0.x, 0.0, home.0.z)),
                    rot: softsync_bevy::glue::to_bevy_quat(home.1),
                }));
            crate::rollback_view::add_systems(&mut app);
        }
        _ => return Err(Failure::usage("this front end is not in this build")),
    }
    let started = WallInstant::now();
    let (duration, timeout) = (a.duration, a.connect_timeout);
    use bevy::ecs::schedule::IntoScheduleConfigs;
    let end = move |room: bevy::ecs::system::Res<RollbackRoom>,
                    mut exit: MessageWriter<AppExit>,
                    mut done: bevy::ecs::system::Local<bool>| {
        if *done {
            return;
        }
        let failed = failure.lock().unwrap_or_else(|e| e.into_inner()).is_some();
        if !joined.load(Ordering::SeqCst) && started.elapsed() > timeout {
            let f = Failure::connect("no welcome from the room's host in time");
            failure
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get_or_insert(f);
        }
        let failed = failed || failure.lock().unwrap_or_else(|e| e.into_inner()).is_some();
        if failed || !room.running() || duration.is_some_and(|d| started.elapsed() >= d) {
            *done = true;
            exit.write(AppExit::Success);
        }
    };
    let exit = app
        .add_plugins(softsync_bevy::RollbackPlugin {
            exit_on_failure: false,
        })
        .insert_resource(room)
        .insert_resource(Time::<Fixed>::from_hz(a.sim_hz))
        .add_systems(Last, end.before(softsync_bevy::SoftsyncSet::Leave))
        .run();
    Ok(match exit {
        AppExit::Success => ExitCode::SUCCESS,
        AppExit::Error(code) => ExitCode::from(code.get()),
    })
}

/// A refusal said plainly, naming the room's sync mode when that is why.
pub fn refusal(reason: &str) -> String {
    let host_rollback = reason.contains(softsync_rollback::room::EPOCH_NAME);
    if reason.contains("configuration differs") {
        if host_rollback {
            return format!(
                "refused: {reason}\n  the room syncs by rollback (its host ran --sync \
                 rollback): join with --sync rollback"
            );
        }
        return format!(
            "refused: {reason}\n  if the room syncs by state (its host ran without --sync \
             rollback), join without --sync rollback"
        );
    }
    format!("refused: {reason}")
}
