//! Multi-process rooms on real WebRTC: the `softsync` binary as separate processes (signaling,
//! host, bots) talking over loopback data channels.
//!
//! These open WebRTC, so on the shared machines they must run inside a network namespace:
//! `scripts/test` runs the whole suite through `scripts/netns-run`, which sets
//! `SOFTSYNC_IN_NETNS=1`. Outside one they fail and say so (they never skip). Every wait is
//! bounded and every process is killed by pid when its test ends.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;
use common::dump::{assert_agree, dist, nearest, objects, read_dump, vec3, wait_for_rest};
use common::{
    embedded_host, field, peer_on, require_netns, scratch, send_signal, signal_url,
    standalone_signal, Proc,
};

/// Arguments built as owned strings, borrowed for a command line.
fn strs(a: &[String]) -> Vec<&str> {
    a.iter().map(String::as_str).collect()
}

const SQUEEZE: &str = "wait 1; reach right softbox in 1; grab right; squeeze right 0.02 in 0.6; \
                       wait 0.6; release right; offset right 0 0.15 0 in 0.5";

/// Host and one bot; the bot takes the host's soft box through the authority request,
/// squeezes it, lets go; after rest both peers show the same room. The bot then says a line
/// to the room (an application message): the host's process receives it and the bot hears
/// it delivered.
fn two_process_sync(test: &str, condition: Option<&str>) {
    require_netns();
    let dir = scratch(test);
    let hd = dir.join("host.jsonl");
    let jd = dir.join("bot.jsonl");
    let mut common = vec!["--dump-hz", "10", "--quiet"];
    if let Some(c) = condition {
        common.extend(["--net-condition", c]);
    }
    let mut host_args = vec![
        "host",
        "--room",
        "sync",
        "--bind",
        "127.0.0.1:0",
        "--duration",
        "17",
    ];
    host_args.extend(["--dump", hd.to_str().unwrap()]);
    host_args.extend(&common);
    let mut host = Proc::spawn(&dir, "host", &host_args);
    let url = signal_url(&host);
    let script = format!("{SQUEEZE}; say hello from the bot; wait 1");
    let mut bot_args = vec!["join", "--room", "sync", "--signal", &url, "--bot", &script];
    bot_args.extend(["--duration", "13", "--dump", jd.to_str().unwrap()]);
    bot_args.extend(&common);
    let host_id = host.peer_id();
    let mut bot = Proc::spawn(&dir, "bot", &bot_args);
    assert_eq!(bot.wait_exit(Duration::from_secs(40)), 0, "{}", bot.logs());
    let out = bot.stdout();
    // The bot has no --scene: the host sent it the room's, the bunny's mesh with it.
    let got = out
        .lines()
        .find(|l| l.starts_with(&format!("scene thesis-room from peer {host_id}: ")))
        .unwrap_or_else(|| panic!("the bot did not receive the scene\n{}", bot.logs()));
    let bytes: u64 = got.split_whitespace().nth(5).unwrap().parse().unwrap();
    assert!(bytes > 110_000, "{got}");
    assert!(out.contains("authority-asked"), "{}", bot.logs());
    assert!(
        out.contains("grabbed object"),
        "the bot never held the box\n{}",
        bot.logs()
    );
    assert!(
        out.contains("authority-released"),
        "authority never went back after rest\n{}",
        bot.logs()
    );
    assert!(
        out.contains("message-delivered seq=1"),
        "the bot's message was not delivered\n{}",
        bot.logs()
    );
    assert_eq!(
        host.wait_exit(Duration::from_secs(30)),
        0,
        "{}",
        host.logs()
    );
    assert!(
        host.stdout().contains("say=\"hello from the bot\""),
        "the host never received the bot's message\n{}",
        host.logs()
    );
    let (h, j) = (read_dump(&hd), read_dump(&jd));
    let last = j.last().expect("bot dump empty");
    let peer_h = nearest(&h, last["wall_ms"].as_u64().unwrap());
    assert_eq!(last["host"], peer_h["peer"]);
    assert_agree(peer_h, last, test);
    // During the squeeze the host showed the box deformed (the bot's simulation arrived).
    let box_id = objects(last)
        .iter()
        .find(|(_, o)| o["kind"] == "softbox")
        .map(|(id, _)| *id)
        .unwrap();
    let rest = objects(&h[0])[&box_id]["particles"].clone();
    let max_dev = h
        .iter()
        .map(|l| {
            let p = objects(l)[&box_id]["particles"].as_array().unwrap().clone();
            p.iter()
                .zip(rest.as_array().unwrap())
                .map(|(a, b)| dist(vec3(a), vec3(b)))
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max);
    assert!(
        max_dev > 0.008,
        "the host never showed the squeeze ({max_dev} m)"
    );
}

#[test]
fn a_two_processes_hand_over_a_soft_body_and_agree_after_rest() {
    two_process_sync("sync", None);
}

#[test]
fn d_conditioned_links_still_converge_after_rest() {
    two_process_sync("conditioned", Some("lat=50ms,jitter=10ms,loss=5%,seed=7"));
}

/// Standalone signaling, a host and two bots; the host is killed mid-interaction; the earliest
/// joiner takes over with a higher term; nothing is lost, everything has one owner, and a
/// fourth peer joining afterwards gets the whole room.
#[test]
fn b_host_killed_mid_interaction_earliest_joiner_takes_over() {
    require_netns();
    let dir = scratch("kill");
    let (_signal, url) = standalone_signal(&dir);
    let mut host = peer_on(&dir, "host", "host", &url, "mig", &["--bot", "wave"]);
    let host_id = host.peer_id();
    let b1d = dir.join("b1.jsonl");
    let dumped = |dump: &Path, secs: &'static str| {
        [
            "--duration",
            secs,
            "--dump-hz",
            "5",
            "--dump",
            dump.to_str().unwrap(),
        ]
        .map(String::from)
    };
    let with = |mut a: Vec<String>, more: &[&str]| {
        a.extend(more.iter().map(|m| m.to_string()));
        a
    };
    let squeeze_loop =
        "wait 0.5; reach right bunny in 0.5; grab right; squeeze right 0.02 in 0.5; \
                        wait 0.3; release right; offset right 0 0.1 0 in 0.3; loop";
    let b1_args = with(dumped(&b1d, "40").to_vec(), &["--bot", squeeze_loop]);
    let b1 = peer_on(&dir, "bot1", "join", &url, "mig", &strs(&b1_args));
    let b1_id = b1.peer_id();
    b1.wait_line("joined", Duration::from_secs(20));
    let b2d = dir.join("b2.jsonl");
    let b2_args = with(dumped(&b2d, "40").to_vec(), &["--bot", "wave"]);
    let b2 = peer_on(&dir, "bot2", "join", &url, "mig", &strs(&b2_args));
    let b2_id = b2.peer_id();
    b2.wait_line("joined", Duration::from_secs(20));
    b1.wait_line("grabbed object", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(700));
    let killed_at = Instant::now();
    host.kill();
    let changed = b1.wait_line(
        &format!("host-changed host={b1_id}"),
        Duration::from_secs(10),
    );
    let took = killed_at.elapsed();
    println!("host killed; bot1 took over after {took:?}: {changed}");
    assert!(took < Duration::from_secs(2), "migration took {took:?}");
    let term: u32 = field(&changed, "term").parse().unwrap();
    assert!(term >= 2, "term did not rise: {changed}");
    b2.wait_line(
        &format!("host-changed host={b1_id}"),
        Duration::from_secs(5),
    );

    // A fourth peer joins the migrated room.
    std::thread::sleep(Duration::from_secs(2));
    let lated = dir.join("late.jsonl");
    let late_args = dumped(&lated, "5");
    let mut late = peer_on(&dir, "late", "join", &url, "mig", &strs(&late_args));
    let late_id = late.peer_id();
    assert_eq!(
        late.wait_exit(Duration::from_secs(40)),
        0,
        "{}",
        late.logs()
    );
    let l = read_dump(&lated);
    let last = l.last().unwrap();
    assert_eq!(
        last["host"].as_u64(),
        Some(b1_id),
        "late joiner follows the new host"
    );
    let views = [
        (
            "bot1",
            nearest(&read_dump(&b1d), last["wall_ms"].as_u64().unwrap()).clone(),
        ),
        (
            "bot2",
            nearest(&read_dump(&b2d), last["wall_ms"].as_u64().unwrap()).clone(),
        ),
        ("late", last.clone()),
    ];
    let live = [b1_id, b2_id, late_id];
    for (who, v) in &views {
        let objs = objects(v);
        let scene: Vec<_> = objs
            .values()
            .filter(|o| !matches!(o["kind"].as_str(), Some("head" | "hand")))
            .collect();
        assert_eq!(scene.len(), 7, "{who} lost scene objects: {v}");
        for o in objs.values() {
            let owner = o["owner"].as_u64().unwrap();
            assert!(
                live.contains(&owner),
                "{who}: object {} owned by {owner}, not a live peer",
                o["id"]
            );
        }
        let avatars = objs.values().filter(|o| o["kind"] == "head").count();
        assert_eq!(
            avatars, 3,
            "{who}: one head per live peer (the dead host's is removed)"
        );
        assert_ne!(v["host"].as_u64(), Some(host_id));
    }
    // Every peer names the same owner for every object.
    let owners = |v: &Value| -> BTreeMap<u64, u64> {
        objects(v)
            .iter()
            .map(|(id, o)| (*id, o["owner"].as_u64().unwrap()))
            .collect()
    };
    assert_eq!(
        owners(&views[0].1),
        owners(&views[2].1),
        "bot1 and the late joiner disagree on owners"
    );
    assert_eq!(
        owners(&views[1].1),
        owners(&views[2].1),
        "bot2 and the late joiner disagree on owners"
    );
}

