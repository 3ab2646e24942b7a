//! What a session refuses or repairs: a peer of another protocol version or class table,
//! insane interpolation settings, rotations that are not unit quaternions.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use glam::{Quat, Vec3};
use softsync_net::harness::Harness;
use softsync_net::{
    ConditionerConfig, Event, InterpolationConfig, NetError, ObjectState, PeerId, Session,
    PROTOCOL_VERSION,
};

#[test]
fn protocol_version_mismatch_is_refused_with_reason() {
    let mut h = Harness::new(1, config(), ConditionerConfig::default());
    let mut joiner = Session::join(PeerId(7), Harness::id(0), config(), h.now);
    let now = h.now;
    let mut hello = joiner.poll_transmit(now).unwrap();
    hello.payload[0] = PROTOCOL_VERSION + 1;
    h.session(0).handle_packet(now, PeerId(7), &hello.payload);
    let reply = h.session(0).poll_transmit(now).unwrap();
    assert_eq!(reply.to, PeerId(7));
    joiner.handle_packet(now, Harness::id(0), &reply.payload);
    match joiner.poll_event() {
        Some(Event::Refused { reason }) => assert!(reason.contains("version"), "{reason}"),
        other => panic!("expected refusal, got {other:?}"),
    }
    assert!(!joiner.is_connected());
    assert!(h.peers[0].session.members().len() == 1);
}

#[test]
fn class_table_mismatch_is_refused() {
    let mut h = room(1, ConditionerConfig::default());
    let mut other = config();
    other.classes[0].send.rate_hz = 7.0;
    let n = h.add_peer_with(other, 0);
    h.advance(ms(500));
    assert!(!h.peers[n].session.is_connected());
    assert!(h.peers[n]
        .events
        .iter()
        .any(|e| matches!(e, Event::Refused { reason } if reason.contains("configuration"))));
}

/// The "configuration differs" refusal lists the host's message types: a room with many
/// (an app's own) made it longer than a `Refused` may be, the encoder gave empty bytes and the
/// joiner timed out without a reason. Now it is shortened and says so.
#[test]
fn a_refusal_too_long_for_its_message_still_arrives_shortened() {
    let mut cfg = config();
    cfg.messages.kinds = (0..60)
        .map(|i| format!("training.procedure.event_type_{i:02}"))
        .collect();
    let mut h = room_with(1, cfg, ConditionerConfig::default(), ms(300));
    let n = h.add_peer_with(config(), 0);
    h.advance(ms(500));
    assert!(!h.peers[n].session.is_connected());
    let reason = h.peers[n]
        .events
        .iter()
        .find_map(|e| match e {
            Event::Refused { reason } => Some(reason.clone()),
            _ => None,
        })
        .expect("the joiner was told nothing");
    assert!(reason.contains("configuration differs"), "{reason}");
    assert!(
        reason.contains("training.procedure.event_type_00"),
        "{reason}"
    );
    assert!(
        reason.ends_with(" bytes)") && reason.len() <= 512,
        "{reason}"
    );
    assert_eq!(h.peers[0].session.stats().unencodable_controls, 0);
}

/// Negative or non-finite interpolation settings are made sane: display never panics and the
/// delay is never negative.
#[test]
fn bad_interpolation_settings_are_sanitized() {
    let mut h = room(2, ConditionerConfig::rough(3, 20, 5, 0.0));
    let (id, _) = spawn_rigid(&mut h, 0, Vec3::ZERO);
    let start = t(&h);
    h.run_frames(ms(1000), ms(11), |h| {
        publish_rigid(h, 0, id, Vec3::X * (t(h) - start));
    });
    for (intervals, jitter_factor) in [(-5.0, -3.0), (f32::NAN, f32::INFINITY), (-0.0, -1e30)] {
        h.session(1).set_interpolation(InterpolationConfig {
            intervals,
            jitter_factor,
            snap_distance_m: -1.0,
            ..Default::default()
        });
        let cfg = h.peers[1].session.interpolation();
        assert!(cfg.intervals >= 0.0 && cfg.jitter_factor >= 0.0 && cfg.snap_distance_m >= 0.0);
        let now = h.now;
        let shown = h.session(1).display_state(now, id).unwrap();
        assert!(shown.state.pos.is_finite());
        assert!(shown.delay <= ms(300), "{:?}", shown.delay);
    }
}

/// A rotation that is not a unit quaternion is refused (far off, or zero), or normalized
/// (rounding): particle offsets stay right on remote peers either way.
#[test]
fn publish_state_refuses_or_normalizes_non_unit_rotations() {
    let mut h = room(2, ConditionerConfig::default());
    let (id, _) = spawn_soft(&mut h, 0, Vec3::Y);
    h.advance(ms(300));
    let q = Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.3);
    let now = h.now;
    for bad in [q * 2.0, q * 0.5, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)] {
        let st = soft_state(Vec3::Y, q, 0.2);
        let err = h
            .session(0)
            .publish_state(now, id, &ObjectState { rot: bad, ..st });
        assert!(
            matches!(err, Err(NetError::InvalidState(_))),
            "{bad:?}: {err:?}"
        );
    }
    assert!(h
        .session(0)
        .spawn(now, RIGID, ObjectState::rigid(Vec3::ZERO, q * 3.0))
        .is_err());
    // 0.9 % off (|q|² = 1.018): accepted and normalized
    let truth = soft_state(Vec3::Y + Vec3::X * 0.3, q, 0.2);
    let sloppy = ObjectState {
        rot: q * 1.009,
        ..truth.clone()
    };
    h.session(0).publish_state(now, id, &sloppy).unwrap();
    h.advance(ms(1000));
    let got = h.session(1).latest_state(id).unwrap();
    let e = max_particle_error(&truth, &got);
    assert!(e < 0.0015, "particle error {e} m");
    let own = h.session(0).latest_state(id).unwrap();
    assert!((own.rot.length() - 1.0).abs() < 1e-5);
}
