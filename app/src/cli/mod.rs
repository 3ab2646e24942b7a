//! Command-line parsing: clap's derive API for the grammar, `--help` and `softsync help`;
//! the checks that span several flags, and the values' own checks, say which flag is wrong.
//! Exit codes are unchanged: 0 for help, 2 for any usage error.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, Parser, Subcommand};
use softsync_net::ConditionerConfig;

mod keep;
mod values;
mod view;
mod voice;
pub use keep::{ReplayArgs, StoreAction};
use values::*;
pub use view::ViewArgs;
use view::ViewOpts;

/// What `softsync help` prints after the commands.
const AFTER_HELP: &str = "\
A bot script also runs on a desktop or VR peer: it then moves the hands relative to the
tracked ones and its grip adds to the device's. Desktop controls: the right hand on the mouse
cursor; left button grips (Ctrl: left hand), wheel reaches (Shift: zoom), E trigger (the
scalpel tears), X the cutter (sweep it across a body to cut it), right-drag orbits,
middle-drag/WASDQZ pans, P particles, H HUD, M mutes the voice, R reset. VR: the tool button (X/A on Touch)
switches a hand's trigger between scalpel and cutter.

Every peer prints a stats line per second on stderr: peers, host, term, bytes/s up and down,
RTT, objects owned. Exit codes: 0 done, 1 runtime failure, 2 usage or input error, 3 cannot
reach the signaling server or the room, 130 stopped by Ctrl-C/SIGTERM/SIGHUP (after a last
dump and a Leave to the room).";

/// softsync — collaborative soft-body rooms, peer to peer.
#[derive(Parser, Debug)]
#[command(name = "softsync", version, after_help = AFTER_HELP)]
struct Cli {
    #[command(subcommand)]
    command: Option<Sub>,
}

#[derive(Subcommand, Debug)]
enum Sub {
    /// A standalone signaling server. Rooms that must outlive their host use one: new peers
    /// can still join after a migration.
    Signal {
        /// Listen address.
        #[arg(long, default_value = "127.0.0.1:3536", value_parser = address)]
        bind: SocketAddr,
        /// Rooms on this server need this secret (or SOFTSYNC_ROOM_KEY): a peer shows its
        /// proof or a join token, or is refused (HTTP 403) before it sees anyone.
        #[arg(long, value_name = "FILE")]
        room_key_file: Option<PathBuf>,
        /// Serve `wss://` with this certificate chain (PEM; with --tls-key).
        #[arg(long, value_name = "FILE", requires = "tls_key")]
        tls_cert: Option<PathBuf>,
        /// The certificate's private key (PEM).
        #[arg(long, value_name = "FILE", requires = "tls_cert")]
        tls_key: Option<PathBuf>,
        /// Connections at once, in all (more are refused with HTTP 503).
        #[arg(long, default_value_t = 1024, value_name = "N")]
        max_sockets: usize,
        /// Connections at once from one address (more are refused with HTTP 429). Behind a
        /// load balancer every connection comes from its address: raise this there.
        #[arg(long, default_value_t = 256, value_name = "N")]
        max_per_source: usize,
    },
    /// Print a join token for a room with a key: whoever shows it gets in once (the first
    /// peer to use it; that peer may come back with it) until it expires.
    Token {
        /// The room it admits to.
        #[arg(long, value_parser = room_name)]
        room: String,
        /// A file holding the room's secret (or SOFTSYNC_ROOM_KEY).
        #[arg(long, value_name = "FILE")]
        room_key_file: Option<PathBuf>,
        /// Seconds it stays valid.
        #[arg(long, default_value_t = 3600.0, value_parser = positive::<31_536_000>)]
        valid: f64,
    },
    /// Create the room and spawn the scene; embeds a signaling server on --bind unless
    /// --signal names one.
    Host {
        /// The embedded signaling server's address (port 0 picks one).
        #[arg(long, value_parser = address, conflicts_with = "signal")]
        bind: Option<SocketAddr>,
        /// An external signaling server (ws:// or wss://); several, comma-separated: the
        /// first reachable one.
        #[arg(long, value_parser = ws_url)]
        signal: Option<String>,
        #[command(flatten)]
        peer: PeerOpts,
    },
    /// Play back a session a host recorded (`host --store FILE --record`): its events at
    /// their times, its objects' states (--dump), a seek (--from), CSV (--export).
    Replay(ReplayArgs),
    /// List the sound devices voice can use (`--voice-device NAME`), inputs and outputs.
    AudioDevices,
    /// A store's recorded sessions: list them, delete one, prune old ones.
    Store {
        #[command(subcommand)]
        action: StoreAction,
    },
    /// Enter a room as a headless peer (a bot when --bot is given), a desktop peer
    /// (--desktop) or a VR peer (--vr).
    Join {
        /// The room's signaling server (e.g. ws://127.0.0.1:3536); several, comma-separated,
        /// are tried in order (one unreachable, or without the room, is passed over).
        #[arg(long, value_parser = ws_url)]
        signal: String,
        /// Serve the room's signaling here should this peer become host after a host that
        /// served it (`softsync host` without --signal) died; the room's members then register
        /// with it (give the others this address in their --signal lists for new peers).
        #[arg(long, value_parser = address)]
        bind: Option<SocketAddr>,
        #[command(flatten)]
        peer: PeerOpts,
    },
}

