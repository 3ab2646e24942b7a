//! The accuracy reference every method's error is measured against: stable Neo-Hookean XPBD
//! tets ([`MethodKind::NeoHookean`]) on a well-shaped lattice, stepped finely (many substeps of
//! few iterations: Macklin et al. 2019's "small steps"), and the tools to show it is sound —
//! a recording of a scenario with its volume, inverted tets and energy, and the change of the
//! answer between two resolutions (the convergence study of `examples/reference.rs`).

use glam::{Quat, Vec3};

use crate::methods::pbd::Energy;
use crate::methods::scene::{surface_distance_m, ModelScene};
use crate::methods::spec::{MethodKind, MethodSpec};
use crate::metrics::rigid_fit_error;
use crate::scenario::ScenarioKind;
use crate::{Mesh, SoftBodyError};

/// The reference's lattice cell, as a fraction of the object's size (chosen by the
/// convergence study; see docs/results/methods/README.md).
pub const REFERENCE_CELL: f32 = 0.05;
/// The reference's substeps per 60 Hz step (chosen by the study).
pub const REFERENCE_SUBSTEPS: u32 = 80;
/// Gauss–Seidel iterations per substep of the reference.
pub const REFERENCE_ITERATIONS: u32 = 2;
/// Largest change of the answer (shape RMS, mm) between the reference and its refinement in
/// space or in time that counts as converged.
pub const TOLERANCE_MM: f32 = 0.5;
/// The surface is recorded every this many steps.
pub const SAMPLE_EVERY: usize = 6;

/// The Neo-Hookean model at `cell_frac` of the object's size, `substeps` substeps of
/// [`REFERENCE_ITERATIONS`] iterations.
pub fn reference_spec(cell_frac: f32, substeps: u32) -> MethodSpec {
    let mut spec = MethodSpec::new(MethodKind::NeoHookean)
        .cell(cell_frac)
        .budget(substeps, REFERENCE_ITERATIONS);
    // A yardstick never sleeps: sleeping freezes the body at a moment that differs from one
    // resolution to the next.
    spec.params.sleep_after_s = 0.0;
    spec
}

/// The verified reference ([`REFERENCE_CELL`], [`REFERENCE_SUBSTEPS`]).
pub fn verified_reference() -> MethodSpec {
    reference_spec(REFERENCE_CELL, REFERENCE_SUBSTEPS)
}

/// A run of a scenario as the accuracy figures see it.
#[derive(Clone, Debug, Default)]
pub struct Recording {
    /// The surface every [`SAMPLE_EVERY`] steps.
    pub samples: Vec<Vec<Vec3>>,
    /// The body's energy at the same samples (models that report one).
    pub energy: Vec<Energy>,
    /// Most tets inside out at once, over every step.
    pub max_inverted: usize,
    /// Smallest enclosed volume of the surface over its rest volume, at the samples.
    pub min_volume: f32,
    /// Largest enclosed volume ratio at the samples.
    pub max_volume: f32,
    /// The first stability failure seen, or "ok".
    pub verdict: &'static str,
    /// Simulated degrees of freedom.
    pub particles: usize,
    /// How often the hard volume floor engaged over the run: in all tets, and in tets at least
    /// half inside the surface.
    pub floor_hits: (u64, u64),
}

/// Runs `kind` for its whole duration with `spec` on `mesh` at `dt_s`, recording the surface,
/// the energy and the sanity of every step.
pub fn record(
    kind: ScenarioKind,
    mesh: &Mesh,
    spec: &MethodSpec,
    dt_s: f32,
) -> Result<Recording, SoftBodyError> {
    record_paced(kind, mesh, spec, dt_s, (1.0, 1.0), kind.duration_s())
}

/// [`record`] of the scenario with its props `pace` times slower doing `amount` of their
/// action (`(pace, amount)`, [`ModelScene::paced`]), for `duration_s` seconds.
pub fn record_paced(
    kind: ScenarioKind,
    mesh: &Mesh,
    spec: &MethodSpec,
    dt_s: f32,
    (pace, amount): (f32, f32),
    duration_s: f32,
) -> Result<Recording, SoftBodyError> {
    let mut s = ModelScene::paced(kind, mesh, spec, dt_s, pace, amount)?;
    let steps = (duration_s / dt_s).round() as usize;
    let mut r = Recording {
        min_volume: f32::MAX,
        max_volume: f32::MIN,
        verdict: "ok",
        particles: s.model.num_particles(),
        ..Default::default()
    };
    for i in 0..steps {
        s.step();
        r.max_inverted = r.max_inverted.max(s.model.inverted_elements());
        let sanity = s.sanity();
        if !sanity.ok() && r.verdict == "ok" {
            r.verdict = sanity.verdict();
        }
        if i % SAMPLE_EVERY == SAMPLE_EVERY - 1 {
            r.samples.push(s.model.surface().to_vec());
            let v = s.volume_ratio();
            r.min_volume = r.min_volume.min(v);
            r.max_volume = r.max_volume.max(v);
            if let Some(e) = s.model.energy(s.world.gravity) {
                r.energy.push(e);
            }
        }
    }
    r.floor_hits = s.model.volume_floor_hits();
    Ok(r)
}

