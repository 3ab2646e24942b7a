//! The seeded link conditioner: latency, jitter, Gilbert–Elliott bursty loss, duplication,
//! reordering and MTU drop on what a transport sends. Used in tests and in real runs
//! (`softsync join --net-condition …`); all randomness comes from its seed, so a run replays.

use std::collections::BinaryHeap;
use std::time::Duration;

use super::{PeerEvent, Transmit, Transport};
use crate::ids::PeerId;
use crate::rng::SeededRng;
use crate::time::Instant;

/// Link impairments; all randomness comes from `seed`.
#[derive(Clone, Debug, PartialEq)]
pub struct ConditionerConfig {
    /// Seed of the PRNG.
    pub seed: u64,
    /// Base one-way latency.
    pub latency: Duration,
    /// Uniform extra delay in `[0, jitter]` (reorders datagrams).
    pub jitter: Duration,
    /// Loss probability in the good state (Gilbert–Elliott).
    pub loss: f64,
    /// Loss probability in the bad (burst) state.
    pub burst_loss: f64,
    /// Probability per datagram of entering the bad state.
    pub p_enter_burst: f64,
    /// Probability per datagram of leaving the bad state.
    pub p_leave_burst: f64,
    /// Probability a datagram is delivered twice.
    pub duplicate: f64,
    /// Probability a datagram is held back an extra `reorder_delay`.
    pub reorder: f64,
    /// Extra delay of reordered datagrams.
    pub reorder_delay: Duration,
    /// Datagrams above this size are dropped (`None`: no limit here).
    pub mtu: Option<usize>,
}

impl Default for ConditionerConfig {
    fn default() -> Self {
        ConditionerConfig {
            seed: 1,
            latency: Duration::ZERO,
            jitter: Duration::ZERO,
            loss: 0.0,
            burst_loss: 0.0,
            p_enter_burst: 0.0,
            p_leave_burst: 1.0,
            duplicate: 0.0,
            reorder: 0.0,
            reorder_delay: Duration::from_millis(30),
            mtu: None,
        }
    }
}

impl ConditionerConfig {
    /// Uniform loss `p` with short bursts, latency, jitter, some duplication and reordering.
    pub fn rough(seed: u64, latency_ms: u64, jitter_ms: u64, loss: f64) -> Self {
        ConditionerConfig {
            seed,
            latency: Duration::from_millis(latency_ms),
            jitter: Duration::from_millis(jitter_ms),
            loss,
            burst_loss: (loss * 3.0).min(0.9),
            p_enter_burst: if loss > 0.0 { 0.02 } else { 0.0 },
            p_leave_burst: 0.3,
            duplicate: 0.02,
            reorder: 0.03,
            reorder_delay: Duration::from_millis(25),
            mtu: None,
        }
    }
}

#[derive(Debug, PartialEq, Eq)]
struct Delayed {
    at: Instant,
    order: u64,
    transmit: Transmit,
}

impl Ord for Delayed {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        // min-heap on (at, order)
        (other.at, other.order).cmp(&(self.at, self.order))
    }
}

impl PartialOrd for Delayed {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

/// Wraps a transport and impairs what it sends.
#[derive(Debug)]
pub struct LinkConditioner<T: Transport> {
    inner: T,
    cfg: ConditionerConfig,
    rng: SeededRng,
    bad: bool,
    queue: BinaryHeap<Delayed>,
    order: u64,
    /// Datagrams dropped by the conditioner (loss + MTU).
    pub dropped: u64,
}

impl<T: Transport> LinkConditioner<T> {
    /// Wrap `inner`.
    pub fn new(inner: T, cfg: ConditionerConfig) -> Self {
        let rng = SeededRng::new(cfg.seed);
        LinkConditioner {
            inner,
            cfg,
            rng,
            bad: false,
            queue: BinaryHeap::new(),
            order: 0,
            dropped: 0,
        }
    }

    /// Change the impairments (keeps the PRNG stream).
    pub fn set_config(&mut self, cfg: ConditionerConfig) {
        self.cfg = cfg;
    }

    /// Hands the wrapped transport what is due by `now`: datagrams on their way travel on
    /// while their sender's process is stopped (the harness's frozen peers).
    pub fn release(&mut self, now: Instant) {
        self.flush(now);
    }

    fn flush(&mut self, now: Instant) {
        while self.queue.peek().is_some_and(|d| d.at <= now) {
            if let Some(d) = self.queue.pop() {
                self.inner.send(d.at, &d.transmit);
            }
        }
    }

    fn delay(&mut self) -> Duration {
        let j = self.cfg.jitter.as_secs_f64() * self.rng.next_f64();
        let mut d = self.cfg.latency + Duration::from_secs_f64(j);
        if self.rng.chance(self.cfg.reorder) {
            d += self.cfg.reorder_delay;
        }
        d
    }
}

impl<T: Transport> Transport for LinkConditioner<T> {
    fn local_id(&self) -> PeerId {
        self.inner.local_id()
    }

    fn send(&mut self, now: Instant, transmit: &Transmit) {
        self.flush(now);
        if self.cfg.mtu.is_some_and(|m| transmit.payload.len() > m) {
            self.dropped += 1;
            return;
        }
        // Gilbert–Elliott two-state loss
        if self.bad {
            if self.rng.chance(self.cfg.p_leave_burst) {
                self.bad = false;
            }
        } else if self.rng.chance(self.cfg.p_enter_burst) {
            self.bad = true;
        }
        let p = if self.bad {
            self.cfg.burst_loss
        } else {
            self.cfg.loss
        };
        if self.rng.chance(p) {
            self.dropped += 1;
            return;
        }
        let copies = if self.rng.chance(self.cfg.duplicate) {
            2
        } else {
            1
        };
        for _ in 0..copies {
            let at = now + self.delay();
            self.order += 1;
            self.queue.push(Delayed {
                at,
                order: self.order,
                transmit: transmit.clone(),
            });
        }
        self.flush(now);
    }

    fn recv(&mut self, now: Instant) -> Option<(PeerId, Vec<u8>)> {
        self.flush(now);
        self.inner.recv(now)
    }

    fn poll_peer_event(&mut self) -> Option<PeerEvent> {
        self.inner.poll_peer_event()
    }

    fn mtu(&self) -> usize {
        self.cfg
            .mtu
            .map_or(self.inner.mtu(), |m| m.min(self.inner.mtu()))
    }

    fn poll_timeout(&self) -> Option<Instant> {
        crate::time::min_opt(self.queue.peek().map(|d| d.at), self.inner.poll_timeout())
    }

    fn prefer_signaling(&mut self, url: &str) {
        self.inner.prefer_signaling(url);
    }

    fn relayed(&self, peer: PeerId) -> Option<bool> {
        self.inner.relayed(peer)
    }
}
