//! Hostile senders: state kept for unknown peers is bounded and forgotten; a full room refuses.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::time::Duration;

use glam::Vec3;
use softsync_net::harness::Harness;
use softsync_net::session::MAX_STRANGERS;
use softsync_net::wire::{Control, SpawnInfo};
use softsync_net::{
    AuthorityEpoch, AuthorityPolicy, ClassConfig, ClassId, ConditionerConfig, Event, Instant,
    NetId, PeerBudget, PeerId, SendPolicy, Session, SessionConfig, Term,
};

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

/// Sum of particles of the objects `owner` owns, as the host `s` sees them.
fn owned_by(s: &Session, owner: PeerId) -> (usize, usize) {
    let ids: Vec<_> = s
        .object_ids()
        .into_iter()
        .filter(|id| s.owner(*id) == Some(owner))
        .collect();
    let particles = ids
        .iter()
        .map(|id| s.latest_state(*id).map_or(0, |st| st.particles.len()))
        .sum();
    (ids.len(), particles)
}

fn claim(id: u32, owner: PeerId, term: u32, grant: u32, particles: u32) -> SpawnInfo {
    SpawnInfo {
        id: NetId(id),
        class: ClassId(0),
        owner,
        epoch: AuthorityEpoch { term, grant },
        held: true,
        policy: AuthorityPolicy::Free,
        particles,
        pos: [0.0; 3],
        rot: [0.0, 0.0, 0.0, 1.0],
        request: None,
        topology: 0,
    }
}

/// A member sends `Resync` claims with impossible epochs and made-up ids, to the original
/// host (never migrated: no window) and right after a migration: it takes nothing, creates at
/// most its per-peer allowance, and nothing overflows.
#[test]
fn hostile_resync_claims_take_nothing_and_create_boundedly() {
    let mut h = common::room(4, ConditionerConfig::default());
    let a = common::spawn_rigid(&mut h, 0, Vec3::X).0;
    let c = common::spawn_rigid(&mut h, 0, Vec3::Y).0;
    h.advance(Duration::from_millis(300));
    // peer 1 (the heir) holds c
    common::request_authority(&mut h, 1, c);
    h.advance(Duration::from_millis(300));
    assert_eq!(h.peers[0].session.owner(c), Some(Harness::id(1)));
    let bad = Harness::id(3);
    let hostile = |h: &mut Harness, to: usize| {
        let now = h.now;
        let mut claims = vec![
            claim(a.0, bad, u32::MAX, u32::MAX, 0),
            claim(c.0, bad, 1, 1000, 0),
            claim(u32::MAX, bad, 1, 0, 0),
            claim(5000, bad, 1, 0, 65_536),
        ];
        let s = h.session(3);
        for chunk in claims.chunks(4) {
            let msg = Control::Resync {
                claims: chunk.to_vec(),
            };
            s.send_raw_control(now, Harness::id(to), &msg);
        }
        // a flood of claims of unknown ids right after the highest known id
        claims.clear();
        for k in 0..600u32 {
            let particles = if k < 8 { 65_536 } else { 0 };
            claims.push(claim(c.0 + 1 + k, bad, 1, 0, particles));
        }
        for chunk in claims.chunks(16) {
            let msg = Control::Resync {
                claims: chunk.to_vec(),
            };
            s.send_raw_control(now, Harness::id(to), &msg);
        }
    };
    // 1. the original host never sent NewHost: every claim is refused
    hostile(&mut h, 0);
    h.advance(Duration::from_millis(500));
    for i in 0..4 {
        let s = &h.peers[i].session;
        assert_eq!(s.object_ids(), vec![a, c], "peer {i}");
        assert_eq!(s.owner(a), Some(Harness::id(0)), "peer {i}");
        assert_eq!(s.owner(c), Some(Harness::id(1)), "peer {i}");
    }
    assert!(h.peers[0].session.stats().refused_controls > 0);
    // 2. the host dies; right after peer 1 takes over, the hostile member claims again
    h.kill(0);
    while !h.peers[1].session.is_host() {
        h.advance(Duration::from_millis(5));
    }
    let term = h.peers[1].session.term();
    hostile(&mut h, 1);
    h.advance(Duration::from_millis(1500));
    let cfg = h.peers[1].session.config().clone();
    for i in 1..4 {
        let s = &h.peers[i].session;
        assert_eq!(s.owner(a), Some(Harness::id(1)), "peer {i}: a");
        assert_eq!(s.owner(c), Some(Harness::id(1)), "peer {i}: c");
        assert!(s.epoch(a).unwrap().term <= term.0, "peer {i}");
        assert!(s.epoch(c).unwrap().term <= term.0, "peer {i}");
        assert!(!s.object_ids().contains(&NetId(u32::MAX)));
    }
    let host = &h.peers[1].session;
    let (n, particles) = owned_by(host, bad);
    assert!(n <= cfg.max_objects_per_peer, "{n} objects created");
    assert!(
        particles <= cfg.max_particles_per_peer,
        "{particles} particles"
    );
    assert!(host.object_ids().len() <= 2 + cfg.max_objects_per_peer);
    // 3. after the window nothing is accepted any more
    h.advance(Duration::from_millis(1500));
    let before = h.peers[1].session.object_ids();
    hostile(&mut h, 1);
    h.advance(Duration::from_millis(500));
    assert_eq!(h.peers[1].session.object_ids(), before);
    assert_eq!(h.peers[1].session.owner(a), Some(Harness::id(1)));
}

