//! VR smoke test: a VR peer (`softsync join --vr`) under Monado's simulated headset and two
//! simulated controllers (no GPU, no display, no hardware) joins a host over WebRTC. The test
//! checks the OpenXR session runs, the headset and controller poses reach the host as the VR
//! peer's avatar (head and both hands where OpenXR put them), and a scripted squeeze on the
//! right controller grabs the soft box (authority moves to the VR peer).
//!
//! Monado lives in a Debian trixie chroot made by `scripts/vr-sim setup` (scripts/test runs it;
//! ~1.5 min the first time); `scripts/vr-sim run` starts Monado beside the peer. Needs the
//! binary built with `--features vr` and a network namespace (scripts/netns-run).
//!
//! Monado's simulated controllers have no scriptable buttons, so the squeeze comes from a bot
//! script running on the VR peer: its grip adds to the controller's squeeze action, and its
//! motion is added to the tracked poses (the hand reaches from the controller to the box).
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::Value;

mod common;
use common::{binary, field, require_netns, scratch, signal_url, Proc};

fn vr_root() -> PathBuf {
    std::env::var_os("SOFTSYNC_VR_ROOT")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/var/tmp/softsync-vr-trixie"))
}

fn xyz(s: &str) -> [f64; 3] {
    let v: Vec<f64> = s.split(',').map(|x| x.parse().unwrap()).collect();
    [v[0], v[1], v[2]]
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn pos(o: &Value) -> [f64; 3] {
    let a = o["pos"].as_array().unwrap();
    [0, 1, 2].map(|i| a[i].as_f64().unwrap())
}

fn dump(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

#[test]
fn vr_peer_under_a_simulated_headset_shows_its_avatar_and_grabs_with_a_squeeze() {
    require_netns();
    let root = vr_root();
    assert!(
        root.join(".softsync-vr-sim-ready").exists(),
        "no simulated-headset chroot at {}: run `scripts/vr-sim setup` (scripts/test does)",
        root.display()
    );
    let dir = scratch("vr-smoke");
    let host_dump = dir.join("host.jsonl");
    let host = Proc::spawn(
        &dir,
        "host",
        &[
            "host",
            "--room",
            "vr",
            "--bind",
            "127.0.0.1:0",
            "--duration",
            "150",
            "--dump",
            host_dump.to_str().unwrap(),
            "--dump-hz",
            "5",
            "--quiet",
        ],
    );
    let url = signal_url(&host);
    let vr_sim = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/vr-sim");
    let bin = binary();
    let root_s = root.to_str().unwrap().to_owned();
    let vr_dump = dir.join("vr.jsonl");
    let vr_dump_s = vr_dump.to_str().unwrap().to_owned();
    let vr = Proc::spawn_program(
        &dir,
        "vr",
        &vr_sim,
        &[
            "run",
            "--root",
            &root_s,
            "--",
            bin.to_str().unwrap(),
            "join",
            "--vr",
            "--room",
            "vr",
            "--signal",
            &url,
            "--bot",
            "wait 3; reach right softbox in 1; grab right timeout 6; squeeze right 0.02 in 0.5; \
             wait 3; release right; wait 120",
            "--duration",
            "120",
            "--dump",
            &vr_dump_s,
            "--dump-hz",
            "5",
            "--quiet",
        ],
        &[],
    );
    // The runtime is found, the session runs, the peer joins.
    let found = vr.wait_line("vr: ", Duration::from_secs(60));
    println!("{found}");
    assert!(
        found.contains("Monado"),
        "the VR peer did not find Monado: {found}\n{}",
        vr.logs()
    );
    vr.wait_line("xr state=Running", Duration::from_secs(90));
    let joined = vr.wait_line("joined host=", Duration::from_secs(60));
    let me: u64 = field(
        &vr.wait_line("joining room=", Duration::from_secs(5)),
        "peer",
    )
    .parse()
    .unwrap();
    println!("{joined} (VR peer {me})");
    let tracked = vr.wait_line("xr tracked ", Duration::from_secs(60));
    println!("{tracked}");
    let (head, left, right) = (
        xyz(field(&tracked, "head")),
        xyz(field(&tracked, "left")),
        xyz(field(&tracked, "right")),
    );
    assert!(
        (1.0..2.2).contains(&head[1]),
        "the headset is not at standing height in the room: {head:?}"
    );
    // The scripted squeeze grabs the soft box.
    let grabbed = vr.wait_line("grabbed object", Duration::from_secs(60));
    println!("{grabbed}");
    vr.wait_line("authority-gained", Duration::from_secs(5));
    // Held for 3 s: both dumps cover the hold by the time it lets go.
    vr.wait_line("release object", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(500));
    // The host sees the avatar where OpenXR put it, and the box owned by the VR peer.
    let lines = dump(&host_dump);
    let with_avatar: Vec<&Value> = lines
        .iter()
        .filter(|l| {
            l["objects"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|o| o["owner"].as_u64() == Some(me) && o["kind"] == "hand")
                .count()
                == 2
        })
        .collect();
    assert!(
        !with_avatar.is_empty(),
        "the host never showed two hands of the VR peer\n{}",
        vr.logs()
    );
    // The left controller rests (Monado's simulated controllers stand still): the host shows
    // that hand where OpenXR put it.
    let last = with_avatar.last().unwrap();
    let mine = |line: &Value, kind: &str| -> Vec<[f64; 3]> {
        line["objects"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|o| o["owner"].as_u64() == Some(me) && o["kind"] == kind)
            .map(pos)
            .collect()
    };
    let dl = mine(last, "hand")
        .iter()
        .map(|h| dist(*h, left))
        .fold(f64::MAX, f64::min);
    // The simulated headset moves: compare the host's view of the head with the VR peer's
    // own at the same wall-clock time (the dumps' wall_ms), over the whole run.
    let own = dump(&vr_dump);
    let mut errs: Vec<f64> = with_avatar
        .iter()
        .filter_map(|l| {
            let w = l["wall_ms"].as_u64()?;
            let o = own
                .iter()
                .min_by_key(|o| o["wall_ms"].as_u64().unwrap_or(0).abs_diff(w))?;
            if o["wall_ms"].as_u64()?.abs_diff(w) > 150 {
                return None;
            }
            let (a, b) = (mine(l, "head"), mine(o, "head"));
            Some(dist(*a.first()?, *b.first()?))
        })
        .collect();
    errs.sort_by(f64::total_cmp);
    assert!(
        errs.len() >= 5,
        "too few matching dump lines: {}",
        errs.len()
    );
    let median = errs[errs.len() / 2];
    let heights: Vec<f64> = own
        .iter()
        .filter_map(|o| mine(o, "head").first().map(|h| h[1]))
        .collect();
    println!(
        "host shows the VR left hand {:.1} mm from the controller; the VR head {:.1} mm \
         (median over {} lines, max {:.1}) from where the VR peer has it; head height \
         {:.2}-{:.2} m (headset first tracked at {head:?}, right controller at {right:?})",
        dl * 1e3,
        median * 1e3,
        errs.len(),
        errs.last().unwrap() * 1e3,
        heights.iter().copied().fold(f64::MAX, f64::min),
        heights.iter().copied().fold(f64::MIN, f64::max),
    );
    assert!(
        dl < 0.05,
        "the host shows the VR left hand {dl} m from the controller"
    );
    assert!(
        median < 0.03,
        "the host shows the VR head {median} m (median) from where the VR peer has it"
    );
    assert!(
        heights.iter().all(|h| (1.0..2.2).contains(h)),
        "the VR peer's head left standing height: {heights:?}"
    );
    let owned_box = lines.iter().any(|l| {
        l["objects"]
            .as_array()
            .unwrap()
            .iter()
            .any(|o| o["kind"] == "softbox" && o["owner"].as_u64() == Some(me))
    });
    assert!(owned_box, "the host never saw the VR peer own the soft box");
}
