//! A hand's settings: hold mode (velocity-based, or parent-based to compare), soft-body grab
//! (center or particle), reach and hover radii, limits, the physical controller.

use serde::{Deserialize, Serialize};

/// How a held object follows the hand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldMode {
    /// Thesis 4.1: each step the velocity is set to reach the hand; other forces still act.
    Velocity,
    /// Thesis 4.2, for comparison only: the pose is set to the hand's; passes through walls
    /// and cannot throw.
    Parent,
}

/// What a grab on a soft body takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SoftGrab {
    /// The closest particle (thesis 4.1.2).
    Particle,
    /// The whole body by its center, where the center is dynamic (thesis 4.1.1); otherwise
    /// the closest particle.
    Center,
}

/// Per-hand settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HandConfig {
    /// Radius of the hover sphere around the hand, metres. Default 0.06.
    pub hover_radius_m: f32,
    /// Grip value at which a grab starts. Default 0.55.
    pub grip_on: f32,
    /// Grip value below which a grab ends (hysteresis). Default 0.35.
    pub grip_off: f32,
    /// Velocity (default) or parent hold.
    pub hold_mode: HoldMode,
    /// Particle (default) or center grab on soft bodies.
    pub soft_grab: SoftGrab,
    /// Largest linear speed a hold may ask for, m/s. Default 12.
    pub max_linear_speed_mps: f32,
    /// Largest angular speed a hold may ask for, rad/s. Default 25.
    pub max_angular_speed_radps: f32,
    /// A pose further than this from the previous one is a teleport: the hand restarts its
    /// history there, so no throw or hold picks up the jump. Default 0.5 m.
    pub teleport_distance_m: f32,
    /// Grip with nothing hovered makes the hand a physical body that pushes (4.1.3). Default on.
    pub physical_controller: bool,
    /// Radius of the physical controller's ball, metres. Default 0.04.
    pub controller_radius_m: f32,
    /// Mass of the physical controller, kg. Default 0.5.
    pub controller_mass_kg: f32,
    /// Speed below which a released object counts as at rest, m/s. Default 0.02.
    pub rest_speed_mps: f32,
    /// How long it must stay below that speed, seconds. Default 0.5.
    pub rest_time_s: f32,
}

impl HandConfig {
    /// Rejects values outside their range with a message naming the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let check = |name: &'static str, v: f32, lo: f32, hi: f32| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(ConfigError {
                    field: name,
                    value: v,
                    min: lo,
                    max: hi,
                })
            }
        };
        check("hover_radius_m", self.hover_radius_m, 1e-4, 2.0)?;
        check("grip_on", self.grip_on, 0.0, 1.0)?;
        check("grip_off", self.grip_off, 0.0, self.grip_on)?;
        check("max_linear_speed_mps", self.max_linear_speed_mps, 1e-3, 1e3)?;
        check(
            "max_angular_speed_radps",
            self.max_angular_speed_radps,
            1e-3,
            1e4,
        )?;
        check("teleport_distance_m", self.teleport_distance_m, 1e-3, 1e4)?;
        check("controller_radius_m", self.controller_radius_m, 1e-4, 1.0)?;
        check("controller_mass_kg", self.controller_mass_kg, 1e-4, 1e3)?;
        check("rest_speed_mps", self.rest_speed_mps, 0.0, 10.0)?;
        check("rest_time_s", self.rest_time_s, 0.0, 60.0)?;
        Ok(())
    }
}

/// A hand setting out of its range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("hand config: {field} = {value} is outside [{min}, {max}]")]
pub struct ConfigError {
    /// The field.
    pub field: &'static str,
    /// Its value.
    pub value: f32,
    /// Lowest allowed.
    pub min: f32,
    /// Highest allowed.
    pub max: f32,
}

impl Default for HandConfig {
    fn default() -> Self {
        Self {
            hover_radius_m: 0.06,
            grip_on: 0.55,
            grip_off: 0.35,
            hold_mode: HoldMode::Velocity,
            soft_grab: SoftGrab::Particle,
            max_linear_speed_mps: 12.0,
            max_angular_speed_radps: 25.0,
            teleport_distance_m: 0.5,
            physical_controller: true,
            controller_radius_m: 0.04,
            controller_mass_kg: 0.5,
            rest_speed_mps: 0.02,
            rest_time_s: 0.5,
        }
    }
}
