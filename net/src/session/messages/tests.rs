//! Unit tests of application messages: sessions wired in memory (`testkit::Wire`).
#![allow(clippy::unwrap_used)]

use super::super::testkit::{config, Wire};
use super::*;
use crate::policy::SessionConfig;
use crate::wire::MAX_MESSAGE_PAYLOAD;
use crate::NetId;

fn cfg() -> SessionConfig {
    let mut c = config();
    c.messages.kinds = vec!["bell".into(), "valve".into()];
    c
}

/// Peer `p` sends a message of kind `kind` at the wire's time.
fn send(
    w: &mut Wire,
    p: u64,
    kind: u16,
    to: MessageTarget,
    delivery: Delivery,
    payload: Vec<u8>,
) -> Result<u32, MessageRefusal> {
    let now = w.now;
    w.get(p)
        .send_message(now, MessageKind(kind), to, delivery, payload)
}

fn room(n: u64) -> Wire {
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), cfg(), w.now));
    for p in 2..=n {
        w.add(Session::join(PeerId(p), PeerId(1), cfg(), w.now));
        w.settle();
    }
    w
}

fn messages(w: &mut Wire, p: u64) -> Vec<ReceivedMessage> {
    w.events(p)
        .into_iter()
        .filter_map(|e| match e {
            Event::Message(m) => Some(m),
            _ => None,
        })
        .collect()
}

#[test]
fn a_reliable_message_reaches_its_targets_once_and_the_sender_hears_it_delivered() {
    let mut w = room(3);
    let seq = send(
        &mut w,
        2,
        0,
        MessageTarget::Everyone,
        Delivery::Reliable,
        b"ding".to_vec(),
    )
    .unwrap();
    assert_eq!(seq, 1);
    w.settle();
    for p in [1, 3] {
        let got = messages(&mut w, p);
        assert_eq!(got.len(), 1, "peer {p}");
        assert_eq!(got[0].from, PeerId(2));
        assert_eq!(got[0].payload, b"ding");
    }
    assert!(w.events(2).contains(&Event::MessageDelivered { seq: 1 }));
    assert_eq!(w.get(2).messages_in_flight(), 0);
    // to one peer, to the host, to an object's owner
    send(
        &mut w,
        3,
        1,
        MessageTarget::Peer(PeerId(2)),
        Delivery::Reliable,
        vec![7],
    )
    .unwrap();
    send(
        &mut w,
        3,
        1,
        MessageTarget::Host,
        Delivery::Unreliable,
        vec![8],
    )
    .unwrap();
    w.settle();
    assert_eq!(
        messages(&mut w, 2)
            .iter()
            .map(|m| m.payload[0])
            .collect::<Vec<_>>(),
        [7]
    );
    assert_eq!(
        messages(&mut w, 1)
            .iter()
            .map(|m| m.payload[0])
            .collect::<Vec<_>>(),
        [8]
    );
}

#[test]
fn bad_messages_are_refused_and_counted_at_the_sender_and_at_the_host() {
    let mut w = room(2);
    let now = w.now;
    let s = w.get(2);
    let big = vec![0u8; MAX_MESSAGE_PAYLOAD + 1];
    let e = MessageTarget::Everyone;
    assert_eq!(
        s.send_message(now, MessageKind(0), e, Delivery::Reliable, big),
        Err(MessageRefusal::TooLarge)
    );
    assert_eq!(
        s.send_message(now, MessageKind(9), e, Delivery::Reliable, vec![]),
        Err(MessageRefusal::UnknownKind)
    );
    let one = MessageTarget::Peer(PeerId(1));
    assert_eq!(
        s.send_message(now, MessageKind(0), one, Delivery::Retained, vec![]),
        Err(MessageRefusal::BadDelivery)
    );
    assert_eq!(
        s.send_message(
            now,
            MessageKind(0),
            MessageTarget::Peer(PeerId(2)),
            Delivery::Reliable,
            vec![]
        ),
        Err(MessageRefusal::NoSuchTarget)
    );
    let refused = &s.stats().messages.refused;
    assert_eq!(refused.values().sum::<u64>(), 4);
    // a flood: the burst passes, the rest is refused, nothing queues without bound
    // (unreliable messages have a bucket of their own: 240 at once)
    let mut ok = 0;
    for _ in 0..1000 {
        if s.send_message(now, MessageKind(0), e, Delivery::Unreliable, vec![1])
            .is_ok()
        {
            ok += 1;
        }
    }
    assert_eq!(ok, 240);
    assert_eq!(
        s.stats().messages.refused[&MessageRefusal::RateLimited],
        760
    );
    // a modified client skips its own checks: the host refuses, counts, and says so
    let forged = AppMessage {
        origin: PeerId(2),
        seq: 50,
        kind: MessageKind(7),
        to: e,
        delivery: Delivery::Reliable,
        payload: vec![],
    };
    w.get(2)
        .send_raw_control(now, PeerId(1), &Control::Message(forged.clone()));
    let other_origin = AppMessage {
        origin: PeerId(3),
        seq: 51,
        kind: MessageKind(0),
        ..forged
    };
    w.get(2)
        .send_raw_control(now, PeerId(1), &Control::Message(other_origin));
    w.settle();
    let host = w.get(1).stats().messages.refused.clone();
    assert_eq!(host[&MessageRefusal::UnknownKind], 1);
    assert_eq!(host[&MessageRefusal::Malformed], 1);
    // of the flood, what fit the unreliable queue reached the host; nothing forged did
    let got = messages(&mut w, 1);
    assert_eq!(got.len(), 64);
    assert!(got
        .iter()
        .all(|m| m.payload == [1] && m.delivery == Delivery::Unreliable));
    assert_eq!(w.get(2).stats().messages.unreliable_dropped, 240 - 64);
    // and the reliable rate is still whole: its own burst of 120 passes
    let s = w.get(2);
    let reliable = (0..130)
        .filter(|_| {
            s.send_message(now, MessageKind(0), e, Delivery::Reliable, vec![2])
                .is_ok()
        })
        .count();
    assert_eq!(reliable, 120);
}

