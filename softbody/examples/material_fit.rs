//! Each method's knobs as a material (issue 33 point 3): the effective Young's modulus and
//! Poisson's ratio of each particle-method setting, per step rate, and of each position-based
//! method at the evidence's settings (60 Hz; against the material it is given), fitted on the
//! static compression (`softsync_softbody::methods::material`), and named materials turned
//! into particle settings.
//!
//! `cargo run --release -p softsync-softbody --example material_fit [-- --quick]`
//!
//! Prints `RESULT material.fit …` (one per setting and rate) and `RESULT material.named …`
//! (one per named material) lines; writes `docs/results/methods/material.csv` and
//! `material.txt` (the RESULT lines) unless `--quick`. The body: a 0.2 m cube (the bunny's
//! size) of the default particle config.
#![allow(clippy::disallowed_methods, clippy::unwrap_used, missing_docs)]

use softsync_benchkit::{Csv, ResultLine};
use softsync_softbody::methods::material::{
    fit_material, measure_particle_compression, measure_pbd_compression, particle_setting,
    Compression, MaterialFit, NamedMaterial,
};
use softsync_softbody::methods::{MethodKind, MethodSpec};
use softsync_softbody::SoftBodyConfig;

const SIZE_M: f32 = 0.2;

/// A row of `material.csv`: the setting, its fit and the two measured strains.
fn csv_row(
    rate: f32,
    setting: String,
    volume_stiffness: String,
    fit: &MaterialFit,
    m: &Compression,
) -> [String; 10] {
    [
        rate.to_string(),
        setting,
        volume_stiffness,
        format!("{:.4}", fit.young_pa / 1e3),
        format!("{:.4}", fit.poisson),
        format!("{:.2}", fit.fit_err_pct),
        format!("{:.4}", m[0].1 / 1e3),
        format!("{:.5}", m[0].2),
        format!("{:.4}", m[1].1 / 1e3),
        format!("{:.5}", m[1].2),
    ]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let rates: &[f32] = if quick { &[60.0] } else { &[60.0, 90.0, 144.0] };
    let stiffnesses: &[f32] = if quick { &[20.0] } else { &[5.0, 20.0, 80.0] };
    let volumes: &[f32] = if quick {
        &[0.0, 250.0]
    } else {
        &[0.0, 30.0, 90.0, 250.0, 1000.0]
    };
    let mut lines = Vec::new();
    let mut csv = Csv::new(&[
        "rate_hz",
        "setting",
        "volume_stiffness",
        "young_kpa",
        "poisson",
        "fit_err_pct",
        "stress_10_kpa",
        "lateral_10",
        "stress_20_kpa",
        "lateral_20",
    ]);
    for &rate in rates {
        for &k in stiffnesses {
            for &vol in volumes {
                let cfg = SoftBodyConfig {
                    stiffness: k,
                    volume_stiffness: vol,
                    ..Default::default()
                };
                let m = measure_particle_compression(&cfg, SIZE_M, rate).unwrap();
                let fit = fit_material(&m);
                let line = ResultLine::new("material.fit")
                    .field("method", "particle")
                    .field("config", format!("k{k}_vol{vol}_{rate}hz"))
                    .fixed("young_kpa", fit.young_pa / 1e3, 3)
                    .fixed("poisson", fit.poisson, 3)
                    .fixed("fit_err_pct", fit.fit_err_pct, 1);
                println!("{line}");
                lines.push(line.to_string());
                csv.row(csv_row(
                    rate,
                    format!("particle stiffness {k}"),
                    vol.to_string(),
                    &fit,
                    &m,
                ));
            }
        }
    }
    // The position-based methods at the evidence's settings, 60 Hz: what their knobs measure as
    // against the material they are given (`spec.material`: E 200 kPa, K 400 kPa, ν ≈ 0.42).
    let mut pbd = vec![
        MethodSpec::new(MethodKind::Surface).budget(4, 8),
        MethodSpec::new(MethodKind::Ispc).budget(2, 4),
        MethodSpec::new(MethodKind::Tet).cell(0.2).budget(2, 4),
        MethodSpec::new(MethodKind::ShapeMatching)
            .cell(0.1)
            .budget(1, 1),
        MethodSpec::new(MethodKind::NeoHookean)
            .cell(0.1)
            .budget(80, 2),
    ];
    if !quick {
        pbd.extend([
            MethodSpec::new(MethodKind::Surface).budget(1, 4),
            MethodSpec::new(MethodKind::Ispc).budget(1, 4),
            MethodSpec::new(MethodKind::Ispc).budget(4, 8),
            MethodSpec::new(MethodKind::Tet).cell(0.12).budget(4, 8),
            MethodSpec::new(MethodKind::ShapeMatching)
                .cell(0.06)
                .budget(2, 1),
        ]);
    }
    for spec in &pbd {
        let rate = 60.0;
        let (e0, k0) = (spec.material.young_pa, spec.material.bulk_pa);
        let nu0 = (3.0 * k0 - e0) / (6.0 * k0);
        let line = match measure_pbd_compression(spec, SIZE_M, rate) {
            Ok(m) => {
                let fit = fit_material(&m);
                csv.row(csv_row(rate, spec.label(), String::new(), &fit, &m));
                ResultLine::new("material.fit")
                    .field("method", spec.kind.name())
                    .field(
                        "config",
                        format!("{}_{rate}hz", spec.label().replace(' ', "_")),
                    )
                    .fixed("young_kpa", fit.young_pa / 1e3, 3)
                    .fixed("poisson", fit.poisson, 3)
                    .fixed("fit_err_pct", fit.fit_err_pct, 1)
                    .fixed("given_young_kpa", e0 / 1e3, 1)
                    .fixed("given_poisson", nu0, 3)
            }
            Err(e) => ResultLine::new("material.fit")
                .field("method", spec.kind.name())
                .field(
                    "config",
                    format!("{}_{rate}hz", spec.label().replace(' ', "_")),
                )
                .field("error", format!("{e}").replace(' ', "_")),
        };
        println!("{line}");
        lines.push(line.to_string());
    }
    let named: &[(f32, f32)] = if quick {
        &[(5.0, 0.45)]
    } else {
        &[
            (2.0, 0.45),
            (5.0, 0.45),
            (30.0, 0.45),
            (30.0, 0.3),
            (100.0, 0.45),
        ]
    };
    for &rate in rates {
        for &(e, nu) in named {
            let material = NamedMaterial {
                young_kpa: e,
                poisson: nu,
                rate_hz: rate,
            };
            let s = particle_setting(&SoftBodyConfig::default(), SIZE_M, &material).unwrap();
            let line = ResultLine::new("material.named")
                .field("method", "particle")
                .fixed("rate_hz", rate, 0)
                .fixed("want_young_kpa", e, 1)
                .fixed("want_poisson", nu, 2)
                .fixed("stiffness", s.config.stiffness, 2)
                .fixed("volume_stiffness", s.config.volume_stiffness, 1)
                .fixed("particle_mass_kg", s.config.particle_mass_kg, 4)
                .fixed("young_kpa", s.fit.young_pa / 1e3, 3)
                .fixed("poisson", s.fit.poisson, 3)
                .fixed("young_err_pct", s.young_err_pct, 1)
                .fixed("poisson_err", s.poisson_err, 3)
                .fixed("fit_err_pct", s.fit.fit_err_pct, 1)
                .field("evaluations", s.evaluations);
            println!("{line}");
            lines.push(line.to_string());
        }
    }
    if !quick {
        let dir = "docs/results/methods";
        csv.write(format!("{dir}/material.csv")).unwrap();
        std::fs::write(format!("{dir}/material.txt"), lines.join("\n") + "\n").unwrap();
        println!("wrote {dir}/material.csv, material.txt");
    }
}