/// Options of `host` and `join`.
#[derive(Args, Debug)]
struct PeerOpts {
    /// The room's name (1-64 characters of A-Z a-z 0-9 - _ .).
    #[arg(long, value_parser = room_name)]
    room: String,
    /// A bot script: a file, a built-in name (squeeze, idle, wave), or inline commands
    /// separated by ';' (the language: peer/src/bot.rs).
    #[arg(long)]
    bot: Option<String>,
    /// Leave after S seconds (default: run until killed).
    #[arg(long, value_name = "S", value_parser = seconds)]
    duration: Option<f64>,
    /// Impair what this peer sends with the seeded link conditioner, e.g.
    /// "lat=40ms,jitter=8ms,loss=2%,seed=7" (also burst=…%, dup=…%, reorder=…%, mtu=…).
    #[arg(long, value_name = "SPEC", value_parser = condition)]
    net_condition: Option<ConditionerConfig>,
    /// JSON lines of the state this peer shows, --dump-hz times a second and at exit.
    #[arg(long, value_name = "FILE")]
    dump: Option<PathBuf>,
    /// Dump rate.
    #[arg(long, value_name = "HZ", default_value_t = 1.0, value_parser = positive::<240>)]
    dump_hz: f64,
    /// Replication rate of avatars and soft bodies (thesis 5.3).
    #[arg(long, value_name = "HZ", default_value_t = 20.0, value_parser = positive::<240>)]
    send_rate: f64,
    /// Ignore threshold for positions and particles, mm (0-1000).
    #[arg(long, value_name = "MM", default_value_t = 5.0, value_parser = threshold_mm)]
    threshold_mm: f32,
    /// Fixed simulation rate (at least 10).
    #[arg(long, value_name = "HZ", default_value_t = 60.0, value_parser = positive::<1000>)]
    sim_hz: f64,
    /// A scene file (.ron), or the name of one in --assets: thesis-room or bench-ball. The
    /// host spawns its objects (default: thesis-room). A joiner without --scene receives the
    /// room's scene and meshes from the first peer it reaches; one with a scene of other
    /// classes, settings, meshes or message types is refused at the handshake.
    #[arg(long)]
    scene: Option<String>,
    /// Where the shipped scenes and meshes are (default: ./assets, or next to the binary).
    #[arg(long, value_name = "DIR")]
    assets: Option<PathBuf>,
    /// An ICE server (stun:HOST:PORT, turn:HOST:PORT?transport=udp), repeatable; default none
    /// (LAN/loopback). Peers in two homes behind NAT routers reach each other through a TURN
    /// server (README: deploying a room server).
    #[arg(long, value_name = "URL")]
    ice: Vec<String>,
    /// The TURN servers' username (coturn's long-term credentials: `user=NAME:PASSWORD`).
    #[arg(long, value_name = "NAME", requires = "ice")]
    ice_user: Option<String>,
    /// A file holding the TURN password (kept off the command line); or set
    /// SOFTSYNC_ICE_CREDENTIAL.
    #[arg(long, value_name = "FILE", requires = "ice_user")]
    ice_credential_file: Option<PathBuf>,
    /// Give up joining after S seconds.
    #[arg(long, value_name = "S", default_value_t = 15.0, value_parser = positive::<3600>)]
    connect_timeout: f64,
    /// A peer the room went on without (it stalled or was cut off for longer than the failure
    /// detector allows, ~0.35 s by default; a stalled host is replaced) joins again, at most
    /// N times within a minute; 0: exit with code 3 instead.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u32).range(0..=1000))]
    rejoin_limit: u32,
    /// A file holding the room's secret: the host admits only peers that prove they hold
    /// the same (challenge and response; the secret never crosses the wire). Or set
    /// SOFTSYNC_ROOM_KEY. Use 16 or more random bytes.
    #[arg(long, value_name = "FILE")]
    room_key_file: Option<PathBuf>,
    /// The embedded signaling server (a host's, or a new host's after --takeover-bind)
    /// serves `wss://` with this certificate chain (PEM; with --tls-key).
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// The certificate's private key (PEM).
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// For `wss://` signaling whose certificate the web's roots do not vouch for: a PEM file
    /// of CA certificates to trust besides them.
    #[arg(long, value_name = "FILE")]
    tls_ca: Option<PathBuf>,
    /// A join token (`softsync token`) for a room with a key, instead of the key (or set
    /// SOFTSYNC_ROOM_TOKEN).
    #[arg(long, value_name = "TOKEN", value_parser = token)]
    room_token: Option<softsync_net::wire::RoomToken>,
    /// The fixed failure detector: a peer is gone after a second of silence (200 ms
    /// heartbeats). The default notices a dead host or member in about a third of a second
    /// (50 ms heartbeats and a timeout that adapts to each link's loss and jitter) and lets a
    /// peer stopped for less than 250 ms pass. Every peer of a room should choose the same.
    #[arg(long)]
    fixed_detection: bool,
    /// The default now (kept so older scripts run): see --fixed-detection.
    #[arg(long, hide = true, conflicts_with = "fixed_detection")]
    fast_detection: bool,
    /// The room takes at most N peers, the host included: a joiner beyond is refused with the
    /// reason (size a room to what its machines can serve). Every peer of the room must give
    /// the same (a new host after a migration keeps it).
    #[arg(long, value_name = "N", default_value_t = 64, value_parser = clap::value_parser!(u16).range(2..=64))]
    max_members: u16,
    /// Cap this peer's uplink at KBPS kilobits a second (datagrams plus their estimated
    /// transport overhead, shared by its links): held objects go first, then others by
    /// motion, nearness to each peer's head and waiting time.
    #[arg(long, value_name = "KBPS", value_parser = positive::<1_000_000>)]
    uplink_kbps: Option<f64>,
    /// Which way object state travels: `relay` (through the host, the default) or `direct`
    /// (each owner to every member; the host keeps membership and authority). Every peer of
    /// the room must give the same.
    #[arg(long, value_enum, default_value = "relay")]
    state_route: Route,
    /// `state` (owners send state) or `rollback` (all simulate all inputs: ggrs; headless).
    #[arg(long, value_enum, default_value = "state")]
    sync: SyncArg,
    /// Pump the network only in the frame, not on a thread of its own between frames (a slow
    /// frame then slows the room: for comparison).
    #[arg(long)]
    no_net_thread: bool,
    /// Keep the room in this store (a SQLite file, created if missing). A host reopens the
    /// room kept there — the same objects under the same ids, their tears and cuts, the
    /// retained messages — and writes it as the room runs (changes within 0.1 s, every moved
    /// state each --store-checkpoint); a joiner writes it if it becomes host. A store of
    /// another scene is refused.
    #[arg(long, value_name = "FILE", help_heading = "Keeping the room")]
    store: Option<String>,
    /// Start the room afresh from the scene, dropping what the store kept.
    #[arg(long, requires = "store", help_heading = "Keeping the room")]
    store_reset: bool,
    /// Record the session into the store while this peer hosts (`softsync replay` plays it
    /// back): every join, leave, migration, grab, authority change, tear, cut and message
    /// with its room time, and every object's shown state at 20 Hz when it changed.
    #[arg(long, requires = "store", help_heading = "Keeping the room")]
    record: bool,
    /// Delete recordings older than D (e.g. 30d) when the store opens: recordings of people
    /// are personal data.
    #[arg(long, value_name = "D", requires = "store", value_parser = keep::age, help_heading = "Keeping the room")]
    keep_recordings: Option<Duration>,
    /// Seconds between checkpoints of every moved state.
    #[arg(long, value_name = "S", default_value_t = 1.0, value_parser = positive::<3600>, help_heading = "Keeping the room")]
    store_checkpoint: f64,
    /// No stats lines.
    #[arg(long)]
    quiet: bool,
    /// Spawn no avatar (to measure one object's traffic).
    #[arg(long)]
    no_avatar: bool,
    /// A window: orbit camera, the right hand on the mouse (needs a build with --features
    /// desktop).
    #[arg(long, conflicts_with = "vr", help_heading = "Front ends")]
    desktop: bool,
    /// An OpenXR headset and controllers (SteamVR, Monado, …); without a runtime or headset
    /// it says why and opens the desktop peer (needs --features vr).
    #[arg(long, help_heading = "Front ends")]
    vr: bool,
    #[command(flatten)]
    view: ViewOpts,
    #[command(flatten)]
    voice: voice::VoiceOpts,
}

