//! In-process N-peer harness on virtual time (a generalisation of quinn-proto's test `Pair`):
//! step every peer, jump to the next timeout, kill peers, freeze them (a stopped process; the
//! seeded CPU-stall model, [`StallModel`]), partition links, change the MTU. Used by the tests
//! and the bench; no sockets, no sleeps.

use std::time::Duration;

use crate::ids::PeerId;
use crate::policy::SessionConfig;
use crate::rng::SeededRng;
use crate::session::{Event, Session};
use crate::time::Instant;
use crate::transport::{ConditionerConfig, HubEndpoint, LinkConditioner, MemoryHub, Transport};

/// One peer in the harness.
#[derive(Debug)]
pub struct HarnessPeer {
    /// Its session.
    pub session: Session,
    /// Its transport (conditioned hub endpoint).
    pub transport: LinkConditioner<HubEndpoint>,
    /// False once killed.
    pub alive: bool,
    /// Every event the session produced, in order.
    pub events: Vec<Event>,
    /// Last time this peer sent a datagram.
    pub last_send: Option<Instant>,
}

/// A room of peers on one virtual clock.
#[derive(Debug)]
pub struct Harness {
    /// Virtual time.
    pub now: Instant,
    /// The switch.
    pub hub: MemoryHub,
    /// Peers, in creation order (index 0 hosts).
    pub peers: Vec<HarnessPeer>,
    cfg: SessionConfig,
    link: ConditionerConfig,
    /// A peer whose session says it was dropped joins the host it names with a fresh session
    /// at once, as the peer layer does (off by default: tests of the drop itself look at it).
    pub auto_rejoin: bool,
    /// Times peers joined again that way.
    pub rejoins: usize,
}

impl Harness {
    /// A room with `n` peers (peer 0 hosts; the others join one after another), every
    /// sender impaired by `link` (seed varied per peer).
    pub fn new(n: usize, cfg: SessionConfig, link: ConditionerConfig) -> Self {
        let mut h = Harness {
            now: Instant::ZERO,
            hub: MemoryHub::new(cfg.mtu),
            peers: Vec::new(),
            cfg,
            link,
            auto_rejoin: false,
            rejoins: 0,
        };
        for _ in 0..n {
            h.add_peer();
            // stagger joins so join order follows index order on benign links
            h.advance(Duration::from_millis(50));
        }
        h
    }

    /// Peer id of index `i`.
    pub fn id(i: usize) -> PeerId {
        PeerId(100 + i as u64)
    }

    /// Add a peer that joins the current host (or hosts, if it is the first).
    pub fn add_peer(&mut self) -> usize {
        let i = self.peers.len();
        self.add_peer_with(self.cfg.clone(), i)
    }

    /// Add a peer with its own config, joining whoever `join_via` says is host.
    pub fn add_peer_with(&mut self, cfg: SessionConfig, join_via: usize) -> usize {
        let host = self
            .peers
            .get(join_via)
            .and_then(|p| p.session.host_id())
            .unwrap_or(Harness::id(0));
        self.add_peer_contacting(cfg, host)
    }

    /// Add a peer that sends its join request to `contact` (which may redirect it).
    pub fn add_peer_contacting(&mut self, cfg: SessionConfig, contact: PeerId) -> usize {
        let i = self.peers.len();
        let id = Harness::id(i);
        let mut link = self.link.clone();
        link.seed = link.seed.wrapping_mul(31).wrapping_add(i as u64 + 1);
        let transport = LinkConditioner::new(self.hub.endpoint(id), link);
        let session = if i == 0 {
            Session::host(id, cfg, self.now)
        } else {
            Session::join(id, contact, cfg, self.now)
        };
        self.peers.push(HarnessPeer {
            session,
            transport,
            alive: true,
            events: Vec::new(),
            last_send: None,
        });
        i
    }

    /// Crash peer `i`: it never sends or receives again.
    pub fn kill(&mut self, i: usize) {
        if let Some(p) = self.peers.get_mut(i) {
            p.alive = false;
            self.hub.kill(Harness::id(i));
        }
    }

