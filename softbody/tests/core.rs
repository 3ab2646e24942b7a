#![allow(clippy::unwrap_used, missing_docs)]
use softsync_softbody::metrics::measure;
use softsync_softbody::scenario::{Scenario, ScenarioKind};
use softsync_softbody::*;

#[test]
fn smoke_rest() {
    let mesh = Mesh::icosphere(0.1, 3);
    let cfg = SoftBodyConfig::default();
    let mut s = Scenario::new(ScenarioKind::Rest, &mesh, cfg, 1.0 / 90.0).unwrap();
    let n = s.soft_body().num_particles();
    for _ in 0..90 { s.step(); }
    let m = s.metrics();
    println!("particles {n} {m:?}");
    let _ = measure;
}
