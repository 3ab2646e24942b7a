//! Regenerates the soft-body benchmark tables and charts (thesis Tables 2–8, rapier's own soft
//! bodies side by side, step time against shape accuracy).
//!
//! `cargo run --release -p softsync-softbody --example softbody_tables -- [--quick]`
//!
//! `--quick` times fewer runs (init medians of 3, the step table on icosphere4 only) but
//! measures every figure of the `RESULT` lines exactly as the full run does (same scenario,
//! same steps, same bodies), so its ratios agree with the full run's within noise.
//!
//! Writes `docs/results/softbody/{init,step,accuracy,native}.csv`, `accuracy.svg`,
//! `README.md`, and prints `RESULT` lines.
#![allow(
    clippy::disallowed_methods,
    clippy::unwrap_used,
    clippy::print_stdout,
    missing_docs
)]

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use softsync_benchkit::plotters::style::{BLUE, GREEN, MAGENTA, RED};
use softsync_benchkit::{
    thesis, write_svg, ChartStyle, Csv, LineChart, ResultLine, Series, Summary,
};
use softsync_softbody::rapier3d::prelude::{
    ColliderBuilder, PhysicsWorld, RigidBodyBuilder, SoftBodyBuilder,
};
use softsync_softbody::scenario::{Scenario, ScenarioKind};
use softsync_softbody::{build_particle_map, ClusterMethod, Mesh, SoftBodyConfig};

/// Min, median and max of timings (there is always at least one run).
fn stats(v: Vec<f64>) -> Summary {
    Summary::of(&v).unwrap()
}

fn welded(mesh: &Mesh) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let w = mesh.weld(1e-6);
    (w.positions, w.triangles)
}

/// A method of the given kind tuned (bisection on its radius) to give about `target` particles.
fn method_for(kind: &str, p: &[Vec3], t: &[[u32; 3]], target: usize) -> ClusterMethod {
    let make = |r: f32| match kind {
        "distance" => ClusterMethod::Distance { radius_m: r },
        "weighted" => ClusterMethod::WeightedDistance {
            radius_m: r,
            soft_radius_m: 1.6 * r,
        },
        _ => ClusterMethod::PoissonDisk {
            radius_m: r,
            seed: 1,
        },
    };
    if kind == "closest_n" {
        return ClusterMethod::ClosestN {
            vertices_per_particle: ((p.len() as f32 / target as f32).round() as u32).max(1),
        };
    }
    let soft = vec![true; p.len()];
    let (lo, hi) = softsync_softbody::mesh::bounds(p);
    let (mut a, mut b) = (1e-5f32, (hi - lo).max_element());
    let mut best = make(b);
    let mut best_err = usize::MAX;
    for _ in 0..24 {
        let r = (a * b).sqrt();
        let n = build_particle_map(p, t, &soft, make(r), 0.0).unwrap().len();
        if n.abs_diff(target) < best_err {
            best_err = n.abs_diff(target);
            best = make(r);
        }
        if n > target {
            a = r;
        } else {
            b = r;
        }
    }
    best
}