/// A member announces itself as the new host (a huge term, then the next term): nobody
/// follows while the host lives, the real heir takes over when it dies, and nothing
/// overflows.
#[test]
fn hostile_new_host_is_ignored_and_the_real_heir_takes_over() {
    let mut h = common::room(4, ConditionerConfig::default());
    let bad = Harness::id(3);
    let grab = |h: &mut Harness, term: u32| {
        let now = h.now;
        let members: Vec<(PeerId, u32)> = vec![(bad, 0), (Harness::id(1), 1), (Harness::id(2), 2)];
        for to in 0..3 {
            let msg = Control::NewHost {
                term: Term(term),
                host: bad,
                members: members.clone(),
            };
            h.session(3).send_raw_control(now, Harness::id(to), &msg);
        }
    };
    grab(&mut h, u32::MAX);
    grab(&mut h, 2);
    h.advance(Duration::from_millis(3000));
    assert!(h.peers[0].session.is_host());
    for i in 0..3 {
        let s = &h.peers[i].session;
        assert_eq!(s.host_id(), Some(Harness::id(0)), "peer {i}");
        assert_eq!(s.term(), Term(1), "peer {i}");
    }
    assert!(h.peers[1].session.stats().refused_controls > 0);
    // the host dies: the earliest joiner takes over, everyone (the hostile peer too) follows
    h.kill(0);
    h.advance(Duration::from_millis(3000));
    for i in 1..4 {
        let s = &h.peers[i].session;
        assert_eq!(s.host_id(), Some(Harness::id(1)), "peer {i}");
        assert_eq!(s.term(), Term(2), "peer {i}");
    }
    // and cannot be unseated by the member either
    grab(&mut h, 3);
    h.advance(Duration::from_millis(3000));
    assert!(h.peers[1].session.is_host());
    assert_eq!(h.peers[2].session.host_id(), Some(Harness::id(1)));
    assert_eq!(h.peers[2].session.term(), Term(2));
}

