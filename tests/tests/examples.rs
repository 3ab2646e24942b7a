//! The `softsync-bevy` examples as a user runs them, in rooms of the real `softsync` binary
//! (multi-process, WebRTC in the network namespace): a user's own bevy app joins, sees the
//! same scene as the host, and its own message types cross the room both ways; the bell's
//! retained state reaches a late joiner.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::collections::BTreeMap;
use std::time::Duration;

mod common;
use common::dump::{dist, objects, read_dump, wait_for_rest};
use common::{embedded_host, example, field, peer_on, repo_file, require_netns, scratch, Proc};

const SCENE: &str = "bevy/examples/lab.ron";

/// The example's `object id=… class=… pos=x,y,z` lines.
fn printed_objects(out: &str) -> BTreeMap<u64, (String, [f64; 3])> {
    out.lines()
        .filter(|l| l.starts_with("object "))
        .map(|l| {
            let p: Vec<f64> = field(l, "pos")
                .split(',')
                .map(|x| x.parse().unwrap())
                .collect();
            (
                field(l, "id").parse().unwrap(),
                (field(l, "class").to_owned(), [p[0], p[1], p[2]]),
            )
        })
        .collect()
}

#[test]
fn a_users_bevy_app_joins_a_room_of_the_binary_sees_its_scene_and_messages_cross() {
    require_netns();
    let dir = scratch("example-hello");
    let scene = repo_file(SCENE);
    let scene = scene.to_str().unwrap();
    let hd = dir.join("host.jsonl");
    let (mut host, url) = embedded_host(
        &dir,
        "lab",
        &[
            "--scene",
            scene,
            "--duration",
            "40",
            "--dump",
            hd.to_str().unwrap(),
        ],
    );
    let host_id = host.peer_id();
    let app_args = ["join", "lab", &url, "--scene", scene, "--seconds", "14"];
    let mut app = Proc::spawn_program(&dir, "app", &example("hello_room"), &app_args, &[]);
    let app_id = app.peer_id();
    app.wait_line(&format!("joined host={host_id}"), Duration::from_secs(30));
    // The binary does not know the example's type, but the scene names it: relayed, logged.
    host.wait_line(
        &format!("message from={app_id} kind=example.greeting"),
        Duration::from_secs(20),
    );
    // A bot of the binary says a line; the app decodes the built-in type.
    let mut bot = peer_on(
        &dir,
        "bot",
        "join",
        &url,
        "lab",
        &[
            "--scene",
            scene,
            "--bot",
            "wait 0.5; say hello from a bot; wait 2",
            "--duration",
            "5",
        ],
    );
    let bot_id = bot.peer_id();
    app.wait_line(
        &format!("say from={bot_id} text=\"hello from a bot\""),
        Duration::from_secs(30),
    );
    assert_eq!(bot.wait_exit(Duration::from_secs(30)), 0, "{}", bot.logs());
    // The app ends by itself and prints the objects its entities show.
    assert_eq!(app.wait_exit(Duration::from_secs(40)), 0, "{}", app.logs());
    wait_for_rest(&hd, Duration::from_secs(10));
    let lines = read_dump(&hd);
    let last = lines.last().unwrap();
    let at_host: BTreeMap<u64, _> = objects(last)
        .into_iter()
        .filter(|(_, o)| ["block", "bell", "softball"].contains(&o["kind"].as_str().unwrap()))
        .collect();
    let seen = printed_objects(&app.stdout());
    assert_eq!(
        seen.keys().collect::<Vec<_>>(),
        at_host.keys().collect::<Vec<_>>(),
        "the app's entities are not the host's objects\n{}",
        app.logs()
    );
    assert_eq!(seen.len(), 3, "{}", app.logs());
    for (id, (class, pos)) in &seen {
        let h = at_host[id];
        assert_eq!(class, h["kind"].as_str().unwrap(), "object {id}");
        // A soft body's entity stays at the origin (its particles are in world space).
        if class != "softball" {
            let d = dist(*pos, common::dump::vec3(&h["pos"]));
            assert!(
                d < 0.01,
                "object {id} ({class}) {d} m from the host's\n{}",
                app.logs()
            );
        }
    }
    host.kill();
}

