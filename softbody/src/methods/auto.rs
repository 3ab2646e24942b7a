//! `method: auto` at run time: a ladder of particle resolutions per soft class, probed once
//! at load, and a per-object controller that moves a body between them as the scene's needs
//! change.
//!
//! - **The ladder** ([`Ladder`]): the class's particle-method config at a few resolutions
//!   (cluster radii times [`AutoSettings::resolutions`], coarsest first; the default is
//!   2×, 1× and ½× the class's own radius).
//! - **The probe** ([`Ladder::probe`]): a quick run at load, not the offline evidence tables
//!   (those are for other meshes and settings than a user's class): each level is dropped on
//!   a floor and squeezed to 30 % of its height by a plate, at 60 Hz, and its cost per step
//!   (median, the caller's clock) and its error against the finest level (the worst RMS
//!   distance of the surface over the run) are measured. [`choose`] then picks the
//!   **touch level** (the cheapest within the error budget) and the **squeeze level** (the
//!   most accurate within the cost budget, never coarser than the touch level).
//! - **The controller** ([`AutoController`]): asleep (an untouched resting body: its bodies
//!   sleep and its step is skipped, it costs one bounds query), touched (the touch level),
//!   squeezed (the squeeze level). Up is immediate — a grab, a contact that wakes it, a
//!   squeeze deeper than [`AutoSettings::squeeze_mm`]; down waits: a squeeze must stay under
//!   half that depth (or the body be still: not held, its shape no longer changing) for
//!   [`AutoSettings::settle_s`], and a body must be still and free for
//!   [`AutoSettings::rest_s`] before it sleeps, and no mode is left before
//!   [`AutoSettings::min_dwell_s`] — so it does not flap.
//!
//! The switch between levels is [`crate::SoftBodySet::reconfigure`] (no pop over 1 mm).

use serde::{Deserialize, Serialize};

use rapier3d::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder};

use crate::body::Activity;
use crate::cluster::ClusterMethod;
use crate::methods::choice::{choose, Candidate, ObjectNeeds};
use crate::methods::spec::{MethodKind, MethodSpec};
use crate::{Mesh, SoftBodyConfig, SoftBodyError, SoftBodySet, StageClock};

/// A class's `auto` settings (scene files: `body: Auto(...)`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AutoSettings {
    /// Largest acceptable error of the touch level against the finest one, mm.
    pub error_budget_mm: f32,
    /// Most a squeezed body may cost per step, ms (this machine's probe).
    pub cost_budget_ms: f32,
    /// Resolution factors of the ladder: cluster radii times these, coarsest (largest) first.
    pub resolutions: Vec<f32>,
    /// A particle displaced this much further from its rest target than when the body was
    /// last calm (a body resting on a table is already displaced a little) is a squeeze, mm.
    pub squeeze_mm: f32,
    /// Seconds a squeeze must stay under half `squeeze_mm` before the body goes back down.
    pub settle_s: f32,
    /// Seconds a body must be still and free (not held, under 2 cm/s, its shape changing
    /// under 1 cm/s) to sleep.
    pub rest_s: f32,
    /// Seconds in a mode before the body may go down from it.
    pub min_dwell_s: f32,
}

impl Default for AutoSettings {
    fn default() -> Self {
        AutoSettings {
            error_budget_mm: 3.0,
            cost_budget_ms: 1.0,
            resolutions: vec![2.0, 1.0, 0.5],
            squeeze_mm: 6.0,
            settle_s: 0.5,
            rest_s: 1.0,
            min_dwell_s: 0.5,
        }
    }
}

/// Most levels a ladder may have.
pub const MAX_LEVELS: usize = 6;

impl AutoSettings {
    /// Checks every value; the message names the field.
    pub fn validate(&self) -> Result<(), SoftBodyError> {
        let range = |name: &str, v: f32, lo: f32, hi: f32| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(SoftBodyError::Config(format!(
                    "auto.{name}: {v} is outside {lo}–{hi}"
                )))
            }
        };
        range("error_budget_mm", self.error_budget_mm, 0.01, 1000.0)?;
        range("cost_budget_ms", self.cost_budget_ms, 0.001, 1000.0)?;
        range("squeeze_mm", self.squeeze_mm, 0.5, 500.0)?;
        range("settle_s", self.settle_s, 0.0, 60.0)?;
        range("rest_s", self.rest_s, 0.0, 600.0)?;
        range("min_dwell_s", self.min_dwell_s, 0.0, 60.0)?;
        if self.resolutions.is_empty() || self.resolutions.len() > MAX_LEVELS {
            return Err(SoftBodyError::Config(format!(
                "auto.resolutions: {} levels, expected 1–{MAX_LEVELS}",
                self.resolutions.len()
            )));
        }
        for (i, f) in self.resolutions.iter().enumerate() {
            range(&format!("resolutions[{i}]"), *f, 0.1, 10.0)?;
        }
        if self.resolutions.windows(2).any(|w| w[1] >= w[0]) {
            return Err(SoftBodyError::Config(
                "auto.resolutions: must be decreasing (coarsest first)".into(),
            ));
        }
        Ok(())
    }
}

