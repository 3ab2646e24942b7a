//! Voice datagrams (first byte `0xF9`, [`crate::door::VOICE`]) and the [`VoiceRouter`] that
//! sends and admits them. Sans-IO like the session: no codec, no clock, no sockets here —
//! the Opus frames are bytes to this module (`softsync-voice` encodes, buffers and plays
//! them).
//!
//! # Who may speak, and to whom
//! - Frames go only to the room's members ([`crate::Session::members`]: in a keyed room,
//!   those who proved the key) and are heard only from them.
//! - A frame's speaker is the transport's verified peer (`from`), never a field the sender
//!   writes. The one exception is a frame the **host** relays: it names the speaker, and it
//!   is believed only from the peer this session follows as host (the same trust as the
//!   session's relayed state), and only for a member.
//! - Every speaker has a token bucket ([`VoiceLimits`]): 50 frames a second is speech, more
//!   is a flood and is dropped and counted ([`VoiceDrops`]) before it is played or relayed,
//!   so a hostile member cannot make the host amplify it.
//!
//! # Routes ([`Route`])
//! - **Mesh**: the speaker sends each frame directly to every other member (n − 1 copies of
//!   its uplink; one hop each).
//! - **Relay**: the speaker sends one copy to the host, which plays it and forwards it to
//!   every other member (the speaker's uplink is one frame; the host's is n − 2 more; two
//!   hops).
//!
//! [`RoutePolicy::Auto`] picks relay when any of the speaker's links to other members goes
//! through a TURN relay (the caller says which: the transport knows), since every copy over
//! TURN crosses the TURN server's uplink too, and mesh otherwise. The host always sends
//! directly (it is the relay).
//!
//! # Layout (all integers little-endian)
//! ```text
//! F9 01 seq:u32 capture_ms:u32 level:u8 len:u16 opus[len] [rlen:u16 red[rlen]]
//!                                                  a frame, speaker → listener (`red`: frame
//!                                                  seq − 1 again, when redundancy is on)
//! F9 02 (as 01)                                    a frame for the host to relay
//! F9 03 speaker:u64 (then as 01)                   a frame the host relays
//! F9 04 loss_permille:u16 late_permille:u16 jitter_ms:u16           a listener's report to a speaker
//! ```
//! `seq` counts the frames a speaker sent (frames not sent during silence are not counted, so
//! a gap in `seq` is loss); `capture_ms` is the room time ([`crate::Session::room_time`], ms,
//! wrapping) of the frame's first sample, from which a listener plays in step with the room;
//! `level` is the frame's loudness (0 silence … 255 full scale, see `softsync-voice`).

use std::collections::BTreeMap;

use crate::ids::PeerId;
use crate::session::Session;
use crate::time::Instant;
use crate::transport::Transmit;

/// First byte of voice datagrams.
pub const VOICE_MARKER: u8 = crate::door::VOICE;
/// The longest Opus frame accepted (20 ms at 160 kb/s is 400 bytes; speech at 24 kb/s is ~60).
pub const MAX_OPUS_BYTES: usize = 400;
/// A frame's duration, in milliseconds (Opus, 48 kHz, 960 samples).
pub const FRAME_MS: u32 = 20;

const KIND_FRAME: u8 = 1;
const KIND_TO_RELAY: u8 = 2;
const KIND_RELAYED: u8 = 3;
const KIND_REPORT: u8 = 4;
const FRAME_HEADER: usize = 4 + 4 + 1 + 2;

/// One voice frame: 20 ms of one speaker's Opus.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VoiceFrame {
    /// The speaker's frame number (frames sent, so a gap is loss).
    pub seq: u32,
    /// Room time of the frame's first sample, in milliseconds (wrapping).
    pub capture_ms: u32,
    /// Loudness, 0 (silence) to 255 (full scale).
    pub level: u8,
    /// The Opus packet.
    pub opus: Vec<u8>,
    /// The previous frame's packet again (`seq − 1`), when the speaker sends redundancy
    /// (RFC 2198 style, on when listeners report loss): a lost frame is rebuilt whole from the
    /// next datagram. Empty: none.
    pub redundant: Vec<u8>,
}

