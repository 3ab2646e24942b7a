//! Tests of topology events: tears, cuts, resolution changes and their layout.
#![allow(clippy::unwrap_used)]
use super::*;
use crate::ids::ClassId;
use crate::session::registry::ObjectState;
use crate::session::testkit::{config, Wire};
use glam::{Quat, Vec3};

fn tear(x: i32) -> TopologyEvent {
    TopologyEvent::Tear {
        from: [x, 0, 0],
        to: [x + 100, 0, 0],
        blade: [0, 1000, 0],
    }
}

/// Host 1 with members 2 and 3; peer 2 owns a soft object (returned).
fn room() -> (Wire, NetId) {
    room_with(config())
}

fn room_with(cfg: crate::policy::SessionConfig) -> (Wire, NetId) {
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), cfg.clone(), w.now));
    w.add(Session::join(PeerId(2), PeerId(1), cfg.clone(), w.now));
    w.settle();
    w.add(Session::join(PeerId(3), PeerId(1), cfg, w.now));
    w.settle();
    let st = ObjectState {
        pos: Vec3::new(0.0, 1.0, 0.0),
        rot: Quat::IDENTITY,
        particles: vec![Vec3::ZERO; 4],
    };
    let now = w.now;
    w.get(2).spawn(now, ClassId(1), st).unwrap();
    w.settle();
    let id = w.get(1).object_ids()[0];
    for p in 1..=3 {
        w.events(p);
    }
    (w, id)
}

fn topo_events(w: &mut Wire, p: u64) -> Vec<(NetId, u32, TopologyEvent)> {
    w.events(p)
        .into_iter()
        .filter_map(|e| match e {
            Event::Topology { id, seq, event } => Some((id, seq, event)),
            _ => None,
        })
        .collect()
}

#[test]
fn the_owners_tears_reach_everyone_in_order_and_late_joiners_get_the_log() {
    let (mut w, id) = room();
    let now = w.now;
    for k in 0..3 {
        w.get(2)
            .request_topology(now, id, tear(k * 100), vec![])
            .unwrap();
    }
    w.settle();
    for p in 1..=3 {
        let got = topo_events(&mut w, p);
        assert_eq!(got.len(), 3, "peer {p}");
        assert!(got.iter().enumerate().all(|(i, g)| g.1 == i as u32));
        assert_eq!(w.get(p).topology_log(id).unwrap().len(), 3);
    }
    // A late joiner gets the same log after the spawn.
    w.add(Session::join(PeerId(4), PeerId(1), config(), w.now));
    w.settle();
    let host_log = w.get(1).topology_log(id).unwrap().to_vec();
    assert_eq!(w.get(4).topology_log(id).unwrap(), host_log.as_slice());
    assert_eq!(topo_events(&mut w, 4).len(), 3);
}

#[test]
fn foreign_stale_and_malformed_events_are_refused_and_counted_changing_nothing() {
    let (mut w, id) = room();
    let now = w.now;
    // Peer 3 does not own it: refused locally ...
    assert!(matches!(
        w.get(3).request_topology(now, id, tear(0), vec![]),
        Err(NetError::NotOwner(..))
    ));
    // ... and at the host when forged.
    let epoch = w.get(3).epoch(id).unwrap();
    let forged = Control::TopologyRequest {
        id,
        epoch,
        event: tear(0),
        pieces: vec![],
    };
    w.get(3).send_control(now, PeerId(1), &forged);
    // The owner with a stale epoch.
    let stale = Control::TopologyRequest {
        id,
        epoch: AuthorityEpoch {
            term: epoch.term,
            grant: epoch.grant + 7,
        },
        event: tear(0),
        pieces: vec![],
    };
    w.get(2).send_control(now, PeerId(1), &stale);
    // A tear with pieces, a cut without, an unknown object.
    for (event, pieces, obj) in [
        (tear(0), vec![3], id),
        (
            TopologyEvent::Cut {
                point: [0; 3],
                normal: [0, 32767, 0],
                keep: 0,
            },
            vec![],
            id,
        ),
        (tear(0), vec![], NetId(999)),
    ] {
        let msg = Control::TopologyRequest {
            id: obj,
            epoch,
            event,
            pieces,
        };
        w.get(2).send_control(now, PeerId(1), &msg);
    }
    w.settle();
    let r = w.get(1).topology_refusals();
    assert_eq!(r.not_owner, 1, "{r:?}");
    assert_eq!(r.stale_epoch, 1, "{r:?}");
    assert_eq!(r.malformed, 2, "{r:?}");
    assert_eq!(r.unknown_object, 1, "{r:?}");
    for p in 1..=3 {
        assert!(w.get(p).topology_log(id).unwrap().is_empty());
        assert!(topo_events(&mut w, p).is_empty());
    }
}

