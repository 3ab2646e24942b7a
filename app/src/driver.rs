//! [`Driver`]: what the `softsync` binary adds around the library's [`Room`]: a bot or a
//! tracked device for the hands, the log lines, the stats line and the dump, and the end of
//! the run (`--duration`, errors). The room itself — transport, clock, network in and out,
//! fixed steps, leaving — is `softsync-bevy`'s, run by its plugin as any user's app runs it;
//! the systems in `plugins.rs` call into the driver at their places around it.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::time::Duration;

use softsync_bevy::{ConnectTimes, Room};
use softsync_net::Event as RoomEvent;
use softsync_peer::messages::MessageTypes;
use softsync_peer::{Bot, DeviceFrame, Event, Say};
use softsync_rollback::script::SqueezeThrow;

use crate::report::{Rates, StatsLine};
use softsync_peer::dump::{snapshot, Dump};

/// The binary's side of one peer: its bot or device and its reports.
pub struct Driver {
    /// The bot, if any.
    pub bot: Option<Bot>,
    /// This frame's tracked device (desktop or VR front end), if any.
    pub device: Option<DeviceFrame>,
    /// Leave after this long.
    pub duration: Option<Duration>,
    /// Dump.
    pub dump: Option<Dump>,
    /// Dump period.
    pub dump_every: Duration,
    /// No stats lines.
    pub quiet: bool,
    /// The last rates of the stats line (the HUD shows them).
    pub last_rates: Rates,
    /// The last few events (the HUD shows them).
    pub recent_events: VecDeque<String>,
    stats: StatsLine,
    next_stats: Duration,
    next_dump: Duration,
    /// Exiting: no more bot, reports or events.
    pub exiting: bool,
    /// `--bot throw`: the rollback bench's squeeze-and-throw motion (the same a rollback
    /// peer's bot makes), with its frame count, instead of a script.
    pub throw: Option<(SqueezeThrow, i32)>,
    /// A joiner's timeline, printed once it shows the room's first state.
    pub join_timeline: Option<JoinTimeline>,
    /// In a played-back recording's room (`softsync replay --serve`): where it stands, as
    /// its host last said, and when we heard it (the HUD's timeline, the desktop's keys).
    pub replay_clock: Option<(softsync_peer::messages::ReplayClock, softsync_net::Instant)>,
}

/// Where a played-back recording stands now, seconds into it: its host's last word, moved on
/// by the time since at its speed (unless paused).
#[cfg_attr(not(feature = "desktop"), allow(dead_code))]
pub fn replay_position(
    clock: &(softsync_peer::messages::ReplayClock, softsync_net::Instant),
    now: softsync_net::Instant,
) -> f64 {
    let (c, at) = clock;
    if c.paused {
        return c.t_s;
    }
    (c.t_s + now.saturating_since(*at).as_secs_f64() * c.speed).min(c.length_s)
}

/// Where a joiner's time went, in milliseconds since the process started (the clock the
/// `SOFTSYNC_LOG` records carry): the room's [`ConnectTimes`], then the Welcome and the first
/// state the peer shows. One line, `join timeline ms: …`, which `softsync bench join` reads.
pub struct JoinTimeline {
    marks: Vec<(&'static str, f64)>,
    welcome: Option<f64>,
}

impl JoinTimeline {
    /// From the room's connect times.
    pub fn new(t: &ConnectTimes) -> Self {
        let ms = |i: std::time::Instant| {
            crate::stderr_log::since_start_ms() - i.elapsed().as_secs_f64() * 1e3
        };
        let mut marks = vec![("start", ms(t.started)), ("registered", ms(t.registered))];
        if let Some(c) = t.contact {
            marks.push(("contact", ms(c)));
        }
        if let Some(s) = t.scene {
            marks.push(("scene", ms(s)));
        }
        marks.push(("opened", ms(t.opened)));
        JoinTimeline {
            marks,
            welcome: None,
        }
    }

    /// Once a frame: the line, when this frame first shows an object of the room.
    fn frame(&mut self, room: &mut Room) -> Option<String> {
        if !room.peer.joined() {
            return None;
        }
        let now_ms = crate::stderr_log::since_start_ms();
        let welcome = *self.welcome.get_or_insert(now_ms);
        let me = room.peer.me();
        let now = room.now();
        let ids: Vec<_> = room
            .peer
            .objects()
            .iter()
            .filter(|(_, o)| o.avatar_of != Some(me))
            .map(|(id, _)| *id)
            .collect();
        if !ids
            .into_iter()
            .any(|id| room.peer.shown_state(now, id).is_some())
        {
            return None;
        }
        let mut line = String::from("join timeline ms:");
        for (name, t) in self
            .marks
            .iter()
            .copied()
            .chain([("welcome", welcome), ("first_state", now_ms)])
        {
            line += &format!(" {name}={t:.1}");
        }
        Some(line)
    }
}

impl Driver {
    /// A driver with `bot`, ending after `duration`, dumping to `dump`.
    pub fn new(
        bot: Option<Bot>,
        duration: Option<Duration>,
        dump: Option<Dump>,
        dump_hz: f64,
        quiet: bool,
    ) -> Self {
        Driver {
            bot,
            device: None,
            duration,
            dump,
            dump_every: Duration::from_secs_f64(1.0 / dump_hz.max(0.01)),
            quiet,
            last_rates: Rates::default(),
            recent_events: VecDeque::new(),
            stats: StatsLine::default(),
            throw: None,
            join_timeline: None,
            next_stats: Duration::from_secs(1),
            next_dump: Duration::ZERO,
            exiting: false,
            replay_clock: None,
        }
    }

