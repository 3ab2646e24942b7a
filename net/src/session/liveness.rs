//! Who is alive: heartbeats (any datagram is one; a ping when a link is quiet, and once a
//! second for the RTT), the peer timeout (a peer silent that long is gone, whatever the
//! transport says), our own stalls ([`StallWatch`]: time we were not listening is not the
//! others' silence), peers that left on purpose ([`Departed`]) and peers the host dropped
//! that may not know it yet ([`DroppedPeers`]).

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use super::migration::heir;
use super::{Role, Session, Transmit};
use crate::ids::{PeerId, Term};
use crate::policy::FailureDetector;
use crate::time::Instant;
use crate::wire::encode_refusal_to;

/// Departed or dropped peers remembered; the set is cleared when full (peers that left long
/// ago send nothing).
const MAX_REMEMBERED: usize = 256;

/// Why a peer is out of the room ([`DroppedPeers`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DropWhy {
    /// This host timed it out.
    TimedOut,
    /// It spoke for this older term: the room elected a host while it was silent.
    OlderTerm(Term),
    /// It left this many control messages unacknowledged (`PeerBudget`).
    OverQuota(usize),
    /// It asked for twice its rate of something or more, seconds in a row.
    Flood(FloodKind),
    /// The host kicked it out and banned it (`Session::kick`).
    Banned,
}

#[derive(Clone, Copy, Debug)]
struct Dropped {
    why: DropWhy,
    /// When it was last told (at most once per heartbeat interval).
    told: Option<Instant>,
}

/// What a member flooded the host with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FloodKind {
    /// Requests (grabs, releases, answers, spawns, despawns, resyncs).
    Requests,
    /// Keyframe requests.
    Keyframes,
    /// Application messages.
    Messages,
    /// `Hello`s repeated by a member.
    Hellos,
}

/// Host: peers out of the room that may not know it, with why and when it last told them
/// so: members it timed out, and peers still speaking for an older term (a host or member
/// that stalled while the room elected this host). A peer whose loop stalled past the peer
/// timeout does not know it is out; when it talks again it is told (a refusal), rather than
/// carrying on alone as the host of a room of one, owning objects others now own.
#[derive(Debug, Default)]
pub(crate) struct DroppedPeers {
    peers: BTreeMap<PeerId, Dropped>,
}

impl DroppedPeers {
    /// `p` is out of the room.
    pub fn insert(&mut self, p: PeerId, why: DropWhy) {
        if self.peers.len() >= MAX_REMEMBERED {
            self.peers.clear();
        }
        self.peers.insert(p, Dropped { why, told: None });
    }

    /// Whether `p` is out.
    pub fn contains(&self, p: PeerId) -> bool {
        self.peers.contains_key(&p)
    }

    /// `p` joins again.
    pub fn remove(&mut self, p: PeerId) {
        self.peers.remove(&p);
    }

    /// Forget every peer (we take over: whom we told as a member are not out of our room;
    /// the soak found a member told of an older term while a client, then shut out of the
    /// room it hosted once it had rejoined).
    pub fn clear(&mut self) {
        self.peers.clear();
    }

    /// Why `p` is out, if it is due to be told at `now` (once per `every`); noted as told.
    pub(super) fn due_notice(
        &mut self,
        p: PeerId,
        now: Instant,
        every: Duration,
    ) -> Option<DropWhy> {
        let d = self.peers.get_mut(&p)?;
        if d.told.is_some_and(|t| now.saturating_since(t) < every) {
            return None;
        }
        d.told = Some(now);
        Some(d.why)
    }
}

/// Peers that said `Leave`: their datagrams still in flight are ignored (bounded).
#[derive(Debug, Default)]
pub(crate) struct Departed {
    peers: BTreeSet<PeerId>,
}

impl Departed {
    /// `p` left.
    pub fn insert(&mut self, p: PeerId) {
        if self.peers.len() >= MAX_REMEMBERED {
            self.peers.clear();
        }
        self.peers.insert(p);
    }

    /// Whether `p` left.
    pub fn contains(&self, p: PeerId) -> bool {
        self.peers.contains(&p)
    }
}

/// When the application last drove the session (a datagram or a timer), and when it last
/// found it had stalled for the peer timeout or longer (the others have timed it out, and
/// may have elected another host meanwhile).
#[derive(Debug, Default)]
pub(crate) struct StallWatch {
    last_driven: Option<Instant>,
    stalled_at: Option<Instant>,
}

