//! The room store's benches (issue 35), SQLite and PostgreSQL side by side on one workload:
//!
//! - **reopen**: the thesis room with its bunny torn by 100 segments and the soft box cut in
//!   two, kept, then opened again as a host does: the store opened and read, every body
//!   rebuilt through its log and placed ([`Peer::reopen`]). Median of several opens
//!   (`RESULT store.reopen`).
//! - **seek**: a 10-minute recording with a soft ball squeezed and turned throughout and two
//!   avatars moving, the room read at times spread over it (`RESULT replay.seek`).
//! - **write**: the frame-budget room ([`crate::frame`]: four peers, tears, cuts, a host
//!   migration) run without a store and with each back end, interleaved round by round; the
//!   host's frames (where the keeper runs) compared (`RESULT store.write`); and once more on
//!   SQLite with the session recorded (`RESULT store.record`: the recording's overhead).
//!
//! PostgreSQL is a cluster of the bench's own ([`softsync_store::testing::PgCluster`]: as the
//! `postgres` user on a unix socket in a scratch folder), unless `--postgres URL` names one.

use std::path::{Path, PathBuf};
use std::time::Duration;

use glam::Vec3;
use softsync_benchkit::{percentile, Csv, ResultLine};
use softsync_net::{Instant, NetId, PeerId, RoomImage, SendPolicy, Session};
use softsync_peer::{Peer, PeerConfig, Scene};
use softsync_store::{RoomIdentity, Tracker};

use crate::frame::{self, FramePlan};
use crate::wall_s;