/// What a listener tells a speaker about its frames, about once a second.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VoiceReport {
    /// Frames lost of those expected, per thousand.
    pub loss_permille: u16,
    /// Frames that came too late to play, per thousand.
    pub late_permille: u16,
    /// The jitter of the frames' transit, in milliseconds.
    pub jitter_ms: u16,
}

/// A voice datagram, decoded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum VoiceDatagram {
    /// A frame from the sender, for us.
    Frame(VoiceFrame),
    /// A frame from the sender, for the host to play and relay.
    ToRelay(VoiceFrame),
    /// A frame the host relays, of `speaker`.
    Relayed {
        /// Whose voice (believed only from the host).
        speaker: PeerId,
        /// The frame.
        frame: VoiceFrame,
    },
    /// A listener's report to the speaker.
    Report(VoiceReport),
}

/// Why a voice datagram could not be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum VoiceWireError {
    /// Not a voice datagram, or too short for its kind.
    #[error("truncated or not a voice datagram")]
    Truncated,
    /// A kind this build does not know.
    #[error("unknown voice datagram kind {0}")]
    UnknownKind(u8),
    /// An Opus payload is empty or longer than [`MAX_OPUS_BYTES`], or the lengths disagree
    /// with the datagram's.
    #[error("voice frame of {0} bytes (1 to {MAX_OPUS_BYTES}, and exactly the rest)")]
    BadLength(usize),
}

fn put_frame(out: &mut Vec<u8>, f: &VoiceFrame) {
    out.extend_from_slice(&f.seq.to_le_bytes());
    out.extend_from_slice(&f.capture_ms.to_le_bytes());
    out.push(f.level);
    let len = f.opus.len().min(MAX_OPUS_BYTES);
    out.extend_from_slice(&(len as u16).to_le_bytes());
    out.extend_from_slice(&f.opus[..len]);
    if !f.redundant.is_empty() {
        let r = f.redundant.len().min(MAX_OPUS_BYTES);
        out.extend_from_slice(&(r as u16).to_le_bytes());
        out.extend_from_slice(&f.redundant[..r]);
    }
}

fn take<const N: usize>(b: &[u8], at: usize) -> Result<[u8; N], VoiceWireError> {
    b.get(at..at + N)
        .and_then(|s| s.try_into().ok())
        .ok_or(VoiceWireError::Truncated)
}

fn read_frame(b: &[u8]) -> Result<VoiceFrame, VoiceWireError> {
    let seq = u32::from_le_bytes(take(b, 0)?);
    let capture_ms = u32::from_le_bytes(take(b, 4)?);
    let [level] = take(b, 8)?;
    let len = usize::from(u16::from_le_bytes(take(b, 9)?));
    let rest = &b[FRAME_HEADER..];
    if len > MAX_OPUS_BYTES || len > rest.len() || len == 0 {
        return Err(VoiceWireError::BadLength(len.max(rest.len())));
    }
    let (opus, tail) = rest.split_at(len);
    let redundant = match tail.len() {
        0 => Vec::new(),
        _ => {
            let r = usize::from(u16::from_le_bytes(take(tail, 0)?));
            let red = &tail[2..];
            if r == 0 || r > MAX_OPUS_BYTES || r != red.len() {
                return Err(VoiceWireError::BadLength(r.max(red.len())));
            }
            red.to_vec()
        }
    };
    Ok(VoiceFrame {
        seq,
        capture_ms,
        level,
        opus: opus.to_vec(),
        redundant,
    })
}