/// `config` with its particles `factor` times as far apart (radii scaled; closest-N's count
/// by `factor²`, the surface's share).
pub fn scaled(config: &SoftBodyConfig, factor: f32) -> SoftBodyConfig {
    let cluster = match config.cluster {
        ClusterMethod::ClosestN {
            vertices_per_particle,
        } => ClusterMethod::ClosestN {
            vertices_per_particle: ((vertices_per_particle as f32) * factor * factor)
                .round()
                .max(1.0) as u32,
        },
        ClusterMethod::Distance { radius_m } => ClusterMethod::Distance {
            radius_m: radius_m * factor,
        },
        ClusterMethod::WeightedDistance {
            radius_m,
            soft_radius_m,
        } => ClusterMethod::WeightedDistance {
            radius_m: radius_m * factor,
            soft_radius_m: soft_radius_m * factor,
        },
        ClusterMethod::PoissonDisk { radius_m, seed } => ClusterMethod::PoissonDisk {
            radius_m: radius_m * factor,
            seed,
        },
    };
    SoftBodyConfig {
        cluster,
        affect_range_m: config.affect_range_m * factor,
        ..config.clone()
    }
}

/// One soft class's levels, what the probe measured, and the two levels it picked.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Ladder {
    /// The resolution factor of each level (from [`AutoSettings::resolutions`]; a factor that
    /// clusters to as many particles as the level before it is left out: it would cost a
    /// switch and change nothing).
    pub resolutions: Vec<f32>,
    /// The config of each level, coarsest first.
    pub configs: Vec<SoftBodyConfig>,
    /// Particles of each level.
    pub particles: Vec<usize>,
    /// The probe's figures per level (cost per step, error against the finest level); empty
    /// before [`probe`](Self::probe).
    pub probed: Vec<Candidate>,
    /// The level a touched body gets.
    pub touch: usize,
    /// The level a squeezed body gets.
    pub squeeze: usize,
}

impl Ladder {
    /// The levels of `base` under `settings`, each clustered once to count its particles
    /// (`mesh` baked as the class builds it). Before probing both picks are the level nearest
    /// the base resolution.
    pub fn new(
        mesh: &Mesh,
        base: &SoftBodyConfig,
        settings: &AutoSettings,
    ) -> Result<Self, SoftBodyError> {
        settings.validate()?;
        let mut configs = Vec::new();
        let mut particles: Vec<usize> = Vec::new();
        let mut resolutions = Vec::new();
        for (i, f) in settings.resolutions.iter().enumerate() {
            let c = scaled(base, *f);
            c.validate()
                .map_err(|e| SoftBodyError::Config(format!("auto level {i} (×{f}): {e}")))?;
            let plan = crate::body::BodyPlan::new(mesh, c.clone())
                .map_err(|e| SoftBodyError::Config(format!("auto level {i} (×{f}): {e}")))?;
            if particles.last() == Some(&plan.map.len()) {
                continue;
            }
            particles.push(plan.map.len());
            configs.push(c);
            resolutions.push(*f);
        }
        let base_level = resolutions
            .iter()
            .enumerate()
            .min_by(|a, b| (a.1 - 1.0).abs().total_cmp(&(b.1 - 1.0).abs()))
            .map_or(0, |(i, _)| i);
        Ok(Ladder {
            resolutions,
            configs,
            particles,
            probed: Vec::new(),
            touch: base_level,
            squeeze: base_level,
        })
    }

    /// Runs the probe (see the module's docs) on `mesh` and picks the touch and squeeze
    /// levels for `settings`' budgets. `clock` reads milliseconds.
    pub fn probe(
        &mut self,
        mesh: &Mesh,
        settings: &AutoSettings,
        clock: StageClock,
    ) -> Result<(), SoftBodyError> {
        let runs: Vec<ProbeRun> = self
            .configs
            .iter()
            .map(|c| probe_run(mesh, c, clock))
            .collect::<Result<_, _>>()?;
        let Some(reference) = runs.last() else {
            return Ok(());
        };
        self.probed = runs
            .iter()
            .zip(&self.resolutions)
            .map(|(r, f)| Candidate {
                spec: MethodSpec {
                    cell_frac: *f,
                    ..MethodSpec::new(MethodKind::Particle)
                },
                cost_ms: r.cost_ms,
                error_mm: r.error_to_m(reference) * 1e3,
            })
            .collect();
        self.pick(settings);
        Ok(())
    }