/// A member that keeps its link alive (it hears heartbeats and pings) but never receives, so
/// never acknowledges, a control message: the host used to keep, and walk at every datagram,
/// an ever longer queue for it. Past its budget it is dropped with the reason, told so, and
/// the honest member keeps everything.
#[test]
fn a_member_that_never_acknowledges_is_dropped_past_its_budget() {
    let cfg = SessionConfig {
        peer_budget: PeerBudget {
            max_control_in_flight: 100,
            ..PeerBudget::default()
        },
        ..SessionConfig::default()
    };
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    let mut honest = Session::join(PeerId(2), PeerId(1), cfg.clone(), now);
    let mut deaf = Session::join(PeerId(3), PeerId(1), cfg, now);
    let step = |now: Instant,
                host: &mut Session,
                honest: &mut Session,
                deaf: &mut Session,
                deaf_hears_control: bool| {
        for s in [&mut *host, &mut *honest, &mut *deaf] {
            s.handle_timeout(now);
        }
        for _ in 0..8 {
            while let Some(t) = host.poll_transmit(now) {
                if t.to == PeerId(2) {
                    honest.handle_packet(now, PeerId(1), &t.payload);
                } else if t.to == PeerId(3)
                    && (deaf_hears_control
                        || !t.reliable
                        || softsync_net::wire::decode_refusal(&t.payload).is_some())
                {
                    deaf.handle_packet(now, PeerId(1), &t.payload);
                }
            }
            for s in [&mut *honest, &mut *deaf] {
                while let Some(t) = s.poll_transmit(now) {
                    if t.to == PeerId(1) {
                        host.handle_packet(now, s.local_id(), &t.payload);
                    }
                }
            }
        }
    };
    for _ in 0..25 {
        now += Duration::from_millis(20);
        step(now, &mut host, &mut honest, &mut deaf, true);
    }
    assert!(honest.is_connected() && deaf.is_connected());
    assert_eq!(host.members().len(), 3);
    // From now on the deaf member hears no control message; the host spawns 150 objects.
    let state = softsync_net::ObjectState::rigid(Vec3::ZERO, glam::Quat::IDENTITY);
    for i in 0..150 {
        let mut s = state.clone();
        s.pos.x = i as f32 * 0.01;
        host.spawn(now, ClassId(0), s).unwrap();
    }
    let mut dropped_at = None;
    for k in 0..150 {
        now += Duration::from_millis(20);
        step(now, &mut host, &mut honest, &mut deaf, false);
        if dropped_at.is_none() && !host.members().contains_key(&PeerId(3)) {
            dropped_at = Some(k);
        }
    }
    assert!(dropped_at.is_some(), "the deaf member was never dropped");
    assert_eq!(host.stats().dropped_over_quota, 1);
    assert!(honest.is_connected());
    assert_eq!(honest.object_ids().len(), 150);
    assert_eq!(host.members().len(), 2);
    // it is told why (it hears everything but control messages: the refusal too)
    let told = std::iter::from_fn(|| deaf.poll_event()).find_map(|e| match e {
        Event::Dropped { reason, .. } => Some(reason),
        _ => None,
    });
    assert!(
        told.as_deref()
            .is_some_and(|r| r.contains("unacknowledged")),
        "{told:?}"
    );
}

/// ~80 `Hello`s fit in one datagram; each used to be answered with a `Welcome` and the whole
/// snapshot. A member's repeated `Hello` gets one `Welcome` in flight, another only once that
/// one is acknowledged, and no more than a few at once and one a second after.
#[test]
fn a_flood_of_hellos_from_a_member_gets_one_welcome() {
    let cfg = SessionConfig::default();
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    let mut m = Session::join(PeerId(2), PeerId(1), cfg.clone(), now);
    for _ in 0..25 {
        now += Duration::from_millis(20);
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, &mut host, &mut [&mut m]);
    }
    assert!(m.is_connected());
    for i in 0..30 {
        let mut s = softsync_net::ObjectState::rigid(Vec3::ZERO, glam::Quat::IDENTITY);
        s.pos.x = i as f32 * 0.01;
        host.spawn(now, ClassId(0), s).unwrap();
    }
    pump(now, &mut host, &mut [&mut m]);
    let hello = Control::Hello {
        protocol: softsync_net::PROTOCOL_VERSION,
        config_digest: cfg.digest(),
    };
    // 80 at once (the last Welcome is acknowledged): one Welcome in flight answers them all
    now += Duration::from_millis(20);
    for _ in 0..80 {
        m.send_raw_control(now, PeerId(1), &hello);
    }
    pump(now, &mut host, &mut [&mut m]);
    assert_eq!(host.stats().repeated_hellos_ignored, 79);
    // (that burst was over the member's 10 Hellos a second: the next second starts afresh)
    now += Duration::from_millis(1000);
    // a member that acknowledges each Welcome and says Hello again at once, every 20 ms for
    // a second: the rest of its burst of three, then one a second
    let mut answered = 0;
    for _ in 0..50 {
        now += Duration::from_millis(20);
        let before = host.stats().repeated_hellos_ignored;
        m.send_raw_control(now, PeerId(1), &hello);
        pump(now, &mut host, &mut [&mut m]);
        answered += usize::from(host.stats().repeated_hellos_ignored == before);
    }
    assert!((2..=3).contains(&answered), "answered {answered}");
    assert!(m.is_connected());
    assert_eq!(host.members().len(), 2);
}