impl StallWatch {
    /// The session is driven at `now`: the time since it was last driven (none the first
    /// time).
    fn driven(&mut self, now: Instant) -> Option<Duration> {
        let last = self.last_driven.replace(now)?;
        Some(now.saturating_since(last))
    }

    /// We found at `now` that we stalled past the peer timeout.
    fn stalled(&mut self, now: Instant) {
        self.stalled_at = Some(now);
    }

    /// A stall past the timeout ended less than 5 timeouts ago.
    fn recent(&self, now: Instant, timeout: Duration) -> bool {
        self.stalled_at
            .is_some_and(|t| now.saturating_since(t) < timeout * 5)
    }
}

impl Session {
    /// Heartbeat round: a ping to every member whose link was quiet for a heartbeat interval
    /// or whose RTT was not probed for a second.
    pub(super) fn heartbeat(&mut self, now: Instant) {
        if now < self.schedule.next_heartbeat {
            return;
        }
        let hb = self.cfg.heartbeat_interval;
        // The adaptive detector reads the rhythm of the gaps: a round every half interval
        // pings the links quiet for three quarters of one, so a quiet link's gaps are one
        // interval even when rounds run a little late, and no live peer's gap is longer than
        // 1.25 intervals when nothing is lost. The fixed one: a round per interval pinging
        // the links quiet for one, so gaps of up to two.
        // Each link at its own interval (`heartbeat_of`): a link between two members is
        // pinged less often than one to or from the host.
        let round = match self.cfg.detector {
            FailureDetector::Fixed => hb,
            FailureDetector::Adaptive { .. } => hb / 2,
        };
        for p in self.others() {
            let link_hb = self.heartbeat_of(p);
            let quiet_for = match self.cfg.detector {
                FailureDetector::Fixed => link_hb,
                FailureDetector::Adaptive { .. } => link_hb * 3 / 4,
            };
            let l = self.links.entry(p).or_default();
            // Any datagram is a heartbeat: an explicit ping only if the link was quiet,
            // and at least once a second for the RTT estimate.
            let quiet = l.last_sent.is_none_or(|t| now >= t + quiet_for);
            let rtt_due = l
                .last_ping
                .is_none_or(|t| now >= t + Duration::from_secs(1));
            if quiet || rtt_due {
                l.ping_due = true;
            }
        }
        self.schedule.next_heartbeat = now + round;
    }

    /// Peers we keep link state for that are neither members nor our host.
    pub(super) fn stranger_count(&self) -> usize {
        self.links
            .keys()
            .filter(|p| !self.members.contains_key(p) && Some(**p) != self.host)
            .count()
    }

    /// Drops the state of non-members silent for `peer_timeout` (a joiner that gave up, a
    /// refused or spoofed sender), or first heard `stranger_lifetime` ago however much they
    /// talk, with whatever was still queued for them.
    pub(super) fn forget_silent_strangers(&mut self, now: Instant) {
        let timeout = self.cfg.peer_timeout;
        let lifetime = self.cfg.peer_budget.stranger_lifetime;
        let gone: Vec<PeerId> = self
            .links
            .iter()
            .filter(|(p, l)| {
                !self.members.contains_key(p)
                    && Some(**p) != self.host
                    && (l.last_heard.is_some_and(|h| now >= h + timeout)
                        || l.first_heard.is_some_and(|f| now >= f + lifetime))
            })
            .map(|(p, _)| *p)
            .collect();
        for p in gone {
            self.links.remove(&p);
            self.stats.links.remove(&p);
        }
    }

    /// The stranger table is full: forget the stranger heard first, if it was first heard at
    /// least `stranger_evictable_after` ago, to make room for a new one (counted in
    /// `Stats::strangers_evicted`). False if none is that old.
    pub(super) fn evict_oldest_stranger(&mut self, now: Instant) -> bool {
        let after = self.cfg.peer_budget.stranger_evictable_after;
        let oldest = self
            .links
            .iter()
            .filter(|(p, _)| !self.members.contains_key(p) && Some(**p) != self.host)
            .filter_map(|(p, l)| l.first_heard.map(|f| (f, *p)))
            .min();
        match oldest {
            Some((first, p)) if now.saturating_since(first) >= after => {
                self.links.remove(&p);
                self.stats.links.remove(&p);
                self.stats.strangers_evicted += 1;
                true
            }
            _ => false,
        }
    }

