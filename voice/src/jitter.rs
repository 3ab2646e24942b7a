//! An adaptive jitter buffer for one speaker (sans-IO: room time in milliseconds is an
//! argument).
//!
//! Frames are stamped with the room time of their first sample (`capture`); the listener
//! plays frame `k` about `delay` after its capture, on the room's clock, so every listener
//! plays a speaker at a known delay and the delay can be matched to the avatar's.
//!
//! - **The delay follows the measured transit** (arrival − capture, which includes the 20 ms
//!   the frame took to fill): the 97th percentile of the last 5 s plus a margin, and never
//!   less than the fastest transit plus one frame (the minimum of one frame of buffering),
//!   nor less than the floor the caller sets for lip-sync ([`JitterBuffer::set_floor`]).
//! - **Talk spurts.** With DTX a speaker sends nothing in silence; its frame numbers keep
//!   counting frames *sent*, so a gap in them is loss, and a jump in capture time is a new
//!   spurt. Each spurt starts at the delay of the moment; within it frames play one per
//!   output block.
//! - **A missing frame** is taken from the next frame's in-band FEC when that one is here,
//!   concealed otherwise (Opus PLC); while the delay is below target, the buffer waits a
//!   frame instead (a concealed frame is inserted and the missing one is still expected:
//!   the delay grows by 20 ms). After [`MAX_CONCEAL`] concealed frames in a row the spurt
//!   ends and the output is silence.
//! - **Too deep** (the delay 40 ms over target with frames waiting): one frame is skipped.

use std::collections::{BTreeMap, VecDeque};

use softsync_net::voice::VoiceFrame;

/// A frame's duration, ms.
pub const FRAME: f64 = 20.0;
/// Concealed frames in a row before a spurt is taken to have ended.
pub const MAX_CONCEAL: u32 = 3;
/// Frames buffered at most per speaker (a flood cannot grow it).
pub const MAX_FRAMES: usize = 64;

/// How the delay is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JitterConfig {
    /// Transit samples kept (250 = 5 s of speech).
    pub window: usize,
    /// The transit percentile the delay covers.
    pub quantile: f64,
    /// Added to it, ms.
    pub margin_ms: f64,
    /// The delay never exceeds this, ms.
    pub max_delay_ms: f64,
}

impl Default for JitterConfig {
    fn default() -> Self {
        JitterConfig {
            window: 250,
            quantile: 0.97,
            margin_ms: 4.0,
            max_delay_ms: 500.0,
        }
    }
}

/// What to play for one 20 ms block.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Play {
    /// Nothing: the speaker is silent (or has not started).
    Silence,
    /// This frame's packet.
    Frame {
        /// The Opus packet.
        opus: Vec<u8>,
        /// Its level byte.
        level: u8,
    },
    /// The lost frame before this packet, from its FEC.
    Fec {
        /// The next frame's packet.
        next: Vec<u8>,
    },
    /// A concealed frame.
    Conceal,
}

/// Counts, since the start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct JitterStats {
    /// Frames that arrived (once each).
    pub received: u64,
    /// Copies of a frame already here.
    pub duplicates: u64,
    /// Frames that came after their time (or the buffer's bound).
    pub late: u64,
    /// Frames played from their own packet.
    pub played: u64,
    /// Frames recovered from the next frame's FEC.
    pub fec: u64,
    /// Frames concealed (loss, or waiting for a late frame).
    pub concealed: u64,
    /// Times the buffer waited a frame to raise its delay.
    pub stretched: u64,
    /// Frames skipped to lower its delay.
    pub shrunk: u64,
    /// Spurts started.
    pub spurts: u64,
    /// Lost frames rebuilt whole from the next datagram's redundant copy.
    pub redundant: u64,
}

#[derive(Clone, Debug)]
struct Arrived {
    capture: f64,
    level: u8,
    opus: Vec<u8>,
}

#[derive(Clone, Copy, Debug)]
struct Playing {
    /// The next frame number to play.
    next: u32,
    /// Its expected capture time.
    next_capture: f64,
    /// Concealed frames in a row.
    concealed_run: u32,
    /// The delay of the last block played.
    delay: f64,
}