/// 32 strangers that keep talking (refused joiners replaying their `Hello`) used to fill the
/// stranger table for ever: nobody else could even say `Hello`. Now a newcomer takes the
/// place of the stranger heard first (once it is 2 s old), and strangers expire.
#[test]
fn strangers_that_keep_talking_cannot_hold_the_door_shut() {
    let cfg = SessionConfig::default();
    let other = SessionConfig {
        classes: vec![ClassConfig::rigid("other", SendPolicy::default())],
        ..SessionConfig::default()
    };
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    // their first datagrams (a Hello each), replayed every 100 ms from then on
    let hellos: Vec<(PeerId, Vec<u8>)> = (0..MAX_STRANGERS as u64)
        .map(|i| {
            let id = PeerId(1000 + i);
            let mut s = Session::join(id, PeerId(1), other.clone(), now);
            (id, s.poll_transmit(now).unwrap().payload)
        })
        .collect();
    let mut joiner: Option<Session> = None;
    for k in 0..100 {
        now += Duration::from_millis(100);
        host.handle_timeout(now);
        for (id, d) in &hellos {
            host.handle_packet(now, *id, d);
        }
        // what the host says to the strangers is lost; to the joiner it arrives (its
        // heartbeats: a member that hears nothing from its host times it out)
        while let Some(t) = host.poll_transmit(now) {
            if let Some(j) = joiner.as_mut().filter(|j| j.local_id() == t.to) {
                j.handle_packet(now, PeerId(1), &t.payload);
            }
        }
        if k == 30 {
            // 3 s in: an honest joiner
            joiner = Some(Session::join(PeerId(7), PeerId(1), cfg.clone(), now));
        }
        if let Some(j) = joiner.as_mut() {
            j.handle_timeout(now);
            pump(now, &mut host, &mut [j]);
        }
    }
    let joiner = joiner.unwrap();
    assert!(joiner.is_connected(), "the honest joiner never got in");
    assert!(host.members().contains_key(&PeerId(7)));
    assert!(host.stats().strangers_evicted > 0);
    // the table never held more than its bound
    assert!(host.stats().links.len() <= MAX_STRANGERS + 1);
}

/// A stranger that asks a keyed room's host for keyframes of its objects (ids are small
/// numbers, easily guessed) used to get their state: the room's content without the key.
#[test]
fn a_strangers_keyframe_request_reads_nothing_of_a_keyed_room() {
    use softsync_net::wire::{decode_packet, PacketHeader, PacketWriter, Section};
    let cfg = SessionConfig {
        room_key: Some(softsync_net::RoomKey::new(b"the room's secret", 7)),
        ..SessionConfig::default()
    };
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg, now);
    let (id, _) = host
        .spawn(
            now,
            ClassId(0),
            softsync_net::ObjectState::rigid(Vec3::new(0.3, 0.8, 0.1), glam::Quat::IDENTITY),
        )
        .unwrap();
    let mut w = PacketWriter::new(
        &PacketHeader {
            term: Term(0),
            seq: 0,
            time_ms: 0,
        },
        1200,
    );
    assert!(w.keyframe_request(&[id, NetId(id.0 + 1), NetId(id.0 + 2)]));
    let (request, _) = w.finish();
    let mut state_bytes = 0;
    for _ in 0..20 {
        now += Duration::from_millis(50);
        host.handle_timeout(now);
        host.handle_packet(now, PeerId(66), &request);
        while let Some(t) = host.poll_transmit(now) {
            if t.to != PeerId(66) {
                continue;
            }
            if let Ok((_, sections)) = decode_packet(&t.payload) {
                for s in sections {
                    if let Section::State { bits, .. } = s {
                        state_bytes += bits.len();
                    }
                }
            }
        }
    }
    assert_eq!(state_bytes, 0, "the stranger got state");
    assert!(host.stats().refused_controls >= 20);
}

