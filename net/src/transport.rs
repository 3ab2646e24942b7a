//! Transports: one small object-safe trait, an in-memory hub for tests and a seeded link
//! conditioner (latency, jitter, bursty loss, duplication, reordering, MTU drop) wrapping any
//! transport.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap, VecDeque};
use std::rc::Rc;
use std::time::Duration;

use crate::ids::PeerId;
use crate::rng::SeededRng;
use crate::time::Instant;

/// Connectivity news from the transport (informational: the session trusts only silence).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeerEvent {
    /// A peer became reachable.
    Connected(PeerId),
    /// A peer became unreachable.
    Disconnected(PeerId),
}

/// An unreliable datagram transport. Time is passed in; nothing blocks.
pub trait Transport {
    /// This endpoint's address.
    fn local_id(&self) -> PeerId;
    /// Send one datagram (best effort).
    fn send(&mut self, now: Instant, to: PeerId, datagram: &[u8]);
    /// Next datagram that has arrived by `now`.
    fn recv(&mut self, now: Instant) -> Option<(PeerId, Vec<u8>)>;
    /// Next connectivity event.
    fn poll_peer_event(&mut self) -> Option<PeerEvent>;
    /// Largest datagram the path carries.
    fn mtu(&self) -> usize;
    /// When something queued inside the transport becomes due (virtual-time drivers).
    fn poll_timeout(&self) -> Option<Instant> {
        None
    }
}

#[derive(Default, Debug)]
struct HubInner {
    inboxes: BTreeMap<PeerId, VecDeque<(PeerId, Vec<u8>)>>,
    events: BTreeMap<PeerId, VecDeque<PeerEvent>>,
    dead: BTreeSet<PeerId>,
    cut: BTreeSet<(PeerId, PeerId)>,
    mtu: usize,
    dropped_mtu: u64,
}

/// In-memory datagram switch: endpoints deliver instantly into each other's inboxes.
#[derive(Clone, Debug)]
pub struct MemoryHub {
    inner: Rc<RefCell<HubInner>>,
}

impl MemoryHub {
    /// A hub whose links carry datagrams up to `mtu` bytes.
    pub fn new(mtu: usize) -> Self {
        MemoryHub {
            inner: Rc::new(RefCell::new(HubInner {
                mtu,
                ..HubInner::default()
            })),
        }
    }

    /// Attach an endpoint; every existing endpoint hears `Connected`.
    pub fn endpoint(&self, id: PeerId) -> HubEndpoint {
        let mut h = self.inner.borrow_mut();
        let others: Vec<PeerId> = h.inboxes.keys().copied().collect();
        for o in &others {
            h.events
                .entry(*o)
                .or_default()
                .push_back(PeerEvent::Connected(id));
            h.events
                .entry(id)
                .or_default()
                .push_back(PeerEvent::Connected(*o));
        }
        h.inboxes.entry(id).or_default();
        h.dead.remove(&id);
        HubEndpoint {
            id,
            hub: self.clone(),
        }
    }

    /// The endpoint stops sending and receiving (a crash).
    pub fn kill(&self, id: PeerId) {
        let mut h = self.inner.borrow_mut();
        h.dead.insert(id);
        if let Some(q) = h.inboxes.get_mut(&id) {
            q.clear();
        }
    }

    /// Cut (or restore) both directions between `a` and `b`.
    pub fn set_partition(&self, a: PeerId, b: PeerId, cut: bool) {
        let mut h = self.inner.borrow_mut();
        for pair in [(a, b), (b, a)] {
            if cut {
                h.cut.insert(pair);
            } else {
                h.cut.remove(&pair);
            }
        }
    }

    /// Change the path MTU.
    pub fn set_mtu(&self, mtu: usize) {
        self.inner.borrow_mut().mtu = mtu;
    }

    /// Datagrams dropped for exceeding the MTU.
    pub fn dropped_over_mtu(&self) -> u64 {
        self.inner.borrow().dropped_mtu
    }
}

/// One endpoint of a [`MemoryHub`].
#[derive(Debug)]
pub struct HubEndpoint {
    id: PeerId,
    hub: MemoryHub,
}

impl Transport for HubEndpoint {
    fn local_id(&self) -> PeerId {
        self.id
    }

    fn send(&mut self, _now: Instant, to: PeerId, datagram: &[u8]) {
        let mut h = self.hub.inner.borrow_mut();
        if h.dead.contains(&self.id) || h.dead.contains(&to) || h.cut.contains(&(self.id, to)) {
            return;
        }
        if datagram.len() > h.mtu {
            h.dropped_mtu += 1;
            return;
        }
        if let Some(q) = h.inboxes.get_mut(&to) {
            q.push_back((self.id, datagram.to_vec()));
        }
    }

    fn recv(&mut self, _now: Instant) -> Option<(PeerId, Vec<u8>)> {
        let mut h = self.hub.inner.borrow_mut();
        if h.dead.contains(&self.id) {
            return None;
        }
        h.inboxes.get_mut(&self.id)?.pop_front()
    }

    fn poll_peer_event(&mut self) -> Option<PeerEvent> {
        self.hub
            .inner
            .borrow_mut()
            .events
            .get_mut(&self.id)?
            .pop_front()
    }

    fn mtu(&self) -> usize {
        self.hub.inner.borrow().mtu
    }
}

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
    to: PeerId,
    bytes: Vec<u8>,
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

    fn flush(&mut self, now: Instant) {
        while self.queue.peek().is_some_and(|d| d.at <= now) {
            if let Some(d) = self.queue.pop() {
                self.inner.send(d.at, d.to, &d.bytes);
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

    fn send(&mut self, now: Instant, to: PeerId, datagram: &[u8]) {
        self.flush(now);
        if self.cfg.mtu.is_some_and(|m| datagram.len() > m) {
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
                to,
                bytes: datagram.to_vec(),
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
}
