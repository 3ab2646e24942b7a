//! The soft-body component's options (thesis Appendix A, "Component to create a deformable
//! soft mesh"), as a serde config with units.

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::{ClusterMethod, SoftBodyError};

/// Collider shape of each particle (Appendix A item 2; thesis 3.2.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParticleCollider {
    /// A sphere of the particle's radius.
    Sphere,
    /// A cube whose half extent is the particle's radius.
    Box,
    /// No collider: the particle is moved by the shape restoration and grabs only.
    None,
}

/// Where the body simulates (Appendix A item 11; thesis 3.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SimulationSpace {
    /// The center is fixed; the body deforms in place.
    Local,
    /// The center is a dynamic body with gravity and a collider; the particles follow it.
    World,
}

/// How the shape-restoring velocity is computed each step (thesis 3.2.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RestoringScheme {
    /// This crate's form: per-step fraction `1 − exp(−k·dt)`, normalised relative neighbour
    /// coupling, the center's rigid velocity fed forward. Stable for every k and dt.
    Exact,
    /// The thesis's form (Appendix A.6–A.7), kept to compare: `(dir − Σ w·dir_nb) · k ·
    /// dt/(1/90)`, raw neighbour weights, no feed-forward. With `α = k·dt²·90`, a uniform
    /// displacement grows by `1 + α(Σw − 1)` per step: wherever a particle's neighbour
    /// weights sum past 1 — at the default affection range they do — it diverges at every
    /// stiffness and step rate. Without neighbours it overshoots past α = 1 and diverges past
    /// α = 2 (measured: `thesis_scheme_fails_exactly_where_its_docs_say`).
    Thesis,
}

/// Continuous collision detection for the particles (the thesis sets its particles to
/// `ContinuousDynamic`, Appendix A.1–2): without it, a particle pushed by a moving plate and
/// pulled back by its restoring velocity can cross a thin wall in one step and stay caught.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "mode")]
pub enum ContinuousCollision {
    /// Discrete contacts only (cheapest; tunnels through walls thinner than a step's motion).
    Off,
    /// Rapier's soft CCD: predictive contacts up to this distance ahead along the motion.
    Soft {
        /// Prediction distance, metres.
        prediction_m: f32,
    },
    /// Rapier's full CCD (shape casts and substeps).
    Full,
}

/// Collider of the center body in world mode (Appendix A items 12–13).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CenterCollider {
    /// A ball of radius `center_scale` × the mean vertex distance from the center.
    Ball,
    /// The convex hull of the mesh, scaled by `center_scale` about the center ("use mesh
    /// collider for center").
    ConvexHull,
}

/// A region of the body's local (baked) space; vertices inside are soft (thesis 3.5.2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "shape")]
pub enum SoftRegion {
    /// An axis-aligned box.
    Aabb {
        /// Minimum corner, metres.
        min_m: Vec3,
        /// Maximum corner, metres.
        max_m: Vec3,
    },
    /// A ball.
    Ball {
        /// Center, metres.
        center_m: Vec3,
        /// Radius, metres.
        radius_m: f32,
    },
}

impl SoftRegion {
    /// True if `p` lies in the region.
    pub fn contains(&self, p: Vec3) -> bool {
        match *self {
            SoftRegion::Aabb { min_m, max_m } => p.cmpge(min_m).all() && p.cmple(max_m).all(),
            SoftRegion::Ball { center_m, radius_m } => {
                p.distance_squared(center_m) <= radius_m * radius_m
            }
        }
    }
}

