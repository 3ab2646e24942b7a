//! Section 1b of the evidence (issue 33 point 2): every method scored again where the
//! scenario is predictable. Over a whole drop, squeeze or poke a 5 % change of the step grows
//! to millimetres (bounces, stick-slip), so whole-run errors mix the method's error with the
//! scenario's own sensitivity. Here each scenario's predictable window is measured in the same
//! run (the reference against itself with 5 % more substeps, within 0.5 mm until …), every
//! method is scored inside it, and where the window ends before the scenario's action the
//! squeeze and the poke are run again with their props slower ([`slow`]), so that the action
//! fits in the window. The whole-run figures stay beside, labelled as such.

use std::fmt::Write as _;
use std::path::Path;

use softsync_benchkit::{Csv, ResultLine};
use softsync_softbody::methods::choice::{pareto_front, Candidate};
use softsync_softbody::methods::reference::{
    nudged, shape_change_profile, within_tolerance_until_s,
};
use softsync_softbody::scenario::ScenarioKind;
use softsync_softbody::Mesh;

use crate::checked::{find, num, results};
use crate::{Case, Point};

/// The variants whose action fits in their window: (kind, pace, amount) — props `pace`
/// times slower doing `amount` of the scenario's action (`ModelScene::paced`). Slowing alone
/// does not make the action fit ([`pace_study`]): the window grows with the pace, because what
/// ends it is how far the body is deformed (the squeezed bunny buckles), not how fast.
pub const SLOW: [(ScenarioKind, f32, f32); 2] = [
    (ScenarioKind::Squeeze, 2.0, 0.5),
    (ScenarioKind::Poke, 2.0, 0.45),
];

/// The variant of `kind` in [`SLOW`]: run until its action is done and 0.1 s more.
pub fn slow(kind: ScenarioKind) -> Case {
    let (_, pace, amount) = SLOW
        .iter()
        .copied()
        .find(|s| s.0 == kind)
        .unwrap_or((kind, 1.0, 1.0));
    let action = action_s(kind, pace).unwrap_or(f64::from(kind.duration_s()));
    Case {
        kind,
        pace,
        amount,
        duration_s: action as f32 + 0.1,
    }
}

/// When the scenario's action is done (the plates closed, the poker at its depth), seconds;
/// `None` for a drop (its action, the impact and the bounces, has no set time).
pub fn action_s(kind: ScenarioKind, pace: f32) -> Option<f64> {
    match kind {
        ScenarioKind::Squeeze => Some(0.8 * f64::from(pace)),
        ScenarioKind::Poke => Some(0.5 * f64::from(pace)),
        _ => None,
    }
}

/// How a scenario's predictable window moves with the pace, at its full amount: (case,
/// pace, window s, action done s). The reference and the reference nudged only.
pub fn pace_study(mesh: &Mesh, quick: bool) -> Vec<(String, f32, f64, f64)> {
    let rs = crate::reference_spec(quick);
    let mut rows = Vec::new();
    for kind in [ScenarioKind::Squeeze, ScenarioKind::Poke] {
        for pace in [2.0f32, 4.0] {
            let action = action_s(kind, pace).unwrap_or(0.0);
            let case = Case {
                kind,
                pace,
                amount: 1.0,
                duration_s: action as f32 + 0.1,
            };
            let (Some(a), Some(b)) = (
                crate::run(case, mesh, &rs),
                crate::run(case, mesh, &nudged(&rs)),
            ) else {
                continue;
            };
            let profile = shape_change_profile(&a.samples, &b.samples);
            let window = within_tolerance_until_s(&[&profile], crate::DT);
            println!(
                "  {} at pace {pace}: window {window:.1} s of {action:.1}",
                kind.name()
            );
            rows.push((kind.name().to_string(), pace, window, action));
        }
    }
    rows
}

/// One scenario's scores.
pub struct Scored {
    pub case: String,
    pub window_s: f64,
    pub action_s: Option<f64>,
    pub duration_s: f32,
    pub points: Vec<Point>,
}

/// Ranks (1 = most accurate) of `points` by `error`.
fn ranks(points: &[Point], error: impl Fn(&Point) -> f32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| error(&points[a]).total_cmp(&error(&points[b])));
    let mut rank = vec![0; points.len()];
    for (r, &i) in order.iter().enumerate() {
        rank[i] = r + 1;
    }
    rank
}

/// Spearman's rank correlation of two rankings of the same items.
fn spearman(a: &[usize], b: &[usize]) -> f64 {
    let n = a.len() as f64;
    if n < 2.0 {
        return f64::NAN;
    }
    let d2: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum();
    1.0 - 6.0 * d2 / (n * (n * n - 1.0))
}

