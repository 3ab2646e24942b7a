//! Command-line parsing (no parser crate: the surface is small and errors name the flag).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use softsync_net::ConditionerConfig;

/// Usage text.
pub const USAGE: &str = "\
softsync — collaborative soft-body rooms, peer to peer

USAGE:
  softsync signal [--bind ADDR]
  softsync host --room NAME [--bind ADDR | --signal URL] [--scene SCENE] [PEER OPTIONS]
  softsync join --room NAME --signal URL [PEER OPTIONS]
  softsync bench net-live [--out DIR] [--seconds S] [--quick]
  softsync bench room-load [--out DIR] [--seconds S] [--peers 2,4,8]

signal          a standalone signaling server (default --bind 127.0.0.1:3536). Rooms that must
                outlive their host use one: new peers can still join after a migration.
host            creates the room and spawns the scene; embeds a signaling server on --bind
                (default 127.0.0.1:3536, port 0 picks one) unless --signal names one
join            enters a room as a headless peer (a bot when --bot is given), a desktop peer
                (--desktop) or a VR peer (--vr)

PEER OPTIONS:
  --bot SCRIPT          a bot script: a file, a built-in name (squeeze, idle, wave), or inline
                        commands separated by ';' (see peer/src/bot.rs)
  --duration S          leave after S seconds (default: run until killed)
  --net-condition SPEC  impair what this peer sends with the seeded link conditioner, e.g.
                        \"lat=40ms,jitter=8ms,loss=2%,seed=7\" (also burst=…%, dup=…%, mtu=…)
  --dump FILE           JSON lines of the state this peer shows, once per second and at exit
  --dump-hz HZ          dump rate (default 1)
  --send-rate HZ        replication rate of avatars and soft bodies (default 20; thesis 5.3)
  --threshold-mm MM     ignore threshold for positions and particles (default 5)
  --sim-hz HZ           fixed simulation rate (default 60)
  --scene SCENE         a scene file (.ron), or the name of one in --assets: thesis-room
                        (default) or bench-ball. The host spawns its objects; a joiner needs
                        the host's classes (a joiner with other classes, settings or meshes is
                        refused at the handshake)
  --assets DIR          where the shipped scenes and meshes are (default: ./assets, or next
                        to the binary)
  --ice URL             an ICE server (stun:/turn:), repeatable; default none (LAN/loopback)
  --connect-timeout S   give up joining after S seconds (default 15)
  --rejoin-limit N      a peer the room went on without (it stalled or was cut off for longer
                        than the 1 s peer timeout; a stalled host is replaced) joins the room
                        again, at most N times (default 3); 0: exit with code 3 instead
  --quiet               no stats lines
  --no-avatar           spawn no avatar (to measure one object's traffic)

FRONT ENDS (host or join; need a build with `--features desktop` or `--features vr`):
  --desktop             a window: orbit camera, the right hand on the mouse cursor; left
                        button grips (Ctrl: left hand), wheel reaches (Shift: zoom), E trigger,
                        right-drag orbits, middle-drag/WASDQZ pans, P particles, H HUD, R reset
  --vr                  an OpenXR headset and controllers (SteamVR, Monado, ...): head and grip
                        poses drive the avatar, squeeze grips, trigger triggers. Without a
                        runtime or headset it says why and opens the desktop peer instead
  --window WxH          desktop window size (default 1280x800)
  --focus KIND          start the camera close to an object (softbox, bunny, softball, ...)
  --particles           draw soft-body particles and their neighbour links (thesis Fig. 1.1)
  --hide-avatars        draw no avatars
  --no-hud              no HUD
  --screenshot-dir DIR  save frame-NNNN.png there every --screenshot-every S (default 1) and
                        print a line per frame (soft bodies' deformation and screen boxes);
                        at most --screenshots N (default 60)
  A bot script also runs on a desktop or VR peer: it then moves the hands relative to the
  tracked ones and its grip adds to the device's.

Every peer prints a stats line per second on stderr: peers, host, term, bytes/s up and down,
RTT, objects owned. Exit codes: 0 done, 1 runtime failure, 2 usage or input error, 3 cannot
reach the signaling server or the room, 130 stopped by Ctrl-C/SIGTERM/SIGHUP (after a last
dump and a Leave to the room).
";

/// Options that only a desktop or VR peer takes.
const VIEW_FLAGS: [&str; 8] = [
    "window",
    "focus",
    "particles",
    "hide-avatars",
    "no-hud",
    "screenshot-dir",
    "screenshot-every",
    "screenshots",
];

/// A usage error (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}\n(run `softsync help` for usage)")]
pub struct UsageError(pub String);

fn err<T>(msg: impl Into<String>) -> Result<T, UsageError> {
    Err(UsageError(msg.into()))
}

/// What to run.
#[derive(Clone, Debug)]
pub enum Command {
    /// Standalone signaling.
    Signal {
        /// Listen address.
        bind: SocketAddr,
    },
    /// A peer.
    Peer(Box<PeerArgs>),
    /// The live network benchmark.
    BenchNetLive {
        /// Output directory.
        out: PathBuf,
        /// Seconds per configuration.
        seconds: f64,
        /// Fewer configurations.
        quick: bool,
    },
    /// Rooms of growing size.
    BenchRoomLoad {
        /// Output directory.
        out: PathBuf,
        /// Seconds measured per room.
        seconds: f64,
        /// Room sizes (peers, host included).
        peers: Vec<usize>,
    },
    /// Usage.
    Help,
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
    /// External signaling URL.
    pub signal: Option<String>,
    /// Scene name.
    pub scene: String,
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
    /// Join timeout.
    pub connect_timeout: Duration,
    /// How many times to join again after the room went on without us.
    pub rejoin_limit: u32,
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

/// Options of the desktop and VR views.
#[derive(Clone, Debug)]
#[cfg_attr(not(feature = "desktop"), allow(dead_code))]
pub struct ViewArgs {
    /// Window size.
    pub window: (u32, u32),
    /// Start the camera at this kind of object.
    pub focus: Option<String>,
    /// Particle overlay.
    pub particles: bool,
    /// Draw no avatars.
    pub hide_avatars: bool,
    /// No HUD.
    pub no_hud: bool,
    /// Screenshot folder.
    pub screenshot_dir: Option<PathBuf>,
    /// Screenshot period.
    pub screenshot_every: Duration,
    /// Screenshot count.
    pub screenshots: u32,
}

fn secs(flag: &str, v: &str) -> Result<f64, UsageError> {
    match v.parse::<f64>() {
        Ok(s) if s.is_finite() && (0.0..1e7).contains(&s) => Ok(s),
        _ => err(format!("{flag}: {v:?} is not a number of seconds")),
    }
}

fn positive(flag: &str, v: &str, max: f64) -> Result<f64, UsageError> {
    match v.parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 && s <= max => Ok(s),
        _ => err(format!("{flag}: {v:?} must be a number in (0, {max}]")),
    }
}

fn addr(flag: &str, v: &str) -> Result<SocketAddr, UsageError> {
    v.parse().map_err(|_| {
        UsageError(format!(
            "{flag}: {v:?} is not an address like 127.0.0.1:3536"
        ))
    })
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

/// Parse the arguments after the program name.
pub fn parse(args: &[String]) -> Result<Command, UsageError> {
    let Some(cmd) = args.first() else {
        return Ok(Command::Help);
    };
    let rest = &args[1..];
    let mut flags: Vec<(String, Option<String>)> = Vec::new();
    let mut positional = Vec::new();
    let mut i = 0;
    while i < rest.len() {
        let a = &rest[i];
        if let Some(name) = a.strip_prefix("--") {
            let takes_value = !matches!(
                name,
                "quiet"
                    | "quick"
                    | "help"
                    | "no-avatar"
                    | "desktop"
                    | "vr"
                    | "particles"
                    | "hide-avatars"
                    | "no-hud"
            );
            if let Some((n, v)) = name.split_once('=') {
                flags.push((n.to_owned(), Some(v.to_owned())));
            } else if takes_value {
                let Some(v) = rest.get(i + 1) else {
                    return err(format!("--{name} needs a value"));
                };
                flags.push((name.to_owned(), Some(v.clone())));
                i += 1;
            } else {
                flags.push((name.to_owned(), None));
            }
        } else {
            positional.push(a.clone());
        }
        i += 1;
    }
    let get = |n: &str| -> Option<String> {
        flags
            .iter()
            .rev()
            .find(|(k, _)| k == n)
            .and_then(|(_, v)| v.clone())
    };
    let has = |n: &str| flags.iter().any(|(k, _)| k == n);
    let allowed = |ok: &[&str]| -> Result<(), UsageError> {
        for (k, _) in &flags {
            if !ok.contains(&k.as_str()) {
                return err(format!("{cmd}: unknown option --{k}"));
            }
        }
        Ok(())
    };
    match cmd.as_str() {
        "help" | "--help" | "-h" => Ok(Command::Help),
        "signal" => {
            allowed(&["bind"])?;
            let bind = addr(
                "--bind",
                &get("bind").unwrap_or_else(|| "127.0.0.1:3536".into()),
            )?;
            Ok(Command::Signal { bind })
        }
        "bench" => {
            allowed(&["out", "seconds", "quick", "peers"])?;
            let out = get("out")
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from("docs/results/live"));
            match positional.first().map(String::as_str) {
                Some("net-live") => Ok(Command::BenchNetLive {
                    out,
                    seconds: match get("seconds") {
                        Some(s) => positive("--seconds", &s, 600.0)?,
                        None => 8.0,
                    },
                    quick: has("quick"),
                }),
                Some("room-load") => {
                    let peers = get("peers").unwrap_or_else(|| "2,4,8".into());
                    let peers: Vec<usize> = peers
                        .split(',')
                        .map(|p| match p.trim().parse::<usize>() {
                            Ok(n) if (2..=32).contains(&n) => Ok(n),
                            _ => err(format!("--peers: {p:?} must be 2-32")),
                        })
                        .collect::<Result<_, _>>()?;
                    Ok(Command::BenchRoomLoad {
                        out,
                        seconds: match get("seconds") {
                            Some(s) => positive("--seconds", &s, 600.0)?,
                            None => 10.0,
                        },
                        peers,
                    })
                }
                other => err(format!(
                    "bench: unknown benchmark {other:?} (net-live, room-load)"
                )),
            }
        }
        "host" | "join" => {
            let host = cmd == "host";
            let mut ok = vec![
                "room",
                "signal",
                "bot",
                "duration",
                "net-condition",
                "dump",
                "dump-hz",
                "send-rate",
                "threshold-mm",
                "sim-hz",
                "assets",
                "scene",
                "ice",
                "connect-timeout",
                "rejoin-limit",
                "quiet",
                "no-avatar",
                "desktop",
                "vr",
            ];
            ok.extend(VIEW_FLAGS);
            if host {
                ok.push("bind");
            }
            allowed(&ok)?;
            if let Some(p) = positional.first() {
                return err(format!("{cmd}: unexpected argument {p:?}"));
            }
            let room =
                get("room").ok_or_else(|| UsageError(format!("{cmd}: --room NAME is required")))?;
            if !softsync_net_matchbox::valid_room_name(&room) {
                return err(format!(
                    "--room: {room:?} is not a room name (1-64 characters of A-Z a-z 0-9 - _ .)"
                ));
            }
            let signal = get("signal");
            if !host && signal.is_none() {
                return err("join: --signal URL is required (e.g. ws://127.0.0.1:3536)");
            }
            if host && signal.is_some() && has("bind") {
                return err("host: --bind and --signal exclude each other");
            }
            if let Some(s) = &signal {
                if !(s.starts_with("ws://") || s.starts_with("wss://")) {
                    return err(format!("--signal: {s:?} is not a ws:// or wss:// URL"));
                }
            }
            let scene = get("scene").unwrap_or_else(|| "thesis-room".into());
            let front = match (has("desktop"), has("vr")) {
                (true, true) => return err("--desktop and --vr exclude each other"),
                (true, false) => FrontEnd::Desktop,
                (false, true) => FrontEnd::Vr,
                (false, false) => FrontEnd::Headless,
            };
            if front == FrontEnd::Headless {
                if let Some(f) = VIEW_FLAGS.iter().find(|f| has(f)) {
                    return err(format!("--{f} needs --desktop or --vr"));
                }
            }
            let window = match get("window") {
                Some(w) => match w
                    .split_once('x')
                    .map(|(a, b)| (a.parse::<u32>(), b.parse::<u32>()))
                {
                    Some((Ok(a), Ok(b)))
                        if (64..=8192).contains(&a) && (64..=8192).contains(&b) =>
                    {
                        (a, b)
                    }
                    _ => return err(format!("--window: {w:?} is not WIDTHxHEIGHT (64-8192)")),
                },
                None => (1280, 800),
            };
            let view = ViewArgs {
                window,
                focus: get("focus"),
                particles: has("particles"),
                hide_avatars: has("hide-avatars"),
                no_hud: has("no-hud"),
                screenshot_dir: get("screenshot-dir").map(PathBuf::from),
                screenshot_every: match get("screenshot-every") {
                    Some(s) => Duration::from_secs_f64(positive("--screenshot-every", &s, 3600.0)?),
                    None => Duration::from_secs(1),
                },
                screenshots: match get("screenshots") {
                    Some(s) => match s.parse::<u32>() {
                        Ok(n) if (1..=100_000).contains(&n) => n,
                        _ => return err(format!("--screenshots: {s:?} must be 1-100000")),
                    },
                    None => 60,
                },
            };
            Ok(Command::Peer(Box::new(PeerArgs {
                host,
                room,
                bind: addr(
                    "--bind",
                    &get("bind").unwrap_or_else(|| "127.0.0.1:3536".into()),
                )?,
                signal,
                scene,
                bot: get("bot"),
                duration: match get("duration") {
                    Some(s) => Some(Duration::from_secs_f64(secs("--duration", &s)?)),
                    None => None,
                },
                condition: match get("net-condition") {
                    Some(s) => Some(parse_condition(&s)?),
                    None => None,
                },
                dump: get("dump").map(PathBuf::from),
                dump_hz: match get("dump-hz") {
                    Some(s) => positive("--dump-hz", &s, 240.0)?,
                    None => 1.0,
                },
                send_rate_hz: match get("send-rate") {
                    Some(s) => positive("--send-rate", &s, 240.0)? as f32,
                    None => 20.0,
                },
                threshold_m: match get("threshold-mm") {
                    Some(s) => match s.parse::<f32>() {
                        Ok(v) if v.is_finite() && (0.0..=1000.0).contains(&v) => v / 1000.0,
                        _ => return err(format!("--threshold-mm: {s:?} must be 0-1000")),
                    },
                    None => 0.005,
                },
                sim_hz: match get("sim-hz") {
                    Some(s) => positive("--sim-hz", &s, 1000.0)?.max(10.0),
                    None => 60.0,
                },
                assets: get("assets").map(PathBuf::from),
                ice: flags
                    .iter()
                    .filter(|(k, _)| k == "ice")
                    .filter_map(|(_, v)| v.clone())
                    .collect(),
                connect_timeout: match get("connect-timeout") {
                    Some(s) => Duration::from_secs_f64(positive("--connect-timeout", &s, 3600.0)?),
                    None => Duration::from_secs(15),
                },
                rejoin_limit: match get("rejoin-limit") {
                    Some(s) => match s.parse::<u32>() {
                        Ok(n) if n <= 1000 => n,
                        _ => return err(format!("--rejoin-limit: {s:?} must be 0-1000")),
                    },
                    None => 3,
                },
                quiet: has("quiet"),
                no_avatar: has("no-avatar"),
                front,
                view,
            })))
        }
        other => err(format!(
            "unknown command {other:?}: signal, host, join, bench or help"
        )),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn front_end_flags_parse() {
        let Command::Peer(p) = parse(&args(
            "join --room lab --signal ws://127.0.0.1:9 --desktop --window 320x240 --focus softbox \
             --particles --hide-avatars --no-hud --screenshot-dir /tmp/x --screenshot-every 0.5 \
             --screenshots 9",
        ))
        .unwrap() else {
            panic!()
        };
        assert_eq!(p.front, FrontEnd::Desktop);
        assert_eq!(p.view.window, (320, 240));
        assert_eq!(p.view.focus.as_deref(), Some("softbox"));
        assert!(p.view.particles && p.view.hide_avatars && p.view.no_hud);
        assert_eq!(p.view.screenshot_every, Duration::from_millis(500));
        assert_eq!(p.view.screenshots, 9);
        let Command::Peer(p) = parse(&args("host --room lab --vr")).unwrap() else {
            panic!()
        };
        assert_eq!(p.front, FrontEnd::Vr);
        assert_eq!(p.view.window, (1280, 800));
        let Command::Peer(p) = parse(&args("host --room lab")).unwrap() else {
            panic!()
        };
        assert_eq!(p.front, FrontEnd::Headless);
    }

    #[test]
    fn flags_parse_and_bad_ones_are_named() {
        let Command::Peer(p) = parse(&args(
            "join --room lab --signal ws://127.0.0.1:9 --duration 3 --net-condition lat=40ms,jitter=8ms,loss=2%,seed=7",
        ))
        .unwrap() else {
            panic!()
        };
        assert!(!p.host);
        assert_eq!(p.duration, Some(Duration::from_secs(3)));
        let c = p.condition.unwrap();
        assert_eq!(c.latency, Duration::from_millis(40));
        assert_eq!(c.jitter, Duration::from_millis(8));
        assert!((c.loss - 0.02).abs() < 1e-12);
        assert_eq!(c.seed, 7);
        for (bad, says) in [
            ("join --room lab", "--signal"),
            ("join --signal ws://x:1", "--room"),
            ("host --room a/b", "room name"),
            ("host --room a --frob 1", "unknown option --frob"),
            ("join --room a --signal http://x", "ws://"),
            ("host --room a --net-condition loss=200%", "0-100%"),
            ("host --room a --net-condition lag=3", "unknown key"),
            ("host --room a --duration soon", "seconds"),
            ("host --room a --bind nowhere", "address"),
            ("host --room a --dump", "needs a value"),
            ("fly", "unknown command"),
            ("host --room a --desktop --vr", "exclude"),
            ("host --room a --window 10x10", "--window"),
            ("host --room a --desktop --window 800", "--window"),
            ("host --room a --particles", "needs --desktop or --vr"),
            ("host --room a --vr --screenshots 0", "--screenshots"),
        ] {
            let e = parse(&args(bad)).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