    /// Sees our own stalls (the application did not drive the session for a while: a frozen
    /// loop, a debugger, a suspended process). Datagrams that arrived meanwhile wait in the
    /// transport, so the silence of the others over that time says nothing: their `last_heard`
    /// moves on by the gap, and nobody is timed out, nor a host elected, for our own pause.
    /// A stall as long as the peer timeout is remembered: the others have timed us out.
    pub(super) fn note_time(&mut self, now: Instant) {
        let Some(gap) = self.stalls.driven(now) else {
            return;
        };
        // The fixed detector waits a peer timeout, so only a gap of half of one matters. The
        // adaptive one judges after about a third of a second, so a stall of a tenth (a starved
        // process, as the soak with busy loops makes them) must not leave the others looking
        // silent for it; but a driver that calls less often than the session asks (a test on
        // its own cadence, a loop of 10 frames a second) is not stalling: the stall is how late
        // we are past the heartbeat round we asked for, at most two intervals apart.
        let (stall, pause) = match self.cfg.detector {
            FailureDetector::Fixed => (
                gap,
                (self.cfg.peer_timeout / 2).max(self.cfg.heartbeat_interval * 2),
            ),
            FailureDetector::Adaptive { .. } => (
                gap.min(now.saturating_since(self.schedule.next_heartbeat)),
                self.cfg.heartbeat_interval * 2,
            ),
        };
        if stall < pause || self.role == Role::Joining {
            return;
        }
        // Members and our host only: strangers are forgotten on their own schedule.
        for (p, l) in self.links.iter_mut() {
            if !self.members.contains_key(p) && Some(*p) != self.host {
                continue;
            }
            if let Some(h) = l.last_heard.as_mut() {
                *h = (*h + stall).min(now);
            }
            // What arrived during a long stall comes in a burst: not the link's rhythm. (A
            // short one's burst is a few gaps of 64; forgetting them all would leave the
            // detector at the peer timeout for 16 gaps after every hiccup.)
            if gap >= self.cfg.peer_timeout / 2 {
                l.gaps.clear();
            }
        }
        if gap >= self.cfg.peer_timeout {
            self.stalls.stalled(now);
        }
    }

    /// Whether we stalled past the peer timeout lately (see [`Session::note_time`]).
    pub(super) fn stalled_recently(&self, now: Instant) -> bool {
        self.stalls.recent(now, self.cfg.peer_timeout)
    }

    /// Host: sends a dropped peer its refusal, at most once per heartbeat interval.
    pub(super) fn tell_dropped(&mut self, now: Instant, to: PeerId) {
        let Some(why) = self
            .dropped
            .due_notice(to, now, self.cfg.heartbeat_interval)
        else {
            return;
        };
        let reason = match why {
            DropWhy::TimedOut => match self.cfg.detector {
                FailureDetector::Fixed => format!(
                    "dropped from the room: silent for longer than the peer timeout ({} ms); \
                     join again",
                    self.cfg.peer_timeout.as_millis()
                ),
                FailureDetector::Adaptive { min_timeout, .. } => format!(
                    "dropped from the room: silent for longer than the failure detector allows \
                     ({}–{} ms, by the link's loss and jitter); join again",
                    min_timeout.as_millis(),
                    self.cfg.peer_timeout.as_millis()
                ),
            },
            DropWhy::OlderTerm(old) => format!(
                "the room moved on: peer {} became host in term {} while this peer was out of \
                 touch (it still spoke for term {}); join again",
                self.host.unwrap_or(self.local).0,
                self.term.0,
                old.0
            ),
            DropWhy::OverQuota(n) => format!(
                "dropped from the room: {n} control messages unacknowledged (the host keeps at \
                 most {}); join again",
                self.cfg.peer_budget.max_control_in_flight
            ),
            DropWhy::Banned => format!(
                "kicked out of the room and banned by its host: {}",
                self.ban_reason(to).unwrap_or("no reason given")
            ),
            DropWhy::Flood(kind) => {
                let (n, what) = match kind {
                    FloodKind::Requests => (super::link::MAX_REQUESTS_PER_S, "requests"),
                    FloodKind::Keyframes => (
                        super::link::MAX_KEYFRAME_REQUESTS_PER_S,
                        "keyframe requests",
                    ),
                    FloodKind::Messages => (self.message_flood_rate(), "application messages"),
                    FloodKind::Hellos => (super::link::MAX_HELLOS_PER_S, "repeated Hellos"),
                };
                format!(
                    "dropped from the room: more than twice the {n} {what} a second a member \
                     may make, {} seconds in a row",
                    super::link::REQUEST_FLOOD_STRIKES
                )
            }
        };
        // naming our host (ourselves, if we are the host) as the host to join again: a drop
        // notice, which a joining session (the dropped peer's fresh one, reached by a notice
        // its old one provoked) ignores
        self.raw_out.push_back(Transmit {
            to,
            payload: encode_refusal_to(&reason, self.term, Some(self.host.unwrap_or(self.local))),
            reliable: true,
        });
    }

