//! The PostgreSQL store on a real server of the test's own (Debian's package, a unix socket
//! in a scratch folder): the same room as the SQLite tests round-trips, a newer schema and
//! another scene are refused, a second host is refused while the first holds the store, and a
//! server stopped mid-session costs the writes while it is down and nothing else: each
//! failed write is said, the store keeps its last whole write, and once the server is back
//! the next write brings the whole room.
#![allow(clippy::unwrap_used, clippy::disallowed_methods)]

mod common;

use std::time::Duration;

use common::*;
use softsync_net::{ClassId, KeptObject, NetId};
use softsync_store::testing::PgCluster as PgServer;
use softsync_store::{PgStore, RoomStore, StoreError, StoreWriter, Tracker};

#[test]
fn a_room_round_trips_through_postgres_and_what_it_refuses() {
    let pg = PgServer::start("roundtrip").unwrap();
    let r = room();
    {
        let mut s = PgStore::open(&pg.url).unwrap();
        assert_eq!(s.identity().unwrap(), None);
        s.begin(&identity(), b"bundle bytes", false).unwrap();
        s.write(&Tracker::new().diff(&r, true).unwrap()).unwrap();
        // a second host while the first holds it
        let e = PgStore::open(&pg.url).unwrap_err().to_string();
        assert!(e.contains("in use by another host"), "{e}");
    }
    let mut s = PgStore::open(&pg.url).unwrap();
    assert_eq!(s.identity().unwrap(), Some(identity()));
    assert_eq!(s.load().unwrap(), r);
    assert_eq!(
        s.scene(&identity().scene_sha256).unwrap().as_deref(),
        Some(&b"bundle bytes"[..])
    );
    let other = softsync_store::RoomIdentity::of(b"another scene", 1);
    let e = s.begin(&other, b"x", false).unwrap_err();
    assert!(matches!(e, StoreError::OtherScene { .. }), "{e}");
    assert_eq!(s.load().unwrap(), r, "a refusal loses nothing");
    s.execute_raw("UPDATE meta SET value = '7' WHERE key = 'schema_version'")
        .unwrap();
    drop(s);
    let e = PgStore::open(&pg.url).unwrap_err();
    assert!(matches!(e, StoreError::Newer { found: 7, .. }), "{e}");
}

#[test]
fn a_server_stopped_mid_session_costs_only_the_writes_while_it_is_down() {
    let mut pg = PgServer::start("stopped").unwrap();
    let mut s = PgStore::open(&pg.url).unwrap();
    s.begin(&identity(), b"bundle", false).unwrap();
    let writer = StoreWriter::spawn(Box::new(s));
    let mut t = Tracker::new();
    let mut r = room();
    let grow = |r: &mut softsync_net::RoomImage, k: u32| {
        r.objects.push(KeptObject {
            id: NetId(500 + k),
            class: ClassId(1),
            state: soft(k as f32, 30),
            topology: vec![tear(k as i32)],
        });
        r.room_time += Duration::from_millis(100);
    };
    let settle = |w: &StoreWriter, n: u64| {
        for _ in 0..200 {
            let st = w.status();
            if st.written + st.failures >= n {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        panic!("the writer is stuck: {:?}", w.status());
    };
    writer.submit(t.diff(&r, true).unwrap()).unwrap();
    settle(&writer, 1);
    pg.stop();
    grow(&mut r, 1);
    writer.submit(t.diff(&r, false).unwrap()).unwrap();
    settle(&writer, 2);
    assert_eq!(writer.take_failures(), 1, "{:?}", writer.status());
    let e = writer.status().error.unwrap();
    assert!(e.contains("postgres"), "{e}");
    t.resync();
    pg.run().unwrap();
    grow(&mut r, 2);
    writer.submit(t.diff(&r, false).unwrap()).unwrap();
    settle(&writer, 3);
    let st = writer.finish();
    assert_eq!(st.written, 2, "{st:?}");
    assert!(st.error.is_none(), "{st:?}");
    let kept = PgStore::open(&pg.url).unwrap().load().unwrap();
    assert_eq!(
        kept, r,
        "the room is whole again after the server came back"
    );
}

#[test]
fn a_postgres_store_of_the_previous_schema_is_migrated_and_records() {
    let pg = PgServer::start("migrate").unwrap();
    {
        let mut s = PgStore::open(&pg.url).unwrap();
        s.begin(&identity(), b"bundle", false).unwrap();
        s.write(&Tracker::new().diff(&room(), true).unwrap())
            .unwrap();
        s.execute_raw(
            "DROP TABLE recordings; DROP TABLE record_events; DROP TABLE record_states;
             UPDATE meta SET value = '1' WHERE key = 'schema_version';",
        )
        .unwrap();
    }
    let mut s = PgStore::open(&pg.url).unwrap();
    assert_eq!(s.info().migrated_from, 1);
    assert_eq!(s.load().unwrap(), room());
    let b = softsync_store::record::RecordBatch {
        recording: 42,
        start: Some(softsync_store::record::RecStart {
            id: 42,
            room_us: 10,
            host: 1,
            image: room(),
        }),
        states: vec![softsync_store::record::RecState {
            room_us: 10,
            object: NetId(5),
            class: ClassId(1),
            state: soft(0.3, 12),
        }],
        end_us: 20,
        ..Default::default()
    };
    s.write(&softsync_store::Batch {
        record: Some(b),
        ..Default::default()
    })
    .unwrap();
    let list = s.recordings().unwrap();
    assert_eq!((list.len(), list[0].states), (1, 1));
    assert_eq!(s.recording(42).unwrap().unwrap().image, room());
    assert_eq!(
        s.recording_state_at(42, 15).unwrap()[0].state,
        soft(0.3, 12)
    );
    assert!(s.delete_recording(42).unwrap());
}
