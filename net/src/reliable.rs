//! Reliable, ordered delivery of control messages over an unreliable link: sequence numbers,
//! a cumulative ack, retransmission after an RTO, a bounded reorder window.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::time::Instant;

/// Receive window: messages further ahead than this are dropped (bounded memory).
pub const WINDOW: u16 = 512;

/// Most unacknowledged messages a channel keeps: past it, [`ReliableChannel::push`] refuses
/// (the session drops a member long before: `PeerBudget::max_control_in_flight`). Well under
/// half the sequence space, so ordering by wrapping sequence stays sound.
pub const MAX_QUEUED: usize = 8192;

/// `a` comes before `b` in wrapping u16 order.
pub fn seq_before(a: u16, b: u16) -> bool {
    a != b && b.wrapping_sub(a) < 0x8000
}

#[derive(Debug, Clone)]
struct Outgoing {
    seq: u16,
    bytes: Vec<u8>,
    queued: Instant,
    next_send: Instant,
    sends: u32,
}

/// One direction-pair of reliable state for a link.
#[derive(Debug, Clone, Default)]
pub struct ReliableChannel {
    next_seq: u16,
    out: VecDeque<Outgoing>,
    next_expected: u16,
    buffered: BTreeMap<u16, Vec<u8>>,
    /// We received something and owe the peer an ack.
    pub ack_pending: bool,
}

impl ReliableChannel {
    /// Queue a message; returns its sequence number, or `None` (nothing queued) when
    /// [`MAX_QUEUED`] messages already wait for an acknowledgement.
    pub fn push(&mut self, now: Instant, bytes: Vec<u8>) -> Option<u16> {
        if self.out.len() >= MAX_QUEUED {
            return None;
        }
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        self.out.push_back(Outgoing {
            seq,
            bytes,
            queued: now,
            next_send: now,
            sends: 0,
        });
        Some(seq)
    }

    /// Messages due for (re)transmission, in order; each is marked sent with `rto` backoff.
    /// `fits` is asked for each candidate and stops the walk when it returns false.
    pub fn take_due(
        &mut self,
        now: Instant,
        rto: Duration,
        mut fits: impl FnMut(u16, &[u8]) -> bool,
    ) {
        for m in self.out.iter_mut() {
            if m.next_send > now {
                continue;
            }
            if !fits(m.seq, &m.bytes) {
                break;
            }
            m.sends += 1;
            // gentle backoff (×1, ×1.5, ×2 …, at most ×3, capped at 1.5 s): control messages are few and
            // latency-critical (authority, spawn), loss bursts are short
            let factor = 1 + m.sends.min(5);
            let backoff = (rto * factor / 2).min(Duration::from_millis(1500));
            m.next_send = now + backoff;
        }
    }

    /// Earliest retransmission deadline.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.out.iter().map(|m| m.next_send).min()
    }

    /// Anything due now?
    pub fn has_due(&self, now: Instant) -> bool {
        self.out.iter().any(|m| m.next_send <= now)
    }

    /// Process the peer's cumulative ack.
    /// Returns false, changing nothing, for an ack of messages never sent (a stale ack of an
    /// earlier incarnation of the peer's session, or a forged one): acking everything it
    /// names would drop messages the peer never had.
    pub fn on_ack(&mut self, next_expected: u16) -> bool {
        let base = self.out.front().map_or(self.next_seq, |m| m.seq);
        if seq_before(next_expected, base) {
            return true; // an older ack, overtaken: nothing new
        }
        if next_expected.wrapping_sub(base) > self.next_seq.wrapping_sub(base) {
            return false;
        }
        while let Some(front) = self.out.front() {
            if seq_before(front.seq, next_expected) {
                self.out.pop_front();
            } else {
                break;
            }
        }
        true
    }

    /// True once message `seq` has been acknowledged.
    pub fn is_acked(&self, seq: u16) -> bool {
        !self.out.iter().any(|m| m.seq == seq)
    }

    /// Unacknowledged messages.
    pub fn in_flight(&self) -> usize {
        self.out.len()
    }

    /// When the oldest unacknowledged message was queued.
    pub fn oldest_unacked(&self) -> Option<Instant> {
        self.out.front().map(|m| m.queued)
    }

    /// Accept a received message; returns the messages now deliverable in order.
    pub fn on_receive(&mut self, seq: u16, bytes: &[u8]) -> Vec<Vec<u8>> {
        self.ack_pending = true;
        if seq_before(seq, self.next_expected) {
            return Vec::new(); // duplicate
        }
        if seq.wrapping_sub(self.next_expected) >= WINDOW {
            return Vec::new(); // too far ahead: the sender will retransmit
        }
        self.buffered.entry(seq).or_insert_with(|| bytes.to_vec());
        let mut ready = Vec::new();
        while let Some(b) = self.buffered.remove(&self.next_expected) {
            ready.push(b);
            self.next_expected = self.next_expected.wrapping_add(1);
        }
        ready
    }

    /// Value to put in our ack section.
    pub fn next_expected(&self) -> u16 {
        self.next_expected
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn delivers_in_order_once() {
        let mut rx = ReliableChannel::default();
        assert!(rx.on_receive(1, b"b").is_empty());
        let got = rx.on_receive(0, b"a");
        assert_eq!(got, vec![b"a".to_vec(), b"b".to_vec()]);
        assert!(rx.on_receive(0, b"a").is_empty());
        assert_eq!(rx.next_expected(), 2);
    }

    #[test]
    fn an_ack_of_messages_never_sent_changes_nothing() {
        let mut tx = ReliableChannel::default();
        for b in [b"w", b"s", b"r"] {
            tx.push(Instant::ZERO, b.to_vec()).unwrap();
        }
        // a stale ack of an earlier session that had sent 120 messages
        assert!(!tx.on_ack(120));
        assert_eq!(tx.in_flight(), 3);
        // a real one, then an older one overtaken by it
        assert!(tx.on_ack(2));
        assert_eq!(tx.in_flight(), 1);
        assert!(tx.on_ack(1));
        assert_eq!(tx.in_flight(), 1);
        assert!(tx.on_ack(3));
        assert_eq!(tx.in_flight(), 0);
        assert!(!tx.on_ack(4));
    }

    #[test]
    fn a_peer_that_never_acknowledges_costs_a_bounded_queue() {
        let mut tx = ReliableChannel::default();
        for i in 0..MAX_QUEUED {
            assert_eq!(tx.push(Instant::ZERO, vec![1]), Some(i as u16));
        }
        assert_eq!(tx.push(Instant::ZERO, vec![1]), None);
        assert_eq!(tx.in_flight(), MAX_QUEUED);
        // an acknowledgement makes room again, in order
        assert!(tx.on_ack(10));
        assert_eq!(tx.push(Instant::ZERO, vec![2]), Some(MAX_QUEUED as u16));
    }
}