/// A usage error (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

fn err<T>(msg: impl Into<String>) -> Result<T, UsageError> {
    Err(UsageError(format!(
        "{}\n\nFor more information, try '--help'.",
        msg.into()
    )))
}

/// What to run.
#[derive(Clone, Debug)]
pub enum Command {
    /// Standalone signaling.
    Signal {
        /// Listen address.
        bind: SocketAddr,
        /// The rooms' secret's file.
        room_key_file: Option<PathBuf>,
        /// Certificate and key files for `wss://`.
        tls: Option<(PathBuf, PathBuf)>,
        /// Connections at once, in all.
        max_sockets: usize,
        /// Connections at once from one address.
        max_per_source: usize,
    },
    /// A peer.
    Peer(Box<PeerArgs>),
    /// A join token.
    Token {
        /// The room.
        room: String,
        /// The secret's file.
        room_key_file: Option<PathBuf>,
        /// Seconds valid.
        valid: f64,
    },
    /// Play a recording back.
    Replay(ReplayArgs),
    /// Manage a store's recordings.
    Store(StoreAction),
    /// List the sound devices.
    AudioDevices,
    /// Print this (help, or the version).
    Help(String),
}

/// Options of `host` and `join`.
#[derive(Clone, Debug)]
pub struct PeerArgs {
    /// Host or join.
    pub host: bool,
    /// Room.
    pub room: String,
    /// Embedded signaling bind address (host without --signal).
    pub bind: SocketAddr,
    /// A joiner's signaling address should it take over from a host that served it.
    pub takeover_bind: Option<SocketAddr>,
    /// External signaling URL.
    pub signal: Option<String>,
    /// Scene name or file (a joiner without one receives the room's).
    pub scene: Option<String>,
    /// Bot script source.
    pub bot: Option<String>,
    /// Run time.
    pub duration: Option<Duration>,
    /// Link conditioner.
    pub condition: Option<ConditionerConfig>,
    /// Dump file.
    pub dump: Option<PathBuf>,
    /// Dump rate.
    pub dump_hz: f64,
    /// Replication rate.
    pub send_rate_hz: f32,
    /// Ignore threshold (m).
    pub threshold_m: f32,
    /// Simulation rate.
    pub sim_hz: f64,
    /// Assets directory.
    pub assets: Option<PathBuf>,
    /// ICE servers.
    pub ice: Vec<String>,
    /// TURN username.
    pub ice_user: Option<String>,
    /// The file with the TURN password.
    pub ice_credential_file: Option<PathBuf>,
    /// Join timeout.
    pub connect_timeout: Duration,
    /// How many times to join again after the room went on without us.
    pub rejoin_limit: u32,
    /// The room secret's file.
    pub room_key_file: Option<PathBuf>,
    /// Certificate and key files for the embedded signaling server's `wss://`.
    pub tls: Option<(PathBuf, PathBuf)>,
    /// Extra CA certificates for `wss://` signaling.
    pub tls_ca: Option<PathBuf>,
    /// A join token.
    pub room_token: Option<softsync_net::wire::RoomToken>,
    /// The adaptive failure detector and 50 ms heartbeats (true unless --fixed-detection).
    pub fast_detection: bool,
    /// The room's size cap.
    pub max_members: usize,
    /// Pump the network in the frame only.
    pub no_net_thread: bool,
    /// Uplink cap, bytes a second.
    pub uplink_bytes_per_s: Option<u32>,
    /// Voice, if on.
    pub voice: Option<softsync_bevy::voice::VoiceOptions>,
    /// Our name and colour, if given.
    pub presence: Option<softsync_peer::messages::Presence>,
    /// Which way object state travels.
    pub state_route: softsync_net::StateRoute,
    /// Rollback (ggrs) rather than state sync.
    pub rollback: bool,
    /// The room's store.
    pub store: Option<softsync_bevy::StoreOptions>,
    /// No stats lines.
    pub quiet: bool,
    /// Spawn no avatar.
    pub no_avatar: bool,
    /// Which front end.
    pub front: FrontEnd,
    /// View options (desktop and VR; parsed and checked in every build).
    #[cfg_attr(not(feature = "desktop"), allow(dead_code))]
    pub view: ViewArgs,
}

