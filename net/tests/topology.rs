//! Topology events across a room with loss: tears reach everyone in order, survive the host's
//! death, reach a late joiner after the migration, and a cut's pieces exist everywhere with
//! one owner.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use softsync_net::harness::Harness;
use softsync_net::wire::TopologyEvent;
use softsync_net::{ConditionerConfig, NetId};

fn tear(k: i32) -> TopologyEvent {
    TopologyEvent::Tear {
        from: [k * 500, 9000, 0],
        to: [k * 500 + 500, 9000, 0],
        blade: [0, 3000, 0],
    }
}

fn logs(h: &Harness, live: &[usize], id: NetId) -> Vec<Vec<TopologyEvent>> {
    live.iter()
        .map(|&i| h.peers[i].session.topology_log(id).unwrap_or(&[]).to_vec())
        .collect()
}

#[test]
fn tears_survive_the_hosts_death_and_reach_a_late_joiner() {
    let (mut h, ids) = room_with_objects(4, ConditionerConfig::rough(5, 20, 5, 0.05));
    let soft = ids[3]; // the host's soft body
    for k in 0..3 {
        let now = h.now;
        h.session(0)
            .request_topology(now, soft, tear(k), vec![])
            .unwrap();
        h.advance(ms(30));
    }
    h.advance(ms(800));
    for log in logs(&h, &[0, 1, 2, 3], soft) {
        assert_eq!(log, vec![tear(0), tear(1), tear(2)]);
    }
    h.kill(0);
    h.advance(ms(3000));
    let heir = h.earliest_live_joiner(0).unwrap();
    assert!(h.peers[heir].session.is_host());
    // The heir owns the dead host's object now and goes on tearing it.
    assert_eq!(h.peers[heir].session.owner(soft), Some(Harness::id(heir)));
    for k in 3..5 {
        let now = h.now;
        h.session(heir)
            .request_topology(now, soft, tear(k), vec![])
            .unwrap();
        h.advance(ms(30));
    }
    let late = h.add_peer_with(config(), heir);
    h.advance(ms(2000));
    let want: Vec<TopologyEvent> = (0..5).map(tear).collect();
    for (i, log) in [1, 2, 3, late].iter().zip(logs(&h, &[1, 2, 3, late], soft)) {
        assert_eq!(log, want, "peer {i}");
    }
    assert_eq!(h.peers[heir].session.topology_refusals().total(), 0);
}

#[test]
fn a_cut_after_a_migration_leaves_the_same_pieces_everywhere() {
    let (mut h, ids) = room_with_objects(3, ConditionerConfig::rough(8, 15, 5, 0.05));
    let soft = ids[3];
    let now = h.now;
    h.session(0)
        .request_topology(now, soft, tear(0), vec![])
        .unwrap();
    h.advance(ms(500));
    h.kill(0);
    h.advance(ms(3000));
    let heir = h.earliest_live_joiner(0).unwrap();
    let cut = TopologyEvent::Cut {
        point: [0, 10_000, 0],
        normal: [0, 32767, 0],
        keep: 0,
    };
    let now = h.now;
    h.session(heir)
        .request_topology(now, soft, cut, vec![30, 30])
        .unwrap();
    h.advance(ms(1500));
    let live = [1, 2];
    let objects: Vec<Vec<NetId>> = live
        .iter()
        .map(|&i| h.peers[i].session.object_ids())
        .collect();
    assert_eq!(objects[0], objects[1]);
    assert!(!objects[0].contains(&soft));
    let pieces: Vec<NetId> = objects[0]
        .iter()
        .copied()
        .filter(|id| !ids.contains(id))
        .collect();
    assert_eq!(pieces.len(), 2);
    for (k, piece) in pieces.iter().enumerate() {
        let logs = logs(&h, &live, *piece);
        assert_eq!(logs[0], logs[1]);
        assert_eq!(logs[0][0], tear(0));
        assert_eq!(
            logs[0][1],
            TopologyEvent::Cut {
                point: [0, 10_000, 0],
                normal: [0, 32767, 0],
                keep: k as u8
            }
        );
    }
    assert_single_owner_everywhere(&h, &objects[0]);
}