#[test]
fn the_hosts_filter_refuses_with_the_applications_code() {
    let mut w = room(2);
    w.get(1)
        .set_message_filter(|m| if m.payload == b"no" { Err(42) } else { Ok(()) });
    send(
        &mut w,
        2,
        0,
        MessageTarget::Everyone,
        Delivery::Reliable,
        b"no".to_vec(),
    )
    .unwrap();
    send(
        &mut w,
        2,
        0,
        MessageTarget::Everyone,
        Delivery::Reliable,
        b"yes".to_vec(),
    )
    .unwrap();
    w.settle();
    let ev = w.events(2);
    assert!(ev.contains(&Event::MessageRefused {
        seq: 1,
        reason: MessageRefusal::Filtered(42)
    }));
    assert!(ev.contains(&Event::MessageDelivered { seq: 2 }));
    assert_eq!(
        messages(&mut w, 1)
            .iter()
            .map(|m| m.payload.clone())
            .collect::<Vec<_>>(),
        [b"yes".to_vec()]
    );
}

#[test]
fn a_late_joiner_gets_the_retained_message_of_each_kind_after_the_objects() {
    let mut w = room(2);
    let now = w.now;
    for v in [1u8, 2, 3] {
        send(
            &mut w,
            2,
            1,
            MessageTarget::Everyone,
            Delivery::Retained,
            vec![v],
        )
        .unwrap();
    }
    send(
        &mut w,
        1,
        0,
        MessageTarget::Everyone,
        Delivery::Retained,
        vec![9],
    )
    .unwrap();
    w.settle();
    w.add(Session::join(PeerId(3), PeerId(1), cfg(), now));
    w.settle();
    let mut got: Vec<(u16, u8)> = messages(&mut w, 3)
        .iter()
        .map(|m| (m.kind.0, m.payload[0]))
        .collect();
    got.sort();
    assert_eq!(got, [(0, 9), (1, 3)]);
    assert_eq!(w.get(3).retained_messages().count(), 2);
}

#[test]
fn per_object_state_reaches_late_joiners_and_goes_with_its_object() {
    use crate::session::ObjectState;
    use glam::{Quat, Vec3};
    let mut w = room(2);
    let now = w.now;
    let st = ObjectState::rigid(Vec3::Y, Quat::IDENTITY);
    let (a, _) = w.get(1).spawn(now, crate::ClassId(0), st.clone()).unwrap();
    let (b, _) = w.get(1).spawn(now, crate::ClassId(0), st).unwrap();
    w.settle();
    let valve = MessageKind(1);
    for (id, opening) in [(a, 10u8), (a, 40), (b, 70)] {
        w.get(2)
            .send_message(
                now,
                valve,
                MessageTarget::Everyone,
                Delivery::ObjectState(id),
                vec![opening],
            )
            .unwrap();
    }
    assert_eq!(
        w.get(2).send_message(
            now,
            valve,
            MessageTarget::Everyone,
            Delivery::ObjectState(NetId(99)),
            vec![1]
        ),
        Err(MessageRefusal::NoSuchTarget)
    );
    w.settle();
    w.add(Session::join(PeerId(3), PeerId(1), cfg(), now));
    w.settle();
    let got: Vec<(Delivery, u8)> = messages(&mut w, 3)
        .iter()
        .map(|m| (m.delivery, m.payload[0]))
        .collect();
    assert_eq!(got.len(), 2);
    assert!(
        got.contains(&(Delivery::ObjectState(a), 40))
            && got.contains(&(Delivery::ObjectState(b), 70))
    );
    assert_eq!(
        w.get(1)
            .object_messages(a)
            .map(|m| m.payload[0])
            .collect::<Vec<_>>(),
        [40]
    );
    w.get(1).despawn(now, a).unwrap();
    w.settle();
    for p in 1..=3 {
        assert_eq!(w.get(p).object_messages(a).count(), 0, "peer {p}");
        assert_eq!(w.get(p).object_messages(b).count(), 1, "peer {p}");
    }
}

