//! Hostile senders: state kept for unknown peers is bounded and forgotten; a full room refuses.
#![allow(clippy::unwrap_used, missing_docs)]

use std::time::Duration;

use softsync_net::session::MAX_STRANGERS;
use softsync_net::{ClassConfig, Event, Instant, PeerId, SendPolicy, Session, SessionConfig};

/// Delivers everything queued between `a` and the sessions in `bs` until quiet.
fn pump(now: Instant, a: &mut Session, bs: &mut [&mut Session]) {
    for _ in 0..16 {
        let mut any = false;
        while let Some(t) = a.poll_transmit(now) {
            if let Some(b) = bs.iter_mut().find(|b| b.local_id() == t.to) {
                b.handle_packet(now, a.local_id(), &t.payload);
                any = true;
            }
        }
        for b in bs.iter_mut() {
            while let Some(t) = b.poll_transmit(now) {
                if t.to == a.local_id() {
                    a.handle_packet(now, b.local_id(), &t.payload);
                    any = true;
                }
            }
        }
        if !any {
            break;
        }
    }
}

#[test]
fn a_flood_of_made_up_senders_costs_bounded_state_and_is_forgotten() {
    let cfg = SessionConfig::default();
    let other = SessionConfig {
        classes: vec![ClassConfig::rigid("other", SendPolicy::default())],
        ..SessionConfig::default()
    };
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    // 5000 joiners with a mismatched class table: each is refused, none becomes a member.
    for k in 0..5000u64 {
        let mut j = Session::join(PeerId(1000 + k), PeerId(1), other.clone(), now);
        while let Some(t) = j.poll_transmit(now) {
            host.handle_packet(now, j.local_id(), &t.payload);
        }
        while host.poll_transmit(now).is_some() {}
    }
    // Plus garbage from 5000 more ids.
    for k in 0..5000u64 {
        host.handle_packet(now, PeerId(100_000 + k), &[0xde, 0xad, 0xbe, 0xef, k as u8]);
    }
    assert_eq!(host.members().len(), 1);
    assert!(
        host.stats().links.len() <= MAX_STRANGERS,
        "per-peer state for {} senders",
        host.stats().links.len()
    );
    assert!(host.stats().dropped_strangers > 4000);
    // After the timeout the strangers are forgotten and a real joiner gets in.
    now += Duration::from_millis(1500);
    host.handle_timeout(now);
    assert_eq!(host.stats().links.len(), 0);
    let mut joiner = Session::join(PeerId(7), PeerId(1), cfg, now);
    for step in 0..20 {
        now += Duration::from_millis(20);
        host.handle_timeout(now);
        joiner.handle_timeout(now);
        pump(now, &mut host, &mut [&mut joiner]);
        if joiner.is_connected() {
            break;
        }
        assert!(step < 19, "joiner never got in");
    }
    assert!(host.members().contains_key(&PeerId(7)));
}

#[test]
fn a_full_room_refuses_with_a_reason() {
    let cfg = SessionConfig {
        max_members: 2,
        ..SessionConfig::default()
    };
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    let mut a = Session::join(PeerId(2), PeerId(1), cfg.clone(), now);
    let mut b = Session::join(PeerId(3), PeerId(1), cfg, now);
    for _ in 0..20 {
        now += Duration::from_millis(20);
        for s in [&mut host, &mut a, &mut b] {
            s.handle_timeout(now);
        }
        pump(now, &mut host, &mut [&mut a, &mut b]);
    }
    assert!(a.is_connected());
    assert!(!b.is_connected());
    let refused = std::iter::from_fn(|| b.poll_event()).find_map(|e| match e {
        Event::Refused { reason } => Some(reason),
        _ => None,
    });
    assert!(
        refused.as_deref().is_some_and(|r| r.contains("full")),
        "{refused:?}"
    );
    assert_eq!(host.members().len(), 2);
}
