//! Unit-test helpers for the session's parts: sessions wired to each other in memory, with
//! no loss and no latency, on a clock the test moves.

use std::collections::BTreeMap;

use super::{Event, Session};
use crate::ids::PeerId;
use crate::policy::{ClassConfig, SendPolicy, SessionConfig, SoftBodyMode};
use crate::time::Instant;

/// A rigid and a soft-body class.
pub(crate) fn config() -> SessionConfig {
    SessionConfig {
        classes: vec![
            ClassConfig::rigid("rigid", SendPolicy::default()),
            ClassConfig::soft_body("soft", SendPolicy::default(), SoftBodyMode::Particles),
        ],
        ..SessionConfig::default()
    }
}

/// Sessions by peer id, delivering to each other at once.
pub(crate) struct Wire {
    pub peers: BTreeMap<PeerId, Session>,
    pub now: Instant,
}

impl Wire {
    /// No sessions yet, at time zero.
    pub fn new() -> Self {
        Wire {
            peers: BTreeMap::new(),
            now: Instant::ZERO,
        }
    }

    /// Add a session.
    pub fn add(&mut self, s: Session) {
        self.peers.insert(s.local_id(), s);
    }

    /// A session.
    pub fn get(&mut self, p: u64) -> &mut Session {
        self.peers.get_mut(&PeerId(p)).expect("no such peer")
    }

    /// Deliver everything due until quiet (bounded).
    pub fn settle(&mut self) {
        for _ in 0..50 {
            let mut moved = Vec::new();
            for s in self.peers.values_mut() {
                if s.poll_timeout().is_some_and(|t| t <= self.now) {
                    s.handle_timeout(self.now);
                }
                while let Some(t) = s.poll_transmit(self.now) {
                    moved.push((s.local_id(), t));
                }
            }
            if moved.is_empty() {
                return;
            }
            for (from, t) in moved {
                if let Some(to) = self.peers.get_mut(&t.to) {
                    to.handle_packet(self.now, from, &t.payload);
                }
            }
        }
    }

    /// Every event of peer `p` so far.
    pub fn events(&mut self, p: u64) -> Vec<Event> {
        let s = self.get(p);
        std::iter::from_fn(|| s.poll_event()).collect()
    }
}
