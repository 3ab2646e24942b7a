//! Our reference's material and solver (stable Neo-Hookean XPBD tets at the reference's budget)
//! against an independent FEM code (scikit-fem, `scripts/fem-reference`) on the static
//! cantilever: at the coarsest level, with the same discretization (linear tets, k = 2 cells
//! across the section), ours must find the FEM's answer within 2 %. The FEM's answers are
//! committed in `docs/results/methods/fem/fem.csv`; CI also re-runs the FEM's small problems
//! against its committed numbers (`scripts/fem-reference --check`).
#![allow(clippy::unwrap_used, missing_docs)]

use softsync_softbody::methods::statics::{cantilever_tip_mm, StaticSolve};

fn fem_p1(case: &str, level: u32) -> f64 {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/results/methods/fem/fem.csv"
    );
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|c| {
            c.len() >= 8
                && c[0] == "cantilever"
                && c[1] == "tip_mm"
                && c[2] == case
                && c[3] == "P1"
                && c[4] == level.to_string()
        })
        .unwrap_or_else(|| panic!("no P1 k={level} {case} in {path}"))[6]
        .parse()
        .unwrap()
}

#[test]
fn the_reference_sags_the_coarse_cantilever_as_the_fem_does_on_linear_tets() {
    for (young, case) in [(1e6f32, "E=1e6 snh"), (1e5, "E=1e5 snh")] {
        let ours = cantilever_tip_mm(young, 2, StaticSolve::default());
        let fem = fem_p1(case, 2);
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