fn time_ms(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64() * 1e3
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let reps = if quick { 3 } else { 11 };
    let out = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/results/softbody");
    std::fs::create_dir_all(&out).unwrap();
    let bunny = Mesh::load(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/bunny.obj"))
        .unwrap()
        .fit_size(0.2);
    let ico = Mesh::icosphere(0.1, 4);
    let meshes = [("bunny", &bunny), ("icosphere4", &ico)];
    let kinds = ["closest_n", "distance", "weighted", "poisson"];
    let targets = [250usize, 430, 860];
    let mut md = String::new();
    let mut results = Vec::new();

    // ---- Tables 2–4: init time per clustering method.
    let mut csv = Csv::new(&[
        "mesh",
        "vertices",
        "method",
        "target",
        "particles",
        "cluster_ms",
        "insert_ms",
    ]);
    writeln!(
        md,
        "## Init time per clustering method (thesis Tables 2–4)\n"
    )
    .unwrap();
    writeln!(md, "Median of {reps} runs. `cluster` = clustering + particle map (+ neighbours); `insert` = the whole soft body with its rapier bodies.\n").unwrap();
    writeln!(md, "| mesh | vertices | method | particles | cluster ms | insert ms |\n|---|---|---|---|---|---|").unwrap();
    let mut init_max: std::collections::BTreeMap<&str, f64> = Default::default();
    for (mname, mesh) in meshes {
        let (p, t) = welded(mesh);
        for kind in kinds {
            for &target in &targets {
                let m = method_for(kind, &p, &t, target);
                let soft = vec![true; p.len()];
                let mut n = 0;
                let cl = stats(
                    (0..reps)
                        .map(|_| {
                            time_ms(|| {
                                n = build_particle_map(&p, &t, &soft, m, 0.03).unwrap().len()
                            })
                        })
                        .collect(),
                );
                let ins = stats(
                    (0..reps)
                        .map(|_| {
                            let mut world = PhysicsWorld::new();
                            let mut set = softsync_softbody::SoftBodySet::new();
                            let cfg = SoftBodyConfig {
                                cluster: m,
                                ..Default::default()
                            };
                            time_ms(|| {
                                set.insert(mesh, cfg, &mut world).unwrap();
                            })
                        })
                        .collect(),
                );
                csv.row([
                    mname.to_string(),
                    p.len().to_string(),
                    kind.to_string(),
                    target.to_string(),
                    n.to_string(),
                    format!("{:.3}", cl.median),
                    format!("{:.3}", ins.median),
                ]);
                writeln!(
                    md,
                    "| {mname} | {} | {kind} | {n} | {:.2} | {:.2} |",
                    p.len(),
                    cl.median,
                    ins.median
                )
                .unwrap();
                if mname == "icosphere4" {
                    let e = init_max.entry(kind).or_insert(0.0);
                    *e = e.max(cl.median);
                }
            }
        }
    }
    csv.write(out.join("init.csv")).unwrap();
    results.push(
        init_max
            .iter()
            .fold(ResultLine::new("softbody.init icosphere4"), |l, (k, v)| {
                l.fixed(&format!("{k}_ms"), *v, 2)
            }),
    );

    // ---- Tables 5–8: step time, and accuracy against a dense reference.
    // Not shortened by --quick: the RESULT ratios compare these runs, and a shorter run
    // measures a different part of the scenario (the rapier shell before it lands).
    let steps = 270;
    let dt = 1.0 / 90.0;
    let mut csv = Csv::new(&[
        "mesh",
        "vertices",
        "method",
        "particles",
        "min_ms",
        "median_ms",
        "max_ms",
        "poke_rms_mm",
        "squeeze_rms_mm",
    ]);
    writeln!(
        md,
        "\n## Step time incl. deformation of all vertices (thesis Tables 5–8)\n"
    )
    .unwrap();
    writeln!(md, "Poke scenario at 90 Hz, {steps} steps, every particle kept awake (`particles_can_sleep: false`). Error: RMS vertex distance to the dense reference (every vertex a particle) at the same times, mean over the run.\n").unwrap();
    writeln!(md, "| mesh | method | particles | min ms | median ms | max ms | poke rms mm | squeeze rms mm |\n|---|---|---|---|---|---|---|---|").unwrap();
    let trace = |kind: ScenarioKind,
                 mesh: &Mesh,
                 cfg: SoftBodyConfig,
                 steps: usize|
     -> (Vec<f64>, Vec<Vec<Vec3>>) {
        let mut s = Scenario::new(kind, mesh, cfg, dt).unwrap();
        let mut times = Vec::with_capacity(steps);
        let mut snaps = Vec::new();
        for i in 0..steps {
            times.push(time_ms(|| s.step()));
            if i % 9 == 8 {
                snaps.push(s.soft_body().vertices().to_vec());
            }
        }
        (times, snaps)
    };
    let err = |a: &[Vec<Vec3>], b: &[Vec<Vec3>]| -> f64 {
        let mut sum = 0.0;
        let mut n = 0usize;
        for (x, y) in a.iter().zip(b) {
            for (p, q) in x.iter().zip(y) {
                sum += p.distance_squared(*q) as f64;
                n += 1;
            }
        }
        (sum / n.max(1) as f64).sqrt() * 1e3
    };
    let mut curves: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    let mut p860_median = 0.0;
    // (mesh, method, particles, min, median, max) of every timed row, for Tables 5-8.
    let mut step_rows: Vec<(&str, &str, usize, f64, f64, f64)> = Vec::new();
    let mut p860_sleep_median = 0.0;
    // --quick: the step table on icosphere4 only (the RESULT lines and the chart use it).
    let step_meshes = if quick { &meshes[1..] } else { &meshes[..] };
    let progress =
        softsync_benchkit::Progress::new((step_meshes.len() * kinds.len()) as u64, "step table");
    for &(mname, mesh) in step_meshes {
        let (p, t) = welded(mesh);
        let dense = SoftBodyConfig {
            cluster: ClusterMethod::ClosestN {
                vertices_per_particle: 1,
            },
            particles_can_sleep: false,
            ..Default::default()
        };
        let (_, ref_poke) = trace(ScenarioKind::Poke, mesh, dense.clone(), steps);
        let (_, ref_sq) = trace(ScenarioKind::Squeeze, mesh, dense, steps);
        for kind in kinds {
            progress.set_message(format!("{mname} {kind}"));
            let mut curve = Vec::new();
            for &target in &[120usize, 250, 430, 860] {
                let m = method_for(kind, &p, &t, target);
                let cfg = SoftBodyConfig {
                    cluster: m,
                    particles_can_sleep: false,
                    ..Default::default()
                };
                let n = build_particle_map(&p, &t, &vec![true; p.len()], m, 0.0)
                    .unwrap()
                    .len();
                let (times, poke) = trace(ScenarioKind::Poke, mesh, cfg.clone(), steps);
                let (_, sq) = trace(ScenarioKind::Squeeze, mesh, cfg, steps);
                let st = stats(times);
                step_rows.push((mname, kind, n, st.min, st.median, st.max));
                let (e1, e2) = (err(&poke, &ref_poke), err(&sq, &ref_sq));
                csv.row([
                    mname.to_string(),
                    p.len().to_string(),
                    kind.to_string(),
                    n.to_string(),
                    format!("{:.4}", st.min),
                    format!("{:.4}", st.median),
                    format!("{:.4}", st.max),
                    format!("{e1:.3}"),
                    format!("{e2:.3}"),
                ]);
                if target != 120 {
                    writeln!(
                        md,
                        "| {mname} | {kind} | {n} | {:.3} | {:.3} | {:.3} | {e1:.2} | {e2:.2} |",
                        st.min, st.median, st.max
                    )
                    .unwrap();
                }
                if mname == "icosphere4" {
                    curve.push((st.median, 0.5 * (e1 + e2)));
                    if kind == "distance" && target == 860 {
                        p860_median = st.median;
                        // The same body with sleeping allowed: what an untouched region costs.
                        let cfg = SoftBodyConfig {
                            cluster: m,
                            ..Default::default()
                        };
                        p860_sleep_median =
                            stats(trace(ScenarioKind::Poke, mesh, cfg, steps).0).median;
                    }
                }
            }
            if mname == "icosphere4" {
                curves.push((kind.to_string(), curve));
            }
            progress.inc();
        }
    }
    progress.finish();
    csv.write(out.join("step.csv")).unwrap();

    // ---- Tables 5-8 side by side with the thesis's figures.
    writeln!(md, "\n## Tables 5–8 beside the thesis\n\nThe thesis's step times (Unity + PhysX, its machine) and ours (rapier, this machine, every particle awake), the nearest of our particle counts to each of its rows. The thesis's 1731-vertex mesh is replaced by the nearest we have, the bunny (1839 vertices); its 2562-vertex sphere is our icosphere4 (2562 vertices). Hard clustering = ours by distance, soft = weights by distance. Our times are of the whole step (restoring velocities, rapier, deformation of every vertex); the thesis's are its simulation time.\n\n| table | mesh (vertices) | clustering | thesis particles | thesis min ms | thesis max ms | our particles | our min ms | our median ms | our max ms | thesis min / our median |\n|---|---|---|---|---|---|---|---|---|---|---|").unwrap();
    for (table, mesh, kind, rows) in [
        (5, "bunny", "distance", thesis::TABLE5),
        (6, "bunny", "weighted", thesis::TABLE6),
        (7, "icosphere4", "distance", thesis::TABLE7),
        (8, "icosphere4", "weighted", thesis::TABLE8),
    ] {
        let ours: Vec<_> = step_rows
            .iter()
            .filter(|r| r.0 == mesh && r.1 == kind)
            .collect();
        let vertices = if mesh == "bunny" { 1839 } else { 2562 };
        for (tp, tmin, tmax) in rows {
            let Some(o) = ours.iter().min_by_key(|r| r.2.abs_diff(tp as usize)) else {
                writeln!(md, "| {table} | {mesh} ({vertices}) | {kind} | {tp} | {tmin} | {tmax} | not run (--quick) | | | | |").unwrap();
                continue;
            };
            writeln!(
                md,
                "| {table} | {mesh} ({vertices}) | {kind} | {tp} | {tmin} | {tmax} | {} | {:.3} | {:.3} | {:.3} | {:.0}× |",
                o.2, o.3, o.4, o.5, tmin as f64 / o.4
            )
            .unwrap();
        }
    }

    // ---- Where the 860-particle step goes: restoring velocities, rapier, deformation.
    let breakdown = {
        let (p, t) = welded(&ico);
        let m = method_for("distance", &p, &t, 860);
        let mut world = PhysicsWorld::new();
        let mut set = softsync_softbody::SoftBodySet::new();
        let cfg = SoftBodyConfig {
            cluster: m,
            particles_can_sleep: false,
            space: softsync_softbody::SimulationSpace::Local,
            ..Default::default()
        };
        let h = set.insert(&ico, cfg, &mut world).unwrap();
        world.integration_parameters.dt = dt;
        let (mut a, mut b, mut c) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..steps {
            // Keep it deforming: one particle circles.
            let goal = Vec3::new(
                0.1 + 0.02 * (i as f32 * 0.1).cos(),
                0.02 * (i as f32 * 0.1).sin(),
                0.0,
            );
            set.get_mut(h).unwrap().set_particle_drive(0, Some(goal));
            a.push(time_ms(|| set.pre_physics(&mut world, dt)));
            b.push(time_ms(|| world.step()));
            c.push(time_ms(|| set.post_physics(&world)));
        }
        (stats(a).median, stats(b).median, stats(c).median)
    };
    writeln!(md, "\nBreakdown of one 860-particle step (icosphere4, all awake): restoring velocities {:.3} ms, rapier step {:.3} ms, deformation + normals {:.3} ms.", breakdown.0, breakdown.1, breakdown.2).unwrap();

    // ---- Bare rapier: 860 free spheres (the floor under our overhead).
    let bare = {
        let mut w = PhysicsWorld::new();
        w.gravity = Vec3::ZERO;
        for i in 0..860 {
            let h = w.insert_body(
                RigidBodyBuilder::dynamic()
                    .translation(Vec3::new(
                        (i % 30) as f32 * 0.02,
                        (i / 30) as f32 * 0.02,
                        0.0,
                    ))
                    .linvel(Vec3::X * 0.01)
                    // Our particles' rapier settings (soft CCD, explicit mass).
                    .soft_ccd_prediction(0.05)
                    .can_sleep(false),
            );
            w.insert_collider(ColliderBuilder::ball(0.005).mass(0.05), Some(h));
        }
        w.integration_parameters.dt = dt;
        stats((0..steps).map(|_| time_ms(|| w.step())).collect()).median
    };

    // ---- rapier 0.36's own soft bodies on the same mesh, same run.
    let native_steps = 45;
    let mut csv = Csv::new(&["body", "particles", "min_ms", "median_ms", "max_ms"]);
    writeln!(
        md,
        "\n## rapier 0.36's own soft bodies (outside baseline), same run\n"
    )
    .unwrap();
    writeln!(md, "Dropped on a floor, `can_sleep(false)` so every frame is active; {native_steps} steps at 90 Hz.\n").unwrap();
    writeln!(
        md,
        "| body | particles | min ms | median ms | max ms |\n|---|---|---|---|---|"
    )
    .unwrap();
    let mut native_shell = f64::NAN;
    let (ip, it) = welded(&ico);
    let (bp, bt) = welded(&bunny);
    let natives: Vec<(&str, Option<SoftBodyBuilder>)> = vec![
        (
            "sphere_shell_ico4",
            Some(SoftBodyBuilder::sphere(Vec3::new(0.0, 0.3, 0.0), 0.1, 4)),
        ),
        (
            "volumetric_skinned_ico4",
            SoftBodyBuilder::volumetric_skinned(&ip, &it, 0.03)
                .map(|b| b.translated(Vec3::new(0.0, 0.3, 0.0))),
        ),
        (
            "trimesh_bunny",
            SoftBodyBuilder::trimesh(bp.clone(), bt.clone())
                .map(|b| b.translated(Vec3::new(0.0, 0.3, 0.0))),
        ),
        (
            "volumetric_skinned_bunny",
            SoftBodyBuilder::volumetric_skinned(&bp, &bt, 0.03)
                .map(|b| b.translated(Vec3::new(0.0, 0.3, 0.0))),
        ),
    ];
    for (name, builder) in natives {
        let Some(builder) = builder else {
            writeln!(md, "| {name} | – | builder returned None | | |").unwrap();
            continue;
        };
        let mut w = PhysicsWorld::new();
        w.integration_parameters.dt = dt;
        let floor = w.insert_body(RigidBodyBuilder::fixed());
        w.insert_collider(ColliderBuilder::cuboid(5.0, 0.05, 5.0), Some(floor));
        let h = w.insert_soft_body(builder.can_sleep(false));
        let n = w.soft_bodies.get(h).map(|b| b.num_particles()).unwrap_or(0);
        let st = stats((0..native_steps).map(|_| time_ms(|| w.step())).collect());
        csv.row([
            name.to_string(),
            n.to_string(),
            format!("{:.3}", st.min),
            format!("{:.3}", st.median),
            format!("{:.3}", st.max),
        ]);
        writeln!(
            md,
            "| {name} | {n} | {:.2} | {:.2} | {:.2} |",
            st.min, st.median, st.max
        )
        .unwrap();
        if name == "sphere_shell_ico4" {
            native_shell = st.median;
        }
    }
    csv.write(out.join("native.csv")).unwrap();
    writeln!(
        md,
        "\nBare rapier world of 860 free spheres drifting at 1 cm/s, with our particles' rapier settings and no soft-body code: median {bare:.3} ms/step (rapier's cost depends on how bodies move; our particles mostly hold still relative to the broad phase)."
    )
    .unwrap();
    results.push(
        ResultLine::new("softbody.step icosphere4_p860")
            .fixed("median_ms", p860_median, 3)
            .fixed("rapier_native_ratio", native_shell / p860_median, 1)
            .fixed("bare_rapier_ms", bare, 3)
            .fixed("sleeping_allowed_median_ms", p860_sleep_median, 3),
    );

    // ---- Chart: step time against accuracy.
    let xmax = curves
        .iter()
        .flat_map(|c| c.1.iter().map(|p| p.0))
        .fold(0.0, f64::max)
        * 1.15;
    let ymax = curves
        .iter()
        .flat_map(|c| c.1.iter().map(|p| p.1))
        .fold(0.0, f64::max)
        * 1.15;
    let chart = LineChart {
        title: "icosphere4 (2562 v): step time vs error to the dense reference".to_owned(),
        x_desc: "median step ms (incl. deformation)".to_owned(),
        y_desc: "RMS error mm (poke+squeeze)".to_owned(),
        x_range: 0.0..xmax.max(1e-3),
        x_log: false,
        y_range: 0.0..ymax.max(1e-3),
        series: curves
            .iter()
            .zip([RED, BLUE, GREEN, MAGENTA])
            .map(|((name, pts), col)| Series::new(name.as_str(), col, pts.clone()))
            .collect(),
        style: ChartStyle::FIGURE,
    };
    write_svg(out.join("accuracy.svg"), (820, 560), &[chart]).unwrap();
    let mut acc = Csv::new(&["method", "median_ms", "rms_mm"]);
    for (name, pts) in &curves {
        for p in pts {
            acc.row([name.clone(), format!("{:.4}", p.0), format!("{:.3}", p.1)]);
        }
    }
    acc.write(out.join("accuracy.csv")).unwrap();
    writeln!(md, "\n![step time vs error](accuracy.svg)\n").unwrap();
    let results: Vec<String> = results.iter().map(ResultLine::to_string).collect();
    writeln!(md, "```\n{}\n```", results.join("\n")).unwrap();
    let header = format!(
        "# Soft-body benchmark results\n\nGenerated by `cargo run --release -p softsync-softbody --example softbody_tables{}` on a {}-core machine. Do not edit by hand.{}\n\n",
        if quick { " -- --quick" } else { "" },
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        if quick {
            " Quick run: init medians of 3 runs and the step table on icosphere4 only; the RESULT figures are measured exactly as in the full run."
        } else {
            ""
        }
    );
    std::fs::write(out.join("README.md"), header + &md).unwrap();
    println!("{md}");
    for r in &results {
        println!("{r}");
    }
}
