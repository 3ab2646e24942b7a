//! A live partition heals (issue 17 point 2): `scripts/partition-live` runs a host and a bot as
//! real processes in namespaces of their own, joined by veth links through a bridge with the
//! signaling server, cuts every packet of the bot's link for 3 s (the bot's session hosts a
//! room of one meanwhile) and restores it; the bot must end in the host's room. Needs nftables
//! (.ci/run installs it) and root inside the test's own namespace (scripts/netns-run).
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

#[test]
fn a_live_partition_of_3_s_heals_into_one_room() {
    common::require_netns();
    let (ok, text) = common::run_script("partition-live", &["3"], &[("PARTITION", "all")]);
    assert!(ok, "{text}");
    let bot = text.lines().find(|l| l.starts_with("bot:")).unwrap();
    assert!(bot.ends_with("peers=2"), "{text}");
}
