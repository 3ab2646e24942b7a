//! `softsync`: signal, host, join, token. See `softsync help`. (The benchmarks are
//! `softsync-bench`, another package.)

#![allow(clippy::disallowed_methods)] // the app is the I/O layer: clocks, sleeps, processes

mod cli;
#[cfg(feature = "desktop")]
mod desktop;
mod driver;
#[cfg(feature = "desktop")]
mod labels;
mod plugins;
mod replay;
mod replay_room;
mod report;
mod rollback;
#[cfg(feature = "desktop")]
mod rollback_view;
#[cfg(feature = "desktop")]
mod screenshot;
mod stderr_log;
#[cfg(feature = "desktop")]
mod view;
#[cfg(feature = "vr")]
mod vr;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use bevy::app::{App, AppExit, PluginGroup, ScheduleRunnerPlugin, TerminalCtrlCHandlerPlugin};
use bevy::time::{Fixed, Time};
use bevy::MinimalPlugins;
#[cfg(feature = "vr")]
use glam::Vec3;
use softsync_bevy::{Room, RoomOptions, SoftsyncApp, SoftsyncPlugin};
use softsync_interaction::HandConfig;
use softsync_net::SendPolicy;
use softsync_net_matchbox::SignalServer;
use softsync_peer::scene::DEFAULT_SCENE;
use softsync_peer::{bot, Bot, PeerConfig, Scene};

use softsync_rollback::script::SqueezeThrow;

use crate::cli::{Command, FrontEnd, PeerArgs, UsageError};
use crate::driver::{Driver, JoinTimeline};
use crate::plugins::ReportPlugin;

/// A failure with its exit code.
pub(crate) struct Failure {
    code: u8,
    msg: String,
}

impl Failure {
    pub(crate) fn usage(msg: impl std::fmt::Display) -> Self {
        Failure {
            code: 2,
            msg: msg.to_string(),
        }
    }
    fn connect(msg: impl std::fmt::Display) -> Self {
        Failure {
            code: 3,
            msg: msg.to_string(),
        }
    }
    pub(crate) fn runtime(msg: impl std::fmt::Display) -> Self {
        Failure {
            code: 1,
            msg: msg.to_string(),
        }
    }
}

impl From<UsageError> for Failure {
    fn from(e: UsageError) -> Self {
        Failure::usage(e)
    }
}

fn main() -> ExitCode {
    stderr_log::install();
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(code) => code,
        Err(f) => {
            eprintln!("error: {}", f.msg);
            ExitCode::from(f.code)
        }
    }
}