impl VoiceDatagram {
    /// The datagram's bytes (an Opus payload over [`MAX_OPUS_BYTES`] is cut to it: the
    /// encoder never makes one).
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(2 + 8 + FRAME_HEADER + MAX_OPUS_BYTES);
        out.push(VOICE_MARKER);
        match self {
            VoiceDatagram::Frame(f) => {
                out.push(KIND_FRAME);
                put_frame(&mut out, f);
            }
            VoiceDatagram::ToRelay(f) => {
                out.push(KIND_TO_RELAY);
                put_frame(&mut out, f);
            }
            VoiceDatagram::Relayed { speaker, frame } => {
                out.push(KIND_RELAYED);
                out.extend_from_slice(&speaker.0.to_le_bytes());
                put_frame(&mut out, frame);
            }
            VoiceDatagram::Report(r) => {
                out.push(KIND_REPORT);
                out.extend_from_slice(&r.loss_permille.to_le_bytes());
                out.extend_from_slice(&r.late_permille.to_le_bytes());
                out.extend_from_slice(&r.jitter_ms.to_le_bytes());
            }
        }
        out
    }

    /// Read a voice datagram; never panics, allocates at most [`MAX_OPUS_BYTES`].
    pub fn decode(b: &[u8]) -> Result<VoiceDatagram, VoiceWireError> {
        let [marker, kind] = take(b, 0)?;
        if marker != VOICE_MARKER {
            return Err(VoiceWireError::Truncated);
        }
        let body = &b[2..];
        match kind {
            KIND_FRAME => Ok(VoiceDatagram::Frame(read_frame(body)?)),
            KIND_TO_RELAY => Ok(VoiceDatagram::ToRelay(read_frame(body)?)),
            KIND_RELAYED => {
                let speaker = PeerId(u64::from_le_bytes(take(body, 0)?));
                Ok(VoiceDatagram::Relayed {
                    speaker,
                    frame: read_frame(body.get(8..).ok_or(VoiceWireError::Truncated)?)?,
                })
            }
            KIND_REPORT => {
                if body.len() != 6 {
                    return Err(VoiceWireError::Truncated);
                }
                Ok(VoiceDatagram::Report(VoiceReport {
                    loss_permille: u16::from_le_bytes(take(body, 0)?).min(1000),
                    late_permille: u16::from_le_bytes(take(body, 2)?).min(1000),
                    jitter_ms: u16::from_le_bytes(take(body, 4)?),
                }))
            }
            k => Err(VoiceWireError::UnknownKind(k)),
        }
    }
}

/// How a speaker's frames reach the room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Route {
    /// Directly to every member.
    Mesh,
    /// One copy to the host, which relays it.
    Relay,
}

/// How the route is chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RoutePolicy {
    /// Relay when any link to another member goes through TURN; mesh otherwise.
    #[default]
    Auto,
    /// Always mesh.
    Mesh,
    /// Always through the host.
    Relay,
}

impl RoutePolicy {
    /// The route, given whether any of our links to members other than the host is relayed
    /// by TURN (or not open).
    pub fn route(self, any_link_turned: bool) -> Route {
        match self {
            RoutePolicy::Mesh => Route::Mesh,
            RoutePolicy::Relay => Route::Relay,
            RoutePolicy::Auto if any_link_turned => Route::Relay,
            RoutePolicy::Auto => Route::Mesh,
        }
    }
}

/// Per-speaker limits on what is heard (and relayed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoiceLimits {
    /// Frames a second a speaker may send (speech is 50).
    pub frames_per_s: f64,
    /// Frames a speaker may send at once after a quiet moment (a burst after a stall).
    pub burst: f64,
    /// Reports a second a listener may send us.
    pub reports_per_s: f64,
}

impl Default for VoiceLimits {
    fn default() -> Self {
        VoiceLimits {
            frames_per_s: 60.0,
            // a second of speech at once: a speaker whose process stalled catches up its
            // capture clock (up to 10 frames), and a link that stalled delivers a burst; both
            // are speech, not a flood (15 dropped such bursts under load)
            burst: 50.0,
            reports_per_s: 4.0,
        }
    }
}