#[test]
fn a_bell_rung_in_a_users_app_reaches_everyone_and_a_late_joiner() {
    require_netns();
    let dir = scratch("example-bell");
    let scene = repo_file(SCENE);
    let scene = scene.to_str().unwrap();
    let (mut host, url) = embedded_host(&dir, "bells", &["--scene", scene, "--duration", "40"]);
    let ringer_args = [
        "join",
        "bells",
        &url,
        "--scene",
        scene,
        "--ring",
        "--seconds",
        "30",
    ];
    let mut ringer = Proc::spawn_program(&dir, "ringer", &example("bell"), &ringer_args, &[]);
    let ringer_id = ringer.peer_id();
    ringer.wait_line("rang the bell: count=1", Duration::from_secs(30));
    host.wait_line(
        &format!("message from={ringer_id} kind=example.bell"),
        Duration::from_secs(20),
    );
    // A peer that joins after the ring hears the bell's state.
    let late_args = ["join", "bells", &url, "--scene", scene, "--seconds", "30"];
    let mut late = Proc::spawn_program(&dir, "late", &example("bell"), &late_args, &[]);
    late.peer_id();
    late.wait_line(
        &format!("bell count=1 by={ringer_id}"),
        Duration::from_secs(30),
    );
    assert!(!late.stdout().contains("rang the bell"), "{}", late.logs());
    late.kill();
    ringer.kill();
    host.kill();
}

#[test]
fn a_users_bevy_app_hosts_and_a_bot_of_the_binary_is_welcomed_in_its_message_type() {
    require_netns();
    let dir = scratch("example-host");
    let scene = repo_file(SCENE);
    let scene = scene.to_str().unwrap();
    let app_args = [
        "host",
        "labhost",
        "127.0.0.1:0",
        "--scene",
        scene,
        "--seconds",
        "20",
    ];
    let mut app = Proc::spawn_program(&dir, "app", &example("hello_room"), &app_args, &[]);
    let app_id = app.peer_id();
    let l = app.wait_line("signal=", Duration::from_secs(20));
    let url = field(&l, "signal").to_owned();
    let mut bot = peer_on(
        &dir,
        "bot",
        "join",
        &url,
        "labhost",
        &[
            "--scene",
            scene,
            "--bot",
            "wait 1; say hi, host",
            "--duration",
            "4",
        ],
    );
    let bot_id = bot.peer_id();
    // The host app welcomes the newcomer in its own type; the binary logs what it cannot decode.
    bot.wait_line(
        &format!("message from={app_id} kind=example.greeting"),
        Duration::from_secs(30),
    );
    app.wait_line(
        &format!("say from={bot_id} text=\"hi, host\""),
        Duration::from_secs(30),
    );
    assert_eq!(bot.wait_exit(Duration::from_secs(30)), 0, "{}", bot.logs());
    app.kill();
}

#[test]
fn a_users_app_runs_either_sync_mode_with_the_same_systems() {
    require_netns();
    // where `either_mode` holds its right hand (its HAND_AT)
    let hand_at = [0.1, 1.05, 0.45];
    for mode in ["state", "rollback"] {
        let dir = scratch(&format!("example-either-{mode}"));
        let dump = dir.join("host.jsonl");
        let room = format!("either{mode}");
        let mut extra = vec![
            "--duration",
            "60",
            "--dump",
            dump.to_str().unwrap(),
            "--dump-hz",
            "5",
        ];
        if mode == "rollback" {
            extra.extend(["--sync", "rollback", "--bot", "idle"]);
        }
        let (mut host, url) = embedded_host(&dir, &room, &extra);
        let app_args = ["join", &room, &url, "--sync", mode, "--seconds", "40"];
        let mut app = Proc::spawn_program(&dir, "app", &example("either_mode"), &app_args, &[]);
        let me = app.peer_id();
        // the same systems see the scene's objects as entities (7, 3 of them soft) ...
        app.wait_line("objects n=7 soft=3", Duration::from_secs(40));
        // ... and drive the hands: the host has the app's right hand where the app holds it
        let start = std::time::Instant::now();
        let err = loop {
            let best = read_dump(&dump)
                .iter()
                .rev()
                .take(10)
                .flat_map(|l| l["objects"].as_array().cloned().unwrap_or_default())
                .filter(|o| o["owner"].as_u64() == Some(me) && o["kind"] == "hand")
                .map(|o| dist(common::dump::pos(&o), hand_at))
                .fold(f64::MAX, f64::min);
            if best < 0.01 {
                break best;
            }
            assert!(
                start.elapsed() < Duration::from_secs(40),
                "{mode}: the host never had the app's hand within 1 cm of where it holds it \
                 ({best} m)\n{}\n{}",
                app.logs(),
                host.logs()
            );
            std::thread::sleep(Duration::from_millis(200));
        };
        println!(
            "{mode}: the host has the app's hand {:.1} mm from where it holds it",
            err * 1e3
        );
        app.kill();
        host.kill();
    }
}