/// Issue 32: a member's requests are rate-limited at the host. A modified client that sends
/// 1,000 authority requests and releases in a second gets `MAX_REQUESTS_PER_S` of them
/// served and the rest refused and counted; keyframe requests likewise. The next second it is
/// served again, and the host's own requests are never limited.
#[test]
fn a_members_request_flood_is_limited_per_second_and_counted() {
    use softsync_net::session::link::{MAX_KEYFRAME_REQUESTS_PER_S, MAX_REQUESTS_PER_S};
    let cfg = SessionConfig::default();
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    let mut m = Session::join(PeerId(2), PeerId(1), cfg, now);
    for _ in 0..25 {
        now += Duration::from_millis(20);
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, &mut host, &mut [&mut m]);
    }
    assert!(m.is_connected());
    let s = softsync_net::ObjectState::rigid(Vec3::ZERO, glam::Quat::IDENTITY);
    let (id, _) = host.spawn(now, ClassId(0), s).unwrap();
    pump(now, &mut host, &mut [&mut m]);
    now += Duration::from_millis(20);
    for k in 0..1000 {
        let c = if k % 2 == 0 {
            Control::AuthorityRequest { id }
        } else {
            Control::AuthorityRelease { id }
        };
        m.send_raw_control(now, PeerId(1), &c);
        if k % 50 == 0 {
            pump(now, &mut host, &mut [&mut m]);
        }
    }
    pump(now, &mut host, &mut [&mut m]);
    let limited = host.stats().requests_rate_limited;
    assert_eq!(limited, 1000 - u64::from(MAX_REQUESTS_PER_S), "{limited}");
    // keyframe requests, each naming the object, 200 in the same second
    let before = host.stats().requests_rate_limited;
    for k in 0..200u8 {
        // a datagram of its own each (as a modified client would send them)
        let header = softsync_net::wire::PacketHeader {
            term: m.term(),
            seq: k,
            time_ms: now.wire_ms(),
        };
        let mut w = softsync_net::wire::PacketWriter::new(&header, 1200);
        assert!(w.keyframe_request(&[id]));
        host.handle_packet(now, PeerId(2), &w.finish().0);
    }
    assert_eq!(
        host.stats().requests_rate_limited - before,
        200 - u64::from(MAX_KEYFRAME_REQUESTS_PER_S)
    );
    // a second later it is served again; the host's own requests were never counted
    now += Duration::from_millis(1100);
    host.handle_timeout(now);
    m.handle_timeout(now);
    pump(now, &mut host, &mut [&mut m]);
    let before = host.stats().requests_rate_limited;
    m.request_authority(now, id).unwrap();
    pump(now, &mut host, &mut [&mut m]);
    assert_eq!(host.stats().requests_rate_limited, before);
    for _ in 0..100 {
        host.request_authority(now, id).unwrap();
    }
    assert_eq!(host.stats().requests_rate_limited, before);
    assert!(m.is_connected() && host.members().len() == 2);
}

