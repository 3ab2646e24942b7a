//! Section 5 of the evidence: where every method fails. Two maps — the throw at a thin wall
//! (stiffness × step rate × speed) and the harder cases (a throw into a corner under gravity,
//! a fast squeeze; step rate × the body's mass from 1 g to 10 kg) — and each method's boundary
//! written as a sentence a user can act on.

use std::fmt::Write as _;
use std::path::Path;

use softsync_benchkit::plotters::prelude::*;
use softsync_benchkit::{Csv, ResultLine};
use softsync_softbody::methods::builders::plain_pbd;
use softsync_softbody::methods::pbd::SolverKind;
use softsync_softbody::methods::scene::ModelScene;
use softsync_softbody::methods::{MethodKind, MethodSpec};
use softsync_softbody::{Mesh, RestoringScheme};

/// One run's verdict: "ok" or the first failure ("nan", "exploded", "inverted", "tunnelled").
fn verdict(
    scene: Result<ModelScene, softsync_softbody::SoftBodyError>,
    steps: usize,
) -> &'static str {
    let Ok(mut s) = scene else {
        return "build_error";
    };
    for _ in 0..steps {
        s.step();
        let san = s.sanity();
        if !san.ok() {
            return san.verdict();
        }
    }
    s.sanity().verdict()
}

