//! Which data channel reaches which peer, and whose word an id is taken on.
//!
//! A channel says which softsync id it speaks for in its first datagram (the ident). The
//! signaling server vouches for one id per channel: the one derived from the channel's
//! matchbox id, which the server assigned at registration ([`crate::net_id`]). A peer
//! speaks for another id only after its server was lost and it registered again elsewhere
//! (its new registration has a new matchbox id; it keeps its softsync id).
//!
//! The rule (issue 32, "identity that cannot be taken"):
//! - a vouched claim is always taken; it evicts the unvouched channels that claimed the same
//!   id before it (an impostor that announced a newcomer's id on a channel of its own before
//!   the newcomer arrived), and it goes first among the peer's channels, so what is sent to
//!   that id goes to the peer the server vouches for;
//! - an unvouched claim is taken only for an id nobody reaches yet (a peer back through
//!   another server), never as a second way to a live peer;
//! - every refused or evicted claim is counted.
//!
//! Pure bookkeeping (no sockets): the transport calls it, the tests drive it alone.

use std::collections::HashMap;

use matchbox_socket::PeerId as MbPeerId;
use softsync_net::PeerId;

/// A data channel: (socket index, the peer's matchbox id on that socket).
pub(crate) type Chan = (usize, MbPeerId);

/// What became of a claim.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum Claim {
    /// The channel was identified already, or claims our own id: nothing changes.
    Ignored,
    /// Taken; `first` when it is the peer's only route (the peer is newly reachable).
    Taken {
        /// The peer had no route before.
        first: bool,
        /// Channels that had claimed the id without the server's word, dropped.
        evicted: Vec<Chan>,
    },
    /// Refused: an unvouched claim for an id someone reaches already.
    Refused,
}

/// Channels to peers and peers to channels.
#[derive(Debug, Default)]
pub(crate) struct Routes {
    chan: HashMap<Chan, PeerId>,
    /// Each peer's channels with whether the server vouched for it; vouched first, the first
    /// one used.
    routes: HashMap<PeerId, Vec<(Chan, bool)>>,
}

impl Routes {
    /// Channel `ch` says it speaks for `id`; `vouched` when the server's word is that id.
    pub(crate) fn claim(&mut self, ch: Chan, id: PeerId, vouched: bool, local: PeerId) -> Claim {
        if self.chan.contains_key(&ch) || id == local {
            return Claim::Ignored;
        }
        let r = self.routes.entry(id).or_default();
        let first = r.is_empty();
        if !vouched && !first {
            return Claim::Refused;
        }
        let mut evicted = Vec::new();
        if vouched {
            r.retain(|(c, v)| {
                if !*v {
                    evicted.push(*c);
                }
                *v
            });
            r.insert(0, (ch, true));
        } else {
            r.push((ch, false));
        }
        for c in &evicted {
            self.chan.remove(c);
        }
        self.chan.insert(ch, id);
        Claim::Taken { first, evicted }
    }

    /// Channel `ch` closed: the peer it spoke for, if that was its last route.
    pub(crate) fn close(&mut self, ch: Chan) -> Option<PeerId> {
        let id = self.chan.remove(&ch)?;
        let r = self.routes.get_mut(&id)?;
        r.retain(|(c, _)| *c != ch);
        if r.is_empty() {
            self.routes.remove(&id);
            return Some(id);
        }
        None
    }

    /// The peer channel `ch` speaks for.
    pub(crate) fn peer_of(&self, ch: &Chan) -> Option<PeerId> {
        self.chan.get(ch).copied()
    }

    /// The channel to send to `id` on.
    pub(crate) fn route(&self, id: PeerId) -> Option<Chan> {
        self.routes
            .get(&id)
            .and_then(|r| r.first())
            .map(|(c, _)| *c)
    }

    /// Whether any identified channel is on socket `sock`.
    pub(crate) fn uses_socket(&self, sock: usize) -> bool {
        self.chan.keys().any(|(j, _)| *j == sock)
    }

    /// The peers we reach.
    pub(crate) fn peers(&self) -> impl Iterator<Item = PeerId> + '_ {
        self.routes.keys().copied()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A matchbox id (a UUID) from a number.
    fn mb(n: u128) -> MbPeerId {
        serde_json::from_str(&format!("\"{n:032x}\"")).unwrap()
    }

    const ME: PeerId = PeerId(1);

    #[test]
    fn an_impostor_that_claims_a_newcomers_id_first_is_evicted_when_the_newcomer_arrives() {
        let mut r = Routes::default();
        let newcomer = PeerId(77);
        // a member's second channel claims the newcomer's id before it exists: taken (it
        // could be that peer back through another server)
        let fake = (1, mb(5));
        assert_eq!(
            r.claim(fake, newcomer, false, ME),
            Claim::Taken {
                first: true,
                evicted: vec![]
            }
        );
        assert_eq!(r.route(newcomer), Some(fake));
        // the newcomer's own channel, which its server vouches for: it wins, the impostor goes
        let real = (0, mb(9));
        assert_eq!(
            r.claim(real, newcomer, true, ME),
            Claim::Taken {
                first: false,
                evicted: vec![fake]
            }
        );
        assert_eq!(r.route(newcomer), Some(real));
        assert_eq!(
            r.peer_of(&fake),
            None,
            "the impostor's channel speaks for nobody"
        );
        // it claims again: refused
        assert_eq!(r.claim(fake, newcomer, false, ME), Claim::Refused);
        assert_eq!(r.route(newcomer), Some(real));
    }

    #[test]
    fn no_channel_speaks_for_a_live_peer_or_for_us_without_the_servers_word() {
        let mut r = Routes::default();
        let p = PeerId(5);
        let a = (0, mb(1));
        assert!(matches!(
            r.claim(a, p, true, ME),
            Claim::Taken { first: true, .. }
        ));
        // a second way to a live peer, unvouched: refused
        assert_eq!(r.claim((0, mb(2)), p, false, ME), Claim::Refused);
        // our own id: ignored
        assert_eq!(r.claim((0, mb(3)), ME, true, ME), Claim::Ignored);
        // an identified channel cannot change its word
        assert_eq!(r.claim(a, PeerId(6), true, ME), Claim::Ignored);
        assert_eq!(r.peer_of(&a), Some(p));
        // a peer back through another server (unvouched) once its old channel closed
        assert_eq!(r.close(a), Some(p));
        assert_eq!(r.route(p), None);
        let b = (1, mb(4));
        assert!(matches!(
            r.claim(b, p, false, ME),
            Claim::Taken { first: true, .. }
        ));
        // two vouched channels (one server each): both kept, the first used, and closing it
        // leaves the other
        let mut r = Routes::default();
        let (c0, c1) = ((0, mb(1)), (1, mb(1)));
        r.claim(c0, p, true, ME);
        assert!(matches!(
            r.claim(c1, p, true, ME),
            Claim::Taken { first: false, .. }
        ));
        assert_eq!(r.close(c1), None);
        assert_eq!(r.route(p), Some(c0));
        assert_eq!(r.peers().collect::<Vec<_>>(), vec![p]);
        assert!(r.uses_socket(0) && !r.uses_socket(1));
    }
}
