//! A hostile member in a live room (issue 32): a modified client (`softsync-hostile`, never
//! part of the `softsync` binary) floods the host over real WebRTC while two honest bots
//! squeeze the soft box; the host throttles it, then drops it and tells it why, and the
//! honest peers go on agreeing. Runs inside `scripts/netns-run` like every WebRTC test.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::time::Duration;

mod common;
use common::dump::{assert_agree, nearest, read_dump};
use common::{embedded_host, require_netns, scratch, Proc};

const SQUEEZE: &str = "wait 1; reach right softbox in 1; grab right; squeeze right 0.02 in 0.6; \
                       wait 0.6; release right; offset right 0 0.15 0 in 0.5";

fn hostile(dir: &std::path::Path, url: &str, room: &str, attack: &str, secs: &str) -> Proc {
    Proc::spawn_program(
        dir,
        &format!("hostile-{attack}"),
        std::path::Path::new(env!("CARGO_BIN_EXE_softsync-hostile")),
        &[
            "--signal",
            url,
            "--room",
            room,
            "--attack",
            attack,
            "--seconds",
            secs,
        ],
        &[],
    )
}

#[test]
fn a_member_flooding_the_host_is_dropped_with_a_reason_while_two_bots_squeeze_and_agree() {
    require_netns();
    let dir = scratch("abuse-live");
    let hd = dir.join("host.jsonl");
    let (mut host, url) = embedded_host(
        &dir,
        "abuse",
        &[
            "--duration",
            "70",
            "--dump",
            hd.to_str().unwrap(),
            "--dump-hz",
            "10",
        ],
    );
    host.peer_id();
    // the hostile member first: it floods while the bots join and squeeze
    let mut bad = hostile(&dir, &url, "abuse", "request-flood", "40");
    bad.wait_line("joined", Duration::from_secs(40));
    let mut bots = Vec::new();
    for k in 0..2 {
        let d = dir.join(format!("bot{k}.jsonl"));
        // each squeezes the box in turn (the second asks for it while the first holds it),
        // twice, then rests
        let script = format!("wait {}; {SQUEEZE}; {SQUEEZE}; wait 4", 3 * k);
        let p = Proc::spawn(
            &dir,
            &format!("bot{k}"),
            &[
                "join",
                "--room",
                "abuse",
                "--signal",
                &url,
                "--bot",
                &script,
                "--duration",
                "30",
                "--dump",
                d.to_str().unwrap(),
                "--dump-hz",
                "10",
                "--quiet",
            ],
        );
        bots.push((p, d));
    }
    // throttled, then out with the reason (five seconds over twice the rate)
    let told = bad.wait_line("told: ", Duration::from_secs(30));
    assert!(
        told.contains("twice the 60 requests a second"),
        "{told}\n{}",
        bad.logs()
    );
    for (b, _) in &mut bots {
        assert_eq!(b.wait_exit(Duration::from_secs(90)), 0, "{}", b.logs());
        assert!(
            b.stdout().contains("grabbed object"),
            "a bot never held the box\n{}",
            b.logs()
        );
    }
    // the honest peers show the same room as the host at their last moment (at rest), and
    // the hostile member is not in it
    let h = read_dump(&hd);
    let bad_id = bad
        .wait_line("hostile id ", Duration::from_secs(1))
        .trim_start_matches("hostile id ")
        .trim()
        .parse::<u64>()
        .unwrap();
    // one moment both bots are in (2 s before the first of them left; at rest) — the bots
    // leave at different times, and an avatar despawns first where its owner left
    let dumps: Vec<_> = bots.iter().map(|(_, d)| read_dump(d)).collect();
    let at = dumps
        .iter()
        .map(|j| {
            j.last().expect("bot dump empty")["wall_ms"]
                .as_u64()
                .unwrap()
        })
        .min()
        .unwrap()
        - 2000;
    for (k, j) in dumps.iter().enumerate() {
        let line = nearest(j, at);
        let at_host = nearest(&h, line["wall_ms"].as_u64().unwrap());
        assert_agree(at_host, line, &format!("bot {k}"));
        let members: Vec<u64> = at_host["members"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|m| m.as_u64())
            .collect();
        assert!(
            !members.contains(&bad_id),
            "the hostile member is still in: {members:?}"
        );
    }
    host.kill();
    bad.kill();
}
