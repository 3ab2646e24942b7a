//! Several hands from several processes on one soft body, on real WebRTC (issue 31): a host,
//! and three bots that hold the thesis room's bunny at once and pull it apart. The first bot
//! to grab gets authority (nobody held it); the other two hold it as remote hands (no grab is
//! refused). A fourth bot, which owns and holds nothing, tears the bunny between their hands
//! (its strokes go to the owner as requests). The owner is SIGKILLed mid-pull: the host takes
//! the bunny back and applies the two remaining hands, which never let go. After they let go
//! and the bunny rests, the survivors and a late joiner agree on the owner, the holders
//! (none), the torn topology and the shape.
//!
//! Opens WebRTC: runs inside a network namespace (`scripts/netns-run`), as `live_rooms` does.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::path::Path;
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;
use common::dump::{assert_agree, nearest, objects, read_dump, wait_for_rest};
use common::{peer_on, require_netns, scratch, standalone_signal, Proc};

/// The first `holders object=ID hands=…` line of `p` naming `n` hands, after its first
/// `skip` lines.
fn holders_line(p: &Proc, n: usize, skip: usize, within: Duration) -> String {
    let start = Instant::now();
    loop {
        let out = p.stdout();
        let found = out.lines().skip(skip).find(|l| {
            l.contains("holders object=")
                && l.split("hands=")
                    .nth(1)
                    .is_some_and(|h| h != "-" && h.split(',').count() == n)
        });
        if let Some(l) = found {
            return l.to_owned();
        }
        assert!(
            start.elapsed() < within,
            "{} never said {n} hands hold something\n{}",
            p.name,
            p.logs()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn dumped(dump: &Path, secs: &str) -> Vec<String> {
    ["--duration", secs, "--dump-hz", "5", "--dump"]
        .iter()
        .map(|s| s.to_string())
        .chain([dump.to_str().unwrap().to_owned()])
        .collect()
}

fn with(mut a: Vec<String>, more: &[&str]) -> Vec<String> {
    a.extend(more.iter().map(|m| m.to_string()));
    a
}

fn strs(a: &[String]) -> Vec<&str> {
    a.iter().map(String::as_str).collect()
}

#[test]
fn three_bots_hold_the_bunny_at_once_and_survive_its_owners_death() {
    require_netns();
    let dir = scratch("comanip");
    let (_signal, url) = standalone_signal(&dir);
    let hd = dir.join("host.jsonl");
    let host = peer_on(&dir, "host", "host", &url, "co", &strs(&dumped(&hd, "120")));
    let host_id = host.peer_id();
    // bot1 takes the bunny's left side first: nobody holds it, so authority comes to it
    let one = "wait 0.5; reach right bunny at -0.09 0 0 in 0.8; grab right; \
               pull right -0.03 0 0 in 1.5; wait 30";
    let b1d = dir.join("b1.jsonl");
    let mut b1 = peer_on(
        &dir,
        "bot1",
        "join",
        &url,
        "co",
        &strs(&with(dumped(&b1d, "120"), &["--bot", one])),
    );
    let b1_id = b1.peer_id();
    b1.wait_line("grabbed object", Duration::from_secs(40));
    let bunny: u64 = holders_line(&b1, 1, 0, Duration::from_secs(10))
        .split("object=")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    // two more take the right side and the top: remote hands on bot1's bunny, held 25 s (the
    // other's join, the tearer's join and stroke, then the owner's death, come in that time
    // even on a loaded machine: a 4 s hold let go before the kill there, and under two CPU
    // hogs one bot joined 25 s after the other)
    let two = "wait 0.3; reach right bunny at 0.09 0 0 in 0.8; grab right; \
               pull right 0.03 0 0 in 1.5; wait 25; release right; offset right 0 0.15 0 in 0.5; \
               wait 30";
    let three = "wait 0.3; reach left bunny at 0 0.09 0 in 0.8; grab left; \
                 pull left 0 0.03 0 in 1.5; wait 25; release left; offset left 0 0.15 0 in 0.5; \
                 wait 30";
    let b2d = dir.join("b2.jsonl");
    let b3d = dir.join("b3.jsonl");
    let b2 = peer_on(
        &dir,
        "bot2",
        "join",
        &url,
        "co",
        &strs(&with(dumped(&b2d, "60"), &["--bot", two])),
    );
    let b3 = peer_on(
        &dir,
        "bot3",
        "join",
        &url,
        "co",
        &strs(&with(dumped(&b3d, "60"), &["--bot", three])),
    );
    b2.wait_line("grabbed object", Duration::from_secs(40));
    b3.wait_line("grabbed object", Duration::from_secs(40));
    // everyone hears the owner say three hands hold it
    for p in [&host, &b2, &b3] {
        let l = holders_line(p, 3, 0, Duration::from_secs(10));
        assert!(l.contains(&format!("object={bunny}")), "{l}");
    }
    // a fourth bot, owning and holding nothing, tears across the bunny's back between them
    let cut = "wait 0.5; tear right bunny 0 0.03 -0.05 0 0.03 -0.025 0 0.03 0 0 0.03 0.025                0 0.03 0.05 in 0.12; wait 30";
    let cd = dir.join("cutter.jsonl");
    let cutter = peer_on(
        &dir,
        "cutter",
        "join",
        &url,
        "co",
        &strs(&with(dumped(&cd, "60"), &["--bot", cut])),
    );
    cutter.wait_line("tore object", Duration::from_secs(40));
    // the owner applied it (the next log entries reach everyone), then, mid-pull, dies
    std::thread::sleep(Duration::from_millis(500));
    let said = host.stdout().lines().count();
    b1.kill();
    let killed = Instant::now();
    // the host takes the bunny back and applies the two hands left
    let l = holders_line(&host, 2, said, Duration::from_secs(10));
    println!("owner killed; after {:?}: {l}", killed.elapsed());
    assert!(!l.contains(&b1_id.to_string()), "{l}");
    for p in [&b2, &b3] {
        p.wait_line("release object", Duration::from_secs(45));
    }
    wait_for_rest(&hd, Duration::from_secs(20));
    // a late joiner
    let ld = dir.join("late.jsonl");
    let mut late = peer_on(&dir, "late", "join", &url, "co", &strs(&dumped(&ld, "5")));
    assert_eq!(
        late.wait_exit(Duration::from_secs(40)),
        0,
        "{}",
        late.logs()
    );

    assert!(
        !cutter.stdout().contains("tear object"),
        "the cutter's tear was refused\n{}",
        cutter.logs()
    );
    for (p, what) in [(&b2, "bot2"), (&b3, "bot3")] {
        let out = p.stdout();
        assert!(
            !out.contains("authority-denied"),
            "{what} was refused\n{out}"
        );
        assert!(!out.contains("grab: nothing taken"), "{what}\n{out}");
        // its hand held on through the owner's death: one grab, ended by its own release
        assert_eq!(out.matches("grab-ended").count(), 1, "{what}\n{out}");
        assert!(
            !out.contains("authority-gained"),
            "{what} took authority\n{out}"
        );
    }
    let l = read_dump(&ld);
    let last = l.last().unwrap();
    let at = last["wall_ms"].as_u64().unwrap();
    let views: Vec<(&str, Value)> = vec![
        ("host", nearest(&read_dump(&hd), at).clone()),
        ("bot2", nearest(&read_dump(&b2d), at).clone()),
        ("bot3", nearest(&read_dump(&b3d), at).clone()),
        ("cutter", nearest(&read_dump(&cd), at).clone()),
    ];
    // torn: five segments and a lift, on every peer
    let log = objects(last)[&bunny]["log"].as_u64().unwrap();
    assert!(
        log >= 5,
        "the late joiner's bunny has {log} topology entries"
    );
    for (who, v) in &views {
        assert_agree(v, last, &format!("{who} and the late joiner"));
        let o = objects(v)[&bunny];
        assert_eq!(o["owner"].as_u64(), Some(host_id), "{who}: {o}");
        assert!(o.get("holders").is_none(), "{who}: still held {o}");
        assert_eq!(o["topology"], objects(last)[&bunny]["topology"], "{who}");
    }
}
