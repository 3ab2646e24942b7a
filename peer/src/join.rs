//! Getting into the room: which peer a joiner says `Hello` to, when it tries the next one,
//! when it gives up, and whether a peer the room went on without may join again.
//!
//! A joiner's first contact is the first peer whose data channel opened; that one may be a
//! joiner itself, which knows no host yet and cannot answer. So after [`JOIN_RETRY`] without
//! a welcome the joiner asks the next connected peer, in the order they connected, around
//! and around: the host answers `Welcome`, a member `Redirect`, another joiner nothing.

use std::time::Duration;

use softsync_net::{Instant, PeerEvent, PeerId};

/// How long a joiner waits for an answer to its `Hello` before trying the next peer.
pub const JOIN_RETRY: Duration = Duration::from_millis(1000);

/// A peer's rejoins are limited within this window (a loop of drops and rejoins is what the
/// limit stops; a process stalled now and then over a long session is not one).
pub const REJOIN_WINDOW: Duration = Duration::from_secs(60);

/// Whether a peer the room went on without may join again, having done so `rejoins` times
/// within the last [`REJOIN_WINDOW`] under a limit of `limit` (0: never).
pub fn may_rejoin(rejoins: u64, limit: u32) -> bool {
    rejoins < u64::from(limit)
}

/// A peer's way into the room: in or not, the peers it can ask, the one it asked last.
#[derive(Clone, Debug)]
pub struct Joining {
    joined: bool,
    /// Peers with open data channels, in the order they connected.
    contacts: Vec<PeerId>,
    /// The peer our `Hello` went to last, and when.
    contact: Option<(PeerId, Instant)>,
    /// When joining started (the join timeout counts from here).
    started: Instant,
    /// When we joined again lately (within [`REJOIN_WINDOW`]).
    rejoined: std::collections::VecDeque<Instant>,
}

impl Joining {
    /// In the room already (a host), or asking `contact` since `now`.
    pub fn new(now: Instant, joined: bool, contact: Option<PeerId>) -> Self {
        Joining {
            joined,
            contacts: contact.into_iter().collect(),
            contact: contact.map(|c| (c, now)),
            started: now,
            rejoined: std::collections::VecDeque::new(),
        }
    }

    /// Whether we may join again at `now` under `limit` rejoins per [`REJOIN_WINDOW`].
    pub fn may_rejoin(&mut self, now: Instant, limit: u32) -> bool {
        while self
            .rejoined
            .front()
            .is_some_and(|t| now.saturating_since(*t) >= REJOIN_WINDOW)
        {
            self.rejoined.pop_front();
        }
        may_rejoin(self.rejoined.len() as u64, limit)
    }

    /// In the room (host, or welcomed).
    pub fn joined(&self) -> bool {
        self.joined
    }

    /// Welcomed.
    pub fn set_joined(&mut self) {
        self.joined = true;
    }

    /// Connectivity news: a joiner collects the peers it could ask.
    pub fn on_link_event(&mut self, e: PeerEvent) {
        match e {
            PeerEvent::Connected(p) if !self.contacts.contains(&p) => self.contacts.push(p),
            PeerEvent::Disconnected(p) => self.contacts.retain(|q| *q != p),
            _ => {}
        }
    }

    /// The peer to say `Hello` to now, if our contact has not answered within [`JOIN_RETRY`]:
    /// the one after it among the connected peers (the first if it is gone).
    pub fn next_contact(&mut self, now: Instant) -> Option<PeerId> {
        if self.joined {
            return None;
        }
        let (current, since) = self.contact?;
        if now.saturating_since(since) < JOIN_RETRY || self.contacts.is_empty() {
            return None;
        }
        let next = self
            .contacts
            .iter()
            .position(|p| *p == current)
            .map_or(0, |i| (i + 1) % self.contacts.len());
        let next = self.contacts[next];
        self.contact = Some((next, now));
        Some(next)
    }

    /// Out of the room: join again through `host`, counting the timeout from `now`.
    pub fn restart(&mut self, now: Instant, host: PeerId) {
        self.rejoined.push_back(now);
        self.joined = false;
        if !self.contacts.contains(&host) {
            self.contacts.push(host);
        }
        self.contact = Some((host, now));
        self.started = now;
    }

    /// Count the join timeout from `now` (the driver starts pumping the network late).
    pub fn restart_clock(&mut self, now: Instant) {
        self.started = now;
    }

    /// Not in the room after waiting `timeout` since joining started.
    pub fn overdue(&self, now: Instant, timeout: Duration) -> bool {
        !self.joined && now.saturating_since(self.started) >= timeout
    }

