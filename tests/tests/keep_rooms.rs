//! A kept room survives every process dying at once, live (real processes on WebRTC in the
//! test's network namespace). The host keeps the room in a SQLite file (`--store`); a bot
//! tears the bunny, leaves a retained note and is squeezing the soft ball when the host and
//! the bot are SIGKILLed together. The store then holds the whole tear (four segments and the
//! lift) and the note; the host reopens the room from it, a late joiner comes, and both show
//! the same torn bunny (topology hashes), the bunny where and as it was kept (within 1 mm),
//! the same objects under the same ids, and the note. And a room whose host dies goes on being
//! kept: the member that takes over opens the same store and writes what happens after.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::time::Duration;

use serde_json::Value;
use softsync_store::{RoomStore, SqliteStore};

mod common;
use common::dump::{nearest, objects, read_dump};
use common::{peer_on, require_netns, scratch, standalone_signal};

fn v3(v: &Value) -> [f64; 3] {
    [0, 1, 2].map(|i| v[i].as_f64().unwrap())
}

#[test]
fn a_room_whose_every_process_was_killed_mid_squeeze_reopens_from_its_store_as_it_was() {
    require_netns();
    let dir = scratch("keep");
    let db = dir.join("room.db");
    let db_arg = db.to_str().unwrap().to_owned();
    let (_signal, url) = standalone_signal(&dir);
    let mut host = peer_on(
        &dir,
        "host",
        "host",
        &url,
        "keep",
        &["--bot", "idle", "--store", &db_arg],
    );
    host.wait_line("keeping the room in", Duration::from_secs(20));
    host.peer_id();
    let script = "wait 1; own bunny; \
                  tear right bunny -0.05 0.03 0 -0.025 0.03 0.005 0 0.03 0 0.025 0.03 -0.005 0.05 0.03 0 in 0.1; \
                  note the flap is open; \
                  reach left softball; grab left; squeeze left 0.03 in 6; wait 20";
    let mut bot = peer_on(&dir, "bot", "join", &url, "keep", &["--bot", script]);
    bot.wait_line("joined", Duration::from_secs(20));
    bot.wait_line("tore object", Duration::from_secs(20));
    bot.wait_line("grab-started", Duration::from_secs(20));
    // a checkpoint (1 s) and more after the tear, mid-squeeze: then everyone dies at once
    std::thread::sleep(Duration::from_millis(1500));
    host.kill();
    bot.kill();

    let kept = SqliteStore::open(&db).unwrap().load().unwrap();
    let bunny = kept
        .objects
        .iter()
        .find(|o| o.topology.len() == 5)
        .unwrap_or_else(|| {
            panic!(
                "no torn bunny kept: {:?}",
                kept.objects
                    .iter()
                    .map(|o| (o.id, o.topology.len()))
                    .collect::<Vec<_>>()
            )
        });
    assert_eq!(kept.retained.len(), 1, "the note was kept");
    let ids: Vec<u64> = kept.objects.iter().map(|o| u64::from(o.id.0)).collect();

    // the room again, from its store, and a late joiner
    let hd = dir.join("host2.jsonl");
    let hd_arg = hd.to_str().unwrap().to_owned();
    let host2 = peer_on(
        &dir,
        "host2",
        "host",
        &url,
        "keep",
        &[
            "--store",
            &db_arg,
            "--dump",
            &hd_arg,
            "--dump-hz",
            "5",
            "--duration",
            "60",
        ],
    );
    let reopened = host2.wait_line("reopened the room kept in", Duration::from_secs(20));
    assert!(reopened.contains("5 topology entries"), "{reopened}");
    assert!(reopened.contains("1 retained messages"), "{reopened}");
    host2.peer_id();
    let ld = dir.join("late.jsonl");
    let ld_arg = ld.to_str().unwrap().to_owned();
    let mut late = peer_on(
        &dir,
        "late",
        "join",
        &url,
        "keep",
        &["--dump", &ld_arg, "--dump-hz", "5", "--duration", "6"],
    );
    assert_eq!(
        late.wait_exit(Duration::from_secs(40)),
        0,
        "{}",
        late.logs()
    );
    assert!(
        late.stdout().contains("say=\"the flap is open\""),
        "the late joiner never got the note: {}",
        late.stdout()
    );
    let last_late = read_dump(&ld).last().unwrap().clone();
    let at = last_late["wall_ms"].as_u64().unwrap();
    let h = read_dump(&hd);
    let last_host = nearest(&h, at).clone();
    let (ho, lo) = (objects(&last_host), objects(&last_late));
    // the same objects under the same ids (the avatars are new)
    for id in &ids {
        assert!(
            ho.contains_key(id) && lo.contains_key(id),
            "object {id} missing"
        );
    }
    let b = u64::from(bunny.id.0);
    assert_eq!(ho[&b]["log"].as_u64(), Some(5));
    assert_eq!(
        ho[&b]["topology"], lo[&b]["topology"],
        "host and joiner disagree on the tear"
    );
    // the bunny at rest where and as it was kept (the host's own copy)
    let pos = v3(&ho[&b]["pos"]);
    let kp = bunny.state.pos;
    let d = ((pos[0] - f64::from(kp.x)).powi(2)
        + (pos[1] - f64::from(kp.y)).powi(2)
        + (pos[2] - f64::from(kp.z)).powi(2))
    .sqrt();
    assert!(d < 1e-3, "the bunny is {d} m from where it was kept");
    let parts = ho[&b]["particles"].as_array().unwrap();
    assert_eq!(parts.len(), bunny.state.particles.len());
    let worst = parts
        .iter()
        .zip(&bunny.state.particles)
        .map(|(p, k)| {
            let p = v3(p);
            ((p[0] - f64::from(k.x)).powi(2)
                + (p[1] - f64::from(k.y)).powi(2)
                + (p[2] - f64::from(k.z)).powi(2))
            .sqrt()
        })
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-3,
        "the bunny's shape is {worst} m from the kept one"
    );
}

