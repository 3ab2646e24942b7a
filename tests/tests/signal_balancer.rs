//! Signaling scaled out (issue 18 point 4): `scripts/bench-signal-lb`, short — three
//! `softsync signal` instances behind HAProxy with the repository's configuration
//! (deploy/haproxy/signal.cfg), 60 rooms of light signaling clients and one of real peers
//! opened through the balancer (every joiner must reach the instance that holds its room: its
//! host hears it arrive and gets its signal), then one instance SIGKILLed: every room must take
//! a new joiner, the dead instance's rooms after their hosts registered again elsewhere; then
//! the instance is started again and every room takes one more joiner (the balancer keeps a
//! room where its host is now). Needs
//! haproxy (.ci/run installs it); runs in a namespace of its own.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

#[test]
fn rooms_behind_a_balancer_stay_joinable_when_an_instance_dies() {
    common::require_netns();
    let out = common::scratch("signal-lb");
    let (ok, text) = common::run_script(
        "bench-signal-lb",
        &[
            "--rooms",
            "60",
            "--real-rooms",
            "1",
            "--out",
            out.to_str().unwrap(),
        ],
        &[],
    );
    assert!(ok, "{text}");
    let line = |name: &str| {
        text.lines()
            .find(|l| l.starts_with(&format!("RESULT {name} ")))
            .unwrap_or_else(|| panic!("no {name} line:\n{text}"))
    };
    let rooms = line("lb.rooms");
    println!("{rooms}\n{}\n{}", line("lb.kill"), line("lb.real"));
    assert_eq!(common::field(rooms, "opened"), "60", "{text}");
    // affinity, yet balanced: every instance holds some of the rooms
    let per: Vec<u32> = common::field(rooms, "per_instance")
        .split('/')
        .map(|n| n.parse().unwrap())
        .collect();
    assert_eq!(per.iter().sum::<u32>(), 60, "{text}");
    assert!(per.iter().all(|n| *n > 0), "{text}");
    let kill = line("lb.kill");
    assert_eq!(common::field(kill, "joinable_after"), "60", "{text}");
    assert_eq!(
        common::field(kill, "moved"),
        common::field(kill, "rooms_on_killed"),
        "{text}"
    );
    // the dead instance back: rooms stay where their hosts are now
    assert_eq!(
        common::field(line("lb.restart"), "joinable_after"),
        "60",
        "{text}"
    );
    assert_eq!(
        common::field(line("lb.real"), "joined_after_kill"),
        "1",
        "{text}"
    );
    assert_eq!(common::field(line("lb.summary"), "ok"), "true", "{text}");
}
