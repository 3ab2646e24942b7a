//! The frame-budget bench's short run (CI's smoke run): it completes, every kind of event in
//! it happened, and it writes its RESULT lines. Bounds on the figures are the bench's job.
#![allow(clippy::unwrap_used, missing_docs)]

use std::path::Path;

use softsync_bench::frame::{run, FramePlan};

#[test]
fn the_quick_frame_budget_room_does_everything_and_prints_its_result() {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let report = run(&FramePlan::quick(&assets)).unwrap();
    // four peers for half the run, three after the host stopped
    let frames = report.samples.len();
    assert!(
        (8 * 90 * 3..=8 * 90 * 4).contains(&frames),
        "{frames} frames"
    );
    assert!(report.tears_asked >= 8 * 5, "{report:?}");
    assert!(report.cuts_asked >= 2, "{} cuts", report.cuts_asked);
    // C applied the cuts and tears its blades asked for (the owner did them)
    assert!(
        report.topology_seen >= 4,
        "{} topology entries",
        report.topology_seen
    );
    assert!(
        report.soft_bodies_at_end > 10,
        "{} soft bodies",
        report.soft_bodies_at_end
    );
    // both hands held the ball at once, and the room moved to a new host
    assert_eq!(report.most_holders, 2);
    assert!(
        report.host_changes >= 3,
        "{} host changes",
        report.host_changes
    );
    let dir = std::env::temp_dir().join(format!("softsync-frame-{}", std::process::id()));
    let lines = report.write(&dir).unwrap();
    assert!(
        lines[0].starts_with("RESULT frame.budget p50_ms="),
        "{}",
        lines[0]
    );
    // a row per peer and 0.1 s: 8 s, three or four peers
    let csv = std::fs::read_to_string(dir.join("frame.csv")).unwrap();
    assert!(
        (240..=330).contains(&csv.lines().count()),
        "{}",
        csv.lines().count()
    );
    assert!(dir.join("frame.svg").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}
