//! [`RoomVoice`]: a room's voice, driven by the room on its clock — capture every 20 ms from
//! the microphone (a sound device through `cpal`, echo-cancelled, denoised and levelled by
//! [`softsync_voice::processing`]) and/or a WAV file (a bot's voice: `--voice-in`), frames
//! to the room along the route ([`softsync_net::voice`]), frames heard into the jitter
//! buffers ([`softsync_voice::VoiceChat`]), a block played every 20 ms to the loudspeaker
//! and/or the sink (WAV files: `--voice-out`), reports to speakers once a second, and the room's message API told when
//! this peer mutes or starts and stops speaking ([`VoiceState`]).
//!
//! Timing: the capture and playback clocks tick every 20 ms of this machine's clock, caught
//! up when a frame or pump ran late (a late block is still played at its own room time, so
//! recordings stay on one timeline). A frame is stamped with the room time of its first
//! sample, so every listener plays it at a known delay from when it was said.
//!
//! Devices: a peer opens only what its options name (desktop and VR peers the system's
//! default; bots none). One that is absent or fails, at the start or later, gives a
//! [`VoiceEvent::Warning`] and the peer goes on silent on that side.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use glam::{Quat, Vec3};
use softsync_net::voice::{Heard, RoutePolicy, VoiceDrops, VoiceRouter};
use softsync_net::{Delivery, Instant, MessageTarget, PeerId, Transmit, Transport};
use softsync_peer::messages::VoiceState;
use softsync_peer::scene::Kind;
use softsync_peer::Peer;
use softsync_voice::device::{AudioIn, AudioOut, DeviceChoice, DeviceStats};
use softsync_voice::files::{WavSink, WavSource};
use softsync_voice::processing::{MicProcessor, ProcessingConfig};
use softsync_voice::{SpeakerStatus, VoiceChat, VoiceConfig, FRAME_SAMPLES};

const FRAME: Duration = Duration::from_millis(20);
const REPORT_EVERY: Duration = Duration::from_secs(1);
const STATS_EVERY: u32 = 5;
/// How far the voice may run ahead of the lips, ms (audio that leads is noticed sooner than
/// audio that lags; ITU-R BT.1359 puts detection at about 45 ms lead).
const LIP_LEAD_MS: f64 = 30.0;
/// A speaking avatar's head is shown one send interval late (not two), with the usual jitter
/// allowance: the voice buffer can then match it without adding much delay.
const HEAD_INTERPOLATION: softsync_net::InterpolationConfig = softsync_net::InterpolationConfig {
    intervals: 1.0,
    jitter_factor: 2.0,
    max_extrapolation: Duration::from_millis(50),
    snap_distance_m: 2.0,
};
/// Blocks caught up at most after a stall (more are skipped: 200 ms).
const MAX_CATCH_UP: u32 = 10;

/// How a peer speaks and listens (`softsync join … --voice-in F --voice-out D`).
#[derive(Clone, Debug, PartialEq)]
pub struct VoiceOptions {
    /// A WAV file this peer says (a bot's voice), at [`say_after`](Self::say_after) and then
    /// every [`say_every`](Self::say_every).
    pub input: Option<PathBuf>,
    /// Seconds after joining before it is first said.
    pub say_after: f64,
    /// Say it again this many seconds after each start (0: once).
    pub say_every: f64,
    /// A folder to write what this peer plays (`mix.wav`, `peer-ID.wav`, `voice.json`).
    pub output: Option<PathBuf>,
    /// How frames travel.
    pub route: RoutePolicy,
    /// Start muted.
    pub muted: bool,
    /// Codec and buffer settings.
    pub config: VoiceConfig,
    /// Move this peer's head with its voice (a bot's "mouth": the head rises with the level),
    /// which is how the benchmark sees lip-sync from outside.
    pub nod: bool,
    /// The microphone to open, if any.
    pub input_device: Option<DeviceChoice>,
    /// The loudspeaker or headset to open, if any.
    pub output_device: Option<DeviceChoice>,
    /// The microphone's processing (echo cancellation only runs when something is played on
    /// a device too).
    pub processing: ProcessingConfig,
    /// Send only while the talk key or button is held ([`RoomVoice::set_talk_held`]).
    pub push_to_talk: bool,
}

impl Default for VoiceOptions {
    fn default() -> Self {
        VoiceOptions {
            input: None,
            say_after: 1.0,
            say_every: 0.0,
            output: None,
            route: RoutePolicy::Auto,
            muted: false,
            config: VoiceConfig::default(),
            nod: false,
            input_device: None,
            output_device: None,
            processing: ProcessingConfig::default(),
            push_to_talk: false,
        }
    }
}

