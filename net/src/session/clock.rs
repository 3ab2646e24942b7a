//! The room clock: one time every peer of a room reads alike, for stamping events, recordings,
//! animation phases and speech.
//!
//! The host's clock is the room's: room time is the host's local clock plus an offset, zero for
//! the peer that created the room. A member learns the offset from the host's `Pong`s, which
//! carry the host's room time when it answered and how long our ping waited there for the
//! answer (`h`): with `t₀` our ping's send time, `t₁` the pong's arrival and `R` the room time
//! in it, the sample is `R + (t₁ − t₀ − h)/2 − t₁` (Cristian's algorithm, with NTP's
//! correction for the time spent at the server: half the network round trip is the answer's
//! way back). Queueing only ever makes a round
//! trip longer, and a longer one a worse sample, so the estimate is the sample of the shortest
//! round trip among the last [`WINDOW`] (NTP's clock filter).
//!
//! A new host (a migration) keeps the offset it had as a member: its room time carries on
//! where its estimate of the old host's stood, within that estimate's error, and the members
//! re-estimate against it. Read times never go back: a reading earlier than the last one
//! (a better estimate that moved the offset down) returns the last one until the clock
//! passes it, so room time stands still for a few milliseconds instead of jumping back.

use std::cell::Cell;
use std::collections::VecDeque;
use std::time::Duration;

use crate::time::Instant;

/// Pong samples the estimate chooses from.
pub const WINDOW: usize = 16;

/// A peer's reading of the room clock.
#[derive(Debug, Default)]
pub(crate) struct RoomClock {
    /// Room time = local time + this, µs; `None` until known.
    offset_us: Option<i64>,
    /// Recent samples from the current host: (round trip µs, offset µs).
    samples: VecDeque<(u64, i64)>,
    /// The latest room time read, µs (readings never go back).
    last_read_us: Cell<u64>,
}

impl RoomClock {
    /// We host: a room we create starts its clock at our own; a host that was a member keeps
    /// the offset it had (the room's time carries on).
    pub fn host(&mut self) {
        self.offset_us.get_or_insert(0);
        self.samples.clear();
    }

    /// We host a room reopened at `now` whose clock read `room` when it was last kept: room
    /// time carries on from there.
    pub fn resume(&mut self, now: Instant, room: Duration) {
        let room_us = i64::try_from(room.as_micros()).unwrap_or(i64::MAX / 2);
        self.offset_us = Some(room_us - now.as_micros() as i64);
        self.samples.clear();
    }

    /// Another peer hosts from now on: its samples start afresh (the offset stays until they
    /// come).
    pub fn follow(&mut self) {
        self.samples.clear();
    }

    /// A pong from the host arrived at `now` for our ping sent at `sent`, saying the room
    /// time was `room_us` when the host answered and that our ping waited `held_us` there.
    /// Samples with no network round trip (a clock that went back, a wait longer than the
    /// round trip) or past a minute are ignored.
    pub fn on_pong(&mut self, now: Instant, sent: Instant, room_us: u64, held_us: u64) {
        let Some(rtt) = now
            .as_micros()
            .checked_sub(sent.as_micros())
            .and_then(|r| r.checked_sub(held_us))
        else {
            return;
        };
        if rtt > 60_000_000 || room_us > i64::MAX as u64 / 2 {
            return;
        }
        let offset = room_us as i64 + (rtt / 2) as i64 - now.as_micros() as i64;
        if self.samples.len() == WINDOW {
            self.samples.pop_front();
        }
        self.samples.push_back((rtt, offset));
        if let Some(&(_, best)) = self.samples.iter().min_by_key(|(r, _)| *r) {
            self.offset_us = Some(best);
        }
    }

    /// The room time at our local time `now`, if known: never earlier than a time read
    /// before.
    pub fn read(&self, now: Instant) -> Option<Duration> {
        let offset = self.offset_us?;
        let t = (now.as_micros() as i64 + offset).max(0) as u64;
        let t = t.max(self.last_read_us.get());
        self.last_read_us.set(t);
        Some(Duration::from_micros(t))
    }

    /// The room time at `now` to put in a pong, µs, without the monotonic hold (the
    /// answer's sample is corrected by its receiver's filter, not by our readings).
    pub fn stamp_us(&self, now: Instant) -> Option<u64> {
        let offset = self.offset_us?;
        Some((now.as_micros() as i64 + offset).max(0) as u64)
    }

    /// The round trip of the sample the estimate rests on, if any.
    pub fn best_rtt(&self) -> Option<Duration> {
        self.samples
            .iter()
            .map(|(r, _)| *r)
            .min()
            .map(Duration::from_micros)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn at(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    #[test]
    fn the_shortest_round_trip_wins_and_half_of_it_is_added() {
        let mut c = RoomClock::default();
        assert_eq!(c.read(at(5)), None);
        // host's room time = our time + 1000 ms; a 40 ms round trip queued 30 ms one way
        c.on_pong(at(140), at(100), 1_000_000 + 130_000, 0);
        // symmetric 10 ms round trip: exact
        c.on_pong(at(210), at(200), 1_000_000 + 205_000, 0);
        assert_eq!(c.read(at(300)), Some(Duration::from_millis(1300)));
        assert_eq!(c.best_rtt(), Some(Duration::from_millis(10)));
    }

    #[test]
    fn the_wait_at_the_host_is_not_half_the_way_back() {
        let mut c = RoomClock::default();
        // 10 ms each way, and the ping waited 30 ms for the host's next datagram: the host
        // answered at our 140 ms, room time 1140 ms
        c.on_pong(at(150), at(100), 1_140_000, 30_000);
        assert_eq!(c.read(at(150)), Some(Duration::from_millis(1150)));
    }

    #[test]
    fn readings_never_go_back_when_the_estimate_moves_down() {
        let mut c = RoomClock::default();
        c.on_pong(at(150), at(100), 1_000_000 + 135_000, 0); // offset +1010 ms (asymmetric)
        let first = c.read(at(200)).unwrap();
        c.on_pong(at(310), at(300), 1_000_000 + 305_000, 0); // better: +1000 ms
        assert_eq!(c.read(at(201)), Some(first), "held, not back");
        assert_eq!(c.read(at(215)), Some(Duration::from_millis(1215)));
    }

    #[test]
    fn a_new_host_carries_on_from_its_estimate() {
        let mut c = RoomClock::default();
        c.on_pong(at(110), at(100), 5_000_000 + 105_000, 0);
        let before = c.read(at(500)).unwrap();
        c.host();
        assert_eq!(c.read(at(500)), Some(before));
        assert_eq!(c.stamp_us(at(600)), Some(5_600_000));
        // the creator of a room starts at its own clock
        let mut first = RoomClock::default();
        first.host();
        assert_eq!(first.read(at(42)), Some(Duration::from_millis(42)));
    }

    #[test]
    fn hostile_samples_are_ignored() {
        let mut c = RoomClock::default();
        c.on_pong(at(100), at(200), 7, 0); // a pong before its ping
        c.on_pong(at(100_000), at(0), 7, 0); // a 100 s round trip
        c.on_pong(at(110), at(100), u64::MAX, 0);
        c.on_pong(at(110), at(100), 7, 20_000); // held longer than the round trip
        assert_eq!(c.read(at(300)), None);
    }
}
