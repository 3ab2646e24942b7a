//! Is the accuracy reference itself right? Stable Neo-Hookean tets (the verified reference of
//! `softsync_softbody::methods::reference`) refined in space and in time on every scenario of
//! the evidence, with its own volume, inverted tets, volume-floor engagements and energy.
//!
//! `cargo run --release -p softsync-softbody --example reference -- [--quick]`
//!
//! Writes `docs/results/methods/{reference.md,reference.csv,reference.svg}` and prints
//! `RESULT reference.converged …` lines. `--quick` runs the same study four times coarser
//! (cells ×2, substeps ÷4) and says so: its figures are not the reference's.
#![allow(
    clippy::disallowed_methods,
    clippy::unwrap_used,
    clippy::print_stdout,
    missing_docs
)]

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use softsync_benchkit::plotters::style::RGBColor;
use softsync_benchkit::{write_svg, ChartStyle, Csv, LineChart, ResultLine, Series};
use softsync_softbody::methods::reference::{
    energy_summary, record, reference_spec, shape_change, shape_change_profile,
    within_tolerance_until_s, Recording, ShapeChange, REFERENCE_CELL, REFERENCE_ITERATIONS,
    REFERENCE_SUBSTEPS, SAMPLE_EVERY, TOLERANCE_MM,
};
use softsync_softbody::scenario::ScenarioKind;
use softsync_softbody::Mesh;

const DT: f32 = 1.0 / 60.0;

/// One object in one scenario of the evidence.
struct Case {
    name: &'static str,
    mesh: Mesh,
    kind: ScenarioKind,
}

/// A rung of a ladder: a resolution, its recording and how long it took.
struct Rung {
    cell: f32,
    substeps: u32,
    run: Recording,
    wall_s: f64,
}

fn rung(case: &Case, cell: f32, substeps: u32) -> Rung {
    let spec = reference_spec(cell, substeps);
    let t = Instant::now();
    let run = record(case.kind, &case.mesh, &spec, DT).unwrap();
    let wall_s = t.elapsed().as_secs_f64();
    println!(
        "  {:<14} {:<34} {:>6} nodes {:>6.1} s  inverted {} floor {:?} vol {:.3}..{:.3} {}",
        case.name,
        spec.label(),
        run.particles,
        wall_s,
        run.max_inverted,
        run.floor_hits,
        run.min_volume,
        run.max_volume,
        run.verdict
    );
    Rung {
        cell,
        substeps,
        run,
        wall_s,
    }
}

/// One line per case, coloured in turn, and the tolerance across `x`; with the largest value
/// drawn (the tolerance at least).
fn with_tolerance(
    series: &[(String, Vec<(f64, f64)>)],
    colors: &[RGBColor],
    x: (f64, f64),
) -> (Vec<Series>, f64) {
    let ymax = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .fold(TOLERANCE_MM as f64, f64::max);
    let mut lines: Vec<Series> = series
        .iter()
        .zip(colors)
        .map(|((name, pts), c)| Series::new(name.as_str(), *c, pts.clone()))
        .collect();
    lines.push(Series::new(
        format!("tolerance {TOLERANCE_MM} mm"),
        RGBColor(0, 0, 0),
        vec![(x.0, TOLERANCE_MM as f64), (x.1, TOLERANCE_MM as f64)],
    ));
    (lines, ymax)
}

/// Runs every `(case, cell, substeps)` of `jobs` on as many threads as the machine has cores,
/// in the order given; returns each rung keyed by `(case, cell bits, substeps)`.
#[allow(clippy::type_complexity)]
fn run_all(cases: &[Case], jobs: &[(usize, f32, u32)]) -> Vec<((usize, u32, u32), Rung)> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let next = std::sync::atomic::AtomicUsize::new(0);
    let out = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..threads.min(jobs.len()) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(&(k, c, s)) = jobs.get(i) else {
                    break;
                };
                let r = rung(&cases[k], c, s);
                out.lock().unwrap().push(((k, c.to_bits(), s), r));
            });
        }
    });
    out.into_inner().unwrap()
}