/// What the voice did, for the front end's log.
#[derive(Clone, Debug, PartialEq)]
pub enum VoiceEvent {
    /// The input file started, its first sample at this room time (ms).
    Said {
        /// Room time of the first sample, ms.
        room_ms: f64,
    },
    /// A speaker started or stopped being heard here.
    Speaking {
        /// Who.
        peer: PeerId,
        /// Speaking now.
        on: bool,
    },
    /// Every 5 s: what we sent and what we heard of each speaker.
    Stats {
        /// Voice bytes sent (frames, relays, reports).
        sent_bytes: u64,
        /// Frames sent, and frames not sent for silence.
        frames: (u64, u64),
        /// The encoder's bitrate now.
        bitrate: i32,
        /// Frames relayed as host.
        relayed: u64,
        /// Voice datagrams dropped, by reason.
        drops: VoiceDrops,
        /// Each speaker as heard here.
        heard: Vec<(PeerId, SpeakerStatus)>,
        /// The microphone's ring, if one is open.
        mic: Option<DeviceStats>,
        /// The loudspeaker's ring, if one is open.
        speaker: Option<DeviceStats>,
        /// How far back the echo canceller's reference is taken, ms (the devices' round
        /// trip), when it runs.
        echo_ref_ms: Option<f64>,
        /// Where the echo was found by correlation (ms back, Pearson's r), once it was.
        echo_found: Option<(f64, f64)>,
    },
    /// The sound devices opened: their names.
    Devices {
        /// The microphone.
        input: Option<String>,
        /// The loudspeaker or headset.
        output: Option<String>,
        /// The microphone's processing.
        processing: ProcessingConfig,
    },
    /// Something went wrong that does not stop the room (a file that cannot be written, a
    /// sound device absent or lost).
    Warning(String),
}

/// A room's voice (see the module's doc).
pub struct RoomVoice {
    opts: VoiceOptions,
    chat: VoiceChat,
    router: VoiceRouter,
    source: Option<WavSource>,
    sink: Option<WavSink>,
    mic: Option<AudioIn>,
    speaker: Option<AudioOut>,
    processor: Option<MicProcessor>,
    /// The loudspeaker's latency when the last block was queued.
    out_latency: Duration,
    capture_next: Option<Instant>,
    play_next: Option<Instant>,
    report_next: Option<Instant>,
    say_next: Option<Instant>,
    /// The first saying was scheduled.
    scheduled: bool,
    speaking: BTreeMap<PeerId, bool>,
    announced: Option<(VoiceState, softsync_net::NetId)>,
    events: Vec<VoiceEvent>,
    out: Vec<Transmit>,
    /// Room time of the newest block played, ms.
    last_block_ms: Option<f64>,
    /// Our head's rest height, when it nods.
    nod_base: Option<(Vec3, Quat)>,
    /// Report rounds, for the stats every [`STATS_EVERY`].
    rounds: u32,
    /// Remote heads given [`HEAD_INTERPOLATION`].
    heads_set: std::collections::BTreeSet<softsync_net::NetId>,
}

impl std::fmt::Debug for RoomVoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RoomVoice")
            .field("opts", &self.opts)
            .finish()
    }
}

/// Room time in ms at local time `at`, from the room's clock read at `now`.
fn room_ms(peer: &Peer, now: Instant, at: Instant) -> Option<f64> {
    let r = peer.session().room_time(now)?;
    let back = now.saturating_since(at);
    Some((r.as_secs_f64() - back.as_secs_f64()) * 1000.0)
}