fn front(points: &[Point], error: impl Fn(&Point) -> f32) -> String {
    let cands: Vec<Candidate> = points
        .iter()
        .map(|p| Candidate {
            spec: p.spec,
            cost_ms: p.ms as f32,
            error_mm: error(p),
        })
        .collect();
    pareto_front(&cands)
        .iter()
        .map(|c| format!("`{}` {:.1} mm", c.spec.label(), c.error_mm))
        .collect::<Vec<_>>()
        .join(" → ")
}

/// Writes section 1b into `md`, its RESULT lines into `results` and `windows.csv` into `out`.
pub fn section(
    md: &mut String,
    results_out: &mut Vec<ResultLine>,
    out: &Path,
    scored: &[Scored],
    paces: &[(String, f32, f64, f64)],
    quick: bool,
) {
    let study = results(out, "reference.md");
    writeln!(md, "## 1b. Scores where the scenario is predictable\n").unwrap();
    let variants: Vec<String> = SLOW
        .iter()
        .map(|(k, pace, amount)| match k {
            ScenarioKind::Squeeze => format!(
                "*squeeze slow*: the plates close {:.0} % of the height (not 70 %) over {:.1} s",
                70.0 * amount,
                0.8 * pace
            ),
            ScenarioKind::Poke => format!(
                "*poke slow*: the poker goes {:.2} × the size deep (not 0.3) in {:.1} s",
                0.3 * amount,
                0.5 * pace
            ),
            _ => String::new(),
        })
        .collect();
    writeln!(md, "Over a whole scenario a 5 % change of the step (84 substeps for 80) moves the reference's answer by millimetres: bounces and stick-slip amplify it, doubling every 0.13–0.27 s on the bunny ([reference.md](reference.md)). A whole-run error therefore mixes a method's own error with the scenario's sensitivity. Here each scenario's **predictable window** is measured in this run — the last sample up to which the reference and the reference nudged stay within 0.5 mm of each other, sample by sample — and every method of section 1 is scored inside it (the same shape metric, over the window's samples only). The whole-run figures of section 1 stay beside them, labelled *whole run*. `ladders until`: how long the reference stays within 0.5 mm of its next finer rungs in space and time (the convergence study, [reference.md](reference.md); the scenarios' own timing only) — within the window the nudge is below 0.5 mm, but the reference's own discretization error may not be.{}\n", if quick { " **Quick run: against the coarse reference.**" } else { "" }).unwrap();
    writeln!(md, "**The squeeze's and the poke's windows end before their action is done** (below). Slowing them down does not make the action fit — their windows grow with the pace, as the action does (`ModelScene::paced`, the reference and its nudge only):\n\n| scenario | pace | window s | action done at s | window / action |\n|---|---|---|---|---|").unwrap();
    for (case, pace, window, action) in paces {
        writeln!(
            md,
            "| {case} | {pace} | {window:.1} | {action:.1} | {:.2} |",
            window / action.max(1e-9)
        )
        .unwrap();
    }
    writeln!(md, "\nWhat ends the window is how far the body is deformed, not how fast: the squeezed bunny buckles (the FEM's stability analysis of the compressed cube finds the homogeneous state unstable past about 46 % strain in the continuum, [fem/README.md](fem/README.md)), and past that point which way it folds is decided by anything — a 5 % change of the step. So the variants are slower **and shallower**: {}. Each runs until its action is done and 0.1 s more.\n", variants.join("; ")).unwrap();
    writeln!(
        md,
        "| scenario | predictable window s | action done at s | action inside the window | ladders until s | run s |\n|---|---|---|---|---|---|"
    )
    .unwrap();
    for s in scored {
        let ladders = find(
            &study,
            &[("scenario", &format!("bunny_{}", s.case.replace(' ', "_")))],
        )
        .map_or("–".to_string(), |l| {
            format!("{:.1}", num(l, "converged_until_s"))
        });
        let fits = match s.action_s {
            Some(a) if s.window_s + 1e-6 >= a => "**yes**".to_string(),
            Some(a) => format!("no ({:.0} % of it)", 100.0 * s.window_s / a),
            None => "– (a fall: the impact and bounces)".to_string(),
        };
        writeln!(
            md,
            "| {} | {:.1} | {} | {fits} | {ladders} | {:.1} |",
            s.case,
            s.window_s,
            s.action_s.map_or("–".to_string(), |a| format!("{a:.1}")),
            s.duration_s
        )
        .unwrap();
    }
    let mut csv = Csv::new(&[
        "scenario",
        "label",
        "method",
        "p25_ms",
        "window_s",
        "window_rms_mm",
        "window_max_mm",
        "whole_run_rms_mm",
    ]);
    for s in scored {
        let pts: Vec<Point> = s
            .points
            .iter()
            .filter(|p| p.window.is_some())
            .cloned()
            .collect();
        let win = |p: &Point| p.window.map_or(f32::NAN, |w| w.0);
        let r_win = ranks(&pts, win);
        let r_all = ranks(&pts, |p| p.rms_mm);
        writeln!(md, "\n### {} — window {:.1} s\n\n| method | ms/step | within the window: RMS mm (max) | rank | whole run: RMS mm | rank |\n|---|---|---|---|---|---|", s.case, s.window_s).unwrap();
        let mut order: Vec<usize> = (0..pts.len()).collect();
        order.sort_by_key(|&i| r_win[i]);
        for &i in &order {
            let p = &pts[i];
            let (w_rms, w_max) = p.window.unwrap_or((f32::NAN, f32::NAN));
            let whole = if s.case.contains('×') {
                format!("{:.2} (its {:.1} s)", p.rms_mm, s.duration_s)
            } else {
                format!("{:.2}", p.rms_mm)
            };
            writeln!(
                md,
                "| `{}` | {:.3} | {w_rms:.2} ({w_max:.1}) | {} | {whole} | {} |",
                p.label, p.ms, r_win[i], r_all[i]
            )
            .unwrap();
            csv.row([
                s.case.replace(' ', "_"),
                p.label.clone(),
                p.method.to_string(),
                format!("{:.4}", p.ms),
                format!("{:.2}", s.window_s),
                format!("{w_rms:.3}"),
                format!("{w_max:.3}"),
                format!("{:.3}", p.rms_mm),
            ]);
            results_out.push(
                ResultLine::new(format!(
                    "methods.window {} {}",
                    s.case.replace(' ', "_"),
                    p.label
                ))
                .fixed("window_s", s.window_s, 1)
                .fixed(
                    if quick {
                        "window_rms_mm_vs_coarse_reference"
                    } else {
                        "window_rms_mm"
                    },
                    w_rms,
                    2,
                )
                .fixed("whole_run_rms_mm", p.rms_mm, 2),
            );
        }
        let moved: Vec<String> = (0..pts.len())
            .filter(|&i| r_win[i].abs_diff(r_all[i]) >= 3)
            .map(|i| format!("`{}` {} → {}", pts[i].label, r_all[i], r_win[i]))
            .collect();
        let best = |r: &[usize]| {
            (0..pts.len())
                .find(|&i| r[i] == 1)
                .map_or(String::new(), |i| format!("`{}`", pts[i].label))
        };
        writeln!(md, "\nRank correlation (Spearman) between the window's ranking and the whole run's: {:.2}. Most accurate: {} within the window, {} over the whole run. Methods that move three places or more (whole run → window): {}.\n\nPareto front within the window: {}.\n\nPareto front over the whole run: {}.", spearman(&r_win, &r_all), best(&r_win), best(&r_all), if moved.is_empty() { "none".to_string() } else { moved.join(", ") }, front(&pts, win), front(&pts, |p| p.rms_mm)).unwrap();
    }
    csv.write(out.join("windows.csv")).unwrap();
    // What changes, scenario by scenario, said once more in one place.
    writeln!(md, "\n**What the windows change.**").unwrap();
    for s in scored {
        let pts: Vec<&Point> = s.points.iter().filter(|p| p.window.is_some()).collect();
        let best_by = |e: &dyn Fn(&Point) -> f32| {
            pts.iter()
                .min_by(|a, b| e(a).total_cmp(&e(b)))
                .map(|p| (p.label.clone(), e(p)))
        };
        let (Some((bw, ew)), Some((ba, ea))) = (
            best_by(&|p: &Point| p.window.map_or(f32::NAN, |w| w.0)),
            best_by(&|p: &Point| p.rms_mm),
        ) else {
            continue;
        };
        let spread = |e: &dyn Fn(&Point) -> f32| {
            let v: Vec<f32> = pts.iter().map(|p| e(p)).collect();
            (
                v.iter().copied().fold(f32::MAX, f32::min),
                v.iter().copied().fold(f32::MIN, f32::max),
            )
        };
        let (wlo, whi) = spread(&|p: &Point| p.window.map_or(f32::NAN, |w| w.0));
        let (alo, ahi) = spread(&|p: &Point| p.rms_mm);
        let inside = match s.action_s {
            Some(a) if s.window_s + 1e-6 >= a => "the whole action inside the window".to_string(),
            Some(a) => format!(
                "the window ends at {:.1} s, before the action is done ({a:.1} s): its window scores the approach, not the deformation",
                s.window_s
            ),
            None => format!("the window is the first {:.1} s of the fall", s.window_s),
        };
        if whi < 0.05 {
            writeln!(md, "- *{}*: every method is within {whi:.2} mm of the reference — the props did not deform the body, so this case measures nothing.", s.case).unwrap();
            continue;
        }
        writeln!(md, "- *{}* ({inside}): methods span {wlo:.2}–{whi:.2} mm within the window against {alo:.2}–{ahi:.2} mm over the whole run; the most accurate is `{bw}` ({ew:.2} mm) within it{}.", s.case, if bw == ba { " as over the whole run".to_string() } else { format!(", `{ba}` ({ea:.2} mm) over the whole run") }).unwrap();
    }
}