/// A method's map: its label and its cells (row, column, sane).
struct Map {
    label: String,
    cells: Vec<(usize, usize, bool)>,
    verdicts: Vec<(String, &'static str)>,
}

/// The methods of both maps: every method at its default, the thesis's original restoring
/// scheme, self-collisions and no rolling resistance for the particle method, plain PBD for ISPC, and the reference.
fn methods() -> Vec<MethodSpec> {
    vec![
        MethodSpec::new(MethodKind::Particle),
        // without rolling resistance (its default is 0.05): what that setting changes
        MethodSpec::new(MethodKind::Particle).rolling_resistance(0.0),
        MethodSpec::new(MethodKind::Particle).restoring(RestoringScheme::Thesis),
        MethodSpec::new(MethodKind::Particle).self_collisions(true),
        MethodSpec::new(MethodKind::Surface).budget(2, 4),
        MethodSpec::new(MethodKind::Ispc).budget(2, 4),
        plain_pbd(MethodSpec::new(MethodKind::Ispc).budget(2, 4)),
        MethodSpec::new(MethodKind::Tet).budget(2, 4),
        MethodSpec::new(MethodKind::ShapeMatching).budget(2, 1),
        MethodSpec::new(MethodKind::RapierNative),
        MethodSpec::new(MethodKind::NeoHookean)
            .cell(0.2)
            .budget(20, 1),
    ]
}

fn label(m: &MethodSpec) -> String {
    match m.params.solver {
        SolverKind::Pbd => format!("{} (plain PBD)", m.label()),
        SolverKind::Xpbd => m.label(),
    }
}

/// Draws `maps` as panels of green (sane) and red cells.
fn draw(path: &Path, maps: &[Map], rows: &[String], cols: &[String]) {
    let ncols = 4;
    let nrows = maps.len().div_ceil(ncols);
    let root = SVGBackend::new(path, (1200, 330 * nrows as u32)).into_drawing_area();
    root.fill(&WHITE).unwrap();
    let panels = root.split_evenly((nrows, ncols));
    for (panel, map) in panels.iter().zip(maps) {
        let mut c = ChartBuilder::on(panel)
            .caption(map.label.as_str(), ("sans-serif", 13))
            .margin(6)
            .x_label_area_size(30)
            .y_label_area_size(96)
            .build_cartesian_2d(0..cols.len(), 0..rows.len())
            .unwrap();
        c.configure_mesh()
            .disable_mesh()
            .x_labels(cols.len())
            .x_label_formatter(&|i| cols.get(*i).cloned().unwrap_or_default())
            .y_labels(rows.len())
            .y_label_formatter(&|j| rows.get(*j).cloned().unwrap_or_default())
            .label_style(("sans-serif", 10))
            .draw()
            .unwrap();
        c.draw_series(map.cells.iter().map(|&(row, col, ok)| {
            Rectangle::new(
                [(col, row), (col + 1, row + 1)],
                if ok {
                    RGBColor(120, 200, 120).filled()
                } else {
                    RGBColor(220, 80, 80).filled()
                },
            )
        }))
        .unwrap();
    }
    root.present().unwrap();
}

/// The failing cases of a map, grouped by verdict: "inverted: k×1 30 Hz 5 m/s, …".
fn failures(map: &Map) -> String {
    let mut by: std::collections::BTreeMap<&str, Vec<&str>> = Default::default();
    for (case, v) in &map.verdicts {
        if *v != "ok" {
            by.entry(v).or_default().push(case);
        }
    }
    if by.is_empty() {
        return "none".into();
    }
    by.iter()
        .map(|(v, cases)| format!("{v} ({}): {}", cases.len(), cases.join(", ")))
        .collect::<Vec<_>>()
        .join("; ")
}

/// Writes section 5 into `md`, the maps' CSV and SVG files into `out`, RESULT lines into
/// `results`; returns a one-line boundary per method label.
pub fn section(
    md: &mut String,
    results: &mut Vec<ResultLine>,
    out: &Path,
) -> Vec<(String, String)> {
    let small = Mesh::icosphere(0.1, 2);
    let volume = {
        let w = small.weld(1e-6);
        softsync_softbody::mesh::enclosed_volume(&w.positions, &w.triangles)
    };
    let stiff = [0.2f32, 1.0, 5.0, 25.0];
    let rates = [30.0f32, 60.0, 90.0, 144.0];
    let speeds = [0.0f32, 2.5, 5.0, 10.0];
    let hard_rates = [30.0f32, 60.0, 144.0];
    let masses = [0.001f32, 0.1, 1.0, 10.0];
    let methods = methods();
    let mut csv = Csv::new(&[
        "map", "method", "case", "rate_hz", "axis", "value", "verdict",
    ]);
    writeln!(md, "## 5. Where every method fails\n\n### The throw at a wall\n\nIcosphere (162 vertices, 0.2 m, {:.2} kg at the default density) thrown weightless at a fixed wall 1 cm thick for 1 s; stiffness factor × the default material (Young's modulus for the position-based methods, restoring rate for the particle method, spring frequency² for rapier's); sane = no NaN, no vertex beyond 2 sizes from the centroid or faster than 100 m/s, no inverted tet at any step, no vertex past the wall. New here: the particle method with the thesis's own restoring scheme (`thesis`) and with self-collisions on (`selfcol`), and the reference (`neo_hookean`, at a coarse cell).\n\n![stability](stability.svg)\n\n| method | sane runs | failing cases |\n|---|---|---|", volume * 1000.0).unwrap();
    let mut wall_maps = Vec::new();
    for m in &methods {
        let mut map = Map {
            label: label(m),
            cells: Vec::new(),
            verdicts: Vec::new(),
        };
        for (si, &k) in stiff.iter().enumerate() {
            for (ri, &hz) in rates.iter().enumerate() {
                for (vi, &v) in speeds.iter().enumerate() {
                    let mut spec = *m;
                    spec.material.young_pa *= k;
                    spec.material.bulk_pa *= k;
                    spec.material.shape_rate_per_s *= k.sqrt();
                    let scene = ModelScene::impact(&small, &spec, 1.0 / hz, v);
                    let verdict = verdict(scene, hz as usize);
                    csv.row([
                        "wall".to_string(),
                        map.label.clone(),
                        format!("k×{k}"),
                        hz.to_string(),
                        "speed_mps".into(),
                        v.to_string(),
                        verdict.to_string(),
                    ]);
                    map.cells.push((si * rates.len() + ri, vi, verdict == "ok"));
                    map.verdicts
                        .push((format!("k×{k} {hz:.0} Hz {v} m/s"), verdict));
                }
            }
        }
        let okc = map.cells.iter().filter(|c| c.2).count();
        writeln!(
            md,
            "| `{}` | {okc}/{} | {} |",
            map.label,
            map.cells.len(),
            failures(&map)
        )
        .unwrap();
        results.push(
            ResultLine::new(format!("methods.stability {}", map.label.replace(' ', "_")))
                .field("sane", format_args!("{okc}/{}", map.cells.len())),
        );
        println!("  wall map {}: {okc}/{}", map.label, map.cells.len());
        wall_maps.push(map);
    }
    let rows: Vec<String> = stiff
        .iter()
        .flat_map(|k| rates.iter().map(move |r| format!("k×{k} {r:.0}Hz")))
        .collect();
    let cols: Vec<String> = speeds.iter().map(|v| format!("{v} m/s")).collect();
    draw(&out.join("stability.svg"), &wall_maps, &rows, &cols);

    // The harder cases.
    let corner_speed = 10.0f32;
    let close_s = 0.1f32;
    writeln!(md, "\n### Harder cases\n\nThe same icosphere at its default stiffness, its mass set from 1 g to 10 kg (density scaled; the particle method's particle and center masses scaled alike), stepped at 30, 60 and 144 Hz for 1 s: **corner** — under gravity, thrown at {corner_speed} m/s diagonally into the corner of two fixed walls 1 cm thick over a floor 1 cm thick (nothing may end beyond a wall or under the floor); **fast squeeze** — the squeeze's plates close to 30 % of the height in {close_s} s instead of 0.8 s (a kinematic prop faster than any hand).\n\n![harder cases](stability_hard.svg)\n\n| method | sane runs | failing cases |\n|---|---|---|").unwrap();
    let cases = ["corner", "fast squeeze"];
    let mut hard_maps = Vec::new();
    for m in &methods {
        let mut map = Map {
            label: label(m),
            cells: Vec::new(),
            verdicts: Vec::new(),
        };
        for (ci, case) in cases.iter().enumerate() {
            for (ri, &hz) in hard_rates.iter().enumerate() {
                for (mi, &mass) in masses.iter().enumerate() {
                    let spec = m.total_mass(mass, volume);
                    let scene = match ci {
                        0 => ModelScene::corner_throw(&small, &spec, 1.0 / hz, corner_speed),
                        _ => ModelScene::fast_squeeze(&small, &spec, 1.0 / hz, close_s),
                    };
                    let verdict = verdict(scene, hz as usize);
                    csv.row([
                        "hard".to_string(),
                        map.label.clone(),
                        case.to_string(),
                        hz.to_string(),
                        "mass_kg".into(),
                        mass.to_string(),
                        verdict.to_string(),
                    ]);
                    map.cells
                        .push((ci * hard_rates.len() + ri, mi, verdict == "ok"));
                    map.verdicts
                        .push((format!("{case} {hz:.0} Hz {mass} kg"), verdict));
                }
            }
        }
        let okc = map.cells.iter().filter(|c| c.2).count();
        writeln!(
            md,
            "| `{}` | {okc}/{} | {} |",
            map.label,
            map.cells.len(),
            failures(&map)
        )
        .unwrap();
        results.push(
            ResultLine::new(format!(
                "methods.stability_hard {}",
                map.label.replace(' ', "_")
            ))
            .field("sane", format_args!("{okc}/{}", map.cells.len())),
        );
        println!("  hard map {}: {okc}/{}", map.label, map.cells.len());
        hard_maps.push(map);
    }
    csv.write(out.join("stability.csv")).unwrap();
    let rows: Vec<String> = cases
        .iter()
        .flat_map(|c| hard_rates.iter().map(move |r| format!("{c} {r:.0}Hz")))
        .collect();
    let cols: Vec<String> = masses.iter().map(|m| format!("{m} kg")).collect();
    draw(&out.join("stability_hard.svg"), &hard_maps, &rows, &cols);

    // Boundaries as sentences.
    let mut sentences = Vec::new();
    for (wall, hard) in wall_maps.iter().zip(&hard_maps) {
        sentences.push((
            wall.label.clone(),
            boundary(wall, hard, &stiff, &rates, &speeds),
        ));
    }
    writeln!(md, "\n### Each method's boundary\n").unwrap();
    for (label, s) in &sentences {
        writeln!(md, "- `{label}`: {s}").unwrap();
    }
    sentences
}

/// A method's boundary in words, from its two maps.
fn boundary(wall: &Map, hard: &Map, stiff: &[f32], rates: &[f32], speeds: &[f32]) -> String {
    let ok = |m: &Map, f: &dyn Fn(&str) -> bool| {
        m.verdicts
            .iter()
            .filter(|(c, _)| f(c))
            .all(|(_, v)| *v == "ok")
    };
    // The fastest throw up to which every throw is sane, at every stiffness and rate.
    let fastest = speeds
        .iter()
        .take_while(|&&v| ok(wall, &|c: &str| c.ends_with(&format!(" {v} m/s"))))
        .last()
        .copied();
    let all_wall = wall.verdicts.iter().all(|(_, v)| *v == "ok");
    let all_hard = hard.verdicts.iter().all(|(_, v)| *v == "ok");
    let mut s = if all_wall {
        format!(
            "sane in every throw at the wall (stiffness ×{}–×{}, {}–{} Hz, up to {} m/s)",
            stiff[0],
            stiff[stiff.len() - 1],
            rates[0],
            rates[rates.len() - 1],
            speeds[speeds.len() - 1]
        )
    } else {
        let first = wall
            .verdicts
            .iter()
            .find(|(_, v)| *v != "ok")
            .map(|(c, v)| format!("{c} ({v})"))
            .unwrap_or_default();
        match fastest {
            Some(v) if v > 0.0 => format!(
                "at the wall, sane at every stiffness and rate up to {v} m/s; first failure {first}"
            ),
            Some(_) => {
                format!("at the wall, sane only at rest: any throw fails somewhere ({first} first)")
            }
            None => format!("at the wall, fails even at rest ({first})"),
        }
    };
    if all_hard {
        s += "; sane in every corner throw and fast squeeze from 1 g to 10 kg at 30–144 Hz";
    } else {
        let bad: Vec<String> = hard
            .verdicts
            .iter()
            .filter(|(_, v)| *v != "ok")
            .map(|(c, v)| format!("{c} ({v})"))
            .collect();
        s += &format!(
            "; in the harder cases it fails {} of {}: {}",
            bad.len(),
            hard.verdicts.len(),
            bad.join(", ")
        );
    }
    s + "."
}
