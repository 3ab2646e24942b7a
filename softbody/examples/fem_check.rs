//! Our reference against an independent FEM code (scikit-fem, `scripts/fem-reference`) on
//! static problems whose answer is unique — the cantilever, the compression, the indentation
//! (and, with `--bunny-export`, the bunny): see `softsync_softbody::methods::statics`.
//! `-- --indent K SUBSTEPS [K SUBSTEPS …]` runs only the indentation at those levels and
//! prints its lines (it reads `indent.csv`, written by `scripts/fem-reference --indent`).
//!
//! `cargo run --release -p softsync-softbody --example fem_check [-- --quick]`
//!
//! Reads the FEM's answers (`docs/results/methods/fem/fem.csv`, written by
//! `scripts/fem-reference --all`), solves the same cantilever with our reference's material and
//! solver (stable Neo-Hookean XPBD tets, 80 substeps × 2 iterations, the reference's budget)
//! at k = 2, 4 (and 8) cells across the section, and prints and writes under
//! `docs/results/methods/fem/`: `RESULT reference.fem …` lines (`results.txt`), `ours.csv`.
//! Each line compares ours at level k with the FEM's converged answer (quadratic tets, the
//! finest level: `fem`, `fem_change_pct`) and with the FEM's linear tets at the same level
//! (`fem_p1`: the same discretization as ours, so `diff_p1_pct` is our solver's own error).

use std::collections::BTreeMap;

use softsync_benchkit::{Csv, ResultLine};
use softsync_softbody::methods::statics::{
    self, bunny_mesh, bunny_sag, cantilever_tip_mm, compress_cube, indent_slab, StaticSolve,
};

/// (problem, quantity, case, element, level) → (value, change_pct)
type Table = BTreeMap<(String, String, String, String, u32), (f64, Option<f64>)>;

fn read_fem(path: &str) -> Table {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{path}: {e} (run scripts/fem-reference --all)"));
    let mut t = Table::new();
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        if c.len() < 8 {
            continue;
        }
        let (Ok(level), Ok(value)) = (c[4].parse::<u32>(), c[6].parse::<f64>()) else {
            continue;
        };
        t.insert(
            (c[0].into(), c[1].into(), c[2].into(), c[3].into(), level),
            (value, c[7].parse().ok()),
        );
    }
    t
}

/// `--bunny-export FILE [CELL_FRAC] [YOUNG_PA]`: meshes the bunny problem, solves ours and
/// writes both as JSON for `scripts/fem-reference --bunny FILE` (nodes, tets, weights, fixed
/// nodes, material, our displacement field and solve).
fn bunny_export(args: &[String]) {
    let path = args
        .first()
        .expect("--bunny-export FILE [CELL_FRAC] [YOUNG_PA]");
    let cell: f32 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(0.05);
    let young: f32 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(2e4);
    let mesh =
        softsync_softbody::Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj"))
            .expect("assets/bunny.obj");
    let m = bunny_mesh(&mesh, cell).expect("the bunny's lattice");
    // Settled to 2e-3: the fringe nodes (tets almost all outside the surface) keep a residual
    // jitter of about 1e-3 of the displacement (measured: the largest displacement moves by
    // 0.1 % between 300 and 2400 steps).
    let solve = StaticSolve {
        rest_rel: 2e-3,
        ..StaticSolve::default()
    };
    let (u, a) = bunny_sag(&m, young, solve);
    let v3 = |v: &glam::Vec3| format!("[{:.9},{:.9},{:.9}]", v.x, v.y, v.z);
    let list = |items: Vec<String>| format!("[{}]", items.join(","));
    let json = format!(
        "{{\"cell_frac\":{cell},\"young_pa\":{young},\"nu\":{nu},\"density_kg_m3\":{rho},\"gravity\":[0,-9.81,0],\"nodes\":{nodes},\"tets\":{tets},\"weight\":{weight},\"fixed\":{fixed},\"ours\":{ours},\"ours_steps\":{steps},\"ours_max_speed_mps\":{speed},\"ours_budget\":\"s{sub}i{it}\"}}",
        nu = statics::NU,
        rho = statics::DENSITY_KG_M3,
        nodes = list(m.nodes.iter().map(v3).collect()),
        tets = list(m.tets.iter().map(|t| format!("[{},{},{},{}]", t[0], t[1], t[2], t[3])).collect()),
        weight = list(m.weight.iter().map(|w| format!("{w:.6}")).collect()),
        fixed = list(m.fixed.iter().map(|i| i.to_string()).collect()),
        ours = list(u.iter().map(v3).collect()),
        steps = a.steps,
        speed = a.max_speed_mps,
        sub = StaticSolve::default().substeps,
        it = StaticSolve::default().iterations,
    );
    std::fs::write(path, json).expect("write the bunny's JSON");
    println!(
        "bunny c{cell} E={young}: {} nodes, {} tets, {} fixed; ours: largest displacement {:.3} mm after {} steps (max speed {:.2e} m/s) -> {path}",
        m.nodes.len(),
        m.tets.len(),
        m.fixed.len(),
        a.value,
        a.steps,
        a.max_speed_mps
    );
}