/// The back ends to measure: (name, target).
pub type Backends = Vec<(&'static str, String)>;

const DT: Duration = Duration::from_micros(11_111);

fn host_peer(scene: &Scene) -> Result<Peer, String> {
    let policy = SendPolicy::default();
    let cfg = scene.session_config(policy.clone(), policy.clone(), policy);
    let session = Session::host(PeerId(1), cfg, Instant::ZERO);
    let config = PeerConfig {
        dt_s: DT.as_secs_f32(),
        avatar: false,
        build_off_frame: false,
        ..PeerConfig::default()
    };
    Peer::new(Instant::ZERO, session, None, scene.clone(), config).map_err(|e| e.to_string())
}

fn run_for(peer: &mut Peer, now: &mut Instant, frames: usize) -> Result<(), String> {
    for _ in 0..frames {
        *now += DT;
        peer.pump(*now).map_err(|e| e.to_string())?;
        peer.fixed_step(*now);
        while peer.poll_transmit(*now).is_some() {}
        while peer.poll_event().is_some() {}
    }
    Ok(())
}

/// The thesis room after `segments` tear segments on the bunny (strokes of ten 1 cm segments
/// across its back, each stroke lifted) and a cut through the soft box; the image a store
/// keeps, and how many tear segments its log holds.
pub fn torn_room(assets: &Path, segments: usize) -> Result<(Scene, RoomImage, usize), String> {
    let scene = Scene::by_name("thesis-room", assets)?;
    let mut peer = host_peer(&scene)?;
    let mut now = Instant::ZERO;
    peer.open(now).map_err(|e| e.to_string())?;
    run_for(&mut peer, &mut now, 180)?;
    let find = |peer: &Peer, name: &str| {
        let kind = peer.scene().kind(name);
        peer.objects()
            .iter()
            .find(|(_, o)| Some(o.kind) == kind)
            .map(|(id, _)| *id)
    };
    let bunny = find(&peer, "bunny").ok_or("no bunny in the thesis room")?;
    let soft_box = find(&peer, "softbox").ok_or("no soft box in the thesis room")?;
    let mut asked = 0;
    let mut stroke = 0;
    while asked < segments && stroke < 4 * segments {
        let c = peer.shown_state(now, bunny).ok_or("the bunny is gone")?.pos;
        let z = -0.02 + 0.004 * (stroke % 11) as f32;
        for k in 0..10 {
            if asked == segments {
                break;
            }
            let x = |k: usize| -0.05 + 0.01 * k as f32;
            let from = c + Vec3::new(x(k), 0.025, z);
            let to = c + Vec3::new(x(k + 1), 0.025, z);
            if peer.tear(now, bunny, from, to, Vec3::Y * 0.04).is_ok() {
                asked += 1;
            }
            run_for(&mut peer, &mut now, 1)?;
        }
        let _ = peer.lift(now, bunny);
        stroke += 1;
        run_for(&mut peer, &mut now, 3)?;
    }
    let c = peer
        .shown_state(now, soft_box)
        .ok_or("the soft box is gone")?
        .pos;
    peer.cut(now, soft_box, c, Vec3::new(0.2, 1.0, 0.0))
        .map_err(|e| e.to_string())?;
    run_for(&mut peer, &mut now, 180)?;
    let image = peer.room_image(now);
    let tears = peer
        .session()
        .topology_log(bunny)
        .unwrap_or(&[])
        .iter()
        .filter(|e| matches!(e, softsync_net::wire::TopologyEvent::Tear { .. }))
        .count();
    Ok((scene, image, tears))
}

/// One reopen: (store opened and read ms, bodies rebuilt ms).
fn reopen_once(scene: &Scene, target: &str) -> Result<(f64, f64), String> {
    let t0 = wall_s();
    let mut store = softsync_store::open(target).map_err(|e| e.to_string())?;
    let image = store.load().map_err(|e| e.to_string())?;
    let t1 = wall_s();
    let mut peer = host_peer(scene)?;
    peer.reopen(Instant::ZERO, &image)
        .map_err(|e| e.to_string())?;
    let t2 = wall_s();
    drop(store);
    Ok(((t1 - t0) * 1e3, (t2 - t1) * 1e3))
}

/// `RESULT store.reopen` per back end (median of `runs` opens), and `reopen.csv` rows.
pub fn reopen(
    assets: &Path,
    backends: &Backends,
    runs: usize,
    out: &Path,
) -> Result<Vec<ResultLine>, String> {
    let (scene, image, tears) = torn_room(assets, 100)?;
    let mut csv = Csv::new(&["backend", "run", "load_ms", "rebuild_ms", "reopen_ms"]);
    let mut lines = Vec::new();
    for (name, target) in backends {
        {
            let mut store = softsync_store::open(target).map_err(|e| e.to_string())?;
            let bundle = scene.bundle()?;
            let id = RoomIdentity::of(&bundle, 0);
            store.begin(&id, &bundle, true).map_err(|e| e.to_string())?;
            let batch = Tracker::new().diff(&image, true).ok_or("an empty room")?;
            store.write(&batch).map_err(|e| e.to_string())?;
        }
        let (mut load, mut rebuild, mut total) = (Vec::new(), Vec::new(), Vec::new());
        for run in 0..runs {
            let (l, r) = reopen_once(&scene, target)?;
            csv.row(vec![
                name.to_string(),
                run.to_string(),
                format!("{l:.3}"),
                format!("{r:.3}"),
                format!("{:.3}", l + r),
            ]);
            load.push(l);
            rebuild.push(r);
            total.push(l + r);
        }
        lines.push(
            ResultLine::new("store.reopen")
                .field("backend", name)
                .field("objects", image.objects.len())
                .field("tears", tears)
                .fixed("reopen_ms", percentile(&total, 0.5), 1)
                .fixed("load_ms", percentile(&load, 0.5), 2)
                .fixed("rebuild_ms", percentile(&rebuild, 0.5), 1)
                .field("runs", runs),
        );
    }
    csv.write(out.join("reopen.csv"))
        .map_err(|e| format!("reopen.csv: {e}"))?;
    Ok(lines)
}

/// `RESULT store.write` per back end: the frame-budget room without a store and with each,
/// `rounds` rounds interleaved, `seconds` measured each (the host stopped half-way).
pub fn write(
    assets: &Path,
    backends: &Backends,
    rounds: usize,
    seconds: f64,
    out: &Path,
) -> Result<Vec<ResultLine>, String> {
    let mut csv = Csv::new(&[
        "round",
        "backend",
        "frames",
        "p50_ms",
        "p99_ms",
        "host_p99_ms",
        "store_p99_ms",
        "events",
        "bytes",
        "failures",
    ]);
    // per label: host frames ms, all frames ms, store ms, events, bytes, seconds
    type Acc = (Vec<f64>, Vec<f64>, Vec<f64>, u64, u64, f64);
    let mut acc: Vec<(&str, Acc)> = std::iter::once("none")
        .chain(backends.iter().map(|(n, _)| *n))
        .chain(std::iter::once("sqlite+record"))
        .map(|n| (n, Default::default()))
        .collect();
    for round in 0..rounds {
        for (label, a) in acc.iter_mut() {
            let record = *label == "sqlite+record";
            let store = backends
                .iter()
                .find(|(n, _)| *n == label.trim_end_matches("+record"))
                .map(|(_, t)| t.clone());
            let plan = FramePlan {
                seconds,
                kill_host_at_s: Some(seconds / 2.0),
                store,
                record,
                ..FramePlan::full(assets)
            };
            eprintln!("store.write: round {} of {rounds}, {label}", round + 1);
            let r = frame::run(&plan)?;
            let host: Vec<f64> = r
                .samples
                .iter()
                .filter(|s| s.hosting)
                .map(|s| s.total_s * 1e3)
                .collect();
            let all = r.totals_ms();
            let kept: Vec<f64> = r
                .samples
                .iter()
                .filter(|s| s.hosting)
                .map(|s| s.store_s * 1e3)
                .collect();
            let events: u64 = r.store_written.iter().map(|s| s.events).sum();
            let bytes: u64 = r.store_written.iter().map(|s| s.bytes).sum();
            let failures: u64 = r.store_written.iter().map(|s| s.failures).sum();
            if failures > 0 {
                let e: Vec<_> = r
                    .store_written
                    .iter()
                    .filter_map(|s| s.error.clone())
                    .collect();
                return Err(format!("{label}: {failures} writes failed: {e:?}"));
            }
            csv.row(vec![
                round.to_string(),
                label.to_string(),
                all.len().to_string(),
                format!("{:.3}", percentile(&all, 0.5)),
                format!("{:.3}", percentile(&all, 0.99)),
                format!("{:.3}", percentile(&host, 0.99)),
                format!("{:.4}", percentile(&kept, 0.99)),
                events.to_string(),
                bytes.to_string(),
                failures.to_string(),
            ]);
            a.0.extend(host);
            a.1.extend(all);
            a.2.extend(kept);
            a.3 += events;
            a.4 += bytes;
            a.5 += seconds;
        }
    }
    csv.write(out.join("write.csv"))
        .map_err(|e| format!("write.csv: {e}"))?;
    let without = &acc[0].1;
    let (host_without, all_without) = (percentile(&without.0, 0.99), percentile(&without.1, 0.99));
    Ok(acc
        .iter()
        .skip(1)
        .map(|(label, a)| {
            let (name, backend) = match label.strip_suffix("+record") {
                Some(b) => ("store.record", b),
                None => ("store.write", *label),
            };
            ResultLine::new(name)
                .field("backend", backend)
                .field("peers", 4)
                .fixed("events_per_s", a.3 as f64 / a.5, 1)
                .fixed("bytes_per_min", a.4 as f64 / a.5 * 60.0, 0)
                .fixed("frame_p99_ms_with", percentile(&a.1, 0.99), 3)
                .fixed("frame_p99_ms_without", all_without, 3)
                .fixed("host_frame_p99_ms_with", percentile(&a.0, 0.99), 3)
                .fixed("host_frame_p99_ms_without", host_without, 3)
                .fixed("store_p99_ms", percentile(&a.2, 0.99), 4)
                .field("rounds", rounds)
        })
        .collect())
}

/// `RESULT replay.seek` per back end: a recording of `minutes` minutes — the thesis room
/// torn and cut, the soft ball squeezed and turned the whole time (its 60 particles and pose
/// change at every 20 Hz sample), two avatars (head and hands) moving, a tear segment every
/// second — written through the store, then `seeks` seeks to times spread over it (a fixed
/// sequence): each the room at that time (`RoomStore::recording_state_at`).
pub fn seek(
    assets: &Path,
    backends: &Backends,
    minutes: f64,
    seeks: usize,
    out: &Path,
) -> Result<Vec<ResultLine>, String> {
    use softsync_store::record::{RecEvent, RecStart, RecState, RecordBatch};
    let (_, image, _) = torn_room(assets, 10)?;
    let ball = image
        .objects
        .iter()
        .find(|o| o.state.particles.len() == 60)
        .ok_or("no 60-particle soft ball in the thesis room")?
        .clone();
    let avatar = |k: u32| (NetId(1000 + k), softsync_net::ClassId(0));
    let samples = (minutes * 60.0 * 20.0) as u64;
    let mut csv = Csv::new(&["backend", "seek", "t_s", "objects", "ms"]);
    let mut lines = Vec::new();
    for (name, target) in backends {
        let mut store = softsync_store::open(target).map_err(|e| e.to_string())?;
        let id = 7;
        let _ = store.delete_recording(id);
        let t_write = wall_s();
        for second in 0..samples.div_ceil(20) {
            // one event a second: the second numbers them
            let mut b = RecordBatch {
                recording: id,
                first_n: second,
                ..Default::default()
            };
            if second == 0 {
                b.start = Some(RecStart {
                    id,
                    room_us: 0,
                    host: 1,
                    image: image.clone(),
                });
                for o in &image.objects {
                    b.states.push(RecState {
                        room_us: 0,
                        object: o.id,
                        class: o.class,
                        state: o.state.clone(),
                    });
                }
            }
            for k in 0..20 {
                let i = second * 20 + k;
                if i >= samples {
                    break;
                }
                let t = i * 50_000;
                let a = i as f32 * 0.05;
                let squeeze = 1.0 - 0.1 * (a * 2.0).sin().abs();
                let rot = glam::Quat::from_rotation_y(a * 0.3);
                let mut st = ball.state.clone();
                for p in &mut st.particles {
                    let d = *p - ball.state.pos;
                    *p = ball.state.pos + rot * Vec3::new(d.x, d.y * squeeze, d.z);
                }
                st.rot = rot;
                b.states.push(RecState {
                    room_us: t,
                    object: ball.id,
                    class: ball.class,
                    state: st,
                });
                for part in 0..6 {
                    let (oid, class) = avatar(part);
                    let w = a + part as f32;
                    b.states.push(RecState {
                        room_us: t,
                        object: oid,
                        class,
                        state: softsync_net::ObjectState::rigid(
                            Vec3::new(w.sin() * 0.3, 1.2, w.cos() * 0.3),
                            glam::Quat::from_rotation_y(w),
                        ),
                    });
                }
            }
            b.events.push(RecEvent {
                room_us: second * 1_000_000,
                kind: "tear".into(),
                peer: None,
                object: Some(3),
                data: "{\"seq\":0}".into(),
            });
            b.end_us = (second + 1) * 1_000_000;
            store
                .write(&softsync_store::Batch {
                    record: Some(b),
                    ..Default::default()
                })
                .map_err(|e| e.to_string())?;
        }
        let write_s = wall_s() - t_write;
        let info = store
            .recordings()
            .map_err(|e| e.to_string())?
            .into_iter()
            .find(|r| r.id == id)
            .ok_or("the recording was not kept")?;
        let mut ms = Vec::new();
        for k in 0..seeks {
            // spread over the recording, in an order no cache follows
            let f = ((k * 37) % seeks) as f64 / seeks as f64;
            let t = (f * info.end_us as f64) as u64;
            let t0 = wall_s();
            let states = store.recording_state_at(id, t).map_err(|e| e.to_string())?;
            let took = (wall_s() - t0) * 1e3;
            csv.row(vec![
                name.to_string(),
                k.to_string(),
                format!("{:.3}", t as f64 / 1e6),
                states.len().to_string(),
                format!("{took:.3}"),
            ]);
            ms.push(took);
        }
        lines.push(
            ResultLine::new("replay.seek")
                .field("backend", name)
                .fixed("minutes", minutes, 1)
                .field("states", info.states)
                .field("objects", image.objects.len() + 6)
                .fixed("seek_p50_ms", percentile(&ms, 0.5), 2)
                .fixed("seek_p95_ms", percentile(&ms, 0.95), 2)
                .fixed("write_s", write_s, 1)
                .field("seeks", seeks),
        );
        let _ = store.delete_recording(id);
    }
    csv.write(out.join("seek.csv"))
        .map_err(|e| format!("seek.csv: {e}"))?;
    Ok(lines)
}

/// A scratch SQLite file for the benches (removed first).
pub fn scratch_sqlite(name: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("softsync-bench-{name}-{}.db", std::process::id()));
    for suffix in ["", "-wal", "-shm"] {
        let _ = std::fs::remove_file(format!("{}{suffix}", p.display()));
    }
    p
}