    /// When this needs a look next (a retry or the timeout), for virtual-time drivers.
    pub fn poll_timeout(&self, timeout: Duration) -> Option<Instant> {
        if self.joined {
            return None;
        }
        let retry = self
            .contact
            .filter(|_| !self.contacts.is_empty())
            .map(|(_, since)| since + JOIN_RETRY);
        let give_up = self.started + timeout;
        Some(retry.map_or(give_up, |r| r.min(give_up)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: PeerId = PeerId(1);
    const B: PeerId = PeerId(2);
    const C: PeerId = PeerId(3);

    fn at_ms(ms: u64) -> Instant {
        Instant::from_millis(ms)
    }

    #[test]
    fn a_joiner_asks_the_next_connected_peer_in_connection_order_around_and_around() {
        let mut j = Joining::new(at_ms(0), false, Some(A));
        j.on_link_event(PeerEvent::Connected(B));
        j.on_link_event(PeerEvent::Connected(A)); // already known: keeps its place
        j.on_link_event(PeerEvent::Connected(C));
        assert_eq!(j.next_contact(at_ms(999)), None, "asked A too recently");
        assert_eq!(j.next_contact(at_ms(1000)), Some(B));
        assert_eq!(j.next_contact(at_ms(1500)), None, "asked B too recently");
        assert_eq!(j.next_contact(at_ms(2000)), Some(C));
        assert_eq!(j.next_contact(at_ms(3000)), Some(A), "wraps around");
        j.set_joined();
        assert_eq!(
            j.next_contact(at_ms(9000)),
            None,
            "in the room: nobody to ask"
        );
    }

    #[test]
    fn a_contact_that_disconnects_is_skipped_and_a_gone_one_restarts_the_order() {
        let mut j = Joining::new(at_ms(0), false, Some(A));
        j.on_link_event(PeerEvent::Connected(B));
        j.on_link_event(PeerEvent::Connected(C));
        j.on_link_event(PeerEvent::Disconnected(B));
        assert_eq!(j.next_contact(at_ms(1000)), Some(C));
        j.on_link_event(PeerEvent::Disconnected(C));
        // The peer asked last is gone: start again from the first connected.
        assert_eq!(j.next_contact(at_ms(2000)), Some(A));
        j.on_link_event(PeerEvent::Disconnected(A));
        assert_eq!(j.next_contact(at_ms(3000)), None, "nobody connected");
    }

    #[test]
    fn a_host_never_retries_nor_times_out() {
        let mut j = Joining::new(at_ms(0), true, None);
        j.on_link_event(PeerEvent::Connected(B));
        assert_eq!(j.next_contact(at_ms(5000)), None);
        assert!(!j.overdue(at_ms(60_000), Duration::from_secs(15)));
        assert_eq!(j.poll_timeout(Duration::from_secs(15)), None);
    }

    #[test]
    fn the_join_timeout_counts_from_the_last_restart() {
        let timeout = Duration::from_secs(15);
        let mut j = Joining::new(at_ms(0), false, Some(A));
        assert_eq!(
            j.poll_timeout(timeout),
            Some(at_ms(1000)),
            "the retry comes first"
        );
        assert!(!j.overdue(at_ms(14_999), timeout));
        assert!(j.overdue(at_ms(15_000), timeout));
        j.restart_clock(at_ms(10_000));
        assert!(!j.overdue(at_ms(15_000), timeout));
        assert!(j.overdue(at_ms(25_000), timeout));
        // Rejoining: out of the room, asking the host from now on.
        j.set_joined();
        j.restart(at_ms(30_000), C);
        assert!(!j.joined());
        assert_eq!(j.next_contact(at_ms(30_500)), None);
        assert_eq!(
            j.next_contact(at_ms(31_000)),
            Some(A),
            "C is last: wraps to A"
        );
        assert!(j.overdue(at_ms(45_000), timeout));
    }

    #[test]
    fn rejoining_stops_at_the_limit_and_a_zero_limit_never_rejoins() {
        assert!(may_rejoin(0, 3));
        assert!(may_rejoin(2, 3));
        assert!(!may_rejoin(3, 3));
        assert!(!may_rejoin(0, 0));
        // the limit counts rejoins within a minute: a long session's odd stall is no loop
        let mut j = Joining::new(Instant::ZERO, true, None);
        for s in [0, 10, 20] {
            assert!(j.may_rejoin(at_ms(s * 1000), 3));
            j.restart(at_ms(s * 1000), PeerId(1));
        }
        assert!(!j.may_rejoin(at_ms(59_000), 3));
        assert!(j.may_rejoin(at_ms(60_000), 3));
    }
}
