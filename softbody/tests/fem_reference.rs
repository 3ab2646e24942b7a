//! Our reference's material and solver (stable Neo-Hookean XPBD tets at the reference's budget)
//! against an independent FEM code (scikit-fem, `scripts/fem-reference`) on the static
//! cantilever: at the coarsest level, with the same discretization (linear tets, k = 2 cells
//! across the section), ours must find the FEM's answer within 2 %. The FEM's answers are
//! committed in `docs/results/methods/fem/fem.csv`; CI also re-runs the FEM's small problems
//! against its committed numbers (`scripts/fem-reference --check`).
#![allow(clippy::unwrap_used, missing_docs)]

use softsync_softbody::methods::statics::{cantilever_tip_mm, compress_cube, StaticSolve};

/// The rows of the FEM's committed answers (`fem.csv`), split into fields.
fn fem_rows() -> Vec<Vec<String>> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/results/methods/fem/fem.csv"
    );
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split(',').map(str::to_owned).collect::<Vec<_>>())
        .filter(|c| c.len() >= 8)
        .collect()
}

/// The value of the row of `problem`, `quantity`, `case` and `element` at `level` (the
/// finest if `None`).
fn fem(problem: &str, quantity: &str, case: &str, element: &str, level: Option<u32>) -> f64 {
    fem_rows()
        .into_iter()
        .filter(|c| c[0] == problem && c[1] == quantity && c[2] == case && c[3] == element)
        .filter(|c| level.is_none_or(|l| c[4] == l.to_string()))
        .max_by_key(|c| c[4].parse::<u32>().unwrap_or(0))
        .unwrap_or_else(|| panic!("no {problem} {quantity} {case} {element} {level:?} in fem.csv"))
        [6]
    .parse()
    .unwrap()
}

#[test]
fn the_reference_sags_the_coarse_cantilever_as_the_fem_does_on_linear_tets() {
    for (young, case) in [(1e6f32, "E=1e6 snh"), (1e5, "E=1e5 snh")] {
        let ours = cantilever_tip_mm(young, 2, StaticSolve::default());
        let fem = fem("cantilever", "tip_mm", case, "P1", Some(2));
        let diff = (f64::from(ours.value) - fem) / fem;
        println!(
            "{case}: ours {:.4} mm after {} steps, FEM (P1, k = 2) {fem:.4} mm: {:+.2} %",
            ours.value,
            ours.steps,
            100.0 * diff
        );
        assert!(
            ours.steps < StaticSolve::default().max_steps,
            "{case}: no equilibrium"
        );
        assert!(diff.abs() < 0.02, "{case}: {ours:?} against {fem}");
    }
}

/// The compression between frictionless plates is homogeneous, so every mesh has the exact
/// answer: on 2 cells per side, at the reference's budget, ours finds the FEM's force and
/// bulge within 1 % at 10, 20 and 40 % strain (measured: 0.03–0.58 %).
#[test]
fn the_reference_compresses_the_cube_as_the_fem_does() {
    let strains = [0.1f32, 0.2, 0.4];
    let ours = compress_cube(2, &strains, StaticSolve::default());
    for c in &ours {
        let s = format!("s={}", c.strain);
        for (quantity, value) in [("force_n", c.force_n), ("bulge_mm", c.bulge_mm)] {
            // the FEM's converged answer: quadratic tets, its finest level
            let fem = fem("compress", quantity, &s, "P2", None);
            let diff = (f64::from(value) - fem) / fem;
            println!(
                "{s} {quantity}: ours {value:.4}, FEM {fem:.4}: {:+.3} %",
                100.0 * diff
            );
            assert!(diff.abs() < 0.01, "{s} {quantity}: {c:?} against {fem}");
        }
        assert_eq!(c.inverted, 0, "{s}: inverted tets");
    }
}
