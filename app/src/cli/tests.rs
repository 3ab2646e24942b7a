//! The command line's parsing and checks.
#![allow(clippy::unwrap_used)]

use super::*;

fn args(s: &str) -> Vec<String> {
    s.split_whitespace().map(String::from).collect()
}

#[test]
fn help_is_generated_for_every_command() {
    for a in ["", "help", "--help", "help host", "join --help"] {
        let Command::Help(text) = parse(&args(a)).unwrap() else {
            panic!("{a:?} is not help");
        };
        assert!(text.contains("Usage"), "{a:?}: {text}");
    }
    let Command::Help(text) = parse(&args("help join")).unwrap() else {
        panic!()
    };
    assert!(
        text.contains("--net-condition") && text.contains("--signal"),
        "{text}"
    );
}

#[test]
fn front_end_flags_parse() {
    let Command::Peer(p) = parse(&args(
        "join --room lab --signal ws://127.0.0.1:9 --desktop --window 320x240 --focus softbox \
         --particles --hide-avatars --no-hud --screenshot-dir /tmp/x --screenshot-every 0.5 \
         --screenshots 9",
    ))
    .unwrap() else {
        panic!()
    };
    assert_eq!(p.front, FrontEnd::Desktop);
    assert_eq!(p.view.window, (320, 240));
    assert_eq!(p.view.focus.as_deref(), Some("softbox"));
    assert!(p.view.particles && p.view.hide_avatars && p.view.no_hud);
    assert_eq!(p.view.screenshot_every, Duration::from_millis(500));
    assert_eq!(p.view.screenshots, 9);
    let Command::Peer(p) = parse(&args("host --room lab --vr")).unwrap() else {
        panic!()
    };
    assert_eq!(p.front, FrontEnd::Vr);
    assert_eq!(p.view.window, (1280, 800));
    let Command::Peer(p) = parse(&args("host --room lab")).unwrap() else {
        panic!()
    };
    assert_eq!(p.front, FrontEnd::Headless);
}

#[test]
fn flags_parse_and_bad_ones_are_named() {
    let Command::Peer(p) = parse(&args(
        "join --room lab --signal ws://127.0.0.1:9 --duration 3 --net-condition lat=40ms,jitter=8ms,loss=2%,seed=7",
    ))
    .unwrap() else {
        panic!()
    };
    assert!(!p.host);
    assert_eq!(p.duration, Some(Duration::from_secs(3)));
    let c = p.condition.unwrap();
    assert_eq!(c.latency, Duration::from_millis(40));
    assert_eq!(c.jitter, Duration::from_millis(8));
    assert!((c.loss - 0.02).abs() < 1e-12);
    assert_eq!(c.seed, 7);
    for (bad, says) in [
        ("join --room lab", "--signal"),
        ("join --signal ws://x:1", "--room"),
        ("host --room a/b", "room name"),
        ("host --room a --frob 1", "--frob"),
        ("join --room a --signal http://x", "ws://"),
        ("host --room a --net-condition loss=200%", "0-100%"),
        ("host --room a --net-condition lag=3", "unknown key"),
        ("host --room a --duration soon", "seconds"),
        ("host --room a --bind nowhere", "address"),
        ("host --room a --dump", "value is required"),
        ("fly", "unrecognized subcommand"),
        ("host --room a --desktop --vr", "cannot be used with"),
        ("host --room a --window 10x10", "--window"),
        ("host --room a --desktop --window 800", "--window"),
        ("host --room a --particles", "needs --desktop or --vr"),
        ("host --room a --vr --screenshots 0", "--screenshots"),
        (
            "host --room a --signal ws://x:1 --bind 127.0.0.1:1",
            "cannot be used with",
        ),
        // the benchmarks are softsync-bench's, not the product's
        ("bench soak", "unrecognized subcommand"),
    ] {
        let e = parse(&args(bad)).unwrap_err().to_string();
        assert!(e.contains(says), "{bad}: {e}");
    }
}

#[test]
fn sync_is_state_unless_rollback_is_asked_and_a_wrong_mode_is_refused() {
    let Command::Peer(p) = parse(&args("host --room r")).unwrap() else {
        panic!()
    };
    assert!(!p.rollback);
    let Command::Peer(p) = parse(&args(
        "join --room r --signal ws://127.0.0.1:1 --sync rollback",
    ))
    .unwrap() else {
        panic!()
    };
    assert!(p.rollback);
    assert!(parse(&args("host --room r --sync lockstep")).is_err());
}