/// A peer that joins after 10 s of interaction gets the same room as the host.
#[test]
fn c_late_joiner_after_ten_seconds_gets_the_same_state() {
    require_netns();
    let dir = scratch("late");
    let hd = dir.join("host.jsonl");
    let dumped = |dump: &Path, secs: &'static str| {
        [
            "--duration",
            secs,
            "--dump-hz",
            "10",
            "--dump",
            dump.to_str().unwrap(),
        ]
        .map(String::from)
    };
    let host_args = dumped(&hd, "19");
    let (mut host, url) = embedded_host(&dir, "late", &strs(&host_args));
    let script = "wait 0.5; reach right bunny in 0.7; grab right; squeeze right 0.02 in 0.5; \
                  wait 0.3; release right; offset right 0 0.12 0 in 0.3; reach left softbox in 0.7; \
                  grab left; squeeze left 0.02 in 0.5; release left; offset left 0 0.12 0 in 0.3; \
                  reach right block in 0.7; grab right; offset right 0 0.05 0 in 0.4; release right; \
                  wait 0.5";
    let _b1 = peer_on(
        &dir,
        "bot1",
        "join",
        &url,
        "late",
        &["--duration", "18", "--bot", script],
    );
    std::thread::sleep(Duration::from_secs(10));
    let ld = dir.join("late.jsonl");
    let late_args = dumped(&ld, "6");
    let mut late = peer_on(&dir, "late", "join", &url, "late", &strs(&late_args));
    assert_eq!(
        late.wait_exit(Duration::from_secs(40)),
        0,
        "{}",
        late.logs()
    );
    assert_eq!(
        host.wait_exit(Duration::from_secs(40)),
        0,
        "{}",
        host.logs()
    );
    let l = read_dump(&ld);
    let last = l.last().unwrap();
    let h = read_dump(&hd);
    assert_agree(
        nearest(&h, last["wall_ms"].as_u64().unwrap()),
        last,
        "late join",
    );
}

