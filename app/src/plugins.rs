//! The bevy side of a peer: plugins that wrap the network session, the soft-body simulation
//! and the reports. The headless peer runs on `MinimalPlugins` with the simulation in
//! `FixedUpdate` at the simulation rate.
//!
//! Frame order (every loop iteration: ~250 Hz headless, the frame rate with a window):
//! 1. `PreUpdate` — [`NetPlugin`]: datagrams in, session timers and events. Desktop/VR front
//!    ends then read their device frame (mouse hands, or OpenXR poses after bevy_mod_xr has
//!    located its spaces), so this frame's fixed steps use it.
//! 2. `FixedUpdate` (0..n times, at `--sim-hz`) — [`SimPlugin`]: the bot and/or the device set
//!    the hands, hands update (authority requests), remote objects are shown, soft bodies and
//!    rapier step, owned objects are published.
//! 3. `Update` — with a window or headset only: the view copies the room into bevy entities
//!    (poses, deformed soft meshes, tints, avatars, HUD).
//! 4. `PostUpdate` — [`NetPlugin`]: datagrams out. Then bevy renders.
//! 5. `Last` — [`ReportPlugin`]: stats line, dump, the end of `--duration`.

use std::collections::VecDeque;
use std::time::Duration;

use bevy::app::{App, AppExit, FixedUpdate, Last, Plugin, PostUpdate, PreUpdate};
use bevy::ecs::message::{MessageReader, MessageWriter};
use bevy::ecs::schedule::{IntoScheduleConfigs, SystemSet};
use bevy::ecs::system::NonSendMut;

use crate::bot::Bot;
use crate::device::DeviceFrame;
use crate::report::{snapshot, Dump, StatsLine};
use crate::room::{Note, Room};

/// Everything one peer owns: the room (session, transport, world) and its drivers.
pub struct Peer {
    /// The room.
    pub room: Room,
    /// The bot, if any.
    pub bot: Option<Bot>,
    /// This frame's tracked device (desktop or VR front end), if any.
    pub device: Option<DeviceFrame>,
    /// False while a front end warms up (window, renderer, XR session): the network is not
    /// pumped, so nobody sees us join and then time out during the first frames' stalls
    /// (measured: an OpenXR session start on a software renderer froze the loop for over the
    /// session's 1 s peer timeout). Headless peers start ready.
    pub ready: bool,
    /// Room name.
    pub room_name: String,
    /// Leave after this long.
    pub duration: Option<Duration>,
    /// Give up joining after this long.
    pub connect_timeout: Duration,
    /// Dump.
    pub dump: Option<Dump>,
    /// Dump period.
    pub dump_every: Duration,
    /// No stats lines.
    pub quiet: bool,
    /// The last rates of the stats line (the HUD shows them).
    pub last_rates: crate::report::Rates,
    /// The last few events (the HUD shows them).
    pub recent_events: VecDeque<String>,
    /// Kept alive while the peer runs (the host's embedded signaling server): held, never
    /// read; dropping it stops the server.
    #[allow(dead_code)]
    pub signal: Option<softsync_net_matchbox::SignalServer>,
    stats: StatsLine,
    next_stats: Duration,
    next_dump: Duration,
    exiting: bool,
}

impl Peer {
    /// A peer around `room`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        room: Room,
        bot: Option<Bot>,
        room_name: String,
        duration: Option<Duration>,
        connect_timeout: Duration,
        dump: Option<Dump>,
        dump_hz: f64,
        quiet: bool,
        signal: Option<softsync_net_matchbox::SignalServer>,
    ) -> Self {
        Peer {
            room,
            bot,
            device: None,
            ready: true,
            room_name,
            duration,
            connect_timeout,
            dump,
            dump_every: Duration::from_secs_f64(1.0 / dump_hz.max(0.01)),
            quiet,
            last_rates: crate::report::Rates::default(),
            recent_events: VecDeque::new(),
            signal,
            stats: StatsLine::default(),
            next_stats: Duration::from_secs(1),
            next_dump: Duration::ZERO,
            exiting: false,
        }
    }

    /// The front end is up: start pumping the network (and counting the join timeout).
    #[cfg_attr(not(feature = "desktop"), allow(dead_code))]
    pub fn set_ready(&mut self) {
        if !self.ready {
            self.ready = true;
            self.room.start_join_clock();
            println!(
                "front end ready after {:.1} s: entering the room",
                self.room.now().as_secs_f64()
            );
        }
    }

    fn write_dump(&mut self) {
        if self.dump.is_some() {
            let line = snapshot(&mut self.room);
            if let Some(d) = &mut self.dump {
                if let Err(e) = d.write(&line) {
                    eprintln!("dump: {e}; no more dumps");
                    self.dump = None;
                }
            }
        }
    }
}

fn fail(exit: &mut MessageWriter<AppExit>, peer: &mut Peer, msg: String, code: u8) {
    eprintln!("error: {msg}");
    peer.write_dump();
    peer.exiting = true;
    exit.write(AppExit::from_code(code));
}