/// Issue 32: throttled, then out. A member that keeps asking for ten times its request rate
/// is refused past the rate at once and dropped once it has done so
/// `REQUEST_FLOOD_STRIKES` seconds in a row, told why; an honest burst (one second over the
/// rate, then quiet) is not.
#[test]
fn a_member_that_keeps_flooding_requests_is_dropped_with_a_reason() {
    use softsync_net::session::link::{MAX_REQUESTS_PER_S, REQUEST_FLOOD_STRIKES};
    let cfg = SessionConfig::default();
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    let mut m = Session::join(PeerId(2), PeerId(1), cfg, now);
    for _ in 0..25 {
        now += Duration::from_millis(20);
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, &mut host, &mut [&mut m]);
    }
    let s = softsync_net::ObjectState::rigid(Vec3::ZERO, glam::Quat::IDENTITY);
    let (id, _) = host.spawn(now, ClassId(0), s).unwrap();
    pump(now, &mut host, &mut [&mut m]);
    let mut dropped_after = None;
    for tick in 0..100 {
        // 100 ms: the flood's share (ten times the rate), then the ordinary traffic
        now += Duration::from_millis(100);
        for _ in 0..MAX_REQUESTS_PER_S {
            m.send_raw_control(now, PeerId(1), &Control::AuthorityRequest { id });
        }
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, &mut host, &mut [&mut m]);
        if !host.members().contains_key(&PeerId(2)) {
            dropped_after = Some(tick);
            break;
        }
    }
    let ticks = dropped_after.expect("the flooding member was never dropped");
    // after REQUEST_FLOOD_STRIKES full seconds over twice the rate, and not much later
    assert!(
        (10 * REQUEST_FLOOD_STRIKES as usize..=10 * (REQUEST_FLOOD_STRIKES as usize + 2))
            .contains(&ticks),
        "dropped after {ticks} ticks of 100 ms"
    );
    assert_eq!(host.stats().dropped_over_quota, 1);
    assert!(host.stats().requests_rate_limited > 1000);
    // it is told why
    for _ in 0..5 {
        now += Duration::from_millis(100);
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, &mut host, &mut [&mut m]);
    }
    let told = std::iter::from_fn(|| m.poll_event()).find_map(|e| match e {
        Event::Dropped { reason, .. } => Some(reason),
        _ => None,
    });
    assert!(
        told.as_deref()
            .is_some_and(|r| r.contains("twice the 60 requests a second")),
        "{told:?}"
    );
}

#[test]
fn another_protocols_datagram_is_never_answered_as_a_wrong_version() {
    use softsync_net::door::{classify, Door};
    let now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), SessionConfig::default(), now);
    // a datagram of a protocol this build does not know (a newer peer's voice, say), and
    // one of every registered non-session protocol: not the session's, so no refusal
    // (answering each with a refusal datagram would amplify a flood)
    for d in [
        &[0xF6, 1, 2, 3][..],
        &[0x80][..],
        &[0xF7, 1, 0, 0, 0, 0][..],
        &[0xF5, 1, 0, 0][..],
        &softsync_net::wire::CHANNEL_IDENT[..],
    ] {
        assert!(!matches!(classify(d), Door::Session | Door::OtherVersion));
        host.handle_packet(now, PeerId(9), d);
        assert!(host.poll_transmit(now).is_none(), "answered {d:?}");
    }
    // a session of another version is told why
    let other = softsync_net::wire::PROTOCOL_VERSION + 1;
    assert_eq!(classify(&[other, 0, 0, 0, 0]), Door::OtherVersion);
    host.handle_packet(now, PeerId(9), &[other, 0, 0, 0, 0]);
    let t = host.poll_transmit(now).expect("a refusal");
    assert_eq!(classify(&t.payload), Door::Refusal);
}

fn reason_of(events: &[Event]) -> Option<String> {
    events.iter().rev().find_map(|e| match e {
        Event::Refused { reason } | Event::Dropped { reason, .. } => Some(reason.clone()),
        _ => None,
    })
}