impl RoomVoice {
    /// Voice with these options: the input file read, the output folder made.
    pub fn new(opts: VoiceOptions) -> Result<Self, String> {
        let chat = VoiceChat::new(opts.config).map_err(|e| e.to_string())?;
        let source = match &opts.input {
            Some(p) => Some(WavSource::open(p).map_err(|e| format!("--voice-in: {e}"))?),
            None => None,
        };
        let sink = match &opts.output {
            Some(d) => Some(WavSink::create(d).map_err(|e| format!("--voice-out: {e}"))?),
            None => None,
        };
        let mut chat = chat;
        chat.set_muted(opts.muted);
        if opts.push_to_talk {
            chat.set_push_to_talk(Some(false));
        }
        let mut events = Vec::new();
        let mut warn = |side: &str, e: &dyn std::fmt::Display, then: &str| {
            events.push(VoiceEvent::Warning(format!(
                "voice: no {side} ({e}): {then}"
            )));
        };
        let mic = opts.input_device.as_ref().and_then(|c| {
            AudioIn::open(c)
                .map_err(|e| warn("microphone", &e, "this peer is silent"))
                .ok()
        });
        let speaker = opts.output_device.as_ref().and_then(|c| {
            AudioOut::open(c)
                .map_err(|e| warn("loudspeaker", &e, "this peer plays nothing aloud"))
                .ok()
        });
        // echo cancellation needs both ends on devices (a file's voice has no echo)
        let mut processing = opts.processing;
        processing.echo_cancel &= speaker.is_some();
        let processor = match mic.as_ref().map(|_| MicProcessor::new(processing)) {
            Some(Ok(p)) => p,
            Some(Err(e)) => {
                warn("voice processing", &e, "the microphone is sent as it is");
                None
            }
            None => None,
        };
        if mic.is_some() || speaker.is_some() {
            events.push(VoiceEvent::Devices {
                input: mic.as_ref().map(|m| m.name().to_owned()),
                output: speaker.as_ref().map(|s| s.name().to_owned()),
                processing: processor
                    .as_ref()
                    .map_or(ProcessingConfig::OFF, MicProcessor::config),
            });
        }
        Ok(RoomVoice {
            opts,
            chat,
            router: VoiceRouter::default(),
            source,
            sink,
            mic,
            speaker,
            processor,
            out_latency: Duration::ZERO,
            capture_next: None,
            play_next: None,
            report_next: None,
            say_next: None,
            scheduled: false,
            speaking: BTreeMap::new(),
            announced: None,
            events,
            out: Vec::new(),
            last_block_ms: None,
            nod_base: None,
            rounds: 0,
            heads_set: Default::default(),
        })
    }

    /// The voice engine (mute, push-to-talk, volumes, who is speaking).
    pub fn chat(&mut self) -> &mut VoiceChat {
        &mut self.chat
    }

    /// The talk key or button, held or not (the front end calls this every frame): with
    /// push-to-talk on, frames are sent only while it is held; otherwise it does nothing.
    pub fn set_talk_held(&mut self, held: bool) {
        if self.opts.push_to_talk {
            self.chat.set_push_to_talk(Some(held));
        }
    }

    /// Whether this peer talks only while a key is held.
    pub fn push_to_talk(&self) -> bool {
        self.opts.push_to_talk
    }

    /// Whether our frames go out now (not muted, and the talk key held under push-to-talk).
    pub fn transmitting(&self) -> bool {
        self.chat.transmitting()
    }

    /// The microphone's and the loudspeaker's names, when open.
    pub fn devices(&self) -> (Option<&str>, Option<&str>) {
        (
            self.mic.as_ref().map(AudioIn::name),
            self.speaker.as_ref().map(AudioOut::name),
        )
    }

    /// What we hear of `peer`.
    pub fn status(&self, peer: PeerId) -> Option<SpeakerStatus> {
        self.chat.status(peer)
    }

    /// Our microphone is muted.
    pub fn muted(&self) -> bool {
        self.chat.muted()
    }

    /// The speakers heard speaking now, with their level (dBFS): for indicators and mouths.
    pub fn speaking(&self) -> Vec<(PeerId, f32)> {
        self.chat
            .speakers()
            .into_iter()
            .filter_map(|p| {
                let s = self.chat.status(p)?;
                s.speaking.then_some((p, s.level_db))
            })
            .collect()
    }

    /// Voice datagrams dropped, by reason.
    pub fn drops(&self) -> VoiceDrops {
        self.router.drops()
    }

    /// Voice bytes sent, and frames relayed as host.
    pub fn traffic(&self) -> (u64, u64) {
        (self.router.sent_bytes(), self.router.relayed())
    }

