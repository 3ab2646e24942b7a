//! A room reopened from what was kept: the host restores objects under their old ids with
//! their logs, the retained messages and the room time before anyone joins; a joiner then
//! gets all of it through the ordinary snapshot, and new objects get fresh ids. A replayed
//! recording's objects appear mid-session, locked, and their logs grow.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::*;
use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::wire::{AppMessage, Delivery, MessageKind, MessageTarget, TopologyEvent};
use softsync_net::{Event, KeptObject, NetError, NetId, ObjectState, PeerId};

fn kept_room() -> (Vec<KeptObject>, AppMessage) {
    let tear = |x: i32| TopologyEvent::Tear {
        from: [x, 0, 0],
        to: [x + 500, 0, 0],
        blade: [0, 4000, 0],
    };
    let objects = vec![
        KeptObject {
            id: NetId(3),
            class: RIGID,
            state: ObjectState::rigid(Vec3::new(0.5, 1.0, 0.0), Quat::from_rotation_y(0.3)),
            topology: vec![],
        },
        KeptObject {
            id: NetId(12),
            class: SOFT,
            state: soft_state(Vec3::new(-0.3, 1.1, 0.2), Quat::IDENTITY, 0.1),
            topology: vec![tear(0), tear(500), TopologyEvent::Lift],
        },
    ];
    let msg = AppMessage {
        origin: PeerId(7),
        seq: 4,
        kind: MessageKind(0),
        to: MessageTarget::Everyone,
        delivery: Delivery::Retained,
        payload: b"step 3".to_vec(),
    };
    (objects, msg)
}

#[test]
fn a_reopened_room_gives_a_joiner_the_same_ids_logs_states_messages_and_a_later_clock() {
    let mut cfg = config();
    cfg.messages.kinds = vec!["procedure".into()];
    let mut h = Harness::new(1, cfg, steady_link());
    let (objects, msg) = kept_room();
    let now = h.now;
    let host = h.session(0);
    for o in &objects {
        host.restore_object(now, o.clone()).unwrap();
    }
    host.restore_retained(msg.clone()).unwrap();
    host.resume_room_time(now, Duration::from_secs(600))
        .unwrap();
    // an id in use, a message of a kind the room does not have: refused
    assert!(matches!(
        host.restore_object(now, objects[0].clone()),
        Err(NetError::Restore(_))
    ));
    let bad = AppMessage {
        kind: MessageKind(5),
        ..msg.clone()
    };
    assert!(host.restore_retained(bad).is_err());
    assert!(host.room_time(now).unwrap() >= Duration::from_secs(600));

    let j = h.add_peer();
    h.advance(ms(1500));
    let joiner = &h.peers[j].session;
    assert!(joiner.is_connected());
    for o in &objects {
        assert_eq!(joiner.class_of(o.id), Some(o.class), "object {:?}", o.id);
        assert_eq!(joiner.topology_log(o.id).unwrap(), o.topology.as_slice());
        let s = joiner.latest_state(o.id).unwrap();
        assert!(s.pos.distance(o.state.pos) < 1e-3);
        assert!(max_particle_error(&s, &o.state) < 2e-3);
    }
    let got: Vec<_> = h.peers[j]
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Message(m) => Some(m.payload.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(
        got,
        vec![b"step 3".to_vec()],
        "the retained message reached the joiner"
    );
    assert!(h.peers[j].session.room_time(h.now).unwrap() > Duration::from_secs(601));

    // restoring is for a room nobody joined yet; a new object's id is past the kept ones
    let now = h.now;
    let host = h.session(0);
    let late = KeptObject {
        id: NetId(40),
        ..objects[0].clone()
    };
    assert!(matches!(
        host.restore_object(now, late),
        Err(NetError::Restore(_))
    ));
    let (id, _) = spawn_rigid(&mut h, 0, Vec3::ZERO);
    assert!(id.0 > 12, "fresh id {id:?} collides with the kept ones");
}

/// A recorded session played back as a room: with a member in, the host makes recorded
/// objects appear under fresh ids with their logs, locked (the member is refused their
/// authority), appends a tear to one's log and moves it; the member has every step.
#[test]
fn a_replayed_object_appears_under_a_fresh_id_locked_and_its_log_grows_for_the_members() {
    let mut h = room(2, steady_link());
    let (objects, _) = kept_room();
    let now = h.now;
    let ids: Vec<NetId> = objects
        .iter()
        .map(|o| h.session(0).replay_object(now, o.clone()).unwrap())
        .collect();
    assert!(ids.iter().all(|id| !objects.iter().any(|o| o.id == *id)));
    h.advance(ms(500));
    for (o, id) in objects.iter().zip(&ids) {
        let member = &h.peers[1].session;
        assert_eq!(member.class_of(*id), Some(o.class));
        assert_eq!(member.topology_log(*id).unwrap(), o.topology.as_slice());
        assert!(max_particle_error(&member.latest_state(*id).unwrap(), &o.state) < 2e-3);
    }
    // locked: the member is refused
    request_authority(&mut h, 1, ids[0]);
    h.advance(ms(500));
    assert!(h.peers[1]
        .events
        .iter()
        .any(|e| matches!(e, Event::AuthorityDenied { id, .. } if *id == ids[0])));
    assert_eq!(h.session(1).owner(ids[0]), Some(Harness::id(0)));
    // a tear appended; a cut is not an entry
    let tear = TopologyEvent::Tear {
        from: [0, 0, 0],
        to: [300, 0, 0],
        blade: [0, 4000, 0],
    };
    let now = h.now;
    h.session(0).replay_entry(now, ids[1], tear).unwrap();
    let cut = TopologyEvent::Cut {
        point: [0, 0, 0],
        normal: [32767, 0, 0],
        keep: 0,
    };
    assert!(h.session(0).replay_entry(now, ids[1], cut).is_err());
    let moved = soft_state(Vec3::new(-0.2, 1.1, 0.2), Quat::IDENTITY, 0.2);
    h.session(0).publish_state(now, ids[1], &moved).unwrap();
    h.advance(ms(500));
    let log = h.peers[1].session.topology_log(ids[1]).unwrap().to_vec();
    assert_eq!(log.len(), objects[1].topology.len() + 1);
    assert_eq!(log.last(), Some(&tear));
    let s = h.peers[1].session.latest_state(ids[1]).unwrap();
    assert!(max_particle_error(&s, &moved) < 2e-3);
    // a member cannot replay
    let now = h.now;
    assert!(h.session(1).replay_object(now, objects[0].clone()).is_err());
}
