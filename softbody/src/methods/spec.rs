//! What a method is and how it is set up: the [`MethodKind`], its resolution and solver budget
//! ([`MethodSpec`]) and the [`Material`] every method models. Both the builders and the
//! models read these; this module depends on neither.

use serde::{Deserialize, Serialize};

use crate::methods::pbd::PbdParams;
use crate::{RestoringScheme, SoftBodyError, SoftRegion};

/// The methods compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum MethodKind {
    /// The thesis's particle method on rapier ([`crate::SoftBodySet`]).
    Particle,
    /// PBD/XPBD on the surface only: edge distance + dihedral bending.
    Surface,
    /// The surface model plus internal shape-preserving links (ISPC paper).
    Ispc,
    /// XPBD on tets (edges + volume) with the surface embedded: the accuracy reference.
    Tet,
    /// Shape matching on overlapping clusters from the particle map (Müller et al. 2005).
    ShapeMatching,
    /// rapier 0.36's own volumetric soft body, surface embedded in its cells.
    RapierNative,
    /// Stable Neo-Hookean XPBD tets (Macklin & Müller 2021) on a Kuhn lattice weighted by
    /// inside fraction, surface embedded: the accuracy reference. A small-steps method: it
    /// needs about 20 or more substeps per 60 Hz step (fewer, and a step can overshoot).
    NeoHookean,
    /// The ISPC paper's tetrahedral baseline (its eqs. 5–11): strain constraints (stretch and
    /// shear of Green's strain) plus tet-edge distances on the same tet cover as [`Self::Tet`].
    StrainTet,
}

impl MethodKind {
    /// All methods.
    pub const ALL: [MethodKind; 8] = [
        MethodKind::Particle,
        MethodKind::Surface,
        MethodKind::Ispc,
        MethodKind::Tet,
        MethodKind::ShapeMatching,
        MethodKind::RapierNative,
        MethodKind::NeoHookean,
        MethodKind::StrainTet,
    ];

    /// Short name.
    pub fn name(&self) -> &'static str {
        match self {
            MethodKind::Particle => "particle",
            MethodKind::Surface => "surface_pbd",
            MethodKind::Ispc => "ispc",
            MethodKind::Tet => "tet",
            MethodKind::ShapeMatching => "shape_matching",
            MethodKind::RapierNative => "rapier_native",
            MethodKind::NeoHookean => "neo_hookean",
            MethodKind::StrainTet => "strain_tet",
        }
    }
}

/// Material shared by the position-based methods, so that they model the same object.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Young's modulus, Pa (distance constraints get `E · V_share / L²`).
    pub young_pa: f32,
    /// Bulk modulus of the tet volume constraints, Pa.
    pub bulk_pa: f32,
    /// Bending stiffness as a fraction of `E · L³`.
    pub bend_ratio: f32,
    /// Density, kg/m³.
    pub density_kg_m3: f32,
    /// Plain-PBD stiffness per iteration, (0, 1].
    pub pbd_stiffness: f32,
    /// Shape-matching rate, 1/s.
    pub shape_rate_per_s: f32,
    /// Stiffness of the ISPC links relative to a rod sharing the body's volume evenly: links
    /// span the body, so a thin rod underestimates the solid they stand for (the paper tunes
    /// its link stiffness against the tet model the same way).
    pub link_scale: f32,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            young_pa: 2.0e5,
            bulk_pa: 4.0e5,
            bend_ratio: 0.05,
            density_kg_m3: 1000.0,
            pbd_stiffness: 0.5,
            shape_rate_per_s: 120.0,
            link_scale: 30.0,
        }
    }
}

/// A method at one resolution and solver budget.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MethodSpec {
    /// The method.
    pub kind: MethodKind,
    /// Resolution knob as a fraction of the object's size: tet / native cell size, particle
    /// and shape-matching cluster radius. Unused by the surface and ISPC models (they use the
    /// mesh's own vertices).
    pub cell_frac: f32,
    /// Substeps and iterations, solver and contact settings of the position-based methods.
    pub params: PbdParams,
    /// Material.
    pub material: Material,
    /// Only this region (world coordinates of the mesh given to
    /// [`build_model`](crate::methods::build_model)) is soft; the rest follows rigidly (thesis
    /// 3.5.2). Particle method only; `None` = all soft.
    #[serde(default)]
    pub soft_region: Option<SoftRegion>,
    /// The particle method's restoring scheme (thesis 3.2.2; default ours, `Thesis` the
    /// original kept to compare). Particle method only.
    #[serde(default = "exact_restoring")]
    pub restoring: RestoringScheme,
    /// The particle method's particles collide with each other (thesis 3.5.3 turns this off;
    /// default off). Particle method only.
    #[serde(default)]
    pub self_collisions: bool,
    /// The particle method's rolling resistance (`SoftBodyConfig::rolling_resistance`;
    /// default that config's). Particle method only.
    #[serde(default = "default_rolling_resistance")]
    pub rolling_resistance: f32,
    /// The particle method's volume term (`SoftBodyConfig::volume_stiffness`, 1/s; default
    /// that config's, 0 turns it off). Particle method only.
    #[serde(default = "default_volume_stiffness")]
    pub volume_stiffness: f32,
}