fn run(args: &[String]) -> Result<ExitCode, Failure> {
    match cli::parse(args)? {
        Command::Help(text) => {
            print!("{text}");
            Ok(ExitCode::SUCCESS)
        }
        Command::Signal {
            bind,
            room_key_file,
            tls,
            max_sockets,
            max_per_source,
        } => signal(
            bind,
            room_key(room_key_file.as_deref())?,
            tls_identity(tls.as_ref())?,
            softsync_net_matchbox::SignalLimits {
                max_sockets,
                max_per_source,
                ..Default::default()
            },
        ),
        Command::Peer(p) => peer(*p),
        Command::Replay(r) => replay::replay(r),
        Command::Store(a) => replay::store(a),
        Command::AudioDevices => {
            let (inputs, outputs) = softsync_voice::device::list();
            println!("inputs:");
            for d in &inputs {
                println!("  {d}");
            }
            println!("outputs:");
            for d in &outputs {
                println!("  {d}");
            }
            if inputs.is_empty() && outputs.is_empty() {
                println!("(none: voice can still hear the room through --voice-out files)");
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Token {
            room,
            room_key_file,
            valid,
        } => {
            let Some(key) = room_key(room_key_file.as_deref())? else {
                return Err(Failure::usage(
                    "a token is signed with the room's key: --room-key-file FILE or SOFTSYNC_ROOM_KEY",
                ));
            };
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs());
            let nonce = random_nonce()
                .ok_or_else(|| Failure::runtime("no system random source for the token"))?;
            let token = key
                .for_room(&room)
                .issue_token(now + valid as u64, nonce)
                .ok_or_else(|| Failure::runtime("the key names no room"))?;
            println!("{token}");
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// `--tls-cert` and `--tls-key`, read (a clear usage error if they cannot be).
fn tls_identity(
    files: Option<&(PathBuf, PathBuf)>,
) -> Result<Option<softsync_net_matchbox::TlsIdentity>, Failure> {
    files
        .map(|(cert, key)| softsync_net_matchbox::TlsIdentity::from_pem_files(cert, key))
        .transpose()
        .map_err(Failure::usage)
}

fn signal(
    bind: std::net::SocketAddr,
    key: Option<softsync_net::RoomKey>,
    tls: Option<softsync_net_matchbox::TlsIdentity>,
    limits: softsync_net_matchbox::SignalLimits,
) -> Result<ExitCode, Failure> {
    let keyed = key.is_some();
    let server = SignalServer::start_secure(bind, limits, key, tls).map_err(Failure::connect)?;
    if keyed {
        println!("rooms on this server need the room key (or a join token)");
    }
    println!("signaling on {}", server.url());
    let mut last = Vec::new();
    let mut last_gate = server.gate_stats();
    loop {
        std::thread::sleep(Duration::from_millis(500));
        let g = server.gate_stats();
        let refusals = |g: &softsync_net_matchbox::GateStats| {
            g.refused_full
                + g.refused_source
                + g.tls_failed
                + g.slow
                + g.bad_request
                + g.bad_frames
                + g.flood_dropped
                + g.idle_closed
        };
        if refusals(&g) != refusals(&last_gate) {
            eprintln!(
                "gate: refused {} (full) {} (per address); closed {} (TLS) {} (slow) {} (not an upgrade) {} (bad frames) {} (floods) {} (idle); {} open",
                g.refused_full,
                g.refused_source,
                g.tls_failed,
                g.slow,
                g.bad_request,
                g.bad_frames,
                g.flood_dropped,
                g.idle_closed,
                g.open
            );
            last_gate = g;
        }
        let rooms = server.rooms();
        if rooms != last {
            let list: Vec<String> = rooms
                .iter()
                .map(|r| format!("{}({})", r.name, r.peers))
                .collect();
            eprintln!(
                "rooms: {}",
                if list.is_empty() {
                    "none".into()
                } else {
                    list.join(" ")
                }
            );
            last = rooms;
        }
    }
}

/// The assets folder: `--assets`, `./assets`, or the repository's next to the binary.
fn assets_dir(given: Option<&Path>) -> PathBuf {
    if let Some(p) = given {
        return p.to_owned();
    }
    let here = PathBuf::from("assets");
    if here.join("thesis-room.ron").exists() {
        return here;
    }
    if let Ok(exe) = std::env::current_exe() {
        for up in exe.ancestors().skip(1).take(4) {
            let p = up.join("assets");
            if p.join("thesis-room.ron").exists() {
                return p;
            }
        }
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets")
}

/// bevy's plugins for the desktop peer: a window, the PBR renderer, the UI.
#[cfg(feature = "desktop")]
fn desktop_plugins(a: &PeerArgs) -> bevy::app::PluginGroupBuilder {
    use bevy::prelude::*;
    use bevy::render::RenderPlugin;
    DefaultPlugins
        .set(WindowPlugin {
            primary_window: Some(Window {
                title: format!("softsync — room {}", a.room),
                resolution: a.view.window.into(),
                ..default()
            }),
            ..default()
        })
        .set(RenderPlugin {
            // Asynchronous: objects appear once their pipelines are ready (the first frames on
            // a software renderer are empty), but the frame loop, and with it the session's
            // heartbeats, never stalls on a compile.
            synchronous_pipeline_compilation: false,
            ..default()
        })
        .set(bevy::log::LogPlugin {
            level: bevy::log::Level::WARN,
            filter: "wgpu=error,naga=warn,bevy_render=warn,softsync=info".into(),
            ..default()
        })
}

#[cfg(feature = "desktop")]
fn view_config(a: &PeerArgs, desktop: bool) -> view::ViewConfig {
    view::ViewConfig {
        particles: a.view.particles,
        hide_avatars: a.view.hide_avatars,
        hud: !a.view.no_hud && desktop,
        hide_own_head: true,
        world_labels: !desktop || a.view.world_labels,
        rollback: a.rollback,
        screenshots: a
            .view
            .screenshot_dir
            .as_ref()
            .map(|d| view::ScreenshotPlan {
                dir: d.clone(),
                every: a.view.screenshot_every,
                max: a.view.screenshots,
            }),
    }
}

/// The room's key: `--room-key-file`, or `SOFTSYNC_ROOM_KEY`, or none. Its challenges are
/// seeded from the system's random source.
/// The TURN password: `--ice-credential-file`, else SOFTSYNC_ICE_CREDENTIAL (for a username).
fn ice_credential(a: &PeerArgs) -> Result<Option<String>, Failure> {
    if a.ice_user.is_none() {
        return Ok(None);
    }
    if let Some(f) = &a.ice_credential_file {
        let text = std::fs::read_to_string(f)
            .map_err(|e| Failure::usage(format!("--ice-credential-file {}: {e}", f.display())))?;
        return Ok(Some(text.trim_end_matches(['\n', '\r']).to_owned()));
    }
    match std::env::var("SOFTSYNC_ICE_CREDENTIAL") {
        Ok(c) => Ok(Some(c)),
        Err(_) => Err(Failure::usage(
            "--ice-user needs a password: --ice-credential-file FILE or SOFTSYNC_ICE_CREDENTIAL",
        )),
    }
}

/// 16 random bytes from the system's source.
fn random_nonce() -> Option<[u8; 16]> {
    let mut n = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut n))
        .ok()?;
    Some(n)
}

pub(crate) fn room_key(file: Option<&Path>) -> Result<Option<softsync_net::RoomKey>, Failure> {
    let secret = match file {
        Some(f) => std::fs::read(f)
            .map_err(|e| Failure::usage(format!("--room-key-file {}: {e}", f.display())))?,
        None => match std::env::var_os("SOFTSYNC_ROOM_KEY") {
            Some(v) => v.into_encoded_bytes(),
            None => return Ok(None),
        },
    };
    let trimmed = secret.trim_ascii_end();
    if trimmed.is_empty() {
        return Err(Failure::usage("the room key is empty"));
    }
    if trimmed.len() < 16 {
        eprintln!(
            "warning: the room key has {} bytes; use 16 or more random ones",
            trimmed.len()
        );
    }
    softsync_net::RoomKey::with_random_seed(trimmed)
        .map(Some)
        .ok_or_else(|| Failure::runtime("no system random source for the room key's challenges"))
}

/// `--bot throw` (the squeeze-and-throw motion, starting with the object its id picks) or
/// `--bot throw:N` (starting with the scene's object N): `Some(slot)`; any other bot: `None`.
pub(crate) fn throw_slot(bot: &str) -> Option<Option<usize>> {
    match bot.strip_prefix("throw") {
        Some("") => Some(None),
        Some(n) => n.strip_prefix(':').and_then(|n| n.parse().ok()).map(Some),
        None => None,
    }
}

fn load_bot(src: &str) -> Result<Bot, Failure> {
    let text = if let Some(b) = bot::builtin(src) {
        b.to_owned()
    } else if Path::new(src).is_file() {
        std::fs::read_to_string(src)
            .map_err(|e| Failure::usage(format!("bot script {src}: {e}")))?
    } else if src.contains(' ') || src.contains(';') {
        src.to_owned()
    } else {
        return Err(Failure::usage(format!(
            "--bot {src:?}: no such file or built-in script (squeeze, idle, wave; throw or throw:N for the squeeze-and-throw motion)"
        )));
    };
    let cmds = bot::parse(&text).map_err(Failure::usage)?;
    Ok(Bot::new(cmds))
}

/// The front end this build can open for `asked`: `--vr` without a runtime or a headset says
/// why and falls back to the desktop peer; a front end the build lacks is a usage error.
fn front_end(asked: FrontEnd) -> Result<FrontEnd, Failure> {
    let missing = |feature: &str, flag: &str| {
        Failure::usage(format!(
            "{flag}: this softsync was built without the `{feature}` feature; build it with \
             `cargo build --release -p softsync --features {feature}`"
        ))
    };
    match asked {
        FrontEnd::Headless => Ok(FrontEnd::Headless),
        FrontEnd::Desktop if cfg!(feature = "desktop") => Ok(FrontEnd::Desktop),
        FrontEnd::Desktop => Err(missing("desktop", "--desktop")),
        FrontEnd::Vr => {
            #[cfg(feature = "vr")]
            {
                match vr::probe() {
                    Ok(what) => {
                        println!("vr: {what}");
                        Ok(FrontEnd::Vr)
                    }
                    Err(why) => {
                        eprintln!("vr: {why}");
                        eprintln!("vr: opening the desktop peer instead");
                        Ok(FrontEnd::Desktop)
                    }
                }
            }
            #[cfg(not(feature = "vr"))]
            Err(missing("vr", "--vr"))
        }
    }
}

/// The inputs that need the scene: `--focus` names one of its classes (returned), the bot's
/// script only classes it has.
fn scene_checks(
    a: &PeerArgs,
    bot: Option<&Bot>,
    scene: &Scene,
) -> Result<Option<softsync_peer::Kind>, Failure> {
    if let Some(b) = bot {
        b.check(scene).map_err(Failure::usage)?;
    }
    let Some(k) = a.view.focus.as_deref() else {
        return Ok(None);
    };
    scene.kind(k).map(Some).ok_or_else(|| {
        Failure::usage(format!(
            "--focus: {k:?} is not a class of scene {} ({})",
            scene.name,
            scene
                .object_classes()
                .map(|(_, c)| c.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    })
}

fn peer(a: PeerArgs) -> Result<ExitCode, Failure> {
    // Check every input before opening anything.
    let front = front_end(a.front)?;
    // Meshes load and every soft class is clustered now: seconds for a big mesh (a spinner on
    // a terminal, nothing when piped). A joiner without --scene receives the room's.
    let scene = match (&a.scene, a.host) {
        (None, false) => None,
        (name, _) => {
            let name = name.as_deref().unwrap_or(DEFAULT_SCENE);
            let loading = softsync_benchkit::Progress::spinner(format!("loading scene {name}"));
            let scene = Scene::by_name(name, &assets_dir(a.assets.as_deref()));
            loading.finish();
            let scene = scene.map_err(Failure::usage)?;
            print_materials(&scene, a.sim_hz);
            Some(scene)
        }
    };
    #[cfg(feature = "desktop")]
    if let Some(d) = &a.view.screenshot_dir {
        std::fs::create_dir_all(d)
            .map_err(|e| Failure::usage(format!("--screenshot-dir {}: {e}", d.display())))?;
    }
    // `throw`: the squeeze-and-throw motion both sync modes share (their side-by-side bench)
    let throw = a.bot.as_deref().and_then(throw_slot);
    let bot = a
        .bot
        .as_deref()
        .filter(|b| throw.is_none() && !(a.rollback && *b == "squeeze"))
        .map(load_bot)
        .transpose()?;
    if let Some(scene) = &scene {
        scene_checks(&a, bot.as_ref(), scene)?;
    }
    let dump = match &a.dump {
        Some(p) => Some(
            softsync_peer::dump::Dump::create(p)
                .map_err(|e| Failure::usage(format!("--dump {}: {e}", p.display())))?,
        ),
        None => None,
    };
    let mut opts = if a.host {
        RoomOptions::host(a.room.clone())
    } else {
        let Some(url) = a.signal.clone() else {
            return Err(Failure::usage("join needs --signal"));
        };
        RoomOptions::join(a.room.clone(), url)
    };
    opts.signal = a.signal.clone();
    opts.bind = a.bind;
    opts.takeover_bind = a.takeover_bind;
    opts.uplink_bytes_per_s = a.uplink_bytes_per_s;
    opts.voice = a.voice.clone();
    opts.presence = a.presence.clone();
    opts.state_route = a.state_route;
    opts.ice_servers = a.ice.clone();
    opts.ice_username = a.ice_user.clone();
    opts.ice_credential = ice_credential(&a)?;
    opts.connect_timeout = a.connect_timeout;
    opts.room_key = room_key(a.room_key_file.as_deref())?;
    opts.tls = tls_identity(a.tls.as_ref())?;
    opts.tls_ca = a.tls_ca.clone();
    opts.room_token = match (&a.room_token, std::env::var("SOFTSYNC_ROOM_TOKEN")) {
        (Some(t), _) => Some(t.clone()),
        (None, Ok(t)) => Some(
            t.parse()
                .map_err(|e| Failure::usage(format!("SOFTSYNC_ROOM_TOKEN: {e}")))?,
        ),
        (None, Err(_)) => None,
    };
    opts.fast_detection = a.fast_detection;
    opts.max_members = a.max_members;
    opts.condition = a.condition.clone();
    opts.store = a.store.clone();
    opts.send = SendPolicy {
        rate_hz: a.send_rate_hz,
        position_threshold_m: a.threshold_m,
        particle_threshold_m: a.threshold_m,
        ..SendPolicy::default()
    };
    opts.peer = PeerConfig {
        hand: HandConfig {
            // Bots reach exactly; a physical hand body would shove what it reaches for. VR
            // hands get one (people push things with their controllers); mouse hands do not: a
            // hand resting under the view would shove whatever is there.
            physical_controller: front == FrontEnd::Vr && a.bot.is_none(),
            hover_radius_m: 0.03,
            ..HandConfig::default()
        },
        dt_s: (1.0 / a.sim_hz) as f32,
        avatar: !a.no_avatar,
        rejoin_limit: a.rejoin_limit,
        join_timeout: a.connect_timeout,
        agree_to_hands: true,
        build_off_frame: true,
        // on the wall clock: no frame waits for a build's worker
        land_when_ready: true,
    };
    if a.rollback {
        let scene = match scene {
            Some(s) => s,
            // a rollback joiner builds the room's scene itself (the digest checks it is the
            // host's); it does not fetch one
            None => Scene::by_name(DEFAULT_SCENE, &assets_dir(a.assets.as_deref()))
                .map_err(Failure::usage)?,
        };
        return rollback::run(&a, front, scene, opts, dump, bot);
    }
    // A desktop or VR peer enters the room once its front end renders (`Room::set_ready`).
    opts.start_ready = front == FrontEnd::Headless;
    let started = std::time::Instant::now();
    let opened = match scene {
        Some(scene) => Room::open(scene, opts),
        None => Room::open_fetching_scene(opts),
    };
    let mut room = opened.map_err(|e| Failure {
        code: e.exit_code(),
        msg: e.to_string(),
    })?;
    if let Some(f) = room.fetched_scene() {
        println!(
            "scene {} from peer {}: {} bytes in {:.0} ms ({} requests), kept in {}",
            room.peer.scene().name,
            f.from.0,
            f.bytes,
            f.fetch.as_secs_f64() * 1e3,
            f.requests,
            room.peer.scene().path.display()
        );
        // The checks that needed the scene, now that there is one.
        if let Err(e) = scene_checks(&a, bot.as_ref(), room.peer.scene()) {
            room.leave();
            return Err(e);
        }
    }
    #[cfg(feature = "desktop")]
    let focus = scene_checks(&a, bot.as_ref(), room.peer.scene())?;
    if room.runs_signaling() {
        println!("signaling on {}", room.signal_url());
    }
    if let (false, Some(contact)) = (a.host, room.peer.session().host_id()) {
        println!(
            "connected to peer {} after {:.0} ms",
            contact.0,
            started.elapsed().as_secs_f64() * 1e3
        );
    }
    println!(
        "{} room={} peer={} signal={}",
        if a.host { "hosting" } else { "joining" },
        a.room,
        room.peer.me().0,
        room.signal_url()
    );
    if let (Some(r), Some(k)) = (room.reopened(), room.store()) {
        println!(
            "reopened the room kept in {}: {} objects, {} topology entries replayed, {} retained messages, room time {:.3} s",
            k.target(),
            r.objects,
            r.entries,
            r.messages,
            room.peer.session().room_time(room.now()).unwrap_or_default().as_secs_f64()
        );
    } else if let Some(k) = room.store() {
        if a.host {
            println!("keeping the room in {}", k.target());
        }
    }
    let mut driver = Driver::new(bot, a.duration, dump, a.dump_hz, a.quiet);
    if !a.host {
        driver.join_timeline = room.connect_times().map(JoinTimeline::new);
    }
    if let Some(slot) = throw {
        let me = room.peer.me();
        let slot = slot.unwrap_or((me.0 % 5) as usize);
        driver.throw = Some((SqueezeThrow::new(me, slot), 0));
    }
    // Ctrl-C, SIGTERM and SIGHUP end the peer cleanly (last dump, `Leave`). Installed here
    // with overwrite: bevy's own installer gives up when SIGINT is ignored, which it is for
    // every background job a script starts, and then SIGTERM is not handled either.
    if let Err(e) = ctrlc::set_handler(TerminalCtrlCHandlerPlugin::gracefully_exit) {
        eprintln!("warning: no signal handler ({e}): a kill is noticed by the timeout only");
    }
    let home = room.peer.home();
    let mut app = App::new();
    match front {
        FrontEnd::Headless => {
            // Nothing is shown between two fixed steps: a headless frame comes once a step
            // (the pump thread reads the network between frames). At 2 ms frames a bot spent
            // half its CPU on frames that did nothing (issue 34, point 2).
            let step = Duration::from_secs_f32(room.peer.config().dt_s);
            app.add_plugins(MinimalPlugins.set(ScheduleRunnerPlugin::run_loop(step)))
                .add_plugins(TerminalCtrlCHandlerPlugin);
        }
        #[cfg(feature = "desktop")]
        FrontEnd::Desktop => {
            app.add_plugins(desktop_plugins(&a))
                .add_plugins(view::ViewPlugin(view_config(&a, true)))
                .add_plugins(desktop::DesktopPlugin(desktop::OrbitCamera::at_home(
                    home, focus,
                )));
        }
        #[cfg(feature = "vr")]
        FrontEnd::Vr => {
            app.add_plugins(vr::plugins())
                .add_plugins(view::ViewPlugin(view_config(&a, false)))
                .add_plugins(vr::VrPlugin(vr::StageOrigin {
                    // The floor under our place at the table, facing it.
                    pos: softsync_bevy::glue::to_bevy(Vec3::new(home.0.x, 0.0, home.0.z)),
                    rot: softsync_bevy::glue::to_bevy_quat(home.1),
                }));
        }
        #[allow(unreachable_patterns)]
        _ => return Err(Failure::usage("this front end is not in this build")),
    }
    let _ = home;
    let exit = app
        .add_plugins(SoftsyncPlugin {
            net_thread: !a.no_net_thread,
            ..SoftsyncPlugin::default()
        })
        .add_room(room)
        .insert_resource(Time::<Fixed>::from_hz(a.sim_hz))
        .insert_non_send(driver)
        .add_plugins(ReportPlugin)
        .run();
    Ok(match exit {
        AppExit::Success => ExitCode::SUCCESS,
        AppExit::Error(code) => ExitCode::from(code.get()),
    })
}

/// Each soft class that named a material: the setting found for it and how near it is (and
/// a warning if it was fitted at another step rate than this peer's).
fn print_materials(scene: &Scene, sim_hz: f64) {
    for c in &scene.classes {
        let (Some(setting), Some(named)) = (
            &c.material,
            c.material.as_ref().and_then(|s| s.config.material),
        ) else {
            continue;
        };
        eprintln!(
            "class {:?}: material E {} kPa, ν {} at {} Hz → {setting}",
            c.name, named.young_kpa, named.poisson, named.rate_hz
        );
        if (f64::from(named.rate_hz) - sim_hz).abs() > 0.5 {
            eprintln!(
                "class {:?}: warning: its material was fitted at {} Hz but this peer steps at {sim_hz} Hz \
                 (the particle method is a different material at another rate: set material.rate_hz)",
                c.name, named.rate_hz
            );
        }
    }
}