    /// Picks the touch and squeeze levels from the probed figures.
    pub fn pick(&mut self, settings: &AutoSettings) {
        if self.probed.is_empty() {
            return;
        }
        let level_of = |c: &Option<Candidate>| {
            c.as_ref()
                .and_then(|c| self.probed.iter().position(|p| p == c))
                .unwrap_or(self.probed.len() - 1)
        };
        let touch = choose(
            &[ObjectNeeds {
                name: "touch".into(),
                error_budget_mm: settings.error_budget_mm,
                active: true,
                candidates: self.probed.clone(),
            }],
            f32::INFINITY,
        );
        self.touch = level_of(&touch.choices[0].picked);
        // The most accurate level within the cost budget, not coarser than the touch level.
        self.squeeze = (self.touch..self.probed.len())
            .filter(|&i| self.probed[i].cost_ms <= settings.cost_budget_ms)
            .min_by(|&a, &b| self.probed[a].error_mm.total_cmp(&self.probed[b].error_mm))
            .unwrap_or(self.touch);
    }

    /// The level for a mode.
    pub fn level(&self, mode: AutoMode) -> usize {
        match mode {
            AutoMode::Asleep | AutoMode::Touched => self.touch,
            AutoMode::Squeezed => self.squeeze,
        }
    }
}

/// One probe run: the welded surface per step and the median step cost.
struct ProbeRun {
    frames: Vec<Vec<glam::Vec3>>,
    cost_ms: f32,
}

impl ProbeRun {
    /// The worst RMS surface distance to `other` over the run, metres.
    fn error_to_m(&self, other: &ProbeRun) -> f32 {
        self.frames
            .iter()
            .zip(&other.frames)
            .map(|(a, b)| {
                if a.len() != b.len() || a.is_empty() {
                    return f32::INFINITY;
                }
                let s: f32 = a.iter().zip(b).map(|(x, y)| x.distance_squared(*y)).sum();
                (s / a.len() as f32).sqrt()
            })
            .fold(0.0f32, f32::max)
    }
}

/// Probe steps: 20 to settle, 40 pressing, 20 held, 20 lifting, 20 after.
const PROBE_STEPS: [u32; 5] = [20, 40, 20, 20, 20];
const PROBE_DT_S: f32 = 1.0 / 60.0;
/// The plate presses the body to this fraction of its height.
const PROBE_SQUEEZE: f32 = 0.3;

fn probe_run(
    mesh: &Mesh,
    config: &SoftBodyConfig,
    clock: StageClock,
) -> Result<ProbeRun, SoftBodyError> {
    let (lo, hi) = crate::mesh::bounds(&mesh.positions);
    let mid = (lo + hi) * 0.5;
    // On the floor (top at y = 0), centred over the origin.
    let shift = glam::Vec3::new(-mid.x, -lo.y + 0.002, -mid.z);
    let placed = Mesh {
        positions: mesh.positions.iter().map(|p| *p + shift).collect(),
        normals: mesh.normals.clone(),
        triangles: mesh.triangles.clone(),
    };
    let height = (hi.y - lo.y).max(1e-3);
    let half = ((hi - lo).max_element() * 0.5 + 0.05).max(0.1);
    let mut world = PhysicsWorld::new();
    let floor =
        world.insert_body(RigidBodyBuilder::fixed().translation(glam::Vec3::new(0.0, -0.5, 0.0)));
    world.insert_collider(
        ColliderBuilder::cuboid(half * 4.0, 0.5, half * 4.0),
        Some(floor),
    );
    let top0 = height + 0.002 + 0.01 + 0.005;
    let plate = world.insert_body(
        RigidBodyBuilder::kinematic_position_based().translation(glam::Vec3::new(0.0, top0, 0.0)),
    );
    world.insert_collider(ColliderBuilder::cuboid(half, 0.005, half), Some(plate));
    let mut set = SoftBodySet::new();
    let mut probe_config = config.clone();
    // time every particle: nothing may sleep in the probe
    probe_config.particles_can_sleep = false;
    let h = set.insert(&placed, probe_config, &mut world)?;
    let low = height * (1.0 - PROBE_SQUEEZE) + 0.002 + 0.005;
    let mut frames = Vec::new();
    let mut costs = Vec::new();
    let total: u32 = PROBE_STEPS.iter().sum();
    for step in 0..total {
        let y = plate_height(step, top0, low);
        if let Some(b) = world.bodies.get_mut(plate) {
            b.set_next_kinematic_translation(glam::Vec3::new(0.0, y, 0.0));
        }
        let t0 = clock();
        set.step(&mut world, PROBE_DT_S);
        costs.push((clock() - t0) as f32);
        let b = set
            .get(h)
            .ok_or_else(|| SoftBodyError::Config("the probe's body is gone".into()))?;
        frames.push(b.vertices().to_vec());
    }
    costs.sort_by(f32::total_cmp);
    Ok(ProbeRun {
        frames,
        cost_ms: costs[costs.len() / 2],
    })
}