/// Every option of the thesis's soft-body component, plus the stability knobs this crate adds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SoftBodyConfig {
    /// Particle grouping method and its distances (items 1, 6, 7, 9).
    pub cluster: ClusterMethod,
    /// Particle collider (item 2). Default sphere.
    pub collider: ParticleCollider,
    /// Mass per particle in kg (item 3), 0.01–10. Default 0.05.
    pub particle_mass_kg: f32,
    /// Angular damping of the particles (item 4, "angular drag"). Default 0.05.
    pub angular_damping: f32,
    /// Stiffness, "resistance" (item 5), 0.1–100: the rate in 1/s at which a displaced
    /// particle returns to its rest position. Default 20.
    pub stiffness: f32,
    /// Neighbour distance δ in metres (item 8, "affection range"); 0 disables neighbours.
    /// Default 0: derived as 2.5 × the mean particle spacing.
    pub affect_range_m: f32,
    /// Share in [0, 0.5] of the neighbours' displacement a particle follows (thesis 3.2.2's
    /// "velocity from other particles", normalised so it cannot destabilise). Default 0.35.
    pub neighbour_share: f32,
    /// Scale of the particle colliders relative to their cluster's extent (item 10). Default 1.
    pub particle_scale: f32,
    /// Simulate in local or world space (item 11). Default world.
    pub space: SimulationSpace,
    /// Scale of the center collider (item 12). Default 1: the center never feels its
    /// particles (one-way, as in the thesis), so a body rests on its center collider, and a
    /// smaller one shows as a permanent flattening of the bottom (measured on a dropped
    /// 20 cm icosphere: rest-shape error 5.4 mm at 0.8, 0.8 mm at 1.0).
    pub center_scale: f32,
    /// Center collider shape (item 13). Default ball.
    pub center_collider: CenterCollider,
    /// Mass of the center body in kg (world mode). Default 1.
    pub center_mass_kg: f32,
    /// Particles of this body collide with each other (item 14). Default false (thesis 3.5.3).
    pub self_collisions: bool,
    /// Only vertices inside this region are soft (item 15). Default none: all soft.
    pub soft_region: Option<SoftRegion>,
    /// Largest velocity change per step in m/s (thesis 3.2.2's MoveTowards limit). Default 10.
    pub max_velocity_change_mps: f32,
    /// Particles may sleep when they and the body are at rest (rapier islands). Default true:
    /// an untouched body then costs almost nothing. Benchmarks turn it off to time every
    /// particle active.
    pub particles_can_sleep: bool,
    /// Continuous collision detection of the particles. Default soft CCD, 5 cm.
    pub continuous_collision: ContinuousCollision,
    /// Restoring scheme. Default exact; `thesis` reproduces the original for comparison.
    pub restoring: RestoringScheme,
    /// Contact friction of particles and center. Default 0.5.
    pub friction: f32,
    /// Rolling resistance of the center (world mode), dimensionless: while the center touches
    /// something, a torque of `rolling_resistance × normal force × center radius` opposes its
    /// spin (never reversing it), so a body rolling on a floor slows at about
    /// `5/7 · rolling_resistance · g` and comes to rest (below a rolling speed of 1 cm/s it
    /// leaves the body to rapier's sleep). Rapier has none: without it a soft ball rolls on a
    /// flat table for ever. In flight it does nothing. Range 0–1; default
    /// 0.05 (rubber on wood is 0.01–0.05; a soft body deforms and loses more). 0 turns it off.
    pub rolling_resistance: f32,
    /// Distance below which vertices are welded, metres. Default 1e-6.
    pub weld_epsilon_m: f32,
    /// Width of the slit a tear cuts (tear paper §3.1, the box's width), metres, in
    /// [0.1 mm, 5 cm]; or 0 for an *incision* (the paper's zero-width, non-destructive tear):
    /// the tissue is parted along the blade's path without removing any of it that shows —
    /// the two lips are [`INCISION_WIDTH_M`] apart at rest (they must stay distinct vertices:
    /// the body welds closer ones back into one), and the wound opens only as the tissue is
    /// pulled. Default 3 mm.
    pub tear_width_m: f32,
    /// How far a tear's wound opens at rest, metres (tear paper §3.3.4): the particles beside
    /// each tear segment's slit have their anchors moved away from it, up to this far (the
    /// nearest most, fading to nothing two particle sizes out), so the lips part as tissue
    /// does when cut. Their vertices follow them; the rest mesh is unchanged. In [0, 1 cm];
    /// default 0 (a slit stays as it was cut).
    pub slit_open_m: f32,
    /// Rate, 1/s, at which the body's enclosed volume returns to its rest volume: a global
    /// pressure over the whole surface. The restoring pulls each particle back to its own
    /// place, so a body squeezed between two plates has nowhere to put its volume and loses
    /// it (the thesis's method kept 0.44 of it in the squeeze); this term pushes the free
    /// particles out along the surface's volume gradient instead, so the body bulges as
    /// tissue does. The push is internal: its net force and torque are taken out, so a body
    /// held or pressed on one side is not pushed away from what holds it. Each step it corrects the fraction `1 − exp(−rate·dt)` of the volume the
    /// step would otherwise end with missing (or in excess), the restoring's own motion
    /// included. It reads only the current shape: nothing more travels in a room. Off for a
    /// torn body (its surface is open). 0 turns it off; in [0, 1e4]; default 0 (off): at 250
    /// the bunny squeezed to 30 % of its height keeps about 0.86–0.90 of its volume (the
    /// Neo-Hookean reference 0.88; without the term 0.44). Opt-in: with it on, a cut
    /// piece held in a desktop peer's hand drifted from its other half in one of three runs of
    /// the pixel test (a cut's splinter crawling under it, with the term on or off:
    /// see the stop-53 note), and a rollback room's late joiner desynced
    /// once.
    pub volume_stiffness: f32,
    /// A named material (Young's modulus, Poisson's ratio, the room's step rate) this body
    /// should behave as. The config does not apply it by itself: a scene's loader
    /// (`methods::material::particle_setting`) measures the class's body and sets
    /// `stiffness`, `volume_stiffness` and, past what the rate allows, `particle_mass_kg` to
    /// the nearest setting, and says how near it is. Default none.
    pub material: Option<crate::methods::material::NamedMaterial>,
}