#[test]
fn a_kicked_peer_is_out_for_the_rooms_life_even_after_a_migration() {
    let cfg = SessionConfig::default();
    let mut h = Harness::new(4, cfg.clone(), ConditionerConfig::default());
    h.advance(Duration::from_secs(1));
    assert_eq!(h.session(0).members().len(), 4);
    // the prankster holds an object when it is kicked
    let now = h.now;
    let s = softsync_net::ObjectState::rigid(Vec3::ZERO, glam::Quat::IDENTITY);
    let (id, _) = h.session(0).spawn(now, ClassId(0), s).unwrap();
    h.advance(Duration::from_millis(300));
    let now = h.now;
    h.session(3).request_authority(now, id).unwrap();
    h.advance(Duration::from_millis(500));
    assert_eq!(h.session(0).owner(id), Some(Harness::id(3)));
    // only the host kicks
    let now = h.now;
    assert_eq!(
        h.session(1).kick(now, Harness::id(3), "no"),
        Err(softsync_net::KickError::NotHost)
    );
    h.session(0)
        .kick(now, Harness::id(3), "drew on the patient")
        .unwrap();
    h.advance(Duration::from_secs(1));
    assert!(!h.session(0).members().contains_key(&Harness::id(3)));
    let r = reason_of(&h.peers[3].events).unwrap_or_default();
    assert!(
        r.contains("banned") && r.contains("drew on the patient"),
        "{r:?}"
    );
    for i in 0..3 {
        assert!(h.session(i).is_banned(Harness::id(3)), "peer {i}");
        assert_ne!(h.session(i).owner(id), Some(Harness::id(3)), "peer {i}");
    }
    assert_eq!(h.session(0).stats().kicked, 1);
    // it comes back with a fresh session: refused, with the reason
    let rejoin = |h: &mut Harness, contact: PeerId| {
        let now = h.now;
        h.peers[3].session = Session::join(Harness::id(3), contact, cfg.clone(), now);
        h.peers[3].events.clear();
        h.advance(Duration::from_secs(2));
        reason_of(&h.peers[3].events).unwrap_or_default()
    };
    let r = rejoin(&mut h, Harness::id(0));
    assert!(r.contains("banned"), "{r:?}");
    assert_eq!(h.session(0).members().len(), 3);
    assert!(h.session(0).stats().banned_dropped > 0);
    // the host dies: the next one keeps the ban (asked first, a member would redirect it)
    h.kill(0);
    h.advance(Duration::from_secs(3));
    let new_host = h.host_index().unwrap();
    assert_ne!(new_host, 0);
    let r = rejoin(&mut h, Harness::id(new_host));
    assert!(r.contains("banned"), "{r:?}");
    assert!(!h.session(new_host).members().contains_key(&Harness::id(3)));
    // a new member learns the bans with its snapshot
    let late = h.add_peer_with(cfg.clone(), new_host);
    h.advance(Duration::from_secs(2));
    assert!(h.session(late).is_connected());
    assert!(h.session(late).is_banned(Harness::id(3)));
    assert_eq!(
        h.session(late).banned(),
        vec![(Harness::id(3), "drew on the patient".to_string())]
    );
}

#[test]
fn a_flood_of_other_versions_gets_a_few_refusals_not_one_each() {
    use softsync_net::session::MAX_VERSION_REFUSALS_PER_S;
    let mut host = Session::host(PeerId(1), SessionConfig::default(), Instant::ZERO);
    let other = softsync_net::wire::PROTOCOL_VERSION + 1;
    let mut answered = 0;
    for second in 0..3u64 {
        for k in 0..1000u64 {
            let now = Instant::from_millis(second * 1000 + k / 2);
            host.handle_packet(now, PeerId(10 + k % 7), &[other, 0, 0, 0, 0]);
            while host.poll_transmit(now).is_some() {
                answered += 1;
            }
        }
    }
    assert_eq!(answered, 3 * MAX_VERSION_REFUSALS_PER_S as usize);
}

/// A joined host and member (peer 2), and an object of the host's.
fn joined_with_object() -> (Instant, Session, Session, NetId) {
    let cfg = SessionConfig::default();
    let mut now = Instant::ZERO;
    let mut host = Session::host(PeerId(1), cfg.clone(), now);
    let mut m = Session::join(PeerId(2), PeerId(1), cfg, now);
    for _ in 0..25 {
        now += Duration::from_millis(20);
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, &mut host, &mut [&mut m]);
    }
    let s = softsync_net::ObjectState::rigid(Vec3::ZERO, glam::Quat::IDENTITY);
    let (id, _) = host.spawn(now, ClassId(0), s).unwrap();
    pump(now, &mut host, &mut [&mut m]);
    assert!(m.is_connected());
    (now, host, m, id)
}

/// Ticks of 100 ms, `flood` run each, until the member is out of the host's room; then the
/// reason it was told.
fn flood_until_dropped(
    mut now: Instant,
    host: &mut Session,
    m: &mut Session,
    mut flood: impl FnMut(Instant, &mut Session, &mut Session),
) -> (usize, String) {
    let mut dropped_after = None;
    for tick in 0..100 {
        now += Duration::from_millis(100);
        flood(now, host, m);
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, host, &mut [m]);
        if !host.members().contains_key(&PeerId(2)) {
            dropped_after = Some(tick);
            break;
        }
    }
    let ticks = dropped_after.unwrap_or_else(|| {
        panic!(
            "the flooding member was never dropped: {} refused, {:?} messages refused",
            host.stats().requests_rate_limited,
            host.stats().messages.refused
        )
    });
    for _ in 0..5 {
        now += Duration::from_millis(100);
        host.handle_timeout(now);
        m.handle_timeout(now);
        pump(now, host, &mut [m]);
    }
    let told = std::iter::from_fn(|| m.poll_event())
        .find_map(|e| match e {
            Event::Dropped { reason, .. } => Some(reason),
            _ => None,
        })
        .unwrap_or_default();
    (ticks, told)
}