    /// The events since the last call.
    pub fn drain_events(&mut self) -> std::vec::Drain<'_, VoiceEvent> {
        self.events.drain(..)
    }

    /// Room time of the newest block played, ms.
    pub fn last_block_ms(&self) -> Option<f64> {
        self.last_block_ms
    }

    /// A voice datagram from `from`.
    pub fn handle(
        &mut self,
        now: Instant,
        peer: &mut Peer,
        transport: &mut dyn Transport,
        from: PeerId,
        bytes: &[u8],
    ) {
        let heard = self
            .router
            .handle(now, peer.session(), from, bytes, &mut self.out);
        self.send_out(now, peer, transport);
        match heard {
            Some(Heard::Frame { speaker, frame }) => {
                if let Some(t) = room_ms(peer, now, now) {
                    self.chat.hear(t, speaker, frame);
                }
            }
            Some(Heard::Report { listener, report }) => self.chat.on_report(listener, report),
            None => {}
        }
    }

    fn send_out(&mut self, now: Instant, peer: &mut Peer, transport: &mut dyn Transport) {
        for t in self.out.drain(..) {
            peer.charge_uplink(now, t.to, t.payload.len());
            transport.send(now, &t);
        }
    }

    /// Capture, play and report what is due by `now`; announce our state when it changed.
    pub fn tick(&mut self, now: Instant, peer: &mut Peer, transport: &mut dyn Transport) {
        if !peer.joined() || peer.session().room_time(now).is_none() {
            return;
        }
        let capture_next = *self.capture_next.get_or_insert(now + FRAME);
        let play_next = *self.play_next.get_or_insert(now);
        let report_next = *self.report_next.get_or_insert(now + REPORT_EVERY);
        if !self.scheduled && self.source.is_some() {
            self.scheduled = true;
            self.say_next = Some(now + Duration::from_secs_f64(self.opts.say_after.max(0.0)));
        }
        self.device_errors();
        // nothing to capture without a source or a microphone
        if self.source.is_some() || self.mic.is_some() {
            self.capture(now, capture_next, peer, transport);
        }
        self.play(now, play_next, peer);
        if now >= report_next {
            self.report_next = Some(now + REPORT_EVERY);
            for (to, r) in self.chat.reports() {
                self.router.send_report(to, r, &mut self.out);
            }
            self.send_out(now, peer, transport);
            // voice goes first in the uplink budget, its bitrate at most half a link's share
            // less its 50 packets' headers and transport overhead (at low caps that overhead
            // is most of it: the encoder then runs at its floor, 8 kb/s)
            let cap = peer.session().uplink_share().map(|bytes| {
                let overhead = 50.0 * (softsync_net::stats::TRANSPORT_OVERHEAD_BYTES + 13) as f64;
                ((bytes / 2.0 - overhead).max(0.0) * 8.0) as i32
            });
            self.chat.set_cap(cap);
            self.rounds += 1;
            if self.rounds % STATS_EVERY == 0 {
                let heard = self
                    .chat
                    .speakers()
                    .into_iter()
                    .filter_map(|p| Some((p, self.chat.status(p)?)))
                    .collect();
                self.events.push(VoiceEvent::Stats {
                    sent_bytes: self.router.sent_bytes(),
                    frames: self.chat.sent(),
                    bitrate: self.chat.bitrate(),
                    relayed: self.router.relayed(),
                    drops: self.router.drops(),
                    heard,
                    mic: self.mic.as_ref().map(AudioIn::stats),
                    speaker: self.speaker.as_ref().map(AudioOut::stats),
                    echo_ref_ms: self
                        .processor
                        .as_ref()
                        .filter(|p| p.config().echo_cancel)
                        .map(|p| p.reference_delay_blocks() as f64 * 20.0),
                    echo_found: self
                        .processor
                        .as_ref()
                        .and_then(MicProcessor::echo_estimate)
                        .map(|(b, r)| (b as f64 * 20.0, r)),
                });
            }
        }
        self.announce(now, peer);
    }

    fn capture(
        &mut self,
        now: Instant,
        mut due: Instant,
        peer: &mut Peer,
        transport: &mut dyn Transport,
    ) {
        if now < due {
            return; // the pump runs every 4 ms: most calls have nothing due
        }
        // the room's route: relay when any link to a member other than the host is TURNed
        let session = peer.session();
        let me = session.local_id();
        let host = session.host_id();
        let turned = session
            .members()
            .keys()
            .filter(|p| **p != me && Some(**p) != host)
            .any(|p| transport.relayed(*p) != Some(false));
        let route = self.opts.route.route(turned);
        let mut n = 0;
        while now >= due && n < MAX_CATCH_UP {
            n += 1;
            if let (Some(src), Some(say)) = (&mut self.source, self.say_next) {
                if due >= say {
                    src.start();
                    self.say_next = (self.opts.say_every > 0.0)
                        .then(|| say + Duration::from_secs_f64(self.opts.say_every));
                }
            }
            let (mut pcm, first) = match &mut self.mic {
                Some(m) => {
                    let mut f = m.next_frame();
                    if let Some(p) = &mut self.processor {
                        // a block queued now is heard after `out_latency`; this frame ended
                        // `latency` ago and began a frame before that
                        let trip = self.out_latency + m.latency() + FRAME;
                        p.set_device_delay(trip.as_secs_f64() * 1000.0);
                        p.process(&mut f);
                    }
                    (f, false)
                }
                None => ([0i16; FRAME_SAMPLES], false),
            };
            // a file's voice is mixed over the microphone
            let (file, first) = match &mut self.source {
                Some(s) => s.next_frame(),
                None => ([0i16; FRAME_SAMPLES], first),
            };
            for (p, f) in pcm.iter_mut().zip(file) {
                *p = p.saturating_add(f);
            }
            // the frame that completes at `due` began 20 ms before
            let begun = Instant::from_micros(due.as_micros().saturating_sub(20_000));
            if let Some(t) = room_ms(peer, now, begun) {
                if first {
                    self.events.push(VoiceEvent::Said { room_ms: t });
                }
                if let Some(f) = self.chat.capture(t, &pcm) {
                    self.router
                        .send_frame(peer.session(), route, &f, &mut self.out);
                }
            }
            due += FRAME;
        }
        if now >= due {
            // a stall longer than the catch-up: start again from now
            due = now + FRAME;
        }
        self.capture_next = Some(due);
        self.send_out(now, peer, transport);
        if self.opts.nod {
            self.nod(peer);
        }
    }

    /// A device that failed while running is dropped, with a warning.
    fn device_errors(&mut self) {
        if let Some(e) = self.mic.as_mut().and_then(AudioIn::error) {
            self.events.push(VoiceEvent::Warning(format!(
                "voice: the microphone failed ({e}): this peer is silent"
            )));
            self.mic = None;
            self.processor = None;
        }
        if let Some(e) = self.speaker.as_mut().and_then(AudioOut::error) {
            self.events.push(VoiceEvent::Warning(format!(
                "voice: the loudspeaker failed ({e}): nothing is played aloud"
            )));
            self.speaker = None;
        }
    }

    /// A bot's head rises with its voice (up to 5 cm at full scale).
    fn nod(&mut self, peer: &mut Peer) {
        let Some(head) = peer.avatar_parts()[0] else {
            return;
        };
        let Some(o) = peer.objects().get(&head) else {
            return;
        };
        let (pos, rot) = *self.nod_base.get_or_insert(o.pose);
        let db = self.chat.own().level_db;
        let lift = ((db - softsync_voice::level::FLOOR_DB) / -softsync_voice::level::FLOOR_DB)
            .clamp(0.0, 1.0)
            * 0.05;
        peer.set_avatar_pose(0, pos + Vec3::Y * lift, rot);
    }

    fn play(&mut self, now: Instant, mut due: Instant, peer: &mut Peer) {
        if now < due {
            return;
        }
        // the listener's head, and every speaker's, as shown here
        let me = peer.me();
        let mut listener = None;
        let mut heads = BTreeMap::new();
        let ids: Vec<_> = peer
            .objects()
            .iter()
            .filter(|(_, o)| o.kind == Kind::HEAD)
            .filter_map(|(id, o)| Some((*id, o.avatar_of?)))
            .collect();
        let lip_sync = self.opts.config.lip_sync;
        for (id, who) in ids {
            if lip_sync && who != me && self.heads_set.insert(id) {
                peer.set_object_interpolation(id, Some(HEAD_INTERPOLATION));
            }
            if let Some(s) = peer.shown_state(now, id) {
                if who == me {
                    listener = Some((s.pos, s.rot));
                } else {
                    heads.insert(who, s.pos);
                    if lip_sync {
                        self.lip_sync(now, peer, who, id);
                    }
                }
            }
        }
        let mut n = 0;
        while now >= due && n < MAX_CATCH_UP {
            n += 1;
            let Some(t) = room_ms(peer, now, due) else {
                break;
            };
            let block = self.chat.play(t, listener, &heads);
            self.last_block_ms = Some(t);
            if let Some(out) = &mut self.speaker {
                self.out_latency = out.latency();
                out.play(&block.stereo);
                if let Some(p) = &mut self.processor {
                    p.played(&block.stereo);
                }
            }
            if let Some(sink) = &mut self.sink {
                let shown: Vec<(PeerId, Vec3)> = heads.iter().map(|(p, v)| (*p, *v)).collect();
                let written = sink
                    .write(t, &block.stereo, &block.speakers)
                    .and_then(|()| sink.write_heads(t, &shown));
                if let Err(e) = written {
                    self.events
                        .push(VoiceEvent::Warning(format!("voice out: {e}")));
                    self.sink = None;
                }
            }
            due += FRAME;
        }
        if now >= due {
            due = now + FRAME;
        }
        self.play_next = Some(due);
        for p in self.chat.speakers() {
            let on = self.chat.status(p).is_some_and(|s| s.speaking);
            if self.speaking.insert(p, on).unwrap_or(false) != on {
                self.events.push(VoiceEvent::Speaking { peer: p, on });
            }
        }
        // a speaker who left: forgotten
        let members = peer.session().members();
        let gone: Vec<PeerId> = self
            .chat
            .speakers()
            .into_iter()
            .filter(|p| !members.contains_key(p))
            .collect();
        for p in gone {
            self.chat.forget(p);
            if self.speaking.remove(&p) == Some(true) {
                self.events
                    .push(VoiceEvent::Speaking { peer: p, on: false });
            }
        }
    }

    /// Hold `who`'s voice back to about when its head is shown: the head's interpolation delay
    /// plus its path (the voice's own fastest transit less the frame, and when state goes
    /// through the host and neither of us is it, one more hop and half the host's send
    /// interval), less [`LIP_LEAD_MS`].
    fn lip_sync(&mut self, now: Instant, peer: &mut Peer, who: PeerId, head: softsync_net::NetId) {
        let Some(fastest) = self.chat.status(who).and_then(|s| s.fastest_transit_ms) else {
            return;
        };
        let Some(delay) = peer.display_delay(now, head) else {
            return;
        };
        let session = peer.session();
        let host = session.host_id();
        let relayed = session.config().state_route == softsync_net::StateRoute::Relay
            && !session.is_host()
            && host != Some(who);
        // a relayed state is stamped when the host relays it (at its send tick, half an
        // interval late on average), so the head's interpolation does not see that wait
        let hop = if relayed {
            let to_host = host
                .and_then(|h| session.stats().links.get(&h)?.rtt)
                .map_or(0.0, |r| r.as_secs_f64() * 500.0);
            let tick = session
                .class_of(head)
                .and_then(|c| session.config().classes.get(usize::from(c.0)))
                .map_or(0.0, |c| c.send.interval().as_secs_f64() * 500.0);
            to_host + tick
        } else {
            0.0
        };
        let avatar_ms = delay.as_secs_f64() * 1000.0 + (fastest - 20.0).max(0.0) + hop;
        self.chat.set_lip_sync(who, avatar_ms - LIP_LEAD_MS);
    }

    fn announce(&mut self, now: Instant, peer: &mut Peer) {
        let state = VoiceState {
            muted: self.chat.muted(),
            speaking: self.chat.own().speaking(),
        };
        // kept with our head (a joiner learns it with the head; it goes when we go)
        let Some(head) = peer.avatar_parts()[0] else {
            return;
        };
        if self.announced == Some((state, head)) {
            return;
        }
        if peer
            .send(
                now,
                MessageTarget::Everyone,
                Delivery::ObjectState(head),
                &state,
            )
            .is_ok()
        {
            self.announced = Some((state, head));
        }
    }

    /// Write what the sink holds (headers, `voice.json`).
    pub fn finish(&mut self) {
        if let Some(s) = &mut self.sink {
            if let Err(e) = s.flush() {
                self.events
                    .push(VoiceEvent::Warning(format!("voice out: {e}")));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn an_absent_device_is_a_warning_and_a_silent_peer_not_an_error() {
        let mut v = RoomVoice::new(VoiceOptions {
            input_device: Some(DeviceChoice::Named("no-such-microphone-softsync".into())),
            output_device: Some(DeviceChoice::Named("no-such-speaker-softsync".into())),
            push_to_talk: true,
            ..VoiceOptions::default()
        })
        .unwrap();
        let warnings: Vec<String> = v
            .drain_events()
            .filter_map(|e| match e {
                VoiceEvent::Warning(w) => Some(w),
                _ => None,
            })
            .collect();
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(warnings[0].contains("no microphone") && warnings[0].contains("silent"));
        assert!(warnings[1].contains("no loudspeaker"));
        assert_eq!(v.devices(), (None, None));
        // push-to-talk: nothing goes out until the key is held
        assert!(!v.transmitting());
        v.set_talk_held(true);
        assert!(v.transmitting());
        v.set_talk_held(false);
        assert!(!v.transmitting());
    }
}