/// How a peer is seen and driven.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrontEnd {
    /// No window: a bot or an idle peer.
    Headless,
    /// A window, mouse hands.
    Desktop,
    /// An OpenXR headset (desktop if none).
    Vr,
}

/// Parse `lat=40ms,jitter=8ms,loss=2%,seed=7`.
pub fn parse_condition(spec: &str) -> Result<ConditionerConfig, UsageError> {
    let mut c = ConditionerConfig::default();
    for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let Some((k, v)) = part.split_once('=') else {
            return err(format!("--net-condition: {part:?} is not key=value"));
        };
        let ms = |v: &str| -> Result<Duration, UsageError> {
            let n = v.strip_suffix("ms").unwrap_or(v);
            match n.parse::<f64>() {
                Ok(x) if x.is_finite() && (0.0..=10_000.0).contains(&x) => {
                    Ok(Duration::from_secs_f64(x / 1000.0))
                }
                _ => err(format!("--net-condition: {k}={v} must be 0-10000ms")),
            }
        };
        let pct = |v: &str| -> Result<f64, UsageError> {
            let n = v.strip_suffix('%').unwrap_or(v);
            match n.parse::<f64>() {
                Ok(x) if x.is_finite() && (0.0..=100.0).contains(&x) => Ok(x / 100.0),
                _ => err(format!("--net-condition: {k}={v} must be 0-100%")),
            }
        };
        match k {
            "lat" | "latency" => c.latency = ms(v)?,
            "jitter" => c.jitter = ms(v)?,
            "loss" => c.loss = pct(v)?,
            "burst" => {
                c.burst_loss = pct(v)?;
                c.p_enter_burst = 0.02;
                c.p_leave_burst = 0.3;
            }
            "dup" => c.duplicate = pct(v)?,
            "reorder" => {
                c.reorder = pct(v)?;
                c.reorder_delay = Duration::from_millis(30);
            }
            "seed" => {
                c.seed = v
                    .parse()
                    .map_err(|_| UsageError(format!("--net-condition: seed={v} is not an integer")))?
            }
            "mtu" => match v.parse::<usize>() {
                Ok(m) if (64..=65536).contains(&m) => c.mtu = Some(m),
                _ => return err(format!("--net-condition: mtu={v} must be 64-65536")),
            },
            other => {
                return err(format!(
                    "--net-condition: unknown key {other:?} (lat, jitter, loss, burst, dup, reorder, seed, mtu)"
                ))
            }
        }
    }
    Ok(c)
}