#[test]
fn a_member_that_keeps_flooding_keyframe_requests_or_messages_is_dropped_with_a_reason() {
    use softsync_net::session::link::{MAX_KEYFRAME_REQUESTS_PER_S, REQUEST_FLOOD_STRIKES};
    use softsync_net::wire::{
        AppMessage, Delivery, MessageKind, MessageTarget, PacketHeader, PacketWriter,
    };
    let strikes = REQUEST_FLOOD_STRIKES as usize;
    // keyframe requests at ten times their rate, each in its own datagram
    let (now, mut host, mut m, id) = joined_with_object();
    let mut seq = 0u8;
    let (ticks, told) = flood_until_dropped(now, &mut host, &mut m, |now, host, m| {
        for _ in 0..MAX_KEYFRAME_REQUESTS_PER_S {
            seq = seq.wrapping_add(1);
            let header = PacketHeader {
                term: m.term(),
                seq,
                time_ms: 0,
            };
            let mut w = PacketWriter::new(&header, 1200);
            assert!(w.keyframe_request(&[id]));
            let (bytes, _) = w.finish();
            host.handle_packet(now, PeerId(2), &bytes);
        }
    });
    assert!(
        (10 * strikes..=10 * (strikes + 2)).contains(&ticks),
        "after {ticks} ticks"
    );
    assert!(told.contains("twice the 30 keyframe requests"), "{told:?}");
    // application messages at ten times the rates of every kind together (300 a second)
    let (now, mut host, mut m, _) = joined_with_object();
    let mut n = 0;
    let (ticks, told) = flood_until_dropped(now, &mut host, &mut m, |now, _host, m| {
        for _ in 0..300 {
            n += 1;
            let msg = AppMessage {
                origin: PeerId(2),
                seq: n,
                kind: MessageKind(0),
                to: MessageTarget::Everyone,
                delivery: Delivery::Reliable,
                payload: b"spam".to_vec(),
            };
            m.send_raw_control(now, PeerId(1), &Control::Message(msg));
        }
    });
    assert!(
        (10 * strikes..=10 * (strikes + 3)).contains(&ticks),
        "after {ticks} ticks"
    );
    assert!(told.contains("application messages a second"), "{told:?}");
    assert_eq!(host.stats().dropped_over_quota, 1);
}

/// A member that keeps repeating `Hello` (80 in every datagram, 800 a second) is ignored
/// past 10 a second and, after five seconds of that, dropped with the reason: each of them
/// cost the host a reliable message to take in.
#[test]
fn a_member_that_keeps_repeating_hello_is_dropped_with_a_reason() {
    use softsync_net::session::link::{MAX_HELLOS_PER_S, REQUEST_FLOOD_STRIKES};
    let strikes = REQUEST_FLOOD_STRIKES as usize;
    let (now, mut host, mut m, _) = joined_with_object();
    let hello = Control::Hello {
        protocol: softsync_net::PROTOCOL_VERSION,
        config_digest: SessionConfig::default().digest(),
    };
    let (ticks, told) = flood_until_dropped(now, &mut host, &mut m, |now, _host, m| {
        for _ in 0..80 {
            m.send_raw_control(now, PeerId(1), &hello);
        }
    });
    assert!(
        (10 * strikes..=10 * (strikes + 3)).contains(&ticks),
        "after {ticks} ticks"
    );
    assert!(
        told.contains(&format!(
            "twice the {MAX_HELLOS_PER_S} repeated Hellos a second"
        )),
        "{told:?}"
    );
    assert_eq!(host.stats().dropped_over_quota, 1);
}