/// The FEM's indentation answers (`indent.csv`, written by `scripts/fem-reference --indent`):
/// (law, element, k, depth mm) → force N. Columns are found by their names.
fn read_indent(path: &str) -> BTreeMap<(String, String, u32, String), f64> {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{path}: {e} (run scripts/fem-reference --indent)"));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("{path}: no column {name}"))
    };
    let (law, element, k, d, f) = (
        col("law"),
        col("element"),
        col("k"),
        col("d_mm"),
        col("force_n"),
    );
    let mut t = BTreeMap::new();
    for line in lines {
        let c: Vec<&str> = line.split(',').collect();
        let (Some(Ok(level)), Some(Ok(depth)), Some(Ok(force))) = (
            c.get(k).map(|v| v.parse::<u32>()),
            c.get(d).map(|v| v.parse::<f64>()),
            c.get(f).map(|v| v.parse::<f64>()),
        ) else {
            continue;
        };
        t.insert(
            (
                c[law].to_string(),
                c[element].to_string(),
                level,
                format!("{depth}"),
            ),
            force,
        );
    }
    t
}

/// The indentation: ours at `levels` (k, substeps) against the FEM's finest quadratic level
/// (the converged answer, with its change from the level before) and its linear tets at the
/// same level (the same discretization), and Hertz's half-space answer.
fn indentation(dir: &str, levels: &[(usize, u32)], lines: &mut Vec<String>, csv: &mut Csv) {
    let fem = read_indent(&format!("{dir}/indent.csv"));
    let depths = [0.25f32, 0.5, 1.0, 2.0, 4.0];
    for &(k, substeps) in levels {
        let solve = StaticSolve {
            substeps,
            ..StaticSolve::default()
        };
        for a in indent_slab(k, &depths, solve) {
            let d = format!("{}", f64::from(a.depth_mm));
            let at = |element: &str, level: u32| {
                fem.get(&("snh".to_string(), element.to_string(), level, d.clone()))
                    .copied()
            };
            let mut p2: Vec<u32> = fem
                .keys()
                .filter(|key| key.0 == "snh" && key.1 == "P2" && key.3 == d)
                .map(|key| key.2)
                .collect();
            p2.sort_unstable();
            let (Some(&finest), prev) = (p2.last(), p2.iter().rev().nth(1)) else {
                panic!("no P2 indentation answer at d = {d} mm in {dir}/indent.csv");
            };
            let converged = at("P2", finest).unwrap_or(f64::NAN);
            let change = prev
                .and_then(|&l| at("P2", l))
                .map_or(f64::NAN, |p| 100.0 * (converged - p) / p);
            let p1 = at("P1", k as u32);
            let ours = f64::from(a.force_n);
            let diff = 100.0 * (ours - converged) / converged;
            let diff_p1 = p1.map_or(f64::NAN, |p| 100.0 * (ours - p) / p);
            let line = ResultLine::new("reference.fem")
                .field("problem", "indent")
                .field("quantity", "force_n")
                .field("case", format!("d={d}mm"))
                .field("level", k)
                .fixed("fem", converged, 4)
                .fixed("fem_change_pct", change, 2)
                .field("fem_level", finest)
                .fixed("ours", ours, 4)
                .fixed("diff_pct", diff, 1)
                .fixed("fem_p1", p1.unwrap_or(f64::NAN), 4)
                .fixed("diff_p1_pct", diff_p1, 1)
                .fixed("hertz", f64::from(a.hertz_n), 4)
                .field("budget", format!("s{substeps}i{}", solve.iterations))
                .field("steps", a.solve.steps)
                .fixed("contact_radius_mm", f64::from(a.contact_radius_mm), 2)
                .field("inverted", a.inverted);
            println!("{line}");
            lines.push(line.to_string());
            csv.row([
                format!("indent force_n d={d}mm s{substeps}i{}", solve.iterations),
                k.to_string(),
                a.solve.nodes.to_string(),
                a.solve.steps.to_string(),
                format!("{ours:.5}"),
                p1.map_or(String::new(), |p| format!("{p:.5}")),
                format!("{converged:.5}"),
                format!("{diff_p1:.2}"),
                format!("{diff:.2}"),
            ]);
        }
    }
}