#[test]
fn a_burst_over_the_rate_is_cut_off_and_counted() {
    let (mut w, id) = room();
    let now = w.now;
    for k in 0..(MAX_TOPOLOGY_RATE + 60) {
        w.get(2)
            .request_topology(now, id, tear(k as i32), vec![])
            .unwrap();
        if k % 50 == 0 {
            w.settle();
        }
    }
    w.settle();
    assert_eq!(w.get(1).topology_refusals().rate, 60);
    assert_eq!(
        w.get(3).topology_log(id).unwrap().len(),
        MAX_TOPOLOGY_RATE as usize
    );
}

#[test]
fn a_cut_replaces_the_object_by_pieces_owned_by_the_cutter() {
    let (mut w, id) = room();
    let now = w.now;
    w.get(2).request_topology(now, id, tear(0), vec![]).unwrap();
    w.settle();
    let cut = TopologyEvent::Cut {
        point: [0, 100, 0],
        normal: [0, 32767, 0],
        keep: 0,
    };
    w.get(2).request_topology(now, id, cut, vec![3, 2]).unwrap();
    w.settle();
    for p in 1..=3 {
        let ids = w.get(p).object_ids();
        assert_eq!(ids.len(), 2, "peer {p}: {ids:?}");
        assert!(!ids.contains(&id));
        for (k, piece) in ids.iter().enumerate() {
            assert_eq!(w.get(p).owner(*piece), Some(PeerId(2)));
            let log = w.get(p).topology_log(*piece).unwrap().to_vec();
            assert_eq!(log.len(), 2);
            assert_eq!(log[0], tear(0));
            assert!(matches!(log[1], TopologyEvent::Cut { keep, .. } if keep as usize == k));
        }
    }
}

fn state(n: usize, spread: f32) -> ObjectState {
    ObjectState {
        pos: Vec3::new(0.0, 1.0, 0.0),
        rot: Quat::IDENTITY,
        particles: (0..n)
            .map(|i| Vec3::new(0.0, 1.0, 0.0) + Vec3::X * spread * i as f32)
            .collect(),
    }
}

#[test]
fn a_resolution_change_relays_the_object_out_everywhere_and_late_joiners_get_it() {
    let (mut w, id) = room();
    let now = w.now;
    w.get(2).publish_state(now, id, &state(4, 0.01)).unwrap();
    w.settle();
    assert_eq!(w.get(3).latest_state(id).unwrap().particles.len(), 4);
    let change = TopologyEvent::Resolution {
        level: 2,
        particles: 9,
    };
    w.get(2).request_topology(now, id, change, vec![]).unwrap();
    // until the host confirms, the owner's layout is the old one
    assert!(w.get(2).publish_state(now, id, &state(9, 0.01)).is_err());
    w.get(2).publish_state(now, id, &state(4, 0.02)).unwrap();
    w.settle();
    for p in 1..=3 {
        assert_eq!(topo_events(&mut w, p), vec![(id, 0, change)], "peer {p}");
    }
    let now = w.now;
    assert!(matches!(
        w.get(2).publish_state(now, id, &state(4, 0.01)),
        Err(NetError::InvalidState(_))
    ));
    for _ in 0..5 {
        w.now += Duration::from_millis(100);
        let now = w.now;
        w.get(2).publish_state(now, id, &state(9, 0.015)).unwrap();
        w.settle();
    }
    for p in [1, 3] {
        let got = w.get(p).latest_state(id).unwrap();
        assert_eq!(got.particles.len(), 9, "peer {p}");
        assert!(
            got.particles[8].distance(state(9, 0.015).particles[8]) < 1e-3,
            "peer {p}: {got:?}"
        );
        assert_eq!(w.get(p).stats().decode_errors, 0);
    }
    // a late joiner: the spawn has 9 particles, the log's change is history
    w.add(Session::join(PeerId(4), PeerId(1), config(), w.now));
    w.settle();
    for _ in 0..3 {
        w.now += Duration::from_millis(100);
        let now = w.now;
        w.get(2).publish_state(now, id, &state(9, 0.012)).unwrap();
        w.settle();
    }
    assert_eq!(w.get(4).topology_log(id).unwrap(), &[change]);
    let got = w.get(4).latest_state(id).unwrap();
    assert_eq!(got.particles.len(), 9);
    assert!(got.particles[8].distance(state(9, 0.012).particles[8]) < 1e-3);
}