#[test]
fn every_members_retained_state_follows_the_hosts_relay_order() {
    let mut w = room(3);
    for (p, v) in [(2u64, 20u8), (3, 30), (1, 10), (3, 31)] {
        send(
            &mut w,
            p,
            1,
            MessageTarget::Everyone,
            Delivery::Retained,
            vec![v],
        )
        .unwrap();
    }
    w.settle();
    let table = |w: &mut Wire, p: u64| -> Vec<(PeerId, Vec<u8>)> {
        w.get(p)
            .retained_messages()
            .map(|m| (m.from, m.payload))
            .collect()
    };
    let host = table(&mut w, 1);
    assert_eq!(host.len(), 1);
    for p in [2, 3] {
        assert_eq!(table(&mut w, p), host, "peer {p}'s state is the host's");
    }
    // every peer was told of the others' messages, in the host's order, and not of its own
    let told =
        |w: &mut Wire, p: u64| -> Vec<u8> { messages(w, p).iter().map(|m| m.payload[0]).collect() };
    assert_eq!(told(&mut w, 1), [20, 30, 31]);
    // (the host's own went out first: it relays at once what it sends)
    assert_eq!(told(&mut w, 2), [10, 30, 31]);
    assert_eq!(told(&mut w, 3), [10, 20]);
}

#[test]
fn a_peer_back_with_a_fresh_session_is_heard_from_its_first_message() {
    let mut w = room(3);
    for v in 0..5u8 {
        send(
            &mut w,
            3,
            1,
            MessageTarget::Everyone,
            Delivery::Retained,
            vec![v],
        )
        .unwrap();
    }
    w.settle();
    // peer 3 goes silent until the room drops it, then comes back with the same id and a
    // fresh session numbering from 1 (as `Peer` rejoins); a late joiner then hears the
    // old state and every new message
    w.peers.remove(&PeerId(3));
    for _ in 0..30 {
        w.now += std::time::Duration::from_millis(100);
        w.settle();
    }
    let now = w.now;
    assert!(!w.get(1).members().contains_key(&PeerId(3)));
    w.add(Session::join(PeerId(3), PeerId(1), cfg(), now));
    w.settle();
    send(
        &mut w,
        3,
        0,
        MessageTarget::Everyone,
        Delivery::Reliable,
        vec![77],
    )
    .unwrap();
    w.add(Session::join(PeerId(4), PeerId(1), cfg(), now));
    w.settle();
    send(
        &mut w,
        3,
        0,
        MessageTarget::Everyone,
        Delivery::Reliable,
        vec![78],
    )
    .unwrap();
    w.settle();
    let at_4: Vec<u8> = messages(&mut w, 4).iter().map(|m| m.payload[0]).collect();
    assert_eq!(at_4, [4, 78], "the room's state, then the live message");
    let at_2: Vec<u8> = messages(&mut w, 2).iter().map(|m| m.payload[0]).collect();
    assert_eq!(at_2, [0, 1, 2, 3, 4, 77, 78]);
}

#[test]
fn a_whole_outbox_queued_while_joining_passes_the_hosts_rate_check() {
    let mut w = room(1);
    let now = w.now;
    let mut s = Session::join(PeerId(2), PeerId(1), cfg(), now);
    for v in 0..120u32 {
        s.send_message(
            now,
            MessageKind(0),
            MessageTarget::Host,
            Delivery::Reliable,
            v.to_le_bytes().to_vec(),
        )
        .unwrap();
    }
    w.add(s);
    w.settle();
    assert_eq!(messages(&mut w, 1).len(), 120);
    assert!(w.get(1).stats().messages.refused.is_empty());
    assert_eq!(w.get(2).messages_in_flight(), 0);
}

#[test]
fn a_message_sent_while_joining_goes_out_once_welcomed() {
    let mut w = room(1);
    let now = w.now;
    let mut s = Session::join(PeerId(2), PeerId(1), cfg(), now);
    assert_eq!(
        s.send_message(
            now,
            MessageKind(0),
            MessageTarget::Everyone,
            Delivery::Unreliable,
            vec![]
        ),
        Err(MessageRefusal::NotConnected)
    );
    s.send_message(
        now,
        MessageKind(0),
        MessageTarget::Host,
        Delivery::Reliable,
        vec![5],
    )
    .unwrap();
    w.add(s);
    w.settle();
    assert_eq!(messages(&mut w, 1).len(), 1);
}