/// Mistakes a person makes get a sentence and a non-zero exit code, before anything opens.
#[test]
fn e_errors_are_clear_and_exit_non_zero() {
    require_netns();
    let dir = scratch("errors");
    let run = |name: &str, args: &[&str]| -> (i32, String) {
        let mut p = Proc::spawn(&dir, name, args);
        let code = p.wait_exit(Duration::from_secs(30));
        (code, std::fs::read_to_string(&p.err).unwrap_or_default())
    };
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let dead = format!("ws://127.0.0.1:{port}");
    let (code, err) = run("unreachable", &["join", "--room", "x", "--signal", &dead]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("unreachable"), "{err}");

    let (_signal, url) = standalone_signal(&dir);
    let (code, err) = run("noroom", &["join", "--room", "nobody", "--signal", &url]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("room \"nobody\" not found"), "{err}");

    let (code, err) = run(
        "scene",
        &["host", "--room", "x", "--signal", &url, "--scene", "moon"],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unknown scene \"moon\""), "{err}");

    let bot = dir.join("bad.bot");
    std::fs::write(&bot, "wait 1\nfly right 3\n").unwrap();
    let (code, err) = run(
        "bot",
        &[
            "join",
            "--room",
            "x",
            "--signal",
            &url,
            "--bot",
            bot.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("command 2") && err.contains("unknown command \"fly\""),
        "{err}"
    );

    let (code, err) = run(
        "bad-assets",
        &[
            "host",
            "--room",
            "x",
            "--signal",
            &url,
            "--assets",
            "/nonexistent",
        ],
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("unknown scene \"thesis-room\"") && err.contains("/nonexistent"),
        "{err}"
    );

    // Scene files: a broken one names the file and what is wrong; a joiner whose scene
    // differs from the host's (one soft setting) is refused by the room.
    let assets = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let room = std::fs::read_to_string(assets.join("thesis-room.ron")).unwrap();
    let bunny = assets.join("bunny.obj");
    let room = room.replace("\"bunny.obj\"", &format!("{:?}", bunny.to_str().unwrap()));
    let broken = dir.join("broken.ron");
    std::fs::write(
        &broken,
        room.replace("(class: \"plate\"", "(class: \"saucer\""),
    )
    .unwrap();
    let (code, err) = run(
        "broken-scene",
        &[
            "host",
            "--room",
            "x",
            "--signal",
            &url,
            "--scene",
            broken.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("broken.ron") && err.contains("objects[0]") && err.contains("saucer"),
        "{err}"
    );
    let stiffer = dir.join("stiffer.ron");
    assert!(room.contains("stiffness: 20.0"));
    std::fs::write(&stiffer, room.replace("stiffness: 20.0", "stiffness: 30.0")).unwrap();
    let mut host = peer_on(
        &dir,
        "scene-host",
        "host",
        &url,
        "scenes",
        &["--bot", "idle"],
    );
    host.peer_id();
    let (code, err) = run(
        "other-scene",
        &[
            "join",
            "--room",
            "scenes",
            "--signal",
            &url,
            "--scene",
            stiffer.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("configuration differs"), "{err}");
    host.kill();

    // A room with a key: no key, or another, is refused (exit 3); the key gets in.
    let key = dir.join("room.key");
    std::fs::write(&key, "a long random room secret\n").unwrap();
    let wrong = dir.join("wrong.key");
    std::fs::write(&wrong, "not the room's secret at all").unwrap();
    let (k, w) = (key.to_str().unwrap(), wrong.to_str().unwrap());
    let mut host = peer_on(
        &dir,
        "key-host",
        "host",
        &url,
        "keyed",
        &["--room-key-file", k],
    );
    host.peer_id();
    let join_in = |room: &str, url: &str, name: &str, extra: &[&str]| {
        let mut a = vec!["join", "--room", room, "--signal", url, "--duration", "2"];
        a.extend_from_slice(extra);
        run(name, &a)
    };
    let join = |name: &str, extra: &[&str]| join_in("keyed", &url, name, extra);
    let (code, err) = join("no-key", &[]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("needs a key"), "{err}");
    let (code, err) = join("wrong-key", &["--room-key-file", w]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("wrong room key"), "{err}");
    let (code, err) = join("key", &["--room-key-file", k]);
    assert_eq!(code, 0, "the keyholder was not let in: {err}");
    // several signaling servers: the unreachable one is passed over
    let list = format!("{dead},{url}");
    let (code, err) = join_in("keyed", &list, "list", &["--room-key-file", k]);
    assert_eq!(code, 0, "{err}");
    // Join tokens (`softsync token`): one gets a keyless peer in (the scene fetched with it);
    // the same token again, from another peer, is refused; so is another room's token.
    let token = |room: &str| {
        let out = std::process::Command::new(common::binary())
            .args([
                "token",
                "--room",
                room,
                "--room-key-file",
                k,
                "--valid",
                "600",
            ])
            .output()
            .unwrap();
        assert!(out.status.success());
        String::from_utf8(out.stdout).unwrap().trim().to_owned()
    };
    let (t, other) = (token("keyed"), token("elsewhere"));
    let (code, err) = join("token", &["--room-token", &t]);
    assert_eq!(code, 0, "the token was not let in: {err}");
    let (code, err) = join("token-again", &["--room-token", &t]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("used by another peer"), "{err}");
    let (code, err) = join("token-other-room", &["--room-token", &other]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("not this room's"), "{err}");
    host.kill();
    // A keyed host's embedded signaling server refuses peers without the key or a token
    // before they see anyone (HTTP 403); the token gets through it and into the room.
    let (mut host, url) = embedded_host(&dir, "keyed-embedded", &["--room-key-file", k]);
    host.peer_id();
    let join_at = |name: &str, extra: &[&str]| join_in("keyed-embedded", &url, name, extra);
    let (code, err) = join_at("signal-no-key", &[]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("HTTP 403"), "{err}");
    let t = token("keyed-embedded");
    let (code, err) = join_at("signal-token", &["--room-token", &t]);
    assert_eq!(code, 0, "{err}");
    host.kill();

    let (code, err) = run(
        "flag",
        &["host", "--room", "x", "--net-condition", "loss=150%"],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("0-100%"), "{err}");
}

/// A host that leaves on purpose (end of `--duration`, Ctrl-C) says so: the earliest joiner
/// takes over at once instead of after the 1 s heartbeat timeout.
#[test]
fn f_a_host_that_leaves_is_replaced_at_once() {
    require_netns();
    let dir = scratch("leave");
    let (_signal, url) = standalone_signal(&dir);
    let mut host = peer_on(&dir, "host", "host", &url, "bye", &["--duration", "6"]);
    host.peer_id();
    let bot_args = ["--duration", "12", "--bot", "wave"];
    let bot = peer_on(&dir, "bot", "join", &url, "bye", &bot_args);
    let bot_id = bot.peer_id();
    bot.wait_line("joined", Duration::from_secs(20));
    assert_eq!(
        host.wait_exit(Duration::from_secs(20)),
        0,
        "{}",
        host.logs()
    );
    let left = Instant::now();
    let line = bot.wait_line(
        &format!("host-changed host={bot_id}"),
        Duration::from_secs(5),
    );
    let took = left.elapsed();
    println!("host left; the bot took over {took:?} after the host process ended: {line}");
    assert!(
        took < Duration::from_millis(600),
        "took {took:?}: the Leave was not acted on (the timeout is 1 s)"
    );
}

/// Joiners that start together may first reach each other (neither knows the host yet): they
/// move on to the next peer and all get in.
#[test]
fn g_simultaneous_joiners_all_get_in() {
    require_netns();
    let dir = scratch("crowd");
    let (host, url) = embedded_host(&dir, "crowd", &["--duration", "25"]);
    let bots: Vec<Proc> = (0..4)
        .map(|i| {
            let extra = ["--duration", "20", "--bot", "wave"];
            peer_on(&dir, &format!("bot{i}"), "join", &url, "crowd", &extra)
        })
        .collect();
    for b in &bots {
        b.wait_line("joined", Duration::from_secs(15));
    }
    // The host relays for everyone: it lists all five members.
    let members = bots.len() + 1;
    let start = Instant::now();
    loop {
        let joined = host.stdout().matches("peer-joined").count();
        if joined == bots.len() {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "the host saw {joined} of {} joins ({members} members expected)\n{}",
            bots.len(),
            host.logs()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// SIGTERM (also for a background job, whose SIGINT a shell ignores) ends a peer cleanly:
/// last stats line, exit 130, and the host drops it at once rather than after the timeout.
#[test]
fn h_sigterm_is_a_clean_leave() {
    require_netns();
    let dir = scratch("term");
    let (host, url) = embedded_host(&dir, "term", &["--duration", "20"]);
    let mut bot = peer_on(&dir, "bot", "join", &url, "term", &["--bot", "wave"]);
    let bot_id = bot.peer_id();
    host.wait_line(&format!("peer-joined {bot_id}"), Duration::from_secs(15));
    std::thread::sleep(Duration::from_millis(500));
    send_signal("-TERM", &bot);
    let sent = Instant::now();
    assert_eq!(
        bot.wait_exit(Duration::from_secs(10)),
        130,
        "{}",
        bot.logs()
    );
    assert!(bot.stdout().contains("final stats"), "{}", bot.logs());
    host.wait_line(&format!("peer-left {bot_id}"), Duration::from_secs(5));
    let took = sent.elapsed();
    assert!(
        took < Duration::from_millis(700),
        "the host took {took:?} (timeout 1 s)"
    );
}

/// `softsync host|join --room ROOM --signal URL --quiet EXTRA…`, named "host" or "bot".
fn peer(dir: &Path, command: &str, url: &str, room: &str, extra: &[&str]) -> Proc {
    let name = if command == "host" { "host" } else { "bot" };
    peer_on(dir, name, command, url, room, extra)
}

/// A host whose process stalls (SIGSTOP) past the peer timeout is replaced; when it runs
/// again (SIGCONT) it still believes it is host and owns everything. The new host tells it
/// the room moved on; it drops its stale replica and joins the room it used to host as a
/// member, and ends up showing the same room as the new host.
#[test]
fn i_a_stalled_host_is_told_the_room_moved_on_and_joins_again() {
    require_netns();
    let dir = scratch("stall");
    let (_signal, url) = standalone_signal(&dir);
    let (hd, bd) = (dir.join("host.jsonl"), dir.join("bot.jsonl"));
    let dumped = |command: &str, dump: &Path| {
        let dump = dump.to_str().unwrap();
        let args = ["--duration", "40", "--dump-hz", "5", "--dump", dump];
        peer(&dir, command, &url, "stall", &args)
    };
    let host = dumped("host", &hd);
    let host_id = host.peer_id();
    let bot = dumped("join", &bd);
    let bot_id = bot.peer_id();
    bot.wait_line("joined", Duration::from_secs(20));
    host.wait_line(&format!("peer-joined {bot_id}"), Duration::from_secs(15));
    std::thread::sleep(Duration::from_millis(500));
    send_signal("-STOP", &host);
    let line = bot.wait_line(
        &format!("host-changed host={bot_id}"),
        Duration::from_secs(10),
    );
    println!("host {host_id} stopped; the bot took over: {line}");
    std::thread::sleep(Duration::from_millis(1000));
    send_signal("-CONT", &host);
    let resumed = Instant::now();
    let told = host.wait_line(&format!("rejoining host={bot_id}"), Duration::from_secs(10));
    let took = resumed.elapsed();
    assert!(told.contains("the room moved on"), "{told}");
    println!("the old host was told {took:?} after it resumed: {told}");
    let back = host.wait_line(&format!("joined host={bot_id}"), Duration::from_secs(10));
    println!(
        "and is back {:?} after it resumed: {back}",
        resumed.elapsed()
    );
    bot.wait_line(&format!("peer-joined {host_id}"), Duration::from_secs(5));
    // Once everything rests (the new host restarted the simulation from its replica: a ball
    // may still roll), both show the same room, every object the new host's.
    let rest = wait_for_rest(&bd, Duration::from_secs(20));
    println!("at rest {rest:?} after the old host resumed");
    std::thread::sleep(Duration::from_millis(600));
    let (h, b) = (read_dump(&hd), read_dump(&bd));
    let last = h.last().unwrap();
    assert_eq!(last["host"].as_u64(), Some(bot_id), "{last}");
    assert_eq!(last["members"].as_array().map(Vec::len), Some(2), "{last}");
    let other = nearest(&b, last["wall_ms"].as_u64().unwrap());
    assert_agree(last, other, "after the old host joined again");
    for (id, o) in objects(last) {
        let owner = o["owner"].as_u64().unwrap();
        let avatar = o["kind"]
            .as_str()
            .is_some_and(|k| k == "head" || k == "hand");
        assert!(
            owner == bot_id || (avatar && owner == host_id),
            "object {id} ({}) owned by {owner}",
            o["kind"]
        );
    }
    assert!(
        !bot.stdout()
            .contains(&format!("host-changed host={host_id}")),
        "{}",
        bot.logs()
    );
}

/// A member that stalls past the timeout with `--rejoin-limit 0` stops with a clear message
/// (exit code 3) when the host tells it it was dropped.
#[test]
fn j_a_stalled_member_with_no_rejoins_left_stops_clearly() {
    require_netns();
    let dir = scratch("stall-member");
    let (_signal, url) = standalone_signal(&dir);
    let host = peer(&dir, "host", &url, "drop", &["--duration", "30"]);
    host.peer_id();
    let mut bot = peer(
        &dir,
        "join",
        &url,
        "drop",
        &["--duration", "30", "--rejoin-limit", "0"],
    );
    let bot_id = bot.peer_id();
    bot.wait_line("joined", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(500));
    send_signal("-STOP", &bot);
    host.wait_line(&format!("peer-left {bot_id}"), Duration::from_secs(10));
    send_signal("-CONT", &bot);
    assert_eq!(bot.wait_exit(Duration::from_secs(10)), 3, "{}", bot.logs());
    let logs = bot.logs();
    assert!(
        logs.contains("the room went on without us: dropped from the room"),
        "{logs}"
    );
}

/// A room sized with `--max-members 2` (every peer gives the same): the second peer gets in,
/// the third is refused with the reason and exits non-zero; a peer that gives another size is
/// refused at the handshake (the size is part of the room's digest, so a new host keeps it).
#[test]
fn k_a_full_room_refuses_a_joiner_with_the_reason() {
    require_netns();
    let dir = scratch("full");
    let (_signal, url) = standalone_signal(&dir);
    let two = ["--max-members", "2", "--duration", "20"];
    let host = peer_on(&dir, "host", "host", &url, "small", &two);
    host.wait_line("hosting", Duration::from_secs(20));
    let first = peer_on(&dir, "first", "join", &url, "small", &two);
    first.wait_line("joined", Duration::from_secs(20));
    for (name, args) in [
        ("third", &two[..]),
        ("other", &["--max-members", "3", "--duration", "20"][..]),
    ] {
        let mut p = peer_on(&dir, name, "join", &url, "small", args);
        let code = p.wait_exit(Duration::from_secs(30));
        let logs = p.logs();
        assert_ne!(code, 0, "{logs}");
        let reason = if name == "third" {
            "the room is full (2 members)"
        } else {
            "room configuration differs"
        };
        assert!(logs.contains(reason), "{name}: {logs}");
    }
}

/// Signaling over TLS: `softsync signal --tls-cert --tls-key` serves `wss://`; a host and a
/// bot that trust its CA (`--tls-ca`) meet there and the bot gets the scene and joins; a
/// joiner that does not trust it stops with the certificate error.
#[test]
fn l_signaling_over_tls_lets_in_peers_that_trust_the_certificate() {
    require_netns();
    let dir = scratch("tls");
    let data = |f: &str| {
        common::repo_file(&format!("net/matchbox/tests/data/{f}"))
            .display()
            .to_string()
    };
    let (cert, key, ca) = (data("server.pem"), data("server.key"), data("ca.pem"));
    let signal = Proc::spawn(
        &dir,
        "signal",
        &[
            "signal",
            "--bind",
            "127.0.0.1:0",
            "--tls-cert",
            &cert,
            "--tls-key",
            &key,
        ],
    );
    let url = signal_url(&signal);
    assert!(url.starts_with("wss://"), "{url}");
    let host = peer_on(
        &dir,
        "host",
        "host",
        &url,
        "tls",
        &["--tls-ca", &ca, "--duration", "30"],
    );
    host.wait_line("hosting", Duration::from_secs(30));
    let bot = peer_on(
        &dir,
        "bot",
        "join",
        &url,
        "tls",
        &["--tls-ca", &ca, "--duration", "30"],
    );
    bot.wait_line("joined", Duration::from_secs(40));
    let mut stranger = peer_on(&dir, "stranger", "join", &url, "tls", &["--duration", "10"]);
    let code = stranger.wait_exit(Duration::from_secs(30));
    let logs = stranger.logs();
    assert_ne!(code, 0, "{logs}");
    assert!(logs.to_lowercase().contains("certificate"), "{logs}");
}
