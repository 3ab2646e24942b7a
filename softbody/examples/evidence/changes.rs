//! The reference in the evidence: its own row and uncertainty under each table, and what
//! changed when it replaced the former one (`tet c0.050 s10i10`, which inverted tets in every
//! scenario): the Pareto fronts, the most accurate methods, the method ranking and the
//! per-object choice, under both.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use softsync_softbody::methods::choice::{pareto_front, Candidate, Plan};

use crate::{Point, ReferenceRow};

/// The reference's change to its next finer rung in space and in time, mm, per case of
/// `reference.csv` (written by `examples/reference.rs`); empty if that file is missing.
pub fn uncertainty(out: &Path) -> BTreeMap<String, (f32, f32)> {
    let mut map = BTreeMap::new();
    let Ok(text) = std::fs::read_to_string(out.join("reference.csv")) else {
        return map;
    };
    let mut lines = text.lines();
    let Some(header) = lines.next() else {
        return map;
    };
    let col = |name: &str| header.split(',').position(|h| h == name);
    let (Some(case), Some(ladder), Some(cell), Some(sub), Some(next)) = (
        col("case"),
        col("ladder"),
        col("cell_frac"),
        col("substeps"),
        col("change_to_next_mm"),
    ) else {
        return map;
    };
    let reference_cell = format!(
        "{:.4}",
        softsync_softbody::methods::reference::REFERENCE_CELL
    );
    let reference_substeps = softsync_softbody::methods::reference::REFERENCE_SUBSTEPS.to_string();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        if f.get(cell) != Some(&reference_cell.as_str())
            || f.get(sub) != Some(&reference_substeps.as_str())
        {
            continue;
        }
        let Some(v) = f.get(next).and_then(|v| v.parse::<f32>().ok()) else {
            continue;
        };
        let e = map
            .entry(f[case].to_string())
            .or_insert((f32::NAN, f32::NAN));
        match f.get(ladder) {
            Some(&"space") => e.0 = v,
            Some(&"time") => e.1 = v,
            _ => {}
        }
    }
    map
}

/// The sentence above a scenario's table: the reference, its cost and how sure it is.
pub fn reference_note(r: &ReferenceRow, uncertainty: Option<&(f32, f32)>, quick: bool) -> String {
    let t = &r.trace;
    let energy = t.energy.map_or(String::new(), |[first, max, last, el]| {
        format!(" Its energy (kinetic + gravitational + elastic): {first:.2} J at the first sample, at most {max:.2} J, {last:.2} J at the end; elastic at most {el:.2} J.")
    });
    let sure = match (quick, uncertainty) {
        (true, _) => " Quick run: a coarse reference, not the verified one.".to_string(),
        (false, Some(&(space, time))) => format!(
            " Refining it moves this answer by {space:.2} mm in space and {time:.2} mm in time (shape RMS, [reference.md](reference.md)): differences between methods smaller than {:.1} mm are not resolved by this yardstick.",
            space.max(time)
        ),
        (false, None) => " Its convergence study (reference.csv) was not found.".to_string(),
    };
    format!(
        "Reference `{}`: {:.2} ms/step, {} nodes, {} inverted tets at any step, volume floor engaged {} times ({} in tets mostly material).{energy}{sure}",
        r.label, r.ms, t.particles, t.max_inverted, t.floor_hits.0, t.floor_hits.1
    )
}

/// The reference's own row of a table (its error is zero by definition).
pub fn reference_row(r: &ReferenceRow) -> String {
    let t = &r.trace;
    format!(
        "| `{}` (reference) | {} | {:.3} | 0 | 0 | 0 | {:.3} | {:.3} | {:.2} | {} | {} | – |",
        r.label,
        t.particles,
        r.ms,
        t.min_volume,
        t.end_volume,
        t.rest_mm,
        t.max_inverted,
        t.verdict
    )
}

/// The points as choice candidates with their error against the former reference.
pub fn former_candidates(points: &[Point]) -> Vec<Candidate> {
    points
        .iter()
        .filter_map(|p| {
            p.old_rms_mm.map(|e| Candidate {
                spec: p.spec,
                cost_ms: p.ms as f32,
                error_mm: e,
            })
        })
        .collect()
}

