//! Two homes behind NAT routers reach each other only through a TURN relay (issue 17 point
//! 1): `scripts/nat-turn peers` builds a public network with coturn and the signaling server
//! and two homes behind symmetric NATs that drop everything unsolicited; the host in one home
//! and a bot in the other join with `--ice turn:…` and credentials. The bot grabs the soft
//! box, squeezes it and lets go; after rest both dumps show the same room within 1 mm, and
//! the bot's ICE pair to the host is a relay one (coturn bound channels for both). Needs
//! coturn and nftables (.ci/run installs them) and root in the test's own namespace.
#![allow(clippy::unwrap_used, missing_docs)]

use std::path::PathBuf;

mod common;
use common::dump::{assert_agree, nearest, read_dump};

#[test]
fn two_natted_homes_meet_through_the_turn_relay_grab_and_agree() {
    common::require_netns();
    let (ok, text) = common::run_script("nat-turn", &["peers"], &[]);
    assert!(ok, "{text}");
    let result = text
        .lines()
        .find(|l| l.starts_with("RESULT wild.turn"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(result.contains("joined=yes"), "{text}");
    assert!(
        text.contains("grab-started"),
        "the bot never grabbed: {text}"
    );
    let logs = PathBuf::from(
        text.split("logs in ")
            .nth(1)
            .and_then(|t| t.split_whitespace().next())
            .unwrap(),
    );
    let (h, b) = (
        read_dump(&logs.join("host.jsonl")),
        read_dump(&logs.join("bot.jsonl")),
    );
    let last = b.last().expect("the bot's dump is empty");
    let host_line = nearest(&h, last["wall_ms"].as_u64().unwrap());
    // relayed: the bot reaches the host (and nothing else) through TURN
    let host_id = host_line["peer"].as_u64().unwrap();
    let relayed = common::field(result, "relayed_to");
    assert_eq!(relayed, host_id.to_string(), "{result}");
    let binds: u32 = common::field(result, "turn_channel_binds").parse().unwrap();
    assert!(binds >= 2, "{result}");
    assert_agree(host_line, last, "two homes through TURN");
    let _ = std::fs::remove_dir_all(&logs);
}
