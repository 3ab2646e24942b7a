//! The SQLite store: every kind of topology event, a cut's pieces, retained messages (room-wide
//! and per object) and the room time round-trip; a store of another scene, of a newer schema,
//! a corrupt or truncated file, a file another host holds and a full disk each get a clear
//! error, and what was written before stays readable.
#![allow(clippy::unwrap_used, clippy::disallowed_methods)]

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::*;
use glam::Vec3;
use softsync_net::{ClassId, KeptObject, NetId, RoomImage};
use softsync_store::{
    LogChange, RoomIdentity, RoomStore, SqliteStore, StoreError, StoreWriter, Tracker,
};

fn write_room(store: &mut SqliteStore, r: &RoomImage) {
    store.begin(&identity(), b"bundle bytes", false).unwrap();
    let b = Tracker::new().diff(r, true).unwrap();
    store.write(&b).unwrap();
}

#[test]
fn a_room_with_every_kind_of_event_comes_back_as_it_was_written() {
    let d = temp_dir("roundtrip");
    let path = d.join("room.db");
    let r = room();
    {
        let mut s = SqliteStore::open(&path).unwrap();
        assert_eq!(s.identity().unwrap(), None);
        write_room(&mut s, &r);
    }
    let mut s = SqliteStore::open(&path).unwrap();
    assert_eq!(s.identity().unwrap(), Some(identity()));
    assert_eq!(s.load().unwrap(), r);
    assert_eq!(
        s.scene(&identity().scene_sha256).unwrap().as_deref(),
        Some(&b"bundle bytes"[..])
    );
    // later writes: an entry appended, a piece removed, a state moved
    let mut t = Tracker::new();
    t.diff(&r, true).unwrap();
    let mut r2 = r.clone();
    r2.objects[1].topology.push(tear(1000));
    r2.objects.remove(3);
    r2.objects[0].state.pos = Vec3::new(0.0, 2.0, 0.0);
    r2.room_time += Duration::from_secs(1);
    let b = t.diff(&r2, true).unwrap();
    assert!(!b.full);
    assert_eq!(b.remove, vec![NetId(10)]);
    assert!(matches!(
        b.logs[..],
        [(NetId(5), LogChange::Append { from: 3, .. })]
    ));
    s.write(&b).unwrap();
    assert_eq!(s.load().unwrap(), r2);
}

#[test]
fn another_scene_is_refused_unless_reset() {
    let d = temp_dir("scene");
    let path = d.join("room.db");
    let mut s = SqliteStore::open(&path).unwrap();
    write_room(&mut s, &room());
    let other = RoomIdentity::of(b"another scene", 0x1234);
    let e = s.begin(&other, b"x", false).unwrap_err();
    assert!(matches!(e, StoreError::OtherScene { .. }), "{e}");
    assert!(e.to_string().contains("--store-reset"), "{e}");
    assert_eq!(s.load().unwrap(), room(), "a refusal loses nothing");
    s.begin(&other, b"x", true).unwrap();
    let empty = s.load().unwrap();
    assert!(empty.objects.is_empty() && empty.retained.is_empty());
    assert_eq!(s.identity().unwrap(), Some(other));
}

