//! Reading the JSON-lines dumps peers write (`--dump`): positions, rotations, owners, and
//! whether two peers show the same room.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use serde_json::Value;

/// Every parseable line of a dump (a line being written is skipped).
pub fn read_dump(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// The last dump line at or before wall time `wall_ms` (a peer's final line is written just
/// before it says `Leave`; lines of others after that no longer show its avatar).
pub fn nearest(lines: &[Value], wall_ms: u64) -> &Value {
    lines
        .iter()
        .filter(|l| l["wall_ms"].as_u64().unwrap() <= wall_ms)
        .max_by_key(|l| l["wall_ms"].as_u64().unwrap())
        .expect("no dump line before that time")
}

pub fn vec3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    ]
}

pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

pub fn angle_deg(a: &Value, b: &Value) -> f64 {
    let a = a.as_array().unwrap();
    let b = b.as_array().unwrap();
    let dot: f64 = (0..4)
        .map(|i| a[i].as_f64().unwrap() * b[i].as_f64().unwrap())
        .sum();
    2.0 * dot.abs().min(1.0).acos().to_degrees()
}

pub fn objects(line: &Value) -> BTreeMap<u64, &Value> {
    line["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| (o["id"].as_u64().unwrap(), o))
        .collect()
}

/// Every object of `a` is in `b` within 1 mm and 0.5°, every particle within 1 mm, same owner.
pub fn assert_agree(a: &Value, b: &Value, what: &str) {
    let (oa, ob) = (objects(a), objects(b));
    assert_eq!(
        oa.keys().collect::<Vec<_>>(),
        ob.keys().collect::<Vec<_>>(),
        "{what}: different objects"
    );
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for (id, x) in &oa {
        let y = ob[id];
        assert_eq!(x["owner"], y["owner"], "{what}: object {id} has two owners");
        let d = dist(vec3(&x["pos"]), vec3(&y["pos"]));
        let ang = angle_deg(&x["rot"], &y["rot"]);
        assert!(d < 1e-3, "{what}: object {id} ({}) {d} m apart", x["kind"]);
        assert!(
            ang < 0.5,
            "{what}: object {id} ({}) {ang}° apart",
            x["kind"]
        );
        let (px, py) = (
            x["particles"].as_array().cloned().unwrap_or_default(),
            y["particles"].as_array().cloned().unwrap_or_default(),
        );
        assert_eq!(px.len(), py.len(), "{what}: object {id} particle count");
        let dp = px
            .iter()
            .zip(&py)
            .map(|(p, q)| dist(vec3(p), vec3(q)))
            .fold(0.0, f64::max);
        assert!(
            dp < 1e-3,
            "{what}: object {id} ({}) particles {dp} m apart",
            x["kind"]
        );
        worst = (worst.0.max(d), worst.1.max(ang), worst.2.max(dp));
    }
    println!(
        "{what}: {} objects agree, worst {:.3} mm, {:.3}°, particles {:.3} mm",
        oa.len(),
        worst.0 * 1e3,
        worst.1,
        worst.2 * 1e3
    );
}

/// An object's position.
pub fn pos(o: &Value) -> [f64; 3] {
    vec3(&o["pos"])
}

/// Waits (bounded) until the dump at `path` (5 lines a second) shows no object that moved
/// more than 0.2 mm or 0.05° over its last second.
pub fn wait_for_rest(path: &Path, within: Duration) -> Duration {
    let start = Instant::now();
    loop {
        let d = read_dump(path);
        if d.len() > 5 {
            let (now, before) = (&d[d.len() - 1], &d[d.len() - 6]);
            let (a, b) = (objects(now), objects(before));
            let still = a.len() == b.len()
                && a.iter().all(|(id, x)| {
                    b.get(id).is_some_and(|y| {
                        dist(vec3(&x["pos"]), vec3(&y["pos"])) < 2e-4
                            && angle_deg(&x["rot"], &y["rot"]) < 0.05
                    })
                });
            if still {
                return start.elapsed();
            }
        }
        assert!(
            start.elapsed() < within,
            "nothing came to rest within {within:?}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}
