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
//!   possibly predicted, frame), objects numbered in the scene's order, owned by nobody.

use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant as WallInstant};

use softsync_bevy::{connect, first_contact, scene_server, Clock, RoomOptions, LEAVE_GRACE};
use softsync_net::messages::MessageTypes;
use softsync_net::{Event, LinkConditioner, Session, Transport};
use softsync_peer::dump::{Dump, DumpLine, DumpObject};
use softsync_peer::Scene;
use softsync_rollback::room::register;
use softsync_rollback::script::SqueezeThrow;
use softsync_rollback::{PlayerInput, RollbackConfig, RollbackEvent, RollbackPeer};

use crate::cli::{FrontEnd, PeerArgs};
use crate::Failure;

/// What a rollback bot does.
enum Script {
    Idle,
    Squeeze(SqueezeThrow),
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
    let objects = world
        .objects()
        .iter()
        .enumerate()
        .filter_map(|(i, o)| {
            let (pos, rot) = world.object_pose(i)?;
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
                log: None,
                topology: None,
                holders: Vec::new(),
            })
        })
        .collect();
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

/// Run a rollback peer until `--duration`, a signal, or a refusal.
pub fn run(
    a: &PeerArgs,
    scene: Scene,
    opts: RoomOptions,
    mut dump: Option<Dump>,
) -> Result<ExitCode, Failure> {
    if a.front != FrontEnd::Headless {
        return Err(Failure::usage(
            "--sync rollback: desktop and VR peers are not in rollback rooms yet; run a headless \
             peer (with --bot squeeze or idle)",
        ));
    }
    refuse_unhonoured(a)?;
    let mut cfg = opts
        .session_config(&scene)
        .map_err(|e| Failure::usage(e.to_string()))?;
    let mut types = MessageTypes::from_config(&cfg)
        .ok_or_else(|| Failure::usage("the room's message table names a type twice"))?;
    register(&mut types);
    types.configure(&mut cfg);
    let rcfg = RollbackConfig {
        dt_s: (1.0 / a.sim_hz) as f32,
        ..RollbackConfig::default()
    };
    let mut conn = connect(&opts).map_err(|e| Failure::connect(e.to_string()))?;
    let me = conn.transport.local_id();
    let clock = Clock::start();
    let (session, contact) = if a.host {
        (Session::host(me, cfg, clock.now()), None)
    } else {
        let c = first_contact(&mut conn.transport, &opts, conn.started)
            .map_err(|e| Failure::connect(e.to_string()))?;
        println!(
            "connected to peer {} after {:.0} ms",
            c.0,
            conn.started.elapsed().as_secs_f64() * 1e3
        );
        (Session::join(me, c, cfg, clock.now()), Some(c))
    };
    let mut transport: Box<dyn Transport + Send> = match opts.condition.clone() {
        Some(c) => Box::new(LinkConditioner::new(conn.transport, c)),
        None => Box::new(conn.transport),
    };
    let scene_copy = scene.clone();
    let mut share: Option<softsync_net::share::BlobServer> = None;
    let mut peer = RollbackPeer::new(clock.now(), scene, rcfg, session, contact)
        .map_err(|e| Failure::runtime(e.to_string()))?;
    if a.host {
        peer.open(clock.now())
            .map_err(|e| Failure::runtime(e.to_string()))?;
    }
    if conn.signal.is_some() {
        println!("signaling on {}", conn.url);
    }
    println!(
        "{} room={} peer={} signal={} sync=rollback",
        if a.host { "hosting" } else { "joining" },
        a.room,
        me.0,
        conn.url
    );
    let mut script = match a.bot.as_deref() {
        None | Some("idle") => Script::Idle,
        Some(b) if b == "squeeze" || crate::throw_slot(b).is_some() => {
            let slot = crate::throw_slot(b).flatten();
            Script::Squeeze(SqueezeThrow::new(me, slot.unwrap_or((me.0 % 5) as usize)))
        }
        Some(other) => {
            return Err(Failure::usage(format!(
                "--bot {other:?}: a rollback peer runs the built-in `throw` (also `squeeze`) or \
                 `idle` (the script language drives a state-sync peer)"
            )))
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        if let Err(e) = ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst)) {
            eprintln!("warning: no signal handler ({e})");
        }
    }
    let step = Duration::from_secs_f64(1.0 / a.sim_hz);
    let started = WallInstant::now();
    let mut next = started;
    let mut last_line = started;
    let mut checked = -1i32;
    let mut checked_epoch = 0u32;
    let mut joined = a.host;
    let mut holding: Option<usize> = None;
    // datagram payload bytes sent (session, ggrs, snapshots): the stats line's `up=` rate
    let mut up_bytes = 0u64;
    let mut last_up = (WallInstant::now(), 0u64);
    let mut failure = None;
    let dump_every = Duration::from_secs_f64(1.0 / a.dump_hz.max(0.01));
    let mut next_dump = started;
    let write_dump = |dump: &mut Option<Dump>, peer: &RollbackPeer| {
        let Some(d) = dump.as_mut() else { return };
        // nothing to show before the first epoch's world
        let Some(line) = dump_line(peer, clock.now()) else {
            return;
        };
        if let Err(e) = d.write(&line) {
            eprintln!("warning: --dump: {e}; no more dump lines");
            *dump = None;
        }
    };
    while !stop.load(Ordering::SeqCst) && a.duration.is_none_or(|d| started.elapsed() < d) {
        let now = clock.now();
        while let Some((from, bytes)) = transport.recv(now) {
            // the front door: the scene share here, the rest to the rollback peer's (which
            // takes the session's and its own)
            if softsync_net::door::classify(&bytes) == softsync_net::door::Door::Share {
                // a joiner takes the scene from the room's host only: a member names it
                let session = peer.session();
                if let (false, true, Some(host)) =
                    (session.is_host(), session.is_connected(), session.host_id())
                {
                    if let Some(t) = softsync_net::share::ask_host(from, &bytes, host) {
                        transport.send(now, &t);
                    }
                    continue;
                }
                // a joiner without the scene asks for ours (a state-sync one is then refused
                // at its Hello, told the room syncs by rollback)
                let server = share
                    .get_or_insert_with(|| scene_server(&scene_copy, peer.session().config(), me));
                let session = peer.session();
                let judged =
                    server.handle_judged(now, from, &bytes, |t| session.token_admits(t, from, now));
                if let Some(t) = judged {
                    transport.send(now, &t);
                }
                continue;
            }
            peer.handle_datagram(now, from, &bytes);
        }
        while let Some(e) = transport.poll_peer_event() {
            peer.handle_link_event(e);
        }
        let input = match (&mut script, peer.world()) {
            (Script::Squeeze(s), Some(w)) => s.input(w),
            _ => PlayerInput::default(),
        };
        peer.set_input(input);
        peer.tick(now);
        // our right hand's grabs and releases, in our own (predicted) view
        let held = peer.epoch().and_then(|e| {
            let i = e.players.iter().position(|p| *p == me)?;
            peer.world()?.held(i, 1)
        });
        if held != holding {
            match (holding, held) {
                (_, Some(k)) => println!("grab object={k}"),
                (Some(k), None) => println!("release object={k}"),
                (None, None) => {}
            }
            holding = held;
        }
        while let Some(t) = peer.poll_transmit(now) {
            up_bytes += t.payload.len() as u64;
            transport.send(now, &t);
        }
        while let Some(e) = peer.poll_event() {
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
                    joined = true;
                    println!("joined: host is peer {}", host.0)
                }
                RollbackEvent::Room(Event::Refused { reason }) => {
                    failure = Some(Failure::connect(refusal(&reason)));
                }
                RollbackEvent::Room(Event::Dropped { reason, .. }) => {
                    failure = Some(Failure::runtime(format!("dropped from the room: {reason}")));
                }
                RollbackEvent::Room(Event::PeerJoined(p)) => println!("peer {} joined", p.0),
                RollbackEvent::Room(Event::PeerLeft(p)) => println!("peer {} left", p.0),
                RollbackEvent::Room(Event::HostChanged { host, .. }) => {
                    println!("host is now peer {}", host.0)
                }
                RollbackEvent::Room(_) => {}
            }
        }
        if failure.is_some() {
            break;
        }
        if !joined && started.elapsed() > a.connect_timeout {
            failure = Some(Failure::connect("no welcome from the room's host in time"));
            break;
        }
        if let (Some(c), Some((n, start))) =
            (peer.confirmed_frame(), peer.epoch().map(|e| (e.n, e.frame)))
        {
            if n != checked_epoch {
                // the new epoch's timeline from its frame on: checked again, under its number
                checked_epoch = n;
                checked = checked.min(start);
            }
            let mut f = (checked + 1).max(c - 120);
            f = (f + 59) / 60 * 60;
            while f <= c {
                if let Some(sum) = peer.checksum_at(f) {
                    println!("rollback.check epoch={n} frame={f} checksum={sum:032x}");
                }
                checked = f;
                f += 60;
            }
        }
        if !a.quiet && last_line.elapsed() >= Duration::from_secs(1) {
            last_line = WallInstant::now();
            let s = peer.stats();
            let up = (up_bytes - last_up.1) as f64 / last_up.0.elapsed().as_secs_f64().max(1e-3);
            last_up = (WallInstant::now(), up_bytes);
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
        if dump.is_some() && WallInstant::now() >= next_dump {
            next_dump = WallInstant::now() + dump_every;
            write_dump(&mut dump, &peer);
        }
        next += step;
        let now = WallInstant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else if now - next > Duration::from_millis(250) {
            next = now;
        }
    }
    write_dump(&mut dump, &peer);
    peer.leave(clock.now());
    let end = WallInstant::now() + LEAVE_GRACE;
    while WallInstant::now() < end {
        let now = clock.now();
        while let Some(t) = peer.poll_transmit(now) {
            transport.send(now, &t);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let s = peer.stats();
    let mut ms = s.frame_ms.clone();
    ms.sort_by(f32::total_cmp);
    let p95 = ms.get(ms.len() * 95 / 100).copied().unwrap_or(0.0);
    println!(
        "rollback.summary frames={} resimulated={} rollbacks={} desyncs={} epochs={} epochs_refused={} switch_ms_max={:.0} frame_ms_p95={p95:.2} save_us={:.1} load_us={:.1} ggrs_bytes={} repairs={} repair_ms_max={:.0}",
        s.frames,
        s.resimulated,
        s.rollbacks,
        s.desyncs,
        s.epochs,
        s.epochs_refused,
        s.switch_ms_max,
        s.save_ns as f64 / s.saves.max(1) as f64 / 1e3,
        s.load_ns as f64 / s.rollbacks.max(1) as f64 / 1e3,
        s.ggrs_bytes,
        s.repairs,
        s.repair_ms_max
    );
    match failure {
        Some(f) => Err(f),
        None => Ok(ExitCode::SUCCESS),
    }
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