/// How far apart an incision's lips are at rest (`tear_width_m: 0`), metres: two and a half
/// times the tear's vertex clearance (20 µm), the least gap the mesh keeps as two distinct
/// lips, fifty times the body's weld.
pub const INCISION_WIDTH_M: f32 = 5e-5;

impl SoftBodyConfig {
    /// The width a tear cuts: `tear_width_m`, or an incision's [`INCISION_WIDTH_M`] for 0.
    pub fn effective_tear_width_m(&self) -> f32 {
        if self.tear_width_m == 0.0 {
            INCISION_WIDTH_M
        } else {
            self.tear_width_m
        }
    }
}

impl Default for SoftBodyConfig {
    fn default() -> Self {
        Self {
            cluster: ClusterMethod::ClosestN {
                vertices_per_particle: 3,
            },
            collider: ParticleCollider::Sphere,
            particle_mass_kg: 0.05,
            angular_damping: 0.05,
            stiffness: 20.0,
            affect_range_m: 0.0,
            neighbour_share: 0.35,
            particle_scale: 1.0,
            space: SimulationSpace::World,
            center_scale: 1.0,
            center_collider: CenterCollider::Ball,
            center_mass_kg: 1.0,
            self_collisions: false,
            soft_region: None,
            max_velocity_change_mps: 10.0,
            restoring: RestoringScheme::Exact,
            particles_can_sleep: true,
            continuous_collision: ContinuousCollision::Soft { prediction_m: 0.05 },
            friction: 0.5,
            rolling_resistance: 0.05,
            weld_epsilon_m: 1e-6,
            tear_width_m: 0.003,
            slit_open_m: 0.0,
            volume_stiffness: 0.0,
            material: None,
        }
    }
}

impl SoftBodyConfig {
    /// Rejects values outside their documented range with a message naming the field.
    pub fn validate(&self) -> Result<(), SoftBodyError> {
        let check = |name: &str, v: f32, lo: f32, hi: f32| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(SoftBodyError::Config(format!(
                    "{name} = {v} is outside [{lo}, {hi}]"
                )))
            }
        };
        check("particle_mass_kg", self.particle_mass_kg, 1e-4, 1e3)?;
        check("angular_damping", self.angular_damping, 0.0, 1e3)?;
        check("stiffness", self.stiffness, 0.01, 1e4)?;
        check("affect_range_m", self.affect_range_m, 0.0, 1e3)?;
        check("neighbour_share", self.neighbour_share, 0.0, 0.5)?;
        check("particle_scale", self.particle_scale, 1e-3, 1e2)?;
        check("center_scale", self.center_scale, 1e-3, 10.0)?;
        check("center_mass_kg", self.center_mass_kg, 1e-4, 1e5)?;
        check(
            "max_velocity_change_mps",
            self.max_velocity_change_mps,
            1e-3,
            1e4,
        )?;
        check("friction", self.friction, 0.0, 100.0)?;
        check("rolling_resistance", self.rolling_resistance, 0.0, 1.0)?;
        check("weld_epsilon_m", self.weld_epsilon_m, 0.0, 1.0)?;
        check("slit_open_m", self.slit_open_m, 0.0, 0.01)?;
        check("volume_stiffness", self.volume_stiffness, 0.0, 1e4)?;
        if let Some(m) = &self.material {
            m.validate()?;
        }
        let w = self.tear_width_m;
        if w != 0.0 && !(w.is_finite() && (1e-4..=crate::cut::MAX_TEAR_WIDTH_M).contains(&w)) {
            return Err(SoftBodyError::Config(format!(
                "tear_width_m = {w} is outside [0.0001, {}] (or 0 for an incision)",
                crate::cut::MAX_TEAR_WIDTH_M
            )));
        }
        Ok(())
    }
}