fn net_in(mut peer: NonSendMut<Peer>, mut exit: MessageWriter<AppExit>) {
    if peer.exiting || !peer.ready {
        return;
    }
    let p = &mut *peer;
    if let Err(e) = p.room.pump() {
        fail(&mut exit, p, e.to_string(), 3);
        return;
    }
    if let Err(e) = p.room.join_deadline_passed(&p.room_name, p.connect_timeout) {
        fail(&mut exit, p, e.to_string(), 3);
        return;
    }
    for n in std::mem::take(&mut p.room.notes) {
        let line = match n {
            Note::Joined { host, term } => format!("joined host={} term={}", host.0, term.0),
            Note::HostChanged { host, term } => {
                format!("host-changed host={} term={}", host.0, term.0)
            }
            Note::PeerJoined(q) => format!("peer-joined {}", q.0),
            Note::PeerLeft(q) => format!("peer-left {}", q.0),
            Note::AuthorityAsked(id) => format!("authority-asked object={}", id.0),
            Note::AuthorityGained(id) => format!("authority-gained object={}", id.0),
            Note::AuthorityDenied(id) => format!("authority-denied object={}", id.0),
            Note::AuthorityReleased(id) => format!("authority-released object={}", id.0),
            Note::GrabStarted { id, hand, particle } => format!(
                "grab-started object={} hand={}{}",
                id.0,
                ["left", "right"].get(hand).unwrap_or(&"?"),
                particle.map_or(String::new(), |p| format!(" particle={p}"))
            ),
            Note::GrabEnded { id, hand, speed } => format!(
                "grab-ended object={} hand={} speed={speed:.2}m/s",
                id.0,
                ["left", "right"].get(hand).unwrap_or(&"?")
            ),
            Note::Rejoining { host, reason } => {
                format!("rejoining host={} reason={reason:?}", host.0)
            }
        };
        let t = p.room.now().as_secs_f64();
        println!("event peer={} t={t:.2} {line}", p.room.me().0);
        if p.recent_events.len() >= 6 {
            p.recent_events.pop_front();
        }
        p.recent_events
            .push_back(format!("{t:.1}s {}", hud_event(&line)));
    }
}

/// An event line with its peer ids shortened for the HUD.
fn hud_event(line: &str) -> String {
    // The reason of a rejoin is for the log; the HUD keeps one short line per event.
    let line = line.split(" reason=").next().unwrap_or(line);
    line.split(' ')
        .map(|w| {
            let (k, v) = w.split_once('=').unwrap_or(("", w));
            match v.parse::<u64>() {
                Ok(id) if v.len() > 8 => {
                    let id = format!("{:06x}", id & 0xff_ffff);
                    if k.is_empty() {
                        id
                    } else {
                        format!("{k}={id}")
                    }
                }
                _ => w.to_owned(),
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn net_out(mut peer: NonSendMut<Peer>) {
    // Not before the front end is ready either: a `Hello` flushed early makes the host count
    // us a member, and time us out while we warm up (seen in CI: an XR session took 5 s).
    if peer.ready {
        peer.room.flush();
    }
}

fn simulate(mut peer: NonSendMut<Peer>) {
    let p = &mut *peer;
    if !p.room.joined() || p.exiting {
        return;
    }
    match (&mut p.bot, &p.device) {
        (Some(bot), device) => bot.step_with(&mut p.room, device.as_ref()),
        (None, Some(device)) => device.apply(&mut p.room),
        (None, None) => {}
    }
    p.room.fixed_step();
}

fn report(mut peer: NonSendMut<Peer>, mut exit: MessageWriter<AppExit>) {
    let p = &mut *peer;
    if p.exiting {
        return;
    }
    let t = Duration::from_micros(p.room.now().as_micros());
    if t >= p.next_stats {
        p.next_stats = t + Duration::from_secs(1);
        let (line, rates) = p.stats.line(&p.room);
        if !p.quiet {
            eprintln!("{line}");
        }
        p.last_rates = rates;
    }
    if t >= p.next_dump && p.room.joined() {
        p.next_dump = t + p.dump_every;
        p.write_dump();
    }
    if p.duration.is_some_and(|d| t >= d) {
        exit.write(AppExit::Success);
    }
}

/// Whoever asked to exit (`--duration`, Ctrl-C, an error): a last dump and stats line, and a
/// `Leave` to the room so the others act at once (a host is replaced, authority returns).
fn on_exit(mut peer: NonSendMut<Peer>, mut exits: MessageReader<AppExit>) {
    if exits.read().next().is_none() {
        return;
    }
    let p = &mut *peer;
    if !p.exiting {
        p.write_dump();
        let (line, _) = p.stats.line(&p.room);
        println!("final {line}");
        p.exiting = true;
    }
    if p.room.joined() {
        p.room.leave();
    }
}

/// The system set of datagrams in (device front ends run after it).
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct NetIn;

/// Datagrams in and out around the frame.
pub struct NetPlugin;

impl Plugin for NetPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(PreUpdate, net_in.in_set(NetIn))
            .add_systems(PostUpdate, net_out);
    }
}

/// The fixed-rate simulation: bot, hands, soft bodies, rapier, publishing.
pub struct SimPlugin;

impl Plugin for SimPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(FixedUpdate, simulate);
    }
}

/// Stats line, dump, and leaving at the end of `--duration`.
pub struct ReportPlugin;

impl Plugin for ReportPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(Last, (report, on_exit).chain());
    }
}