fn plate_height(step: u32, top: f32, low: f32) -> f32 {
    let [settle, press, hold, lift, _] = PROBE_STEPS;
    let s = step as f32;
    let (a, b, c, d) = (
        settle as f32,
        (settle + press) as f32,
        (settle + press + hold) as f32,
        (settle + press + hold + lift) as f32,
    );
    if s < a {
        top
    } else if s < b {
        top + (low - top) * (s - a) / (b - a)
    } else if s < c {
        low
    } else if s < d {
        low + (top - low) * (s - c) / (d - c)
    } else {
        top
    }
}

/// What an `auto` body is doing, and so which level it needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum AutoMode {
    /// Untouched and at rest: asleep, costs (almost) nothing.
    Asleep,
    /// Moving, held or touched: the touch level.
    Touched,
    /// Squeezed hard: the squeeze level.
    Squeezed,
}

/// One body's mode with hysteresis (see the module's docs).
#[derive(Clone, Debug)]
pub struct AutoController {
    mode: AutoMode,
    /// When the current mode began, seconds.
    since_s: f64,
    /// Since when the conditions to go down have held, seconds.
    calm_since_s: Option<f64>,
    /// The largest particle displacement when the body was last calm (its resting
    /// deformation), metres: squeezes are measured from it.
    baseline_m: Option<f32>,
}

impl AutoController {
    /// A body that starts awake (it was just placed) at time `now_s`.
    pub fn new(now_s: f64) -> Self {
        AutoController {
            mode: AutoMode::Touched,
            since_s: now_s,
            calm_since_s: None,
            baseline_m: None,
        }
    }

    /// The current mode.
    pub fn mode(&self) -> AutoMode {
        self.mode
    }

    /// Feeds one step's activity at `now_s`; returns the new mode when it changes.
    pub fn update(
        &mut self,
        now_s: f64,
        a: &Activity,
        settings: &AutoSettings,
    ) -> Option<AutoMode> {
        let squeeze_m = settings.squeeze_mm * 1e-3;
        let still = !a.driven && a.speed_mps < 0.02 && a.deformation_speed_mps < 0.01;
        if still && self.mode != AutoMode::Squeezed {
            self.baseline_m = Some(a.max_displacement_m);
        }
        let extra = a.max_displacement_m - *self.baseline_m.get_or_insert(a.max_displacement_m);
        let up = if extra >= squeeze_m {
            Some(AutoMode::Squeezed)
        } else if self.mode == AutoMode::Asleep && (!a.asleep || a.driven) {
            Some(AutoMode::Touched)
        } else {
            None
        };
        if let Some(m) = up {
            if m != self.mode && (m == AutoMode::Squeezed || self.mode == AutoMode::Asleep) {
                return Some(self.enter(m, now_s));
            }
        }
        let calm = match self.mode {
            // eased off, or held still by what presses it (a body resting deformed on a
            // table after a drop: its shape no longer changes, its baseline is now)
            AutoMode::Squeezed => extra < 0.5 * squeeze_m || still,
            AutoMode::Touched => still,
            AutoMode::Asleep => false,
        };
        if !calm {
            self.calm_since_s = None;
            return None;
        }
        let since = *self.calm_since_s.get_or_insert(now_s);
        let wait = match self.mode {
            AutoMode::Squeezed => settings.settle_s,
            _ => settings.rest_s,
        } as f64;
        if now_s - since >= wait && now_s - self.since_s >= settings.min_dwell_s as f64 {
            let down = match self.mode {
                AutoMode::Squeezed => AutoMode::Touched,
                _ => AutoMode::Asleep,
            };
            return Some(self.enter(down, now_s));
        }
        None
    }