fn exact_restoring() -> RestoringScheme {
    RestoringScheme::Exact
}

fn default_rolling_resistance() -> f32 {
    crate::SoftBodyConfig::default().rolling_resistance
}

fn default_volume_stiffness() -> f32 {
    crate::SoftBodyConfig::default().volume_stiffness
}

impl MethodSpec {
    /// `kind` with its default resolution and budget.
    pub fn new(kind: MethodKind) -> Self {
        Self {
            kind,
            cell_frac: match kind {
                MethodKind::Particle | MethodKind::ShapeMatching => 0.06,
                _ => 0.12,
            },
            params: PbdParams::default(),
            material: Material::default(),
            soft_region: None,
            restoring: RestoringScheme::Exact,
            self_collisions: false,
            rolling_resistance: default_rolling_resistance(),
            volume_stiffness: default_volume_stiffness(),
        }
    }

    /// With the particle method's volume term rate, 1/s (0 turns it off).
    pub fn volume_stiffness(mut self, rate_per_s: f32) -> Self {
        self.volume_stiffness = rate_per_s;
        self
    }

    /// With the particle method's rolling resistance (0 turns it off).
    pub fn rolling_resistance(mut self, coefficient: f32) -> Self {
        self.rolling_resistance = coefficient;
        self
    }

    /// With the particle method's restoring scheme.
    pub fn restoring(mut self, scheme: RestoringScheme) -> Self {
        self.restoring = scheme;
        self
    }

    /// With the particle method's self-collisions on or off.
    pub fn self_collisions(mut self, on: bool) -> Self {
        self.self_collisions = on;
        self
    }

    /// With the body's total mass set to `mass_kg` (the density that gives it, for `mesh`'s
    /// enclosed volume `volume_m3`).
    pub fn total_mass(mut self, mass_kg: f32, volume_m3: f32) -> Self {
        self.material.density_kg_m3 = mass_kg / volume_m3.abs().max(1e-12);
        self
    }

    /// With substeps and iterations.
    pub fn budget(mut self, substeps: u32, iterations: u32) -> Self {
        self.params.substeps = substeps.max(1);
        self.params.iterations = iterations.max(1);
        self
    }

    /// With a resolution knob.
    pub fn cell(mut self, cell_frac: f32) -> Self {
        self.cell_frac = cell_frac;
        self
    }

    /// Rejects values outside their range (a spec may come from a file): resolution in
    /// [0.005, 1] of the size, 1–1024 substeps and 1–256 iterations, a finite positive material.
    pub fn validate(&self) -> Result<(), SoftBodyError> {
        let bad = |what: &str| Err(SoftBodyError::Config(format!("{}: {what}", self.label())));
        if !(self.cell_frac.is_finite() && (0.005..=1.0).contains(&self.cell_frac)) {
            return bad("cell_frac must be in [0.005, 1]");
        }
        let p = &self.params;
        if !(1..=1024).contains(&p.substeps) || !(1..=256).contains(&p.iterations) {
            return bad("substeps must be in 1..=1024 and iterations in 1..=256");
        }
        let m = &self.material;
        let positive = [
            m.young_pa,
            m.bulk_pa,
            m.density_kg_m3,
            m.pbd_stiffness,
            m.shape_rate_per_s,
            m.link_scale,
        ];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0))
            || !(m.bend_ratio.is_finite() && m.bend_ratio >= 0.0)
            || m.pbd_stiffness > 1.0
        {
            return bad("material values must be finite and positive (pbd_stiffness ≤ 1)");
        }
        let nonneg = [
            p.damping_per_s,
            p.contact_radius_m,
            p.friction,
            p.sleep_speed_mps,
            p.sleep_after_s,
        ];
        if nonneg.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return bad("solver values must be finite and non-negative");
        }
        Ok(())
    }

    /// With a restricted soft region (particle method).
    pub fn region(mut self, region: Option<SoftRegion>) -> Self {
        self.soft_region = region;
        self
    }

    /// A label such as `tet c0.08 s4i8`.
    pub fn label(&self) -> String {
        let p = &self.params;
        let mut region = if self.soft_region.is_some() {
            " region".to_string()
        } else {
            String::new()
        };
        if self.restoring == RestoringScheme::Thesis {
            region += " thesis";
        }
        if self.self_collisions {
            region += " selfcol";
        }
        if self.kind == MethodKind::Particle
            && self.rolling_resistance != default_rolling_resistance()
        {
            region += &format!(" roll{}", self.rolling_resistance);
        }
        if self.kind == MethodKind::Particle && self.volume_stiffness != default_volume_stiffness()
        {
            region += &format!(" vol{}", self.volume_stiffness);
        }
        match self.kind {
            MethodKind::Surface | MethodKind::Ispc => {
                format!("{} s{}i{}", self.kind.name(), p.substeps, p.iterations)
            }
            MethodKind::Particle | MethodKind::RapierNative => {
                format!("{} c{:.3}{region}", self.kind.name(), self.cell_frac)
            }
            _ => format!(
                "{} c{:.3} s{}i{}",
                self.kind.name(),
                self.cell_frac,
                p.substeps,
                p.iterations
            ),
        }
    }
}
