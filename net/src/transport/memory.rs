//! An in-memory datagram switch for tests and virtual-time runs (feature `testing`): endpoints
//! deliver instantly into each other's inboxes; peers can be killed, links cut, the MTU changed.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::{Arc, Mutex, PoisonError};

use super::{PeerEvent, Transmit, Transport};
use crate::ids::PeerId;
use crate::time::Instant;

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
    inner: Arc<Mutex<HubInner>>,
}

impl MemoryHub {
    /// A hub whose links carry datagrams up to `mtu` bytes.
    pub fn new(mtu: usize) -> Self {
        MemoryHub {
            inner: Arc::new(Mutex::new(HubInner {
                mtu,
                ..HubInner::default()
            })),
        }
    }

    /// Attach an endpoint; every existing endpoint hears `Connected`.
    pub fn endpoint(&self, id: PeerId) -> HubEndpoint {
        let mut h = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
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
        let mut h = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
        h.dead.insert(id);
        if let Some(q) = h.inboxes.get_mut(&id) {
            q.clear();
        }
    }

    /// Cut (or restore) both directions between `a` and `b`.
    pub fn set_partition(&self, a: PeerId, b: PeerId, cut: bool) {
        let mut h = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
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
        self.inner
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .mtu = mtu;
    }

    /// Datagrams dropped for exceeding the MTU.
    pub fn dropped_over_mtu(&self) -> u64 {
        self.inner
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .dropped_mtu
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

    fn send(&mut self, _now: Instant, transmit: &Transmit) {
        let (to, datagram) = (transmit.to, &transmit.payload);
        let mut h = self
            .hub
            .inner
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
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
        let mut h = self
            .hub
            .inner
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if h.dead.contains(&self.id) {
            return None;
        }
        h.inboxes.get_mut(&self.id)?.pop_front()
    }

    fn poll_peer_event(&mut self) -> Option<PeerEvent> {
        self.hub
            .inner
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .events
            .get_mut(&self.id)?
            .pop_front()
    }

    fn mtu(&self) -> usize {
        self.hub
            .inner
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .mtu
    }
}
