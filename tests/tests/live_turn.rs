//! A peer behind a home NAT reaches the room only through a TURN relay (issue 17 point 1, the
//! half that works): `scripts/nat-turn public` builds a public network with coturn and the
//! signaling server, and a home behind a NAT router whose only way out is coturn's port; the
//! host sits in the public network, the bot at home joins with `--ice turn:…` and its
//! credentials, grabs and squeezes the soft box. It can only have connected through the relay.
//! (Both peers behind NAT, relay to relay, does not work yet: see scripts/nat-turn.) Needs
//! coturn and nftables (.ci/run installs them) and root in the test's own namespace.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

#[test]
fn a_peer_behind_nat_joins_through_the_turn_relay_and_grabs() {
    common::require_netns();
    let (ok, text) = common::run_script("nat-turn", &["public"], &[]);
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
}