fn candidates_new(points: &[Point]) -> Vec<Candidate> {
    points
        .iter()
        .map(|p| Candidate {
            spec: p.spec,
            cost_ms: p.ms as f32,
            error_mm: p.rms_mm,
        })
        .collect()
}

fn front_labels(c: &[Candidate]) -> String {
    pareto_front(c)
        .iter()
        .map(|c| format!("`{}`", c.spec.label()))
        .collect::<Vec<_>>()
        .join(" → ")
}

/// Each method's best (smallest) error in `points` by `err`, most accurate first.
fn ranking(points: &[Point], err: impl Fn(&Point) -> Option<f32>) -> Vec<(&'static str, f32)> {
    let mut best: BTreeMap<&'static str, f32> = BTreeMap::new();
    for p in points {
        if let Some(e) = err(p) {
            let b = best.entry(p.method).or_insert(f32::MAX);
            *b = b.min(e);
        }
    }
    let mut v: Vec<(&'static str, f32)> = best.into_iter().collect();
    v.sort_by(|a, b| a.1.total_cmp(&b.1));
    v
}

fn picked(plan: &Plan, i: usize) -> String {
    plan.choices
        .get(i)
        .and_then(|c| c.picked.as_ref())
        .map_or("none".into(), |c| {
            format!("`{}` ({:.2} mm)", c.spec.label(), c.error_mm)
        })
}

/// The section "What changed with the reference".
pub fn section(
    md: &mut String,
    all: &BTreeMap<&str, Vec<Point>>,
    ico_drop: &[Point],
    plan: &Plan,
    former_plan: &Plan,
    uncertainty: &BTreeMap<String, (f32, f32)>,
) {
    writeln!(md, "## 7. What changed with the reference\n\nThe same runs scored against the former reference (`tet c0.050 s10i10`) and against the verified one. A conclusion that flips by less than the reference's own uncertainty (under each table of section 1) is a tie, not a change.\n\n| scenario | Pareto front, former reference | Pareto front, verified reference | most accurate, former → verified | method ranking by best error, former → verified | largest change of one method's error |\n|---|---|---|---|---|---|").unwrap();
    let mut scenarios: Vec<(String, &[Point])> = all
        .iter()
        .map(|(k, v)| (format!("bunny {k}"), v.as_slice()))
        .collect();
    scenarios.push(("icosphere drop".to_string(), ico_drop));
    for (name, pts) in &scenarios {
        let old_rank = ranking(pts, |p| p.old_rms_mm);
        let new_rank = ranking(pts, |p| Some(p.rms_mm));
        let fmt_rank = |r: &[(&str, f32)]| {
            r.iter()
                .map(|(m, e)| format!("{m} {e:.1}"))
                .collect::<Vec<_>>()
                .join(" < ")
        };
        let best = |f: &dyn Fn(&Point) -> Option<f32>| {
            pts.iter()
                .filter_map(|p| f(p).map(|e| (p, e)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map_or("–".into(), |(p, e)| format!("`{}` {e:.2}", p.label))
        };
        let biggest = pts
            .iter()
            .filter_map(|p| p.old_rms_mm.map(|o| (p, p.rms_mm - o)))
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map_or("–".into(), |(p, d)| {
                format!(
                    "`{}` {:.2} → {:.2} mm ({d:+.2})",
                    p.label,
                    p.old_rms_mm.unwrap_or(0.0),
                    p.rms_mm
                )
            });
        writeln!(
            md,
            "| {name}{} | {} | {} | {} → {} | {} → {} | {biggest} |",
            uncertainty
                .get(name)
                .map_or(String::new(), |(s, t)| format!(" (± {:.1} mm)", s.max(*t))),
            front_labels(&former_candidates(pts)),
            front_labels(&candidates_new(pts)),
            best(&|p| p.old_rms_mm),
            best(&|p| Some(p.rms_mm)),
            fmt_rank(&old_rank),
            fmt_rank(&new_rank),
        )
        .unwrap();
    }
    writeln!(
        md,
        "\nThe per-object choice of section 6: poked bunny {} → {}; dropped icosphere {} → {}.\n",
        picked(former_plan, 0),
        picked(plan, 0),
        picked(former_plan, 1),
        picked(plan, 1)
    )
    .unwrap();
}