    /// The heartbeat interval of our link to `p`: the fast one to our host, to every member
    /// when we host, and while joining; [`member_heartbeat_interval`] between two members.
    ///
    /// [`member_heartbeat_interval`]: crate::SessionConfig::member_heartbeat_interval
    pub(super) fn heartbeat_of(&self, p: PeerId) -> Duration {
        let fast = self.cfg.heartbeat_interval;
        if self.role == Role::Client && Some(p) != self.host && self.members.contains_key(&p) {
            fast.max(self.cfg.member_heartbeat_interval)
        } else {
            fast
        }
    }

    /// How long `p` may be silent before it is gone: the peer timeout, or with the adaptive
    /// detector what its link's gaps say. A link between two members, pinged at its slower
    /// interval, is allowed proportionally more: at least two of its intervals, at most the
    /// peer timeout or six intervals.
    pub(super) fn silence_allowed(&self, p: PeerId) -> Duration {
        let hb = self.heartbeat_of(p);
        let slow = hb > self.cfg.heartbeat_interval;
        match (self.cfg.detector, self.links.get(&p)) {
            (
                FailureDetector::Adaptive {
                    phi,
                    deviations,
                    min_timeout,
                },
                Some(l),
            ) => {
                let (min, max) = if slow {
                    (min_timeout.max(hb * 2), self.cfg.peer_timeout.max(hb * 6))
                } else {
                    (min_timeout, self.cfg.peer_timeout)
                };
                l.gaps.timeout(hb, phi, deviations, min, max)
            }
            _ if slow => self.cfg.peer_timeout.max(hb * 6),
            _ => self.cfg.peer_timeout,
        }
    }

    /// Whether we heard from `p` within the silence it is allowed (we are always alive).
    pub(super) fn alive(&self, p: PeerId, now: Instant) -> bool {
        if p == self.local {
            return true;
        }
        let allowed = self.silence_allowed(p);
        self.links
            .get(&p)
            .and_then(|l| l.last_heard)
            .is_some_and(|h| now < h + allowed)
    }

    /// The host drops members silent past the timeout; a member whose host is silent takes
    /// over if it is the heir (or adopts a waiting `NewHost`).
    pub(super) fn check_liveness(&mut self, now: Instant) {
        self.schedule.judged_at = Some(now);
        match self.role {
            Role::Host => {
                let gone: Vec<PeerId> = self
                    .members
                    .keys()
                    .copied()
                    .filter(|p| *p != self.local && !self.alive(*p, now))
                    .collect();
                for p in gone {
                    self.dropped.insert(p, DropWhy::TimedOut);
                    self.host_peer_left(now, p);
                }
                // alive, but acknowledging nothing: its queue would grow for ever (a burst
                // queued at once — a snapshot, many spawns — is not that: the oldest message
                // must also have waited a peer timeout, which an honest peer never lets it)
                let quota = self.cfg.peer_budget.max_control_in_flight;
                let timeout = self.cfg.peer_timeout;
                let over: Vec<(PeerId, usize)> = self
                    .members
                    .keys()
                    .filter(|p| **p != self.local)
                    .filter_map(|p| {
                        let r = &self.links.get(p)?.reliable;
                        let n = r.in_flight();
                        let stuck = r
                            .oldest_unacked()
                            .is_some_and(|t| now.saturating_since(t) > timeout);
                        (n > quota && stuck).then_some((*p, n))
                    })
                    .collect();
                for (p, n) in over {
                    self.stats.dropped_over_quota += 1;
                    self.dropped.insert(p, DropWhy::OverQuota(n));
                    self.host_peer_left(now, p);
                }
            }
            Role::Client => {
                if self.retry_new_hosts(now) {
                    return;
                }
                let Some(host) = self.host else { return };
                if self.alive(host, now) {
                    return;
                }
                // Host silent: the earliest-joined surviving member takes over (no vote).
                if heir(&self.members, host, |p| self.alive(p, now)) == Some(self.local) {
                    self.become_host(now, host);
                }
            }
            Role::Joining | Role::Refused => {}
        }
    }
}