/// How fast the scenario amplifies a small change: the doubling time of the nudge's change
/// (log-linear least squares from its first sample above 0.05 mm to its largest), or `None`
/// if it does not grow.
fn doubling_time_s(nudge: &[f32], at_s: impl Fn(usize) -> f64) -> Option<f64> {
    let first = nudge.iter().position(|&v| v >= 0.05)?;
    let peak = nudge
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)?;
    let pts: Vec<(f64, f64)> = (first..=peak)
        .filter(|&i| nudge[i] > 0.0)
        .map(|i| (at_s(i), (nudge[i] as f64).ln()))
        .collect();
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let slope = sxy / sxx.max(1e-12);
    (slope > 0.0).then(|| std::f64::consts::LN_2 / slope)
}

fn bunny() -> Mesh {
    Mesh::load(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/bunny.obj"))
        .unwrap()
        .fit_size(0.2)
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let t_start = Instant::now();
    let out = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/results/methods");
    std::fs::create_dir_all(&out).unwrap();
    // The quick study is the same study, coarser: it shows the machinery, not the reference.
    let (coarsen, slow) = if quick { (2.0f32, 4u32) } else { (1.0, 1) };
    let cell = REFERENCE_CELL * coarsen;
    let substeps = REFERENCE_SUBSTEPS / slow;
    let root2 = std::f32::consts::SQRT_2;
    let cells = [cell * 2.0, cell * root2, cell, cell / root2];
    let steps = [substeps / 4, substeps / 2, substeps, substeps * 2];
    // The scenario's own sensitivity: 5 % more substeps at the reference's resolution.
    let nudged = substeps + (substeps / 20).max(1);
    let bunny = bunny();
    let cases = [
        Case {
            name: "bunny drop",
            mesh: bunny.clone(),
            kind: ScenarioKind::Drop,
        },
        Case {
            name: "bunny squeeze",
            mesh: bunny.clone(),
            kind: ScenarioKind::Squeeze,
        },
        Case {
            name: "bunny poke",
            mesh: bunny,
            kind: ScenarioKind::Poke,
        },
        Case {
            name: "icosphere drop",
            mesh: Mesh::icosphere(0.1, 3),
            kind: ScenarioKind::Drop,
        },
    ];
    let mut csv = Csv::new(&[
        "case",
        "ladder",
        "cell_frac",
        "substeps",
        "nodes",
        "wall_s",
        "max_inverted",
        "floor_hits",
        "floor_hits_material",
        "min_volume",
        "max_volume",
        "change_to_next_mm",
        "change_to_next_max_mm",
        "change_to_finest_mm",
    ]);
    let mut md = String::new();
    let mut results: Vec<ResultLine> = Vec::new();
    let mut space_series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let mut time_series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let mut summary_rows = Vec::new();
    // Where in each scenario the reference and its finer rungs part, sample by sample.
    let mut profile_csv = Csv::new(&[
        "case",
        "t_s",
        "time_change_mm",
        "space_change_mm",
        "nudge_mm",
    ]);
    let mut time_profiles: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let mut space_profiles: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    // Every rung of every case is independent: run them on every core, the costliest first
    // (cost ~ nodes × substeps ~ substeps / cell³), and take them back in the ladders' order.
    let mut jobs: Vec<(usize, f32, u32)> = Vec::new();
    for k in 0..cases.len() {
        jobs.push((k, cell, substeps));
        jobs.extend(
            cells
                .iter()
                .filter(|&&c| c != cell)
                .map(|&c| (k, c, substeps)),
        );
        jobs.extend(
            steps
                .iter()
                .filter(|&&s| s != substeps)
                .map(|&s| (k, cell, s)),
        );
        jobs.push((k, cell, nudged));
    }
    jobs.sort_by(|a, b| (b.2 as f32 / b.1.powi(3)).total_cmp(&(a.2 as f32 / a.1.powi(3))));
    let mut done = run_all(&cases, &jobs);
    for (k, case) in cases.iter().enumerate() {
        let mut take = |c: f32, s: u32| {
            let at = done
                .iter()
                .position(|(j, _)| *j == (k, c.to_bits(), s))
                .unwrap();
            done.swap_remove(at).1
        };
        // The reference itself is a rung of both ladders.
        let reference = take(cell, substeps);
        let mut space: Vec<Rung> = Vec::new();
        for &c in &cells {
            if c == cell {
                continue;
            }
            space.push(take(c, substeps));
        }
        let mut time: Vec<Rung> = Vec::new();
        for &s in &steps {
            if s == substeps {
                continue;
            }
            time.push(take(cell, s));
        }
        let nudge = take(cell, nudged);
        // Put the reference in its place on both ladders (coarse to fine).
        let place = |ladder: Vec<Rung>, at: usize, r: &Rung| {
            let mut v: Vec<Option<Rung>> = ladder.into_iter().map(Some).collect();
            v.insert(
                at,
                Some(Rung {
                    cell: r.cell,
                    substeps: r.substeps,
                    run: r.run.clone(),
                    wall_s: r.wall_s,
                }),
            );
            v.into_iter().flatten().collect::<Vec<Rung>>()
        };
        let space = place(space, 2, &reference);
        let time = place(time, 2, &reference);
        let mut ladder_changes =
            |name: &str, ladder: &[Rung], series: &mut Vec<(String, Vec<(f64, f64)>)>| {
                let finest = &ladder[ladder.len() - 1].run.samples;
                let mut points = Vec::new();
                let mut to_next_at_reference = ShapeChange::default();
                for (i, r) in ladder.iter().enumerate() {
                    let next = ladder
                        .get(i + 1)
                        .map(|n| shape_change(&r.run.samples, &n.run.samples));
                    let to_finest = shape_change(&r.run.samples, finest);
                    if r.cell == cell && r.substeps == substeps {
                        to_next_at_reference = next.unwrap_or_default();
                    }
                    csv.row([
                        case.name.to_string(),
                        name.to_string(),
                        format!("{:.4}", r.cell),
                        r.substeps.to_string(),
                        r.run.particles.to_string(),
                        format!("{:.1}", r.wall_s),
                        r.run.max_inverted.to_string(),
                        r.run.floor_hits.0.to_string(),
                        r.run.floor_hits.1.to_string(),
                        format!("{:.4}", r.run.min_volume),
                        format!("{:.4}", r.run.max_volume),
                        next.map_or(String::new(), |c| format!("{:.3}", c.rms_mm)),
                        next.map_or(String::new(), |c| format!("{:.2}", c.max_mm)),
                        format!("{:.3}", to_finest.rms_mm),
                    ]);
                    if let Some(c) = next {
                        let x = if name == "space" {
                            r.run.particles as f64
                        } else {
                            r.substeps as f64
                        };
                        points.push((x, c.rms_mm as f64));
                    }
                }
                series.push((case.name.to_string(), points));
                to_next_at_reference
            };
        let space_change = ladder_changes("space", &space, &mut space_series);
        let time_change = ladder_changes("time", &time, &mut time_series);
        let nudge_change = shape_change(&reference.run.samples, &nudge.run.samples);
        // The next finer rungs of both ladders (the reference sits third of four).
        let t_prof = shape_change_profile(&reference.run.samples, &time[3].run.samples);
        let s_prof = shape_change_profile(&reference.run.samples, &space[3].run.samples);
        let n_prof = shape_change_profile(&reference.run.samples, &nudge.run.samples);
        let sample_s = |i: usize| (i + 1) as f64 * SAMPLE_EVERY as f64 * DT as f64;
        for i in 0..t_prof.len().min(s_prof.len()).min(n_prof.len()) {
            profile_csv.row([
                case.name.to_string(),
                format!("{:.3}", sample_s(i)),
                format!("{:.3}", t_prof[i]),
                format!("{:.3}", s_prof[i]),
                format!("{:.3}", n_prof[i]),
            ]);
        }
        let curve = |p: &[f32]| -> Vec<(f64, f64)> {
            p.iter()
                .enumerate()
                .map(|(i, v)| (sample_s(i), *v as f64))
                .collect()
        };
        // How long the answer stays within the tolerance sample by sample: the reference
        // against both finer rungs, and against itself nudged (the scenario's own horizon of
        // predictability: past it no refinement can pin the answer down).
        let horizon = |profiles: &[&[f32]]| within_tolerance_until_s(profiles, DT);
        let converged_until = horizon(&[&t_prof, &s_prof]);
        let nudge_until = horizon(&[&n_prof]);
        let doubling = doubling_time_s(&n_prof, sample_s);
        let doubling_text = doubling.map_or("none".to_string(), |d| format!("{d:.2}"));
        time_profiles.push((case.name.to_string(), curve(&t_prof)));
        space_profiles.push((case.name.to_string(), curve(&s_prof)));
        let worst_inverted = space
            .iter()
            .chain(&time)
            .chain(std::iter::once(&nudge))
            .map(|r| r.run.max_inverted)
            .max()
            .unwrap_or(0);
        let e = energy_summary(&reference.run);
        let change = space_change.rms_mm.max(time_change.rms_mm);
        let converged = change < TOLERANCE_MM;
        results.push(
            ResultLine::new("reference.converged")
                .field("scenario", case.name.replace(' ', "_"))
                .fixed("rms_change_mm", change, 2)
                .field("inverted", reference.run.max_inverted)
                .fixed("space_mm", space_change.rms_mm, 2)
                .fixed("time_mm", time_change.rms_mm, 2)
                .fixed("nudge_mm", nudge_change.rms_mm, 2)
                .field("ladders_inverted", worst_inverted)
                .field("converged", converged)
                .fixed("converged_until_s", converged_until, 1)
                .fixed("nudge_until_s", nudge_until, 1)
                .field("nudge_doubling_s", &doubling_text)
                .fixed("duration_s", case.kind.duration_s() as f64, 1),
        );
        summary_rows.push(format!(
            "| {} | {} | {} | {} ({} in material) | {:.3}–{:.3} | {:.2} / {:.2} / {:.2} / {:.2} | {:.2} ({:.1}) | {:.2} ({:.1}) | {:.2} ({:.1}) | {} | {:.1} / {:.1} of {:.1} | {} |",
            case.name,
            reference.run.particles,
            reference.run.max_inverted,
            reference.run.floor_hits.0,
            reference.run.floor_hits.1,
            reference.run.min_volume,
            reference.run.max_volume,
            e.first_j,
            e.max_j,
            e.last_j,
            e.max_elastic_j,
            space_change.rms_mm,
            space_change.max_mm,
            time_change.rms_mm,
            time_change.max_mm,
            nudge_change.rms_mm,
            nudge_change.max_mm,
            if converged { "**yes**" } else { "no" },
            converged_until,
            nudge_until,
            case.kind.duration_s(),
            doubling_text,
        ));
    }
    csv.write(out.join("reference.csv")).unwrap();
    profile_csv
        .write(out.join("reference_profile.csv"))
        .unwrap();
    let colors = [
        RGBColor(214, 39, 40),
        RGBColor(31, 119, 180),
        RGBColor(44, 160, 44),
        RGBColor(148, 103, 189),
    ];
    let panel = |title: &str, x_desc: &str, series: &[(String, Vec<(f64, f64)>)]| {
        let xs = series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
        let (xmin, xmax) = xs.fold((f64::MAX, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
        let (lines, ymax) = with_tolerance(series, &colors, (xmin * 0.8, xmax * 1.25));
        let ymax = ymax * 1.15;
        LineChart {
            title: title.to_owned(),
            x_desc: x_desc.to_owned(),
            y_desc: "shape RMS change to the next finer rung, mm".to_owned(),
            x_range: (xmin * 0.8)..(xmax * 1.25),
            x_log: true,
            y_range: 0.0..ymax,
            series: lines,
            style: ChartStyle::FIGURE,
        }
    };
    write_svg(
        out.join("reference.svg"),
        (1400, 560),
        &[
            panel(
                &format!("space: cell ×√2 finer, {substeps} substeps"),
                "tet nodes (log)",
                &space_series,
            ),
            panel(
                &format!("time: substeps ×2, cell {cell:.3}"),
                "substeps per 60 Hz step (log)",
                &time_series,
            ),
        ],
    )
    .unwrap();
    let profile = |title: &str, series: &[(String, Vec<(f64, f64)>)]| {
        let xmax = series
            .iter()
            .flat_map(|s| s.1.iter().map(|p| p.0))
            .fold(0.0f64, f64::max);
        let (lines, ymax) = with_tolerance(series, &colors, (0.0, xmax));
        let ymax = ymax * 1.1;
        LineChart {
            title: title.to_owned(),
            x_desc: "scenario time, s".to_owned(),
            y_desc: "shape RMS change at the sample, mm".to_owned(),
            x_range: 0.0..xmax,
            x_log: false,
            y_range: 0.0..ymax,
            series: lines,
            style: ChartStyle::FIGURE,
        }
    };
    write_svg(
        out.join("reference_profile.svg"),
        (1400, 560),
        &[
            profile(
                &format!("reference against {} substeps, over time", substeps * 2),
                &time_profiles,
            ),
            profile(
                &format!("reference against cell {:.3}, over time", cell / root2),
                &space_profiles,
            ),
        ],
    )
    .unwrap();
    let spec = reference_spec(cell, substeps);
    writeln!(
        md,
        "# The accuracy reference: is it right?\n\nGenerated by `cargo run --release -p softsync-softbody --example reference{}` on a {}-core machine in {:.0} s. Do not edit by hand.{}\n",
        if quick { " -- --quick" } else { "" },
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        t_start.elapsed().as_secs_f64(),
        if quick {
            "\n\n**Quick run: cells twice as coarse and a quarter of the substeps of the reference; these are not the verified reference's figures.**"
        } else {
            ""
        }
    )
    .unwrap();
    writeln!(md, "The reference `{}`: stable Neo-Hookean XPBD tets (Macklin & Müller 2021: per tet `C_D = ‖F‖` with compliance `1/(μV)` and `C_H = det F − (1 + μ/λ)` with compliance `1/(λV)`; `λ` raised by `μ` so small strains match the material's E = 200 kPa and K = 400 kPa, ν ≈ 0.42) on a Kuhn lattice (six congruent tets per cube, no slivers) of cell {:.3} × the object's size, each tet's mass and stiffness weighted by the fraction of it inside the surface, the surface embedded; {} substeps of {} Gauss–Seidel iterations per 60 Hz step; only the surface collides; a pinned region holds the same surface vertices at every resolution; a hard floor `det F ≥ 0.2` makes inversion impossible by construction (how often it engaged is counted).\n", spec.label(), cell, substeps, REFERENCE_ITERATIONS).unwrap();
    writeln!(md, "Ladders around it, on every scenario of the evidence: in space (cell ×√2 coarser and finer: {}) at {substeps} substeps, and in time (substeps {}) at cell {cell:.3}. A change is the shape RMS between two rungs (each sample's surface rigidly fitted, the accuracy figures' own metric), over every sample of the scenario; `max` the largest vertex distance. `nudge`: the reference against itself with {nudged} substeps instead of {substeps} — how much the scenario itself moves under a 5 % change of the step (contact stick/slip, buckling, tumbling): no reference can be closer to *the* answer than that. Converged = both the space and the time change of the reference to its next finer rung below {TOLERANCE_MM} mm. `within 0.5 mm until`: the last sample time up to which every sample's change to both finer rungs stays below the tolerance, and the same for the nudge — the scenario's own horizon of predictability (bounces and tumbles amplify any change of the step: past that time no refinement pins the answer down, and errors against the reference measure that sensitivity as much as a method). `nudge doubles every`: how fast the scenario amplifies that change (log-linear fit of the nudge's profile from 0.05 mm to its peak) — a change that doubles every τ grows 2^(T/τ)-fold over T seconds, so holding the answer to the tolerance over the whole scenario would take a step that many times more exact: out of reach of any refinement when T/τ is large.\n", cells.iter().map(|c| format!("{c:.3}")).collect::<Vec<_>>().join(", "), steps.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")).unwrap();
    writeln!(md, "![convergence](reference.svg)\n\n| case | nodes | max inverted tets | floor engaged | volume ratio | energy J: first / max / last / max elastic | space change mm (max) | time change mm (max) | nudge mm (max) | converged | within 0.5 mm until, s: ladders / nudge | nudge doubles every, s |\n|---|---|---|---|---|---|---|---|---|---|---|---|").unwrap();
    for r in &summary_rows {
        writeln!(md, "{r}").unwrap();
    }
    writeln!(md, "\nWhere the rungs part, sample by sample (`reference_profile.csv`, with the nudge):\n\n![profile](reference_profile.svg)\n").unwrap();
    writeln!(md, "\nEnergy: kinetic + gravitational (height above the floor's top) + stored Neo-Hookean energy of the reference at the samples; in the drops the total must never exceed the first sample's (nothing adds energy; contacts and damping remove it); in squeeze and poke the props do work on the body. Every rung of both ladders is in `reference.csv`.\n").unwrap();
    let results: Vec<String> = results.iter().map(ResultLine::to_string).collect();
    writeln!(md, "```\n{}\n```", results.join("\n")).unwrap();
    std::fs::write(out.join("reference.md"), md).unwrap();
    for r in &results {
        println!("{r}");
    }
    println!("total {:.1} s", t_start.elapsed().as_secs_f64());
}