#[test]
fn a_resolution_over_the_owners_particle_budget_or_out_of_range_is_refused() {
    let cfg = crate::policy::SessionConfig {
        max_particles_per_peer: 100,
        ..config()
    };
    let (mut w, id) = room_with(cfg);
    let now = w.now;
    // the new layout replaces the old one in the budget: 100 fits, 101 does not
    let fits = TopologyEvent::Resolution {
        level: 1,
        particles: 100,
    };
    let too_many = TopologyEvent::Resolution {
        level: 2,
        particles: 101,
    };
    w.get(2)
        .request_topology(now, id, too_many, vec![])
        .unwrap();
    w.settle();
    assert_eq!(w.get(1).topology_refusals().no_room, 1);
    assert!(w.get(3).topology_log(id).unwrap().is_empty());
    w.get(2).request_topology(now, id, fits, vec![]).unwrap();
    w.settle();
    assert_eq!(w.get(3).topology_log(id).unwrap(), &[fits]);
    for bad in [
        TopologyEvent::Resolution {
            level: crate::wire::MAX_RESOLUTION_LEVELS,
            particles: 5,
        },
        TopologyEvent::Resolution {
            level: 0,
            particles: 0,
        },
    ] {
        let msg = Control::Topology {
            id,
            seq: 0,
            event: bad,
        };
        assert!(Control::decode(&msg.encode().unwrap()).is_err(), "{bad:?}");
    }
}

#[test]
fn a_particle_chunk_of_another_layout_ends_its_block_without_an_error() {
    use crate::policy::{ClassConfig, SendPolicy, SoftBodyMode};
    use crate::wire::{
        decode_state_block, ChunkEnc, EntryLayout, PartBody, StateBlockWriter, StateEntry,
    };
    let class = ClassConfig::soft_body("s", SendPolicy::default(), SoftBodyMode::Particles);
    let layout = |generation| EntryLayout {
        class: &class,
        particles: 8,
        generation,
    };
    let chunk = |id| StateEntry {
        id: NetId(id),
        epoch_tag: 0,
        seq: 1,
        key: true,
        base: 0,
        rest: false,
        body: PartBody::Chunk {
            chunk: 0,
            values: ChunkEnc::Abs(vec![[1, 2, 3]; 8]),
        },
    };
    let mut wr = StateBlockWriter::new(10_000);
    wr.push(&chunk(1), &layout(0));
    wr.push(&chunk(2), &layout(1));
    wr.push(&chunk(3), &layout(0));
    let (count, bytes) = wr.finish();
    // the receiver is at generation 0 for objects 1 and 3, 2 for object 2 (it saw two
    // changes; the sender one): object 2's chunk ends the block, 1's is kept
    let (got, complete) = decode_state_block(count as u32, &bytes, |id| {
        Some(if id == NetId(2) { layout(2) } else { layout(0) })
    })
    .unwrap();
    assert_eq!(got.len(), 1);
    assert!(!complete);
    // and a transform part needs no layout: it never carries the generation
    let (all, complete) = decode_state_block(count as u32, &bytes, |id| {
        Some(if id == NetId(2) { layout(1) } else { layout(0) })
    })
    .unwrap();
    assert_eq!(all.len(), 3);
    assert!(complete);
}

#[test]
fn out_of_range_events_do_not_decode() {
    let far = TopologyEvent::Tear {
        from: [crate::wire::MAX_TOPOLOGY_COORD + 1, 0, 0],
        to: [0; 3],
        blade: [0, 10, 0],
    };
    let zero_normal = TopologyEvent::Cut {
        point: [0; 3],
        normal: [0; 3],
        keep: 0,
    };
    let many_pieces = Control::TopologyRequest {
        id: NetId(1),
        epoch: AuthorityEpoch::default(),
        event: TopologyEvent::Cut {
            point: [0; 3],
            normal: [0, 1, 0],
            keep: 0,
        },
        pieces: vec![1; MAX_CUT_PIECES + 1],
    };
    for bad in [
        Control::Topology {
            id: NetId(1),
            seq: 0,
            event: far,
        },
        Control::Topology {
            id: NetId(1),
            seq: 0,
            event: zero_normal,
        },
        many_pieces,
    ] {
        assert!(Control::decode(&bad.encode().unwrap()).is_err(), "{bad:?}");
    }
    assert_eq!(TopologyEvent::quantise([f32::NAN, 0.0, 0.0]), None);
    assert_eq!(TopologyEvent::quantise([20.0, 0.0, 0.0]), None);
    assert_eq!(
        TopologyEvent::quantise([0.1, -0.2, 0.000_004]),
        Some([10_000, -20_000, 0])
    );
    assert_eq!(TopologyEvent::quantise_normal([0.0; 3]), None);
    assert_eq!(
        TopologyEvent::quantise_normal([0.0, 2.0, 0.0]),
        Some([0, 32767, 0])
    );
}

#[test]
fn a_log_entry_that_differs_rewrites_from_there_and_a_gap_is_refused() {
    let mut log = TopologyLog::default();
    assert_eq!(log.receive(0, tear(0)), Received::Appended);
    assert_eq!(log.receive(1, tear(1)), Received::Appended);
    assert_eq!(log.receive(1, tear(1)), Received::Duplicate);
    assert_eq!(log.receive(1, tear(5)), Received::Rewrote); // the new host's truth
    assert_eq!(log.entries, vec![tear(0), tear(5)]);
    assert_eq!(log.receive(5, tear(9)), Received::Gap);
    assert_eq!(log.entries.len(), 2);
}