/// Parse the arguments after the program name. `Command::Help` carries the text to print
/// (`softsync`, `softsync help [COMMAND]`, `--help`, `--version`).
pub fn parse(args: &[String]) -> Result<Command, UsageError> {
    use clap::error::ErrorKind;
    let argv = std::iter::once("softsync".to_string()).chain(args.iter().cloned());
    let cli = match Cli::try_parse_from(argv) {
        Ok(c) => c,
        Err(e) => {
            let text = e.render().to_string();
            return match e.kind() {
                ErrorKind::DisplayHelp
                | ErrorKind::DisplayVersion
                | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => Ok(Command::Help(text)),
                _ => Err(UsageError(
                    text.trim_start_matches("error: ").trim_end().to_string(),
                )),
            };
        }
    };
    let Some(sub) = cli.command else {
        use clap::CommandFactory;
        return Ok(Command::Help(Cli::command().render_help().to_string()));
    };
    Ok(match sub {
        Sub::Signal {
            bind,
            room_key_file,
            tls_cert,
            tls_key,
            max_sockets,
            max_per_source,
        } => Command::Signal {
            bind,
            room_key_file,
            tls: tls_cert.zip(tls_key),
            max_sockets,
            max_per_source,
        },
        Sub::Token {
            room,
            room_key_file,
            valid,
        } => Command::Token {
            room,
            room_key_file,
            valid,
        },
        Sub::Replay(r) => Command::Replay(r),
        Sub::Store { action } => Command::Store(action),
        Sub::AudioDevices => Command::AudioDevices,
        Sub::Host { bind, signal, peer } => {
            let bind = bind.unwrap_or(SocketAddr::from(([127, 0, 0, 1], 3536)));
            Command::Peer(Box::new(peer_args(true, bind, signal, peer)?))
        }
        Sub::Join { signal, bind, peer } => {
            let mut a = peer_args(
                false,
                SocketAddr::from(([127, 0, 0, 1], 3536)),
                Some(signal),
                peer,
            )?;
            a.takeover_bind = bind;
            Command::Peer(Box::new(a))
        }
    })
}