    /// The front end is up: the room starts pumping the network (and counting the join
    /// timeout).
    #[cfg_attr(not(feature = "desktop"), allow(dead_code))]
    pub fn set_ready(room: &mut Room) {
        if room.set_ready() {
            println!(
                "front end ready after {:.1} s: entering the room",
                room.now().as_secs_f64()
            );
        }
    }

    /// A peer event: its log line and the HUD's list (warnings to stderr as they are).
    pub fn log_event(&mut self, room: &Room, e: &Event) {
        if let Event::Room(softsync_net::Event::Message(m)) = e {
            if let Some(Ok(c)) = room.peer.decode::<softsync_peer::messages::ReplayClock>(m) {
                self.replay_clock = Some((c, room.now()));
                return;
            }
        }
        let Some(line) = event_line(e, room.peer.message_types()) else {
            if let Event::Warning(w) = e {
                eprintln!("{w}");
            }
            return;
        };
        let t = room.now().as_secs_f64();
        // the room clock (every peer reads it alike) beside this process's own
        let at = room.peer.session().room_time(room.now());
        let rt = at.map_or_else(|| "-".to_string(), |d| format!("{:.3}", d.as_secs_f64()));
        println!(
            "event peer={} t={t:.2} room_t={rt} {line}",
            room.peer.me().0
        );
        if self.recent_events.len() >= 6 {
            self.recent_events.pop_front();
        }
        self.recent_events
            .push_back(format!("{t:.1}s {}", hud_event(&line)));
    }

    /// The voice's news as event lines: `voice_said room_ms=…` (our --voice-in started, its
    /// first sample at that room time), `voice_speaking peer=… on=…`; its warnings to stderr.
    pub fn log_voice(&mut self, room: &mut Room) {
        let me = room.peer.me().0;
        let t = room.now().as_secs_f64();
        let Some(v) = room.voice() else {
            return;
        };
        for e in v.drain_events().collect::<Vec<_>>() {
            let line = match e {
                softsync_bevy::voice::VoiceEvent::Said { room_ms } => {
                    format!("voice_said room_ms={room_ms:.1}")
                }
                softsync_bevy::voice::VoiceEvent::Speaking { peer, on } => {
                    format!("voice_speaking peer={} on={on}", peer.0)
                }
                softsync_bevy::voice::VoiceEvent::Stats {
                    sent_bytes,
                    frames,
                    bitrate,
                    relayed,
                    drops,
                    heard,
                    mic,
                    speaker,
                    echo_ref_ms,
                    echo_found,
                } => {
                    let mut line = format!(
                        "voice_stats sent_bytes={sent_bytes} frames={} silent={} bitrate={bitrate} relayed={relayed} dropped={} malformed={} not_member={} wrong_speaker={} not_host={} flood={}",
                        frames.0, frames.1, drops.total(), drops.malformed, drops.not_member,
                        drops.wrong_speaker, drops.not_host, drops.flood
                    );
                    for (p, s) in heard {
                        let st = s.stats;
                        let _ = write!(
                            line,
                            " heard={}:played={},fec={},concealed={},late={},delay_ms={:.1},target_ms={:.1}",
                            p.0, st.played, st.fec, st.concealed, st.late,
                            s.delay_ms.unwrap_or(f64::NAN), s.target_ms
                        );
                    }
                    if let Some(ms) = echo_ref_ms {
                        let _ = write!(line, " echo_ref_ms={ms:.0}");
                    }
                    if let Some((ms, r)) = echo_found {
                        let _ = write!(line, " echo_found_ms={ms:.0} echo_r={r:.2}");
                    }
                    for (side, d) in [("mic", mic), ("speaker", speaker)] {
                        if let Some(d) = d {
                            let _ = write!(
                                line,
                                " {side}=samples:{},underruns:{},overruns:{},glitches:{}",
                                d.samples, d.underruns, d.overruns, d.glitches
                            );
                        }
                    }
                    line
                }
                softsync_bevy::voice::VoiceEvent::Devices {
                    input,
                    output,
                    processing,
                } => {
                    let name =
                        |d: Option<String>| d.map_or_else(|| "-".to_owned(), |n| format!("{n:?}"));
                    format!(
                        "voice_devices input={} output={} echo_cancel={} noise_suppress={} gain_control={}",
                        name(input),
                        name(output),
                        processing.echo_cancel,
                        processing.noise_suppress,
                        processing.gain_control
                    )
                }
                softsync_bevy::voice::VoiceEvent::Warning(w) => {
                    eprintln!("{w}");
                    continue;
                }
            };
            println!("event peer={me} t={t:.2} {line}");
            if self.recent_events.len() >= 6 {
                self.recent_events.pop_front();
            }
            self.recent_events.push_back(format!("{t:.1}s {line}"));
        }
    }

