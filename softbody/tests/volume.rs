//! The particle method's volume term (`SoftBodyConfig::volume_stiffness`): the squeeze keeps
//! at least 0.85 of the bunny's volume (without the term it kept 0.44), the wall map's 64
//! throws stay sane with it, and the fast squeeze stays finite at every step rate.
#![allow(clippy::unwrap_used, missing_docs)]

use softsync_softbody::methods::scene::ModelScene;
use softsync_softbody::methods::{MethodKind, MethodSpec};
use softsync_softbody::scenario::ScenarioKind;
use softsync_softbody::Mesh;

/// The volume term's rate these tests run at (it is off by default).
const RATE: f32 = 250.0;

fn bunny() -> Mesh {
    Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj"))
        .unwrap()
        .fit_size(0.2)
}

/// The smallest volume ratio over the squeeze (plates to 30 % of the height, held, opened),
/// and the ratio at its end.
fn squeeze_volume(spec: &MethodSpec, hz: f32) -> (f32, f32) {
    let mut s = ModelScene::new(ScenarioKind::Squeeze, &bunny(), spec, 1.0 / hz).unwrap();
    let mut least = f32::INFINITY;
    while s.time_s() < ScenarioKind::Squeeze.duration_s() {
        s.step();
        assert!(s.sanity().ok(), "{}: {:?}", spec.label(), s.sanity());
        least = least.min(s.volume_ratio());
    }
    (least, s.volume_ratio())
}

#[test]
fn the_squeeze_keeps_the_volume_with_the_term_and_loses_it_without() {
    for cell in [0.06f32, 0.1] {
        let spec = MethodSpec::new(MethodKind::Particle)
            .cell(cell)
            .volume_stiffness(RATE);
        let (kept, end) = squeeze_volume(&spec, 90.0);
        let (lost, _) = squeeze_volume(&spec.volume_stiffness(0.0), 90.0);
        println!("c{cell}: least volume {kept:.3} with the term, {lost:.3} without");
        assert!(kept >= 0.85, "c{cell}: the squeeze kept only {kept:.3}");
        assert!(
            lost < 0.6,
            "c{cell}: without the term it kept {lost:.3}: the test no longer shows the term"
        );
        // Released, the body returns to its own volume (the term does not inflate it).
        assert!(
            (end - 1.0).abs() < 0.03,
            "c{cell}: volume {end:.3} at the end"
        );
    }
}

#[test]
fn the_wall_map_stays_sane_with_the_volume_term() {
    // The evidence's wall map (section 5): stiffness factor × step rate × speed, 64 throws
    // of the icosphere at a fixed wall 1 cm thick for 1 s.
    let small = Mesh::icosphere(0.1, 2);
    let mut failed = Vec::new();
    for k in [0.2f32, 1.0, 5.0, 25.0] {
        for hz in [30.0f32, 60.0, 90.0, 144.0] {
            for v in [0.0f32, 2.5, 5.0, 10.0] {
                let mut spec = MethodSpec::new(MethodKind::Particle).volume_stiffness(RATE);
                spec.material.young_pa *= k;
                spec.material.bulk_pa *= k;
                let mut s = ModelScene::impact(&small, &spec, 1.0 / hz, v).unwrap();
                let mut verdict = "ok";
                for _ in 0..hz as usize {
                    s.step();
                    if !s.sanity().ok() {
                        verdict = s.sanity().verdict();
                        break;
                    }
                }
                if verdict != "ok" {
                    failed.push(format!("k×{k} {hz} Hz {v} m/s: {verdict}"));
                }
            }
        }
    }
    assert!(failed.is_empty(), "not sane: {failed:?}");
}

#[test]
fn the_fast_squeeze_stays_finite_at_every_step_rate() {
    let mesh = Mesh::icosphere(0.1, 2);
    for hz in [30.0f32, 60.0, 144.0] {
        let spec = MethodSpec::new(MethodKind::Particle).volume_stiffness(RATE);
        let mut s = ModelScene::fast_squeeze(&mesh, &spec, 1.0 / hz, 0.1).unwrap();
        for _ in 0..hz as usize {
            s.step();
            assert!(s.sanity().ok(), "{hz} Hz: {:?}", s.sanity());
        }
        let v = s.volume_ratio();
        assert!(v.is_finite() && v > 0.5, "{hz} Hz: volume {v}");
    }
}