/// Voice datagrams dropped, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VoiceDrops {
    /// Could not be read (truncated, unknown kind, a length that lies).
    pub malformed: u64,
    /// From a peer that is not a member of our room (or before we are in one).
    pub not_member: u64,
    /// A relayed frame from a peer that is not our host, or naming a speaker who is not a
    /// member (or is us).
    pub wrong_speaker: u64,
    /// A frame sent to us for relaying while we are not the host.
    pub not_host: u64,
    /// Over the speaker's rate ([`VoiceLimits`]).
    pub flood: u64,
}

impl VoiceDrops {
    /// Every drop.
    pub fn total(&self) -> u64 {
        self.malformed + self.not_member + self.wrong_speaker + self.not_host + self.flood
    }
}

/// What a voice datagram brought.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Heard {
    /// `speaker`'s frame, to play.
    Frame {
        /// Whose voice (verified: see the module's doc).
        speaker: PeerId,
        /// The frame.
        frame: VoiceFrame,
    },
    /// `listener`'s report on our frames.
    Report {
        /// Who reports.
        listener: PeerId,
        /// What.
        report: VoiceReport,
    },
}

#[derive(Clone, Copy, Debug)]
struct Bucket {
    tokens: f64,
    last: Instant,
}

impl Bucket {
    fn take(&mut self, now: Instant, rate: f64, burst: f64) -> bool {
        let dt = now.saturating_since(self.last).as_secs_f64();
        self.last = self.last.max(now);
        self.tokens = (self.tokens + dt * rate).min(burst);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Sends a speaker's frames along its route and admits what arrives (see the module's doc).
#[derive(Clone, Debug, Default)]
pub struct VoiceRouter {
    limits: VoiceLimits,
    frames: BTreeMap<PeerId, Bucket>,
    reports: BTreeMap<PeerId, Bucket>,
    drops: VoiceDrops,
    relayed: u64,
    sent_bytes: u64,
}

impl VoiceRouter {
    /// A router with these limits.
    pub fn new(limits: VoiceLimits) -> Self {
        VoiceRouter {
            limits,
            ..Default::default()
        }
    }

    /// What was dropped, by reason.
    pub fn drops(&self) -> VoiceDrops {
        self.drops
    }

    /// Frames this peer relayed as host.
    pub fn relayed(&self) -> u64 {
        self.relayed
    }

    /// Voice bytes this peer has sent (payloads: frames, relays and reports).
    pub fn sent_bytes(&self) -> u64 {
        self.sent_bytes
    }

    /// Our `frame` to the room along `route`: transmits into `out` (none before we are in a
    /// room, or when we are alone).
    pub fn send_frame(
        &mut self,
        session: &Session,
        route: Route,
        frame: &VoiceFrame,
        out: &mut Vec<Transmit>,
    ) {
        if !session.is_connected() {
            return;
        }
        let me = session.local_id();
        let host = session.host_id();
        if route == Route::Relay && !session.is_host() {
            if let Some(h) = host.filter(|h| *h != me) {
                let payload = VoiceDatagram::ToRelay(frame.clone()).encode();
                self.push(out, h, payload);
            }
            return;
        }
        let payload = VoiceDatagram::Frame(frame.clone()).encode();
        for p in session.members().keys().filter(|p| **p != me) {
            self.push(out, *p, payload.clone());
        }
    }

    /// A report to the speaker `to`.
    pub fn send_report(&mut self, to: PeerId, report: VoiceReport, out: &mut Vec<Transmit>) {
        self.push(out, to, VoiceDatagram::Report(report).encode());
    }

    fn push(&mut self, out: &mut Vec<Transmit>, to: PeerId, payload: Vec<u8>) {
        self.sent_bytes += payload.len() as u64;
        out.push(Transmit {
            to,
            payload,
            reliable: false,
        });
    }