    /// Before a fixed step: the bot and/or the device set the hands.
    pub fn drive_hands(&mut self, room: &mut Room) {
        if !room.peer.joined() || self.exiting || room.has_left() {
            return;
        }
        let now = room.now();
        let me = room.peer.me().0;
        if let (Some(d), Some(v)) = (&self.device, room.voice()) {
            v.set_talk_held(d.talk);
        }
        match (&mut self.bot, &self.device) {
            (Some(bot), device) => {
                bot.step(now, &mut room.peer, device.as_ref());
                while let Some(msg) = bot.poll_message() {
                    let t = room.now().as_secs_f64();
                    println!("bot peer={me} t={t:.2} {msg}");
                }
            }
            (None, Some(device)) => device.apply(&mut room.peer),
            (None, None) => {
                if let Some((throw, frame)) = self.throw.as_mut() {
                    *frame += 1;
                    // the scene's objects in spawn order, as this peer shows them now
                    let ids: Vec<_> = room
                        .peer
                        .objects()
                        .iter()
                        .filter(|(_, o)| !o.kind.is_avatar())
                        .map(|(id, _)| *id)
                        .collect();
                    let centers: Vec<_> = ids
                        .iter()
                        .map(|id| room.peer.drawn_pose(now, *id).map(|p| p.0))
                        .collect();
                    let d =
                        throw.device_at(*frame, ids.len(), &|i| centers.get(i).copied().flatten());
                    d.apply(&mut room.peer);
                }
            }
        }
    }

    /// The stats line once a second, the dump at its rate; true when `--duration` is over.
    pub fn report(&mut self, room: &mut Room) -> bool {
        if let Some(line) = self.join_timeline.as_mut().and_then(|j| j.frame(room)) {
            println!("{line}");
            self.join_timeline = None;
        }
        let now = room.now();
        self.stats.frame(now);
        let t = Duration::from_micros(now.as_micros());
        if t >= self.next_stats {
            self.next_stats = t + Duration::from_secs(1);
            let (line, rates) = self.stats.line(now, &room.peer);
            let line = line + &relayed_links(room);
            if !self.quiet {
                eprintln!("{line}");
            }
            self.last_rates = rates;
        }
        if t >= self.next_dump && room.peer.joined() {
            self.next_dump = t + self.dump_every;
            self.write_dump(room);
        }
        self.duration.is_some_and(|d| t >= d)
    }

    /// Stop for `msg`: say why, a last dump, no more frames.
    pub fn fail(&mut self, room: &mut Room, msg: &str) {
        eprintln!("error: {msg}");
        self.write_dump(room);
        self.exiting = true;
    }

    /// The run is over (whoever asked): a last dump and stats line. (The plugin then sends
    /// the `Leave`.)
    pub fn finish(&mut self, room: &mut Room) {
        if !self.exiting {
            self.write_dump(room);
            let (line, _) = self.stats.line(room.now(), &room.peer);
            println!("final {line}{}", relayed_links(room));
            self.exiting = true;
        }
    }

    fn write_dump(&mut self, room: &mut Room) {
        if self.dump.is_some() {
            let wall_ms = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_millis() as u64);
            let line = snapshot(room.now(), wall_ms, &mut room.peer);
            if let Some(d) = &mut self.dump {
                if let Err(e) = d.write(&line) {
                    eprintln!("dump: {e}; no more dumps");
                    self.dump = None;
                }
            }
        }
    }
}