impl Session {
    /// Host: a member whose requests, keyframe requests or application messages have gone
    /// over twice their rate for [`super::link::REQUEST_FLOOD_STRIKES`] seconds in a row is
    /// dropped, told why and
    /// counted (`Stats::dropped_over_quota`): throttled first (refused past the rate), then
    /// out.
    pub(super) fn drop_if_flooding(&mut self, now: Instant, from: PeerId) {
        let Some(l) = self.links.get(&from) else {
            return;
        };
        let strikes = super::link::REQUEST_FLOOD_STRIKES;
        let kind = if l.requests.strikes() >= strikes {
            FloodKind::Requests
        } else if l.keyframe_asks.strikes() >= strikes {
            FloodKind::Keyframes
        } else if l.message_asks.strikes() >= strikes {
            FloodKind::Messages
        } else if l.hello_asks.strikes() >= strikes {
            FloodKind::Hellos
        } else {
            return;
        };
        if self.role == Role::Host && from != self.local && self.members.contains_key(&from) {
            self.stats.dropped_over_quota += 1;
            self.dropped.insert(from, DropWhy::Flood(kind));
            self.host_peer_left(now, from);
        }
    }

    /// Application messages a member may send a second, every kind together (its reliable
    /// and unreliable rates): twice this, seconds in a row, is a flood.
    pub(super) fn message_flood_rate(&self) -> u32 {
        let m = &self.cfg.messages;
        (m.rate_per_s + m.unreliable_rate_per_s).ceil().max(1.0) as u32
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_dropped_peer_is_told_at_most_once_per_interval() {
        let mut d = DroppedPeers::default();
        let p = PeerId(4);
        let every = Duration::from_millis(200);
        assert_eq!(d.due_notice(p, Instant::ZERO, every), None, "not dropped");
        d.insert(p, DropWhy::TimedOut);
        assert!(d.contains(p));
        assert_eq!(
            d.due_notice(p, Instant::from_millis(10), every),
            Some(DropWhy::TimedOut)
        );
        assert_eq!(d.due_notice(p, Instant::from_millis(209), every), None);
        assert_eq!(
            d.due_notice(p, Instant::from_millis(210), every),
            Some(DropWhy::TimedOut)
        );
        d.remove(p);
        assert!(!d.contains(p));
    }

    #[test]
    fn remembered_peers_are_bounded() {
        let mut d = Departed::default();
        let mut dropped = DroppedPeers::default();
        for i in 0..=MAX_REMEMBERED as u64 {
            d.insert(PeerId(i));
            dropped.insert(PeerId(i), DropWhy::OlderTerm(Term(1)));
        }
        assert!(d.peers.len() <= MAX_REMEMBERED && d.contains(PeerId(MAX_REMEMBERED as u64)));
        assert!(dropped.peers.len() <= MAX_REMEMBERED);
    }

    #[test]
    fn the_stall_watch_measures_gaps_and_remembers_a_long_stall_for_five_timeouts() {
        let mut w = StallWatch::default();
        let timeout = Duration::from_secs(1);
        assert_eq!(w.driven(Instant::from_millis(100)), None);
        assert_eq!(
            w.driven(Instant::from_millis(1600)),
            Some(Duration::from_millis(1500))
        );
        assert!(!w.recent(Instant::from_millis(1600), timeout));
        w.stalled(Instant::from_millis(1600));
        assert!(w.recent(Instant::from_millis(6599), timeout));
        assert!(!w.recent(Instant::from_millis(6600), timeout));
    }
}