/// `ours.csv`: one row per problem, case and level.
fn ours_csv() -> Csv {
    Csv::new(&[
        "case",
        "level",
        "nodes",
        "steps",
        "ours",
        "fem_p1",
        "fem",
        "diff_p1_pct",
        "diff_pct",
    ])
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--bunny-export") {
        bunny_export(&args[1..]);
        return;
    }
    let quick = std::env::args().any(|a| a == "--quick");
    let dir = "docs/results/methods/fem";
    if args.first().map(String::as_str) == Some("--indent") {
        // the indentation alone, printed (nothing written)
        let mut csv = ours_csv();
        let mut lines = Vec::new();
        let levels: Vec<(usize, u32)> = args[1..]
            .chunks(2)
            .filter_map(|c| Some((c.first()?.parse().ok()?, c.get(1)?.parse().ok()?)))
            .collect();
        indentation(dir, &levels, &mut lines, &mut csv);
        return;
    }
    let fem = read_fem(&format!("{dir}/fem.csv"));
    let levels: &[usize] = if quick { &[2, 4] } else { &[2, 4, 8] };
    let mut csv = ours_csv();
    let mut lines = Vec::new();
    for (young, case) in [(1e6f32, "E=1e6 snh"), (1e5, "E=1e5 snh")] {
        // the converged answer: the finest quadratic level
        let Some((&(.., fem_level), &(fem_mm, fem_change))) = fem
            .iter()
            .filter(|(k, _)| k.0 == "cantilever" && k.2 == case && k.3 == "P2")
            .max_by_key(|(k, _)| k.4)
        else {
            panic!("no P2 answer for {case} in {dir}/fem.csv");
        };
        for &k in levels {
            let a = cantilever_tip_mm(young, k, StaticSolve::default());
            let p1 = fem
                .get(&(
                    "cantilever".into(),
                    "tip_mm".into(),
                    case.into(),
                    "P1".into(),
                    k as u32,
                ))
                .map(|v| v.0);
            let ours = f64::from(a.value);
            let diff = 100.0 * (ours - fem_mm) / fem_mm;
            let diff_p1 = p1.map(|p| 100.0 * (ours - p) / p);
            let line = ResultLine::new("reference.fem")
                .field("problem", "cantilever")
                .field("quantity", "tip_mm")
                .field("case", case.replace(' ', "_"))
                .field("level", k)
                .fixed("fem", fem_mm, 3)
                .fixed("fem_change_pct", fem_change.unwrap_or(f64::NAN), 2)
                .field("fem_level", fem_level)
                .fixed("ours", ours, 3)
                .fixed("diff_pct", diff, 1)
                .fixed("fem_p1", p1.unwrap_or(f64::NAN), 3)
                .fixed("diff_p1_pct", diff_p1.unwrap_or(f64::NAN), 1);
            println!("{line}");
            lines.push(line.to_string());
            csv.row([
                case.to_string(),
                k.to_string(),
                a.nodes.to_string(),
                a.steps.to_string(),
                format!("{ours:.4}"),
                p1.map_or(String::new(), |p| format!("{p:.4}")),
                format!("{fem_mm:.4}"),
                diff_p1.map_or(String::new(), |d| format!("{d:.2}")),
                format!("{diff:.2}"),
            ]);
        }
    }
    // The compression: homogeneous, so every level has the exact answer (the FEM's finest P2
    // level, which matches the closed form to 1e-11); ours at each level against it.
    let strains = [0.1f32, 0.2, 0.4, 0.7];
    // (level, substeps): the reference's budget (80 × 2) at every level, and at the finest
    // level four times the substeps too (is a miss the solver's budget or the problem?)
    let cube_runs: &[(usize, u32)] = if quick {
        &[(1, 80), (2, 80)]
    } else {
        &[(1, 80), (2, 80), (4, 80), (4, 320)]
    };
    for &(k, substeps) in cube_runs {
        let solve = StaticSolve {
            substeps,
            ..StaticSolve::default()
        };
        let answers = compress_cube(k, &strains, solve);
        for c in &answers {
            let case = format!("s={}", c.strain);
            for (quantity, ours) in [("force_n", c.force_n), ("bulge_mm", c.bulge_mm)] {
                let Some((&(.., fem_level), &(fem, fem_change))) = fem
                    .iter()
                    .filter(|(key, _)| {
                        key.0 == "compress" && key.1 == quantity && key.2 == case && key.3 == "P2"
                    })
                    .max_by_key(|(key, _)| key.4)
                else {
                    panic!("no P2 compress answer for {quantity} {case} in {dir}/fem.csv");
                };
                let ours = f64::from(ours);
                let diff = 100.0 * (ours - fem) / fem;
                let line = ResultLine::new("reference.fem")
                    .field("problem", "compress")
                    .field("quantity", quantity)
                    .field("case", &case)
                    .field("level", k)
                    .fixed("fem", fem, 3)
                    .fixed("fem_change_pct", fem_change.unwrap_or(0.0), 2)
                    .field("fem_level", fem_level)
                    .fixed("ours", ours, 3)
                    .fixed("diff_pct", diff, 2)
                    .field("budget", format!("s{substeps}i{}", solve.iterations))
                    .field("steps", c.solve.steps)
                    .field("inverted", c.inverted);
                println!("{line}");
                lines.push(line.to_string());
                csv.row([
                    format!(
                        "compress {quantity} {case} s{substeps}i{}",
                        solve.iterations
                    ),
                    k.to_string(),
                    c.solve.nodes.to_string(),
                    c.solve.steps.to_string(),
                    format!("{ours:.4}"),
                    String::new(),
                    format!("{fem:.4}"),
                    String::new(),
                    format!("{diff:.2}"),
                ]);
            }
        }
    }
    // The indentation: the same discretization as the FEM's P1 at k = 6 and 12 (5 and 2.5 mm
    // cells), at the reference's budget, and at k = 6 also four times the substeps (about 7
    // minutes: at 2.5 mm cells that budget would take the better part of an hour).
    let indent_levels: &[(usize, u32)] = if quick {
        &[(6, 80)]
    } else {
        &[(6, 80), (6, 320), (12, 80)]
    };
    indentation(dir, indent_levels, &mut lines, &mut csv);
    if !quick {
        csv.write(format!("{dir}/ours.csv"))
            .expect("write ours.csv");
        std::fs::write(format!("{dir}/results.txt"), lines.join("\n") + "\n")
            .expect("write results.txt");
    }
}