    /// Freeze peer `i` (its frame loop stalls: it neither sends nor processes anything, and
    /// what others send it waits in its transport), or thaw it with `false`.
    pub fn freeze(&mut self, i: usize, frozen: bool) {
        if let Some(p) = self.peers.get_mut(i) {
            p.alive = !frozen;
        }
    }

    /// Cut or restore the link between peers `a` and `b`.
    pub fn partition(&mut self, a: usize, b: usize, cut: bool) {
        self.hub.set_partition(Harness::id(a), Harness::id(b), cut);
    }

    /// Change the path MTU of the hub.
    pub fn set_mtu(&mut self, mtu: usize) {
        self.hub.set_mtu(mtu);
    }

    /// Index of the live peer that joined earliest (lowest join order), excluding `except`.
    pub fn earliest_live_joiner(&self, except: usize) -> Option<usize> {
        let view = self.peers.iter().position(|p| p.alive)?;
        let members = self.peers[view].session.members();
        (0..self.peers.len())
            .filter(|i| *i != except && self.peers[*i].alive)
            .filter_map(|i| members.get(&Harness::id(i)).map(|s| (*s, i)))
            .min()
            .map(|(_, i)| i)
    }

    /// Index of the peer that currently believes it is host (first found).
    pub fn host_index(&self) -> Option<usize> {
        self.peers
            .iter()
            .position(|p| p.alive && p.session.is_host())
    }

    /// Session of peer `i`.
    pub fn session(&mut self, i: usize) -> &mut Session {
        &mut self.peers[i].session
    }

    /// Process everything due at the current time (several rounds, so replies go out).
    pub fn step(&mut self) {
        let now = self.now;
        // what a stopped (or killed) peer sent before it stopped is on the wire: it arrives
        // (the hub drops a killed peer's)
        for p in self.peers.iter_mut().filter(|p| !p.alive) {
            p.transport.release(now);
        }
        for _round in 0..4 {
            let mut any = false;
            for p in self.peers.iter_mut().filter(|p| p.alive) {
                while let Some((from, bytes)) = p.transport.recv(now) {
                    p.session.handle_packet(now, from, &bytes);
                    any = true;
                }
                if p.session.poll_timeout().is_some_and(|t| t <= now) {
                    p.session.handle_timeout(now);
                }
                while let Some(t) = p.session.poll_transmit(now) {
                    p.transport.send(now, &t);
                    p.last_send = Some(now);
                    any = true;
                }
                while let Some(e) = p.session.poll_event() {
                    if let (true, Event::Dropped { host, .. }) = (self.auto_rejoin, &e) {
                        // what the old session still had to say goes first
                        while let Some(t) = p.session.poll_transmit(now) {
                            p.transport.send(now, &t);
                        }
                        let me = p.session.local_id();
                        p.session = Session::join(me, *host, self.cfg.clone(), now);
                        self.rejoins += 1;
                        any = true;
                    }
                    p.events.push(e);
                }
            }
            if !any {
                break;
            }
        }
    }