    fn enter(&mut self, mode: AutoMode, now_s: f64) -> AutoMode {
        self.mode = mode;
        self.since_s = now_s;
        self.calm_since_s = None;
        mode
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn act(d_mm: f32, v: f32, driven: bool, asleep: bool) -> Activity {
        Activity {
            driven,
            max_displacement_m: d_mm * 1e-3,
            speed_mps: v,
            deformation_speed_mps: v,
            asleep,
        }
    }

    #[test]
    fn the_controller_goes_up_at_once_and_down_only_after_calm_and_dwell() {
        let s = AutoSettings::default();
        let mut c = AutoController::new(0.0);
        // a resting body deformed 4 mm by its own weight is not squeezed: its baseline
        assert_eq!(c.update(0.0, &act(4.0, 0.0, false, false), &s), None);
        assert_eq!(c.update(0.05, &act(0.0, 0.0, false, false), &s), None);
        // still and free for rest_s: asleep
        assert_eq!(c.update(0.1, &act(0.0, 0.0, false, false), &s), None);
        assert_eq!(
            c.update(1.2, &act(0.0, 0.0, false, false), &s),
            Some(AutoMode::Asleep)
        );
        // a grab wakes it at once
        assert_eq!(
            c.update(1.3, &act(0.0, 0.0, true, false), &s),
            Some(AutoMode::Touched)
        );
        // a squeeze: up at once
        assert_eq!(
            c.update(1.31, &act(8.0, 0.0, true, false), &s),
            Some(AutoMode::Squeezed)
        );
        // it eases to 4 mm (over half of 6): stays squeezed, however long
        assert_eq!(c.update(3.0, &act(4.0, 0.0, true, false), &s), None);
        // under 3 mm, but flapping: each spike restarts the settle time
        assert_eq!(c.update(3.1, &act(2.0, 0.0, true, false), &s), None);
        assert_eq!(c.update(3.4, &act(3.5, 0.0, true, false), &s), None);
        assert_eq!(c.update(3.5, &act(2.0, 0.0, true, false), &s), None);
        assert_eq!(c.update(3.9, &act(2.0, 0.0, true, false), &s), None);
        assert_eq!(
            c.update(4.01, &act(2.0, 0.0, true, false), &s),
            Some(AutoMode::Touched)
        );
        // held: never sleeps
        assert_eq!(c.update(9.0, &act(0.0, 0.0, true, false), &s), None);
        assert_eq!(c.update(20.0, &act(0.0, 0.0, true, false), &s), None);
    }

    #[test]
    fn a_body_that_keeps_moving_never_sleeps_and_min_dwell_holds_a_fresh_mode() {
        let s = AutoSettings {
            min_dwell_s: 2.0,
            ..AutoSettings::default()
        };
        let mut c = AutoController::new(0.0);
        for k in 0..100 {
            assert_eq!(
                c.update(k as f64 * 0.1, &act(0.0, 0.5, false, false), &s),
                None
            );
        }
        let mut c = AutoController::new(0.0);
        assert_eq!(c.update(0.0, &act(0.0, 0.0, false, false), &s), None);
        // calm for 1.5 s (over rest_s) but the mode is younger than min_dwell_s
        assert_eq!(c.update(1.5, &act(0.0, 0.0, false, false), &s), None);
        assert_eq!(
            c.update(2.0, &act(0.0, 0.0, false, false), &s),
            Some(AutoMode::Asleep)
        );
    }

    #[test]
    fn a_body_left_deformed_but_still_goes_back_down_and_its_new_baseline_holds() {
        let s = AutoSettings::default();
        let mut c = AutoController::new(0.0);
        assert_eq!(c.update(0.0, &act(0.0, 0.0, false, false), &s), None);
        // dropped: 9 mm on impact, moving
        assert_eq!(
            c.update(0.1, &act(9.0, 0.3, false, false), &s),
            Some(AutoMode::Squeezed)
        );
        // resting deformed by 5 mm (over half the squeeze), still: down after settle_s
        assert_eq!(c.update(0.7, &act(5.0, 0.0, false, false), &s), None);
        assert_eq!(
            c.update(1.3, &act(5.0, 0.0, false, false), &s),
            Some(AutoMode::Touched)
        );
        // 5 mm is its baseline now: not a squeeze, and it sleeps
        assert_eq!(c.update(1.4, &act(5.0, 0.0, false, false), &s), None);
        assert_eq!(
            c.update(2.5, &act(5.0, 0.0, false, false), &s),
            Some(AutoMode::Asleep)
        );
    }

    #[test]
    fn settings_are_checked_by_field() {
        let bad = AutoSettings {
            resolutions: vec![1.0, 2.0],
            ..AutoSettings::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("decreasing"));
        let bad = AutoSettings {
            error_budget_mm: f32::NAN,
            ..AutoSettings::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("error_budget_mm"));
    }
}