    fn admit(&mut self, now: Instant, speaker: PeerId) -> bool {
        let (rate, burst) = (self.limits.frames_per_s, self.limits.burst);
        let b = self.frames.entry(speaker).or_insert(Bucket {
            tokens: burst,
            last: now,
        });
        if b.take(now, rate, burst) {
            true
        } else {
            self.drops.flood += 1;
            false
        }
    }

    /// A voice datagram from `from`: what it brought, if anything may be played; as host,
    /// the relays of a member's frame go into `relay_out`. Everything refused is counted in
    /// [`drops`](Self::drops).
    pub fn handle(
        &mut self,
        now: Instant,
        session: &Session,
        from: PeerId,
        bytes: &[u8],
        relay_out: &mut Vec<Transmit>,
    ) -> Option<Heard> {
        let Ok(d) = VoiceDatagram::decode(bytes) else {
            self.drops.malformed += 1;
            return None;
        };
        let me = session.local_id();
        let members = session.members();
        if !session.is_connected() || from == me || !members.contains_key(&from) {
            self.drops.not_member += 1;
            return None;
        }
        // forget the buckets of peers who left (bounded by the member cap)
        if self.frames.len() > members.len() + 8 {
            self.frames.retain(|p, _| members.contains_key(p));
            self.reports.retain(|p, _| members.contains_key(p));
        }
        match d {
            VoiceDatagram::Frame(frame) => self.admit(now, from).then_some(Heard::Frame {
                speaker: from,
                frame,
            }),
            VoiceDatagram::ToRelay(frame) => {
                if !session.is_host() {
                    self.drops.not_host += 1;
                    return None;
                }
                if !self.admit(now, from) {
                    return None;
                }
                let payload = VoiceDatagram::Relayed {
                    speaker: from,
                    frame: frame.clone(),
                }
                .encode();
                for p in members.keys().filter(|p| **p != me && **p != from) {
                    self.relayed += 1;
                    self.push(relay_out, *p, payload.clone());
                }
                Some(Heard::Frame {
                    speaker: from,
                    frame,
                })
            }
            VoiceDatagram::Relayed { speaker, frame } => {
                if session.host_id() != Some(from)
                    || session.is_host()
                    || speaker == me
                    || speaker == from
                    || !members.contains_key(&speaker)
                {
                    self.drops.wrong_speaker += 1;
                    return None;
                }
                self.admit(now, speaker)
                    .then_some(Heard::Frame { speaker, frame })
            }
            VoiceDatagram::Report(report) => {
                let (rate, burst) = (self.limits.reports_per_s, 2.0);
                let b = self.reports.entry(from).or_insert(Bucket {
                    tokens: burst,
                    last: now,
                });
                if b.take(now, rate, burst) {
                    Some(Heard::Report {
                        listener: from,
                        report,
                    })
                } else {
                    self.drops.flood += 1;
                    None
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(seq: u32, n: usize) -> VoiceFrame {
        VoiceFrame {
            seq,
            capture_ms: seq.wrapping_mul(FRAME_MS).wrapping_add(1000),
            level: 77,
            opus: vec![0xAB; n],
            redundant: Vec::new(),
        }
    }

    #[test]
    fn every_kind_round_trips() {
        for d in [
            VoiceDatagram::Frame(frame(1, 60)),
            VoiceDatagram::ToRelay(frame(u32::MAX, MAX_OPUS_BYTES)),
            VoiceDatagram::Frame(VoiceFrame {
                redundant: vec![0x11; 55],
                ..frame(2, 60)
            }),
            VoiceDatagram::Relayed {
                speaker: PeerId(9),
                frame: VoiceFrame {
                    redundant: vec![0x22; MAX_OPUS_BYTES],
                    ..frame(3, MAX_OPUS_BYTES)
                },
            },
            VoiceDatagram::Relayed {
                speaker: PeerId(u64::MAX),
                frame: frame(7, 1),
            },
            VoiceDatagram::Report(VoiceReport {
                loss_permille: 50,
                late_permille: 3,
                jitter_ms: 31,
            }),
        ] {
            let b = d.encode();
            assert_eq!(crate::door::classify(&b), crate::door::Door::Voice);
            assert_eq!(VoiceDatagram::decode(&b), Ok(d));
        }
    }

    #[test]
    fn lying_lengths_and_every_truncation_are_refused_without_panic() {
        let good = VoiceDatagram::Relayed {
            speaker: PeerId(3),
            frame: frame(9, 40),
        }
        .encode();
        for n in 0..good.len() {
            assert!(VoiceDatagram::decode(&good[..n]).is_err(), "prefix {n}");
        }
        let mut long = good.clone();
        long.push(0);
        assert!(VoiceDatagram::decode(&long).is_err());
        // a redundant copy whose length lies, or that is empty
        let red = VoiceDatagram::Frame(VoiceFrame {
            redundant: vec![1; 30],
            ..frame(4, 20)
        })
        .encode();
        for n in 0..red.len() {
            assert!(
                VoiceDatagram::decode(&red[..n])
                    .map_or(true, |d| d == VoiceDatagram::Frame(frame(4, 20))
                        && n == red.len() - 32),
                "prefix {n}"
            );
        }
        let mut empty_red = VoiceDatagram::Frame(frame(4, 20)).encode();
        empty_red.extend_from_slice(&[0, 0]);
        assert!(VoiceDatagram::decode(&empty_red).is_err());
        // a length field claiming 65535 bytes
        let mut lie = VoiceDatagram::Frame(frame(1, 10)).encode();
        lie[11] = 0xFF;
        lie[12] = 0xFF;
        assert!(matches!(
            VoiceDatagram::decode(&lie),
            Err(VoiceWireError::BadLength(_))
        ));
        // an oversized payload that is honest about its length
        let mut big = vec![VOICE_MARKER, 1];
        big.extend_from_slice(&[0; 9]);
        big.extend_from_slice(&((MAX_OPUS_BYTES + 1) as u16).to_le_bytes());
        big.extend(std::iter::repeat_n(0u8, MAX_OPUS_BYTES + 1));
        assert!(VoiceDatagram::decode(&big).is_err());
        assert_eq!(
            VoiceDatagram::decode(&[VOICE_MARKER, 9, 0, 0]),
            Err(VoiceWireError::UnknownKind(9))
        );
        // arbitrary bytes: an error or a datagram, never a panic
        let mut x = 0x1234_5678_u64;
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let n = (x % 64) as usize;
            let mut b: Vec<u8> = (0..n).map(|i| (x >> (i % 8 * 8)) as u8).collect();
            if let Some(f) = b.first_mut() {
                *f = VOICE_MARKER;
            }
            if let Ok(d) = VoiceDatagram::decode(&b) {
                assert_eq!(VoiceDatagram::decode(&d.encode()), Ok(d));
            }
        }
    }

    #[test]
    fn the_route_follows_the_links() {
        assert_eq!(RoutePolicy::Auto.route(false), Route::Mesh);
        assert_eq!(RoutePolicy::Auto.route(true), Route::Relay);
        assert_eq!(RoutePolicy::Mesh.route(true), Route::Mesh);
        assert_eq!(RoutePolicy::Relay.route(false), Route::Relay);
    }

    #[test]
    fn a_bucket_admits_speech_and_refuses_a_flood() {
        let mut r = VoiceRouter::default();
        let t0 = Instant::from_micros(0);
        let mut admitted = 0;
        // 10 s of speech at 50 frames a second: all of it
        for k in 0..500u64 {
            if r.admit(Instant::from_micros(k * 20_000), PeerId(2)) {
                admitted += 1;
            }
        }
        assert_eq!(admitted, 500);
        // 1000 frames at once: the burst, then nothing
        let at = Instant::from_micros(20_000_000);
        let flood = (0..1000).filter(|_| r.admit(at, PeerId(3))).count();
        assert_eq!(flood, 50);
        assert_eq!(r.drops().flood, 950);
        let _ = t0;
    }
}