    /// Earliest future deadline of any live peer or transport.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.peers
            .iter()
            .flat_map(|p| {
                let session = p.alive.then(|| p.session.poll_timeout()).flatten();
                [session, p.transport.poll_timeout()]
            })
            .flatten()
            .min()
    }

    /// Run for `d` of virtual time, jumping from deadline to deadline.
    pub fn advance(&mut self, d: Duration) {
        let end = self.now + d;
        self.step();
        loop {
            let next = self
                .next_deadline()
                .map_or(end, |t| t.max(self.now + Duration::from_micros(1)));
            if next > end {
                break;
            }
            self.now = next;
            self.step();
        }
        self.now = end;
        self.step();
    }

    /// Kill the host and run in `frame`s until a surviving peer is host: how long that took
    /// (the failure detector's time plus the takeover), or `None` within `limit`.
    pub fn time_to_new_host(&mut self, limit: Duration, frame: Duration) -> Option<Duration> {
        let old = self.host_index()?;
        self.kill(old);
        let start = self.now;
        while self.now.saturating_since(start) <= limit {
            self.advance(frame);
            if self.host_index().is_some() {
                return Some(self.now.saturating_since(start));
            }
        }
        None
    }

    /// Host changes any peer has seen so far (with nobody killed: false alarms).
    pub fn host_changes(&self) -> usize {
        self.peers
            .iter()
            .flat_map(|p| &p.events)
            .filter(|e| matches!(e, Event::HostChanged { .. }))
            .count()
    }

    /// Host changes and members seen leaving, by any peer, so far (with nobody killed and
    /// nobody leaving: every one is a false alarm of a failure detector).
    pub fn failure_verdicts(&self) -> usize {
        self.peers
            .iter()
            .flat_map(|p| &p.events)
            .filter(|e| matches!(e, Event::HostChanged { .. } | Event::PeerLeft(_)))
            .count()
    }

    /// Run in frames of `frame`, calling `f(harness)` before each (the application's frame).
    pub fn run_frames(
        &mut self,
        total: Duration,
        frame: Duration,
        mut f: impl FnMut(&mut Harness),
    ) {
        let end = self.now + total;
        while self.now < end {
            f(self);
            self.advance(frame);
        }
    }

    /// Run for `total` in frames of `frame` while every peer's process stops now and then, as
    /// `model` says (frozen: it neither sends nor processes, what others send it waits). The
    /// number of stops made.
    pub fn run_with_stalls(
        &mut self,
        total: Duration,
        frame: Duration,
        model: StallModel,
    ) -> usize {
        let n = self.peers.len();
        let mut rng = SeededRng::new(model.seed);
        let start = self.now;
        let mut next: Vec<Instant> = (0..n).map(|_| start + model.gap(&mut rng)).collect();
        let mut until: Vec<Option<Instant>> = vec![None; n];
        let mut stalls = 0;
        self.run_frames(total, frame, |h| {
            for i in 0..n {
                if until[i].is_some_and(|u| h.now >= u) {
                    h.freeze(i, false);
                    until[i] = None;
                    next[i] = h.now + model.gap(&mut rng);
                } else if until[i].is_none() && h.now >= next[i] {
                    h.freeze(i, true);
                    let d =
                        rng.range_f64(model.shortest.as_secs_f64(), model.longest.as_secs_f64());
                    until[i] = Some(h.now + Duration::from_secs_f64(d));
                    stalls += 1;
                }
            }
        });
        for (i, u) in until.iter().enumerate() {
            if u.is_some() {
                self.freeze(i, false);
            }
        }
        stalls
    }
}

/// The seeded CPU-stall model ([`Harness::run_with_stalls`]): every process stops at random
/// moments (exponential gaps of `mean_gap` on average) for a time drawn uniformly from
/// `shortest..longest`, as a loaded machine's scheduler, a page-fault storm or a long frame
/// makes them. With `longest` under the detector's tolerated stall, any host change or member
/// seen leaving is a false alarm.
#[derive(Clone, Copy, Debug)]
pub struct StallModel {
    /// The model's seed.
    pub seed: u64,
    /// The mean time between one process's stops.
    pub mean_gap: Duration,
    /// The shortest stop.
    pub shortest: Duration,
    /// The longest stop.
    pub longest: Duration,
}

impl StallModel {
    /// Stops of 10 ms to just under [`FailureDetector::TOLERATED_STALL`] every 1.5 s on
    /// average.
    ///
    /// [`FailureDetector::TOLERATED_STALL`]: crate::policy::FailureDetector::TOLERATED_STALL
    pub fn tolerated(seed: u64) -> StallModel {
        StallModel {
            seed,
            mean_gap: Duration::from_millis(1500),
            shortest: Duration::from_millis(10),
            longest: crate::policy::FailureDetector::TOLERATED_STALL - Duration::from_millis(1),
        }
    }

    fn gap(&self, rng: &mut SeededRng) -> Duration {
        Duration::from_secs_f64(-self.mean_gap.as_secs_f64() * (1.0 - rng.next_f64()).ln())
    }
}