/// `host`'s and `join`'s options, checked across flags.
fn peer_args(
    host: bool,
    bind: SocketAddr,
    signal: Option<String>,
    p: PeerOpts,
) -> Result<PeerArgs, UsageError> {
    let front = match (p.desktop, p.vr) {
        (true, _) => FrontEnd::Desktop,
        (false, true) => FrontEnd::Vr,
        (false, false) => FrontEnd::Headless,
    };
    if p.sync == SyncArg::Rollback && p.store.is_some() {
        return err("--store keeps state-sync rooms only (not --sync rollback)");
    }
    if front == FrontEnd::Headless {
        if let Some(f) = p.view.first_given() {
            return err(format!("--{f} needs --desktop or --vr"));
        }
        if p.voice.push_to_talk {
            return err("--push-to-talk needs --desktop or --vr (a key or a button to hold)");
        }
    }
    let v = p.view;
    let view = ViewArgs {
        window: v.window.unwrap_or((1280, 800)),
        focus: v.focus,
        particles: v.particles,
        hide_avatars: v.hide_avatars,
        no_hud: v.no_hud,
        world_labels: v.world_labels,
        screenshot_dir: v.screenshot_dir,
        screenshot_every: Duration::from_secs_f64(v.screenshot_every.unwrap_or(1.0)),
        screenshots: v.screenshots.unwrap_or(60),
    };
    Ok(PeerArgs {
        host,
        room: p.room,
        bind,
        takeover_bind: None,
        signal,
        scene: p.scene,
        bot: p.bot,
        duration: p.duration.map(Duration::from_secs_f64),
        condition: p.net_condition,
        dump: p.dump,
        dump_hz: p.dump_hz,
        send_rate_hz: p.send_rate as f32,
        threshold_m: p.threshold_mm / 1000.0,
        sim_hz: p.sim_hz.max(10.0),
        assets: p.assets,
        ice: p.ice,
        ice_user: p.ice_user,
        ice_credential_file: p.ice_credential_file,
        connect_timeout: Duration::from_secs_f64(p.connect_timeout),
        rejoin_limit: p.rejoin_limit,
        room_key_file: p.room_key_file,
        tls: p.tls_cert.zip(p.tls_key),
        tls_ca: p.tls_ca,
        room_token: p.room_token,
        fast_detection: p.fast_detection || !p.fixed_detection,
        max_members: usize::from(p.max_members),
        no_net_thread: p.no_net_thread,
        uplink_bytes_per_s: p.uplink_kbps.map(|k| (k * 125.0).round().max(1.0) as u32),
        voice: p.voice.options(front != FrontEnd::Headless),
        presence: p.voice.presence(),
        state_route: match p.state_route {
            Route::Relay => softsync_net::StateRoute::Relay,
            Route::Direct => softsync_net::StateRoute::Direct,
        },
        rollback: p.sync == SyncArg::Rollback,
        store: p.store.map(|target| softsync_bevy::StoreOptions {
            reset: p.store_reset,
            checkpoint: Duration::from_secs_f64(p.store_checkpoint.max(0.05)),
            record: p.record,
            keep_recordings: p.keep_recordings,
            ..softsync_bevy::StoreOptions::new(target)
        }),
        quiet: p.quiet,
        no_avatar: p.no_avatar,
        front,
        view,
    })
}

#[cfg(test)]
mod tests;