/// The last sample time, seconds, up to which every profile (a shape change per sample,
/// [`shape_change_profile`], samples every [`SAMPLE_EVERY`] steps of `dt_s`) stays below
/// [`TOLERANCE_MM`]: 0 if the first sample already does not. Of the reference against itself
/// with the step changed by 5 %, it is the scenario's predictable window: past it no
/// refinement pins the answer down.
pub fn within_tolerance_until_s(profiles: &[&[f32]], dt_s: f32) -> f64 {
    let n = profiles.iter().map(|p| p.len()).min().unwrap_or(0);
    let mut last = 0.0;
    for i in 0..n {
        if profiles.iter().any(|p| p[i] >= TOLERANCE_MM) {
            break;
        }
        last = (i + 1) as f64 * SAMPLE_EVERY as f64 * f64::from(dt_s);
    }
    last
}

/// The reference nudged: the same spec with 5 % more substeps (84 for 80), the change of the
/// step whose effect [`within_tolerance_until_s`] measures.
pub fn nudged(spec: &MethodSpec) -> MethodSpec {
    let mut s = *spec;
    s.params.substeps += (s.params.substeps / 20).max(1);
    s
}

/// How far apart two recordings of the same surface are, millimetres.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShapeChange {
    /// Shape error: each sample of `b` rigidly fitted onto `a`'s, RMS over vertices and samples.
    pub rms_mm: f32,
    /// The largest vertex distance after the fit.
    pub max_mm: f32,
    /// RMS without the fit (trajectory included).
    pub raw_rms_mm: f32,
}

/// The shape error of `a` against `b` (the accuracy figures' metric: a different bounce
/// height, slide or roll is not deformation error).
pub fn shape_change(a: &[Vec<Vec3>], b: &[Vec<Vec3>]) -> ShapeChange {
    let mut sum = 0.0f64;
    let mut raw = 0.0f64;
    let mut max = 0.0f32;
    let n = a.len().min(b.len()).max(1);
    for (x, y) in a.iter().zip(b) {
        let (r, m) = rigid_fit_error(x, y, Quat::IDENTITY);
        sum += (r as f64).powi(2);
        max = max.max(m);
        raw += (surface_distance_m(x, y).0 as f64).powi(2);
    }
    ShapeChange {
        rms_mm: ((sum / n as f64).sqrt() * 1e3) as f32,
        max_mm: max * 1e3,
        raw_rms_mm: ((raw / n as f64).sqrt() * 1e3) as f32,
    }
}

/// [`shape_change`] sample by sample: the shape RMS (mm) of each sample of `b` rigidly fitted
/// onto `a`'s — where in the scenario two recordings part.
pub fn shape_change_profile(a: &[Vec<Vec3>], b: &[Vec<Vec3>]) -> Vec<f32> {
    a.iter()
        .zip(b)
        .map(|(x, y)| rigid_fit_error(x, y, Quat::IDENTITY).0 * 1e3)
        .collect()
}

/// Energy bookkeeping of a recording: the total at the first sample, the largest total seen
/// after it, the last, and the largest elastic energy, J.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergySummary {
    /// Total at the first sample.
    pub first_j: f32,
    /// Largest total after the first sample.
    pub max_j: f32,
    /// Total at the last sample.
    pub last_j: f32,
    /// Largest elastic energy.
    pub max_elastic_j: f32,
}

/// The energy bookkeeping of `r` (zeros if the model reports none).
pub fn energy_summary(r: &Recording) -> EnergySummary {
    let Some(first) = r.energy.first() else {
        return EnergySummary::default();
    };
    EnergySummary {
        first_j: first.total_j(),
        max_j: r.energy[1..]
            .iter()
            .map(Energy::total_j)
            .fold(first.total_j(), f32::max),
        last_j: r.energy.last().map_or(0.0, Energy::total_j),
        max_elastic_j: r.energy.iter().map(|e| e.elastic_j).fold(0.0, f32::max),
    }
}