/// The log line of an event (after `event peer=… t=…`); None for warnings, which go to stderr
/// as they are.
fn event_line(e: &Event, types: &MessageTypes) -> Option<String> {
    let hand_name = |hand: usize| *["left", "right"].get(hand).unwrap_or(&"?");
    Some(match e {
        Event::Room(RoomEvent::Joined { host, term }) => {
            format!("joined host={} term={}", host.0, term.0)
        }
        Event::Room(RoomEvent::HostChanged { host, term }) => {
            format!("host-changed host={} term={}", host.0, term.0)
        }
        Event::Room(RoomEvent::PeerJoined(q)) => format!("peer-joined {}", q.0),
        Event::Room(RoomEvent::PeerLeft(q)) => format!("peer-left {}", q.0),
        Event::Room(RoomEvent::Message(m)) => match types.decode::<Say>(m) {
            Some(Ok(say)) => format!("message from={} say={:?}", m.from.0, say.text),
            _ => format!(
                "message from={} kind={} bytes={}",
                m.from.0,
                types.name(m.kind).unwrap_or("?"),
                m.payload.len()
            ),
        },
        Event::Room(RoomEvent::MessageDelivered { seq }) => format!("message-delivered seq={seq}"),
        Event::Room(RoomEvent::MessageRefused { seq, reason }) => {
            format!("message-refused seq={seq} reason={:?}", reason.to_string())
        }
        Event::Room(_) | Event::Warning(_) => return None,
        Event::AuthorityAsked(id) => format!("authority-asked object={}", id.0),
        Event::AuthorityGained(id) => format!("authority-gained object={}", id.0),
        Event::AuthorityDenied(id) => format!("authority-denied object={}", id.0),
        Event::AuthorityReleased(id) => format!("authority-released object={}", id.0),
        Event::GrabStarted { id, hand, particle } => format!(
            "grab-started object={} hand={}{}",
            id.0,
            hand_name(*hand),
            particle.map_or(String::new(), |p| format!(" particle={p}"))
        ),
        Event::GrabEnded { id, hand, speed } => format!(
            "grab-ended object={} hand={} speed={speed:.2}m/s",
            id.0,
            hand_name(*hand)
        ),
        Event::Rejoining { host, reason } => {
            format!("rejoining host={} reason={reason:?}", host.0)
        }
        Event::Holders { id, hands } => format!(
            "holders object={} hands={}",
            id.0,
            if hands.is_empty() {
                "-".to_owned()
            } else {
                hands
                    .iter()
                    .map(|h| {
                        format!(
                            "{}:{}:{}",
                            h.peer.0,
                            hand_name(usize::from(h.hand)),
                            h.particle
                        )
                    })
                    .collect::<Vec<_>>()
                    .join(",")
            }
        ),
        Event::ReturnedHome { id, from } => format!(
            "returned-home object={} from={:.2},{:.2},{:.2}",
            id.0, from.x, from.y, from.z
        ),
    })
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

/// ` relayed=ID,…`: the peers we reach through a TURN relay (nothing when none is).
fn relayed_links(room: &Room) -> String {
    let ids: Vec<String> = room
        .peer
        .session()
        .stats()
        .links
        .keys()
        .filter(|p| room.is_relayed(**p) == Some(true))
        .map(|p| p.0.to_string())
        .collect();
    if ids.is_empty() {
        String::new()
    } else {
        format!(" relayed={}", ids.join(","))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use softsync_net::{NetId, PeerId, Term};

    #[test]
    fn event_lines_keep_the_format_the_live_tests_parse() {
        let types = softsync_peer::messages::builtin();
        let host = PeerId(12_345_678_901);
        let (kind, payload) = types.encode(&Say { text: "hi".into() }).unwrap();
        let said = Event::Room(RoomEvent::Message(softsync_net::ReceivedMessage {
            from: host,
            kind,
            to: softsync_net::MessageTarget::Everyone,
            delivery: softsync_net::Delivery::Reliable,
            payload,
        }));
        assert_eq!(
            event_line(&said, &types).as_deref(),
            Some("message from=12345678901 say=\"hi\"")
        );
        let joined = Event::Room(RoomEvent::Joined {
            host,
            term: Term(2),
        });
        assert_eq!(
            event_line(&joined, &types).as_deref(),
            Some("joined host=12345678901 term=2")
        );
        let grab = Event::GrabStarted {
            id: NetId(5),
            hand: 1,
            particle: Some(17),
        };
        assert_eq!(
            event_line(&grab, &types).as_deref(),
            Some("grab-started object=5 hand=right particle=17")
        );
        let ended = Event::GrabEnded {
            id: NetId(5),
            hand: 0,
            speed: 0.256,
        };
        assert_eq!(
            event_line(&ended, &types).as_deref(),
            Some("grab-ended object=5 hand=left speed=0.26m/s")
        );
        let rejoin = Event::Rejoining {
            host,
            reason: "the room moved on".into(),
        };
        let line = event_line(&rejoin, &types).unwrap_or_default();
        assert_eq!(
            line,
            "rejoining host=12345678901 reason=\"the room moved on\""
        );
        assert_eq!(hud_event(&line), "rejoining host=dc1c35");
        assert_eq!(event_line(&Event::Warning("x".into()), &types), None);
        assert_eq!(
            event_line(&Event::Room(RoomEvent::Despawned(NetId(1))), &types),
            None
        );
    }
}