#[test]
fn the_member_that_takes_over_from_a_dead_host_keeps_writing_the_store() {
    require_netns();
    let dir = scratch("keep-heir");
    let db = dir.join("room.db");
    let db_arg = db.to_str().unwrap().to_owned();
    let (_signal, url) = standalone_signal(&dir);
    let mut host = peer_on(
        &dir,
        "host",
        "host",
        &url,
        "heir",
        &["--bot", "idle", "--store", &db_arg],
    );
    host.wait_line("keeping the room in", Duration::from_secs(20));
    host.peer_id();
    // the heir tears the bunny only once it hosts
    let script = "wait 4; own bunny; \
                  tear right bunny -0.05 0.03 0 -0.025 0.03 0.005 0 0.03 0 in 0.1; wait 20";
    let mut heir = peer_on(
        &dir,
        "heir",
        "join",
        &url,
        "heir",
        &["--bot", script, "--store", &db_arg],
    );
    heir.wait_line("joined", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(1500));
    host.kill();
    heir.wait_line("host-changed", Duration::from_secs(10));
    let t0 = std::time::Instant::now();
    while !heir.logs().contains("hosting now: keeping the room in") {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "the heir never kept the room: {}",
            heir.logs()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    heir.wait_line("tore object", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(1000));
    heir.kill();
    let kept = SqliteStore::open(&db).unwrap().load().unwrap();
    let torn: Vec<_> = kept
        .objects
        .iter()
        .filter(|o| o.topology.len() == 3)
        .collect();
    assert_eq!(
        torn.len(),
        1,
        "the tear made after the migration is not in the store: {:?}",
        kept.objects
            .iter()
            .map(|o| (o.id, o.topology.len()))
            .collect::<Vec<_>>()
    );
}