/// Per report window: what a listener tells the speaker.
#[derive(Clone, Copy, Debug, Default)]
struct Window {
    first: Option<u32>,
    last: Option<u32>,
    received: u32,
    late: u32,
}

/// One speaker's jitter buffer.
#[derive(Clone, Debug, Default)]
pub struct JitterBuffer {
    cfg: JitterConfig,
    frames: BTreeMap<u32, Arrived>,
    transit: VecDeque<f64>,
    playing: Option<Playing>,
    /// The newest frame number played from a packet or FEC (older ones are late).
    last_played: Option<u32>,
    floor: f64,
    stats: JitterStats,
    window: Window,
    /// The newest frame number that arrived, and the recent loss (frames missing in the
    /// numbering, a moving average over about 100 frames).
    newest: Option<u32>,
    loss: f64,
}

/// `a` is after `b` in wrapping frame numbers.
fn after(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

fn quantile(xs: &VecDeque<f64>, q: f64) -> Option<f64> {
    if xs.is_empty() {
        return None;
    }
    let mut v: Vec<f64> = xs.iter().copied().collect();
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    v.get(i).copied()
}

impl JitterBuffer {
    /// An empty buffer.
    pub fn new(cfg: JitterConfig) -> Self {
        JitterBuffer {
            cfg,
            ..Default::default()
        }
    }

    /// Counts so far.
    pub fn stats(&self) -> JitterStats {
        self.stats
    }

    /// The lowest delay the caller allows (lip-sync: the speaker's avatar is shown this late).
    pub fn set_floor(&mut self, ms: f64) {
        self.floor = if ms.is_finite() {
            ms.clamp(0.0, self.cfg.max_delay_ms)
        } else {
            0.0
        };
    }

    /// The delay the buffer aims at now, ms from capture to play.
    pub fn target_delay(&self) -> f64 {
        let Some(q) = quantile(&self.transit, self.cfg.quantile) else {
            return (FRAME * 3.0).max(self.floor);
        };
        let fastest = self.transit.iter().copied().fold(f64::INFINITY, f64::min);
        // while frames are being lost, wait one frame more: the next frame, whose FEC
        // rebuilds a lost one, is then here when the lost one is due
        let fec_wait = if self.loss > 0.005 { FRAME } else { 0.0 };
        (q + self.cfg.margin_ms + fec_wait)
            .max(fastest + FRAME)
            .max(self.floor)
            .min(self.cfg.max_delay_ms)
    }

    /// The delay of the last block played, if a spurt is playing.
    pub fn playout_delay(&self) -> Option<f64> {
        self.playing.map(|p| p.delay)
    }

    /// The recent loss (0–1), a moving average over about 100 frames.
    pub fn recent_loss(&self) -> f64 {
        self.loss
    }

    /// The fastest transit of the last window (capture to arrival, the frame's 20 ms
    /// included), ms.
    pub fn fastest_transit(&self) -> Option<f64> {
        self.transit.iter().copied().reduce(f64::min)
    }

    /// The transit jitter (95th percentile less the fastest), ms.
    pub fn jitter(&self) -> f64 {
        let fastest = self.transit.iter().copied().fold(f64::INFINITY, f64::min);
        quantile(&self.transit, 0.95).map_or(0.0, |q| q - fastest)
    }

    /// A frame arrived at room time `now` (ms).
    pub fn push(&mut self, now: f64, frame: VoiceFrame) {
        // the capture time, unwrapped near now (a clock may be a little ahead)
        let age = f64::from((now as u64 as u32).wrapping_sub(frame.capture_ms) as i32);
        if !(-1000.0..=10_000.0).contains(&age) {
            self.stats.late += 1;
            return;
        }
        let capture = now - age;
        self.transit.push_back(age);
        while self.transit.len() > self.cfg.window.max(1) {
            self.transit.pop_front();
        }
        let seq = frame.seq;
        // a frame of a spurt we already left (or a concealed slot of it) that is really the
        // start of a new one: its capture is well past what we expected there
        if let Some(p) = self.playing {
            let slot = p.next.wrapping_sub(p.concealed_run);
            if p.concealed_run > 0
                && !after(slot, seq)
                && !after(seq, p.next)
                && capture > p.next_capture - FRAME * f64::from(p.concealed_run - 1) + FRAME * 1.5
            {
                self.playing = None;
                self.last_played = Some(seq.wrapping_sub(1));
            }
        }
        if self.last_played.is_some_and(|l| !after(seq, l)) {
            self.stats.late += 1;
            self.window.late += 1;
            return;
        }
        if self.frames.contains_key(&seq) {
            self.stats.duplicates += 1;
            return;
        }
        match self.newest {
            Some(n) if after(seq, n) => {
                let missing = f64::from(seq.wrapping_sub(n).saturating_sub(1).min(50));
                self.loss = self.loss * 0.99 + missing * 0.01;
                self.newest = Some(seq);
            }
            Some(_) => {}
            None => self.newest = Some(seq),
        }
        self.stats.received += 1;
        let w = &mut self.window;
        w.received += 1;
        if w.first.is_none_or(|f| after(f, seq)) {
            w.first = Some(seq);
        }
        if w.last.is_none_or(|l| after(seq, l)) {
            w.last = Some(seq);
        }
        // the previous frame again (redundancy): rebuild it if it was lost and is still due
        let prev = seq.wrapping_sub(1);
        if !frame.redundant.is_empty()
            && !self.frames.contains_key(&prev)
            && self.last_played.is_none_or(|l| after(prev, l))
            && self.playing.is_none_or(|p| !after(p.next, prev))
        {
            self.frames.insert(
                prev,
                Arrived {
                    capture: capture - FRAME,
                    level: frame.level,
                    opus: frame.redundant,
                },
            );
            self.stats.redundant += 1;
        }
        self.frames.insert(
            seq,
            Arrived {
                capture,
                level: frame.level,
                opus: frame.opus,
            },
        );
        while self.frames.len() > MAX_FRAMES {
            self.frames.pop_first();
            self.stats.late += 1;
        }
    }

    /// Loss and lateness since the last call (for the report to the speaker): loss (0–1),
    /// late (0–1), jitter (ms).
    pub fn take_report(&mut self) -> (f64, f64, f64) {
        let w = std::mem::take(&mut self.window);
        let expected = match (w.first, w.last) {
            (Some(f), Some(l)) => f64::from(l.wrapping_sub(f)) + 1.0,
            _ => 0.0,
        };
        if expected <= 0.0 {
            return (0.0, 0.0, self.jitter());
        }
        let loss = (1.0 - f64::from(w.received) / expected).clamp(0.0, 1.0);
        let late = (f64::from(w.late) / expected).clamp(0.0, 1.0);
        (loss, late, self.jitter())
    }

    /// The block that starts at room time `now` (ms): call once every 20 ms.
    pub fn pop(&mut self, now: f64) -> Play {
        let target = self.target_delay();
        if self.playing.is_none() {
            // frames older than what was played are of no use
            if let Some(l) = self.last_played {
                self.frames.retain(|s, _| after(*s, l));
            }
            let Some((&first, f)) = self.frames.iter().next() else {
                return Play::Silence;
            };
            // a spurt starts no earlier than its target delay (so the next frame, whose FEC
            // may stand in for a lost one, is here when it is needed)
            if now < f.capture + target {
                return Play::Silence;
            }
            // start at the newest frame whose time has come (a spurt we are late for)
            let mut seq = first;
            let mut capture = f.capture;
            while let Some(c) = self.frames.get(&seq.wrapping_add(1)).map(|nx| nx.capture) {
                if now < c + target {
                    break;
                }
                self.frames.remove(&seq);
                self.stats.shrunk += 1;
                seq = seq.wrapping_add(1);
                capture = c;
            }
            self.stats.spurts += 1;
            self.playing = Some(Playing {
                next: seq,
                next_capture: capture,
                concealed_run: 0,
                delay: now - capture,
            });
        }
        let Some(mut p) = self.playing else {
            return Play::Silence;
        };
        let out = match self.frames.remove(&p.next) {
            Some(f) => {
                p.next_capture = f.capture;
                p.delay = now - f.capture;
                p.concealed_run = 0;
                self.last_played = Some(p.next);
                self.stats.played += 1;
                Play::Frame {
                    opus: f.opus,
                    level: f.level,
                }
            }
            None => {
                // below target with nothing later here: the frame is more likely late than
                // lost, so wait for it (the delay grows a frame); with a later frame here it
                // is lost, and waiting would only shift the rest of the spurt
                let waiting = now - p.next_capture < target - FRAME / 2.0 && self.frames.is_empty();
                let next = self.frames.get(&p.next.wrapping_add(1));
                if waiting && p.concealed_run < MAX_CONCEAL {
                    // below target: wait a frame for it (the delay grows by one frame)
                    p.concealed_run += 1;
                    self.stats.stretched += 1;
                    self.stats.concealed += 1;
                    p.delay = now - p.next_capture;
                    self.playing = Some(p);
                    return Play::Conceal;
                }
                match next {
                    Some(nx) if nx.capture <= p.next_capture + FRAME * 1.5 => {
                        let next = nx.opus.clone();
                        self.stats.fec += 1;
                        self.last_played = Some(p.next);
                        p.concealed_run = 0;
                        p.delay = now - p.next_capture;
                        Play::Fec { next }
                    }
                    _ if p.concealed_run < MAX_CONCEAL => {
                        p.concealed_run += 1;
                        self.stats.concealed += 1;
                        p.delay = now - p.next_capture;
                        Play::Conceal
                    }
                    _ => {
                        // the spurt ended (or a long loss): silence until the next one
                        self.playing = None;
                        return Play::Silence;
                    }
                }
            }
        };
        p.next = p.next.wrapping_add(1);
        p.next_capture += FRAME;
        // too deep: skip one waiting frame
        if p.delay > target + 2.0 * FRAME
            && self.frames.len() >= 2
            && self.frames.remove(&p.next).is_some()
        {
            self.last_played = Some(p.next);
            p.next = p.next.wrapping_add(1);
            p.next_capture += FRAME;
            self.stats.shrunk += 1;
        }
        self.playing = Some(p);
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn f(seq: u32, capture: f64) -> VoiceFrame {
        VoiceFrame {
            seq,
            capture_ms: capture as u64 as u32,
            level: 100,
            opus: vec![seq as u8; 3],
            redundant: Vec::new(),
        }
    }

    /// Frames every 20 ms from t = 1000, delivered after `transit(k)` (None: lost); play
    /// blocks every 20 ms; returns what each block played and the buffer.
    fn run(n: u32, transit: impl Fn(u32) -> Option<f64>) -> (Vec<Play>, JitterBuffer) {
        let mut jb = JitterBuffer::new(JitterConfig::default());
        let mut arrivals: Vec<(f64, VoiceFrame)> = (0..n)
            .filter_map(|k| {
                let c = 1000.0 + f64::from(k) * FRAME;
                transit(k).map(|t| (c + t, f(k, c)))
            })
            .collect();
        arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut out = Vec::new();
        let mut i = 0;
        let mut t = 1003.0;
        while t < 1000.0 + f64::from(n) * FRAME + 600.0 {
            while i < arrivals.len() && arrivals[i].0 <= t {
                jb.push(arrivals[i].0, arrivals[i].1.clone());
                i += 1;
            }
            out.push(jb.pop(t));
            t += FRAME;
        }
        (out, jb)
    }

    #[test]
    fn a_steady_stream_plays_every_frame_in_order_at_one_frame_of_buffer() {
        let (out, jb) = run(200, |_| Some(45.0));
        let played: Vec<u8> = out
            .iter()
            .filter_map(|p| match p {
                Play::Frame { opus, .. } => Some(opus[0]),
                _ => None,
            })
            .collect();
        assert_eq!(played.len(), 200);
        assert!(played.windows(2).all(|w| w[1] == w[0].wrapping_add(1)));
        // 45 ms transit plus one frame of buffer (and the block's alignment)
        let d = jb.target_delay();
        assert!((65.0..=70.0).contains(&d), "{d}");
    }

    #[test]
    fn a_lost_frame_is_recovered_from_fec_and_a_burst_is_concealed() {
        let (out, jb) = run(100, |k| (k != 40 && !(60..63).contains(&k)).then_some(30.0));
        let s = jb.stats();
        assert_eq!(s.fec, 2, "{s:?}"); // 40 and 62 (the last of the burst)
                                       // 60 and 61, and three at the stream's end (a spurt's end is not known until the
                                       // next frame: its first 60 ms are concealed, as after a loss)
        assert_eq!(s.concealed, 5, "{s:?}");
        assert_eq!(s.played, 96);
        assert_eq!(
            out.len() - out.iter().filter(|p| **p == Play::Silence).count(),
            103
        );
    }

    #[test]
    fn under_jitter_the_delay_grows_until_nothing_is_late() {
        // 30 ms of jitter (seeded), 5 % loss
        let mut x = 7u64;
        let mut rnd = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % 10_000) as f64 / 10_000.0
        };
        let plan: Vec<Option<f64>> = (0..1500)
            .map(|_| {
                let lost = rnd() < 0.05;
                let t = 40.0 + 30.0 * rnd();
                (!lost).then_some(t)
            })
            .collect();
        let (_, jb) = run(1500, |k| plan[k as usize]);
        let s = jb.stats();
        // after the first seconds the delay covers the jitter: late frames are rare
        assert!(s.late <= 15, "{s:?}");
        let d = jb.target_delay();
        assert!((70.0..=95.0).contains(&d), "delay {d}");
        // every frame that arrived in time was played or recovered
        assert!(s.played + s.fec >= 1500 - 75 - 15, "{s:?}");
    }

    #[test]
    fn silence_between_spurts_is_not_loss_and_each_spurt_starts_on_time() {
        // frames 0..50 captured at 1000.., then frames 50..100 captured 2 s later (DTX)
        let mut jb = JitterBuffer::new(JitterConfig::default());
        let mut starts = Vec::new();
        let mut t = 1000.0;
        let mut k = 0u32;
        while t < 5000.0 {
            let c = if k < 50 {
                1000.0 + f64::from(k) * FRAME
            } else {
                3000.0 + f64::from(k - 50) * FRAME
            };
            if k < 100 && c + 40.0 <= t {
                jb.push(t, f(k, c));
                k += 1;
                continue;
            }
            let before = jb.stats().spurts;
            let p = jb.pop(t);
            if jb.stats().spurts > before {
                starts.push((t, jb.playout_delay()));
            }
            let _ = p;
            t += FRAME;
        }
        assert_eq!(starts.len(), 2, "{starts:?}");
        let s = jb.stats();
        assert_eq!(s.played, 100, "{s:?}");
        assert_eq!(s.late, 0);
        let (loss, late, _) = jb.take_report();
        assert_eq!((loss, late), (0.0, 0.0));
    }

    #[test]
    fn a_lost_frame_comes_back_whole_from_the_next_datagrams_copy() {
        let mut jb = JitterBuffer::new(JitterConfig::default());
        let mut played = Vec::new();
        let mut t = 1003.0;
        for k in 0..60u32 {
            let c = 1000.0 + f64::from(k) * FRAME;
            if k != 30 {
                let mut fr = f(k, c);
                if k > 0 {
                    fr.redundant = vec![k.wrapping_sub(1) as u8; 3];
                }
                jb.push(c + 40.0, fr);
            }
            while t <= c + 40.0 {
                if let Play::Frame { opus, .. } = jb.pop(t) {
                    played.push(opus[0]);
                }
                t += FRAME;
            }
        }
        assert!(played.contains(&30), "{played:?}");
        assert_eq!(jb.stats().redundant, 1);
        assert_eq!(jb.stats().fec + jb.stats().concealed, 0, "{:?}", jb.stats());
    }

    #[test]
    fn the_floor_holds_voice_back_to_the_avatar() {
        let mut jb = JitterBuffer::new(JitterConfig::default());
        jb.push(1030.0, f(0, 1000.0));
        jb.set_floor(120.0);
        assert_eq!(jb.target_delay(), 120.0);
        assert_eq!(jb.pop(1060.0), Play::Silence);
        assert!(matches!(jb.pop(1120.0), Play::Frame { .. }));
        jb.set_floor(f64::NAN);
        assert!(jb.target_delay() < 120.0);
    }

    #[test]
    fn a_flood_of_numbers_keeps_the_buffer_bounded() {
        let mut jb = JitterBuffer::new(JitterConfig::default());
        for k in 0..10_000u32 {
            jb.push(1000.0, f(k.wrapping_mul(2_654_435_761), 990.0));
        }
        assert!(jb.frames.len() <= MAX_FRAMES);
        assert!(jb.transit.len() <= 250);
    }
}