#[test]
fn a_newer_schema_is_refused_and_a_foreign_database_is_named() {
    let d = temp_dir("newer");
    let path = d.join("room.db");
    {
        let mut s = SqliteStore::open(&path).unwrap();
        write_room(&mut s, &room());
        s.execute_raw("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
            .unwrap();
    }
    let e = SqliteStore::open(&path).unwrap_err();
    assert!(
        matches!(
            e,
            StoreError::Newer {
                found: 99,
                known: 2
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("newer softsync"), "{e}");

    let foreign = d.join("foreign.db");
    {
        let mut s = SqliteStore::open(&d.join("scratch.db")).unwrap();
        s.execute_raw(&format!(
            "ATTACH '{}' AS f; CREATE TABLE f.users (name TEXT); DETACH f;",
            foreign.display()
        ))
        .unwrap();
    }
    let e = SqliteStore::open(&foreign).unwrap_err();
    assert!(matches!(e, StoreError::Foreign(_)), "{e}");
}

#[test]
fn a_corrupt_or_truncated_file_gets_a_clear_error() {
    let d = temp_dir("corrupt");
    let garbage = d.join("garbage.db");
    std::fs::write(&garbage, vec![0x5a; 8192]).unwrap();
    let e = SqliteStore::open(&garbage).unwrap_err().to_string();
    assert!(e.contains("corrupt") || e.contains("not a database"), "{e}");

    let path = d.join("room.db");
    {
        let mut s = SqliteStore::open(&path).unwrap();
        write_room(&mut s, &room());
        // many rows, so the file spans pages a truncation loses
        let mut big = room();
        for k in 0..200 {
            big.objects.push(KeptObject {
                id: NetId(100 + k),
                class: ClassId(1),
                state: soft(k as f32, 200),
                topology: vec![tear(k as i32)],
            });
        }
        let b = Tracker::new().diff(&big, true).unwrap();
        s.write(&b).unwrap();
        s.execute_raw("PRAGMA wal_checkpoint(TRUNCATE)").unwrap();
    }
    let len = std::fs::metadata(&path).unwrap().len();
    let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    f.set_len(len / 2).unwrap();
    drop(f);
    let r = SqliteStore::open(&path).and_then(|mut s| s.load());
    let e = r.unwrap_err().to_string();
    assert!(
        e.contains("corrupt") || e.contains("malformed") || e.contains("not a database"),
        "{e}"
    );
}

#[test]
fn a_store_another_host_holds_is_refused_at_once() {
    let d = temp_dir("locked");
    let path = d.join("room.db");
    let mut first = SqliteStore::open(&path).unwrap();
    write_room(&mut first, &room());
    let e = SqliteStore::open(&path).unwrap_err().to_string();
    assert!(e.contains("in use by another host"), "{e}");
    drop(first);
    assert_eq!(SqliteStore::open(&path).unwrap().load().unwrap(), room());
}

/// A tmpfs of `kib` KiB mounted on `dir` for the guard's life.
struct SmallDisk(PathBuf);

impl SmallDisk {
    fn mount(dir: &Path, kib: u32) -> SmallDisk {
        let ok = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
            .arg(dir)
            .status()
            .unwrap()
            .success();
        assert!(
            ok,
            "mounting a {kib} KiB tmpfs on {} (needs root)",
            dir.display()
        );
        SmallDisk(dir.to_path_buf())
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn a_full_disk_fails_the_write_whole_and_keeps_what_was_written() {
    let d = temp_dir("full");
    let disk = d.join("disk");
    std::fs::create_dir_all(&disk).unwrap();
    let _guard = SmallDisk::mount(&disk, 512);
    let path = disk.join("room.db");
    let store = {
        let mut s = SqliteStore::open(&path).unwrap();
        s.begin(&identity(), b"bundle", false).unwrap();
        s
    };
    let writer = StoreWriter::spawn(Box::new(store));
    let mut t = Tracker::new();
    let mut r = room();
    let mut failed_at = None;
    // grow the room until the disk is full: each batch adds a torn body of 2,000 particles
    for k in 0..200u32 {
        r.objects.push(KeptObject {
            id: NetId(1000 + k),
            class: ClassId(1),
            state: soft(k as f32, 2000),
            topology: (0..20).map(|i| tear(i * 100)).collect(),
        });
        r.room_time += Duration::from_millis(100);
        if writer.take_failures() > 0 {
            failed_at = Some(k);
            t.resync();
            break;
        }
        let b = t.diff(&r, false).unwrap();
        writer.submit(b).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = writer.finish();
    let k = failed_at.expect("the disk never filled");
    let e = status.error.clone().unwrap_or_default();
    assert!(e.contains("disk full") || e.contains("full"), "{e}");
    // every object the store has is whole: its state and its whole log
    let kept = SqliteStore::open(&path).unwrap().load().unwrap();
    assert!(
        kept.objects.len() > room().objects.len(),
        "kept {} objects",
        kept.objects.len()
    );
    assert!(
        kept.objects.len() < r.objects.len(),
        "nothing was refused ({k})"
    );
    for o in &kept.objects {
        let want = r.objects.iter().find(|w| w.id == o.id).unwrap();
        assert_eq!(o, want, "object {:?} half-written", o.id);
    }
}

#[test]
fn a_store_of_the_previous_schema_is_migrated_and_keeps_its_room() {
    let d = temp_dir("migrate");
    let path = d.join("room.db");
    {
        let mut s = SqliteStore::open(&path).unwrap();
        write_room(&mut s, &room());
        // what version 1 was: the same room tables, no recordings
        s.execute_raw(
            "DROP TABLE recordings; DROP TABLE record_events; DROP TABLE record_states;
             UPDATE meta SET value = '1' WHERE key = 'schema_version';",
        )
        .unwrap();
    }
    let mut s = SqliteStore::open(&path).unwrap();
    let info = s.info();
    assert_eq!((info.migrated_from, info.schema_version), (1, 2));
    assert_eq!(s.load().unwrap(), room());
    assert!(s.recordings().unwrap().is_empty());
    drop(s);
    assert_eq!(SqliteStore::open(&path).unwrap().info().migrated_from, 2);
}

#[test]
fn a_recording_round_trips_is_read_at_any_time_and_is_deleted_alone() {
    use softsync_store::record::{RecEvent, RecStart, RecState, RecordBatch};
    let d = temp_dir("record");
    let mut s = SqliteStore::open(&d.join("room.db")).unwrap();
    write_room(&mut s, &room());
    let state = |t: u64, x: f32| RecState {
        room_us: t,
        object: NetId(5),
        class: ClassId(1),
        state: soft(x, 40),
    };
    let ev = |t: u64, kind: &str, object: Option<u32>| RecEvent {
        room_us: t,
        kind: kind.into(),
        peer: Some(9),
        object,
        data: "{}".into(),
    };
    let first = RecordBatch {
        recording: 1_700_000_000_000,
        start: Some(RecStart {
            id: 1_700_000_000_000,
            room_us: 1_000_000,
            host: 9,
            image: room(),
        }),
        events: vec![ev(1_000_000, "join", None), ev(1_100_000, "tear", Some(5))],
        first_n: 0,
        states: vec![state(1_000_000, 0.0), state(1_200_000, 0.2)],
        end_us: 1_200_000,
    };
    let second = RecordBatch {
        recording: first.recording,
        events: vec![ev(1_300_000, "gone", Some(5))],
        first_n: 2,
        end_us: 1_400_000,
        ..Default::default()
    };
    for b in [first.clone(), second] {
        s.write(&softsync_store::Batch {
            record: Some(b),
            ..Default::default()
        })
        .unwrap();
    }
    let list = s.recordings().unwrap();
    assert_eq!(list.len(), 1);
    assert_eq!(
        (list[0].events, list[0].states, list[0].end_us),
        (3, 2, 1_400_000)
    );
    let r = s.recording(first.recording).unwrap().unwrap();
    assert_eq!(r.image, room());
    let evs = s.recording_events(r.info.id, 1_050_000, u64::MAX).unwrap();
    assert_eq!(
        evs.iter().map(|e| e.kind.as_str()).collect::<Vec<_>>(),
        ["tear", "gone"]
    );
    // half-way between two states: interpolated; after `gone`: not there
    let at = s.recording_state_at(r.info.id, 1_100_000).unwrap();
    assert_eq!(at.len(), 1);
    assert!(
        (at[0].state.pos.x - 0.1).abs() < 1e-5,
        "{:?}",
        at[0].state.pos
    );
    assert!(s
        .recording_state_at(r.info.id, 1_350_000)
        .unwrap()
        .is_empty());
    // deleting it leaves the room
    assert_eq!(
        softsync_store::prune_recordings(&mut s, 1_700_000_000_001).unwrap(),
        vec![first.recording]
    );
    assert!(s.recordings().unwrap().is_empty());
    assert_eq!(s.load().unwrap(), room());
}
