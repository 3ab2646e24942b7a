//! The scene file: RON. (Over 800 lines with its 140 lines of tests: the file types and the
//! checks that read them are one owned part — a field's type and the check naming it change
//! together.)
//!
//! Why RON: a scene is mostly Rust types (the soft body's `SoftBodyConfig` with its enums of
//! clustering methods and colliders, the net crate's `AuthorityPolicy`) and RON writes Rust
//! enums and structs as they are, with comments and trailing commas; its errors carry the line
//! and column; bevy users know it from bevy's own scenes, and bevy already builds the crate.
//! JSON has no comments and no enums; TOML's tables make nested enums awkward.
//!
//! ```ron
//! Scene(
//!     name: "my-room",
//!     fixed: [(half_extents: (10.0, 0.5, 10.0), at: (0.0, -0.5, 0.0))],
//!     classes: [
//!         (name: "ball", shape: Ball(radius: 0.035), body: Rigid(density: 300.0)),
//!         (
//!             name: "liver",
//!             shape: Mesh(file: "liver.glb", size_m: 0.18),
//!             body: Soft(cluster: (method: "distance", radius_m: 0.03), stiffness: 15.0),
//!             replication: (send_rate_hz: 30.0),
//!         ),
//!     ],
//!     objects: [(class: "liver", at: (0.0, 0.85, 0.0))],
//! )
//! ```
//!
//! Parsing is two steps: `ron` reads the text into these types (unknown fields, wrong types
//! and syntax errors come back with their line and column), then [`parse`] checks every value
//! and loads every mesh, naming the field (`classes[4] "bunny": shape.size_m: …`). A scene
//! either loads whole or not at all.

use std::path::Path;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use softsync_net::{AuthorityPolicy, SendPolicy};
use softsync_softbody::rapier3d::prelude::{ColliderBuilder, PhysicsWorld};
use softsync_softbody::{Mesh, SoftBodyConfig, SoftBodySet};

use softsync_softbody::methods::auto::AutoSettings;

use super::{
    avatar_classes, rotation_deg, AutoClass, BodyClass, Class, FixedBox, Kind, Placed, Scene, Shape,
};

/// A scene file's extension.
pub const SCENE_EXTENSION: &str = ".ron";

/// Bounds on what a scene may declare (a hostile file costs bounded work).
const MAX_CLASSES: usize = 1000;
const MAX_OBJECTS: usize = 10_000;
const MAX_FIXED: usize = 10_000;
const MAX_NAME_CHARS: usize = 64;
const MAX_MESSAGE_TYPES: usize = 1000;
const MAX_SIZE_M: f32 = 100.0;
const MAX_TEXT_BYTES: usize = 4 << 20;

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Scene")]
struct SceneFile {
    name: String,
    /// The room's box, metres: positions are quantized in it. Default x, z in ±8, y in −2..6.
    #[serde(default)]
    bounds: Option<BoundsFile>,
    #[serde(default)]
    fixed: Vec<FixedFile>,
    classes: Vec<ClassFile>,
    #[serde(default)]
    objects: Vec<ObjectFile>,
    /// The application's message types, by name (`Message::NAME`), after the built-in ones.
    #[serde(default)]
    messages: Vec<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Bounds")]
struct BoundsFile {
    min: [f32; 3],
    max: [f32; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Fixed")]
struct FixedFile {
    half_extents: [f32; 3],
    at: [f32; 3],
    #[serde(default = "default_friction")]
    friction: f32,
    #[serde(default)]
    colour: Option<[f32; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Class")]
struct ClassFile {
    name: String,
    shape: ShapeFile,
    body: BodyFile,
    #[serde(default)]
    colour: Option<[f32; 3]>,
    #[serde(default)]
    replication: ReplicationFile,
    #[serde(default = "default_authority")]
    authority: AuthorityPolicy,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Shape")]
enum ShapeFile {
    Ball {
        radius: f32,
        #[serde(default)]
        subdivisions: Option<u32>,
    },
    Cuboid {
        half_extents: [f32; 3],
        #[serde(default)]
        subdivisions: Option<u32>,
    },
    Cylinder {
        half_height: f32,
        radius: f32,
    },
    Mesh {
        file: String,
        size_m: f32,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Body")]
enum BodyFile {
    Rigid {
        density: f32,
        #[serde(default = "default_friction_rigid")]
        friction: f32,
    },
    /// The particle method's settings: any field of `SoftBodyConfig`, the rest default.
    Soft(SoftBodyConfig),
    /// `method: auto`: the particle method at the resolution the object needs now (asleep
    /// at rest, the cheapest level within `error_budget_mm` when touched, the most accurate
    /// within `cost_budget_ms` when squeezed); `soft` is the 1× level. Fields left out take
    /// the defaults of `softbody::methods::auto::AutoSettings`.
    Auto {
        soft: SoftBodyConfig,
        #[serde(default)]
        error_budget_mm: Option<f32>,
        #[serde(default)]
        cost_budget_ms: Option<f32>,
        #[serde(default)]
        resolutions: Option<Vec<f32>>,
        #[serde(default)]
        squeeze_mm: Option<f32>,
        #[serde(default)]
        rest_s: Option<f32>,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, rename = "Object")]
struct ObjectFile {
    class: String,
    at: [f32; 3],
    /// Euler angles in degrees: yaw about y, then pitch about x, then roll about z.
    #[serde(default)]
    rotation_deg: Option<[f32; 3]>,
}

/// A class's replication settings that differ from the room's defaults (thesis 5.3–5.4); a
/// field left out keeps the default (the `--send-rate` and `--threshold-mm` of the peer).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename = "Replication")]
pub struct ReplicationFile {
    /// Updates per second while moving (0.1–240).
    #[serde(default)]
    pub send_rate_hz: Option<f32>,
    /// A position change below this is not sent, mm.
    #[serde(default)]
    pub position_threshold_mm: Option<f32>,
    /// A rotation change below this is not sent, degrees.
    #[serde(default)]
    pub rotation_threshold_deg: Option<f32>,
    /// A particle offset change below this is not sent, mm.
    #[serde(default)]
    pub particle_threshold_mm: Option<f32>,
    /// Soft bodies: send only the centre (thesis 5.4.1; remotes simulate the particles
    /// themselves) instead of the centre and every particle (5.4.2, the default).
    #[serde(default)]
    pub centre_only: Option<bool>,
    /// Soft bodies: half-extent of particle offsets around the centre, metres (default 0.4).
    #[serde(default)]
    pub particle_extent_m: Option<f32>,
    /// The class's weight when an uplink budget makes objects wait their turn (0.01–100,
    /// default 1; `--uplink-kbps`).
    #[serde(default)]
    pub priority: Option<f32>,
}

impl ReplicationFile {
    /// `base` with these settings over it.
    pub fn over(&self, base: &SendPolicy) -> SendPolicy {
        let mut p = base.clone();
        if let Some(v) = self.send_rate_hz {
            p.rate_hz = v;
        }
        if let Some(v) = self.position_threshold_mm {
            p.position_threshold_m = v * 1e-3;
        }
        if let Some(v) = self.rotation_threshold_deg {
            p.rotation_threshold_rad = v.to_radians();
        }
        if let Some(v) = self.particle_threshold_mm {
            p.particle_threshold_m = v * 1e-3;
        }
        if let Some(v) = self.priority {
            p.priority = v;
        }
        p
    }

    fn check(&self) -> Result<(), String> {
        let range = |field: &str, v: Option<f32>, lo: f32, hi: f32| match v {
            Some(x) if !(x.is_finite() && x >= lo && x <= hi) => {
                Err(format!("replication.{field}: {x} is outside {lo}–{hi}"))
            }
            _ => Ok(()),
        };
        range("send_rate_hz", self.send_rate_hz, 0.1, 240.0)?;
        range(
            "position_threshold_mm",
            self.position_threshold_mm,
            0.0,
            1000.0,
        )?;
        range(
            "rotation_threshold_deg",
            self.rotation_threshold_deg,
            0.0,
            180.0,
        )?;
        range(
            "particle_threshold_mm",
            self.particle_threshold_mm,
            0.0,
            1000.0,
        )?;
        range("particle_extent_m", self.particle_extent_m, 0.01, 10.0)?;
        range("priority", self.priority, 0.01, 100.0)
    }
}

fn default_friction() -> f32 {
    0.8
}

fn default_friction_rigid() -> f32 {
    0.7
}

fn default_authority() -> AuthorityPolicy {
    AuthorityPolicy::Free
}

/// A finite vector (a field's name for the error).
fn finite(field: &str, v: [f32; 3]) -> Result<Vec3, String> {
    let v = Vec3::from_array(v);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{field}: {v} is not finite"))
    }
}

/// A size in (0, MAX_SIZE_M].
fn size(field: &str, v: f32) -> Result<f32, String> {
    if v.is_finite() && v > 0.0 && v <= MAX_SIZE_M {
        Ok(v)
    } else {
        Err(format!("{field}: {v} m is not a size in (0, {MAX_SIZE_M}]"))
    }
}

fn colour(field: &str, c: Option<[f32; 3]>, default: [f32; 3]) -> Result<[f32; 3], String> {
    match c {
        None => Ok(default),
        Some(c) if c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)) => Ok(c),
        Some(c) => Err(format!("{field}: {c:?} has a component outside 0–1")),
    }
}

/// Which files a scene's meshes may name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum MeshPaths {
    /// Any path, relative to the scene's folder: the user's own scene file.
    Any,
    /// Plain relative paths inside the scene's folder (no root, no `..`): a scene that came
    /// from another peer, whose folder is its bundle.
    Confined,
}

/// Reads and checks a scene (`path`: where it was read from; meshes are relative to its
/// directory, and confined to it as `meshes` says).
pub(super) fn parse(text: &str, path: &Path, meshes: MeshPaths) -> Result<Scene, String> {
    if text.len() > MAX_TEXT_BYTES {
        return Err(format!(
            "{} bytes, more than the {MAX_TEXT_BYTES} a scene may have",
            text.len()
        ));
    }
    // `colour: (1.0, 0.5, 0.0)` for an optional field, and `Soft(stiffness: 20.0)` for the
    // settings struct inside the variant.
    let options = ron::Options::default().with_default_extension(
        ron::extensions::Extensions::IMPLICIT_SOME
            | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
    );
    let f: SceneFile = options.from_str(text).map_err(|e| e.to_string())?;
    let dir = path.parent().unwrap_or(Path::new("."));

    if f.name.trim().is_empty() || f.name.chars().count() > MAX_NAME_CHARS {
        return Err(format!(
            "name: {:?} is empty or longer than {MAX_NAME_CHARS} characters",
            f.name
        ));
    }
    let bounds = match &f.bounds {
        None => (Vec3::new(-8.0, -2.0, -8.0), Vec3::new(8.0, 6.0, 8.0)),
        Some(b) => {
            let (lo, hi) = (finite("bounds.min", b.min)?, finite("bounds.max", b.max)?);
            if !(lo.cmplt(hi).all() && (hi - lo).max_element() <= 1000.0) {
                return Err(format!(
                    "bounds: min {lo} must be below max {hi} on every axis, at most 1 km apart"
                ));
            }
            (lo, hi)
        }
    };
    if f.classes.len() > MAX_CLASSES || f.objects.len() > MAX_OBJECTS || f.fixed.len() > MAX_FIXED {
        return Err(format!(
            "{} classes, {} objects, {} fixed boxes: at most {MAX_CLASSES}, {MAX_OBJECTS}, \
             {MAX_FIXED}",
            f.classes.len(),
            f.objects.len(),
            f.fixed.len()
        ));
    }

    let mut fixed = Vec::with_capacity(f.fixed.len());
    for (i, b) in f.fixed.iter().enumerate() {
        let at = |e: String| format!("fixed[{i}].{e}");
        let h = finite("half_extents", b.half_extents).map_err(at)?;
        for x in h.to_array() {
            size("half_extents", x).map_err(at)?;
        }
        fixed.push(FixedBox {
            half_extents_m: h,
            at: finite("at", b.at).map_err(at)?,
            friction: friction(b.friction).map_err(at)?,
            colour: colour("colour", b.colour, [0.45, 0.32, 0.22]).map_err(at)?,
        });
    }

    let mut classes: Vec<Class> = avatar_classes().into();
    for (i, c) in f.classes.into_iter().enumerate() {
        let name = c.name.clone();
        let at = |e: String| format!("classes[{i}] {name:?}: {e}");
        if name.is_empty()
            || name.chars().count() > MAX_NAME_CHARS
            || !name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '-' || ch == '_')
        {
            return Err(at(format!(
                "name: a class name is 1–{MAX_NAME_CHARS} letters, digits, - or _ (bot scripts \
                 and --focus name it)"
            )));
        }
        if classes.iter().any(|k| k.name == name) {
            return Err(at(if name == "head" || name == "hand" {
                "name: head and hand are the avatar's classes".to_owned()
            } else {
                "name: a class of this name comes earlier".to_owned()
            }));
        }
        c.replication.check().map_err(at)?;
        let class = class(c, dir, meshes).map_err(at)?;
        classes.push(class);
    }
    if classes.len() > usize::from(u16::MAX) {
        return Err("too many classes".into());
    }

    let mut objects = Vec::with_capacity(f.objects.len());
    for (i, o) in f.objects.iter().enumerate() {
        let at = |e: String| format!("objects[{i}]: {e}");
        let kind = classes
            .iter()
            .position(|c| c.name == o.class)
            .map(|k| Kind(k as u16))
            .filter(|k| !k.is_avatar())
            .ok_or_else(|| {
                at(format!(
                    "class: no class {:?} in the scene (its classes: {})",
                    o.class,
                    classes
                        .iter()
                        .skip(usize::from(Kind::AVATAR_CLASSES))
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })?;
        let pos = finite("at", o.at).map_err(at)?;
        if !(pos.cmpge(bounds.0).all() && pos.cmple(bounds.1).all()) {
            return Err(at(format!(
                "at: {pos} is outside the room's bounds {} .. {}",
                bounds.0, bounds.1
            )));
        }
        let rot = match o.rotation_deg {
            None => Quat::IDENTITY,
            Some(r) => rotation_deg(finite("rotation_deg", r).map_err(at)?.to_array()),
        };
        objects.push(Placed { kind, pos, rot });
    }

    let messages = message_names(f.messages)?;

    let mut scene = Scene {
        name: f.name,
        path: path.to_owned(),
        classes,
        fixed,
        objects,
        bounds,
        messages,
        content_digest: 0,
        soft_plans: Default::default(),
    };
    scene.content_digest = digest(&scene);
    Ok(scene)
}

/// The scene's message names: each 1–64 printable ASCII characters without spaces, none
/// twice, none a built-in type's.
fn message_names(names: Vec<String>) -> Result<Vec<String>, String> {
    let builtin = crate::messages::builtin();
    if names.len() > MAX_MESSAGE_TYPES {
        return Err(format!(
            "messages: {} types, at most {MAX_MESSAGE_TYPES}",
            names.len()
        ));
    }
    for (i, n) in names.iter().enumerate() {
        let at = |e: &str| format!("messages[{i}] {n:?}: {e}");
        if n.is_empty() || n.len() > MAX_NAME_CHARS || !n.chars().all(|c| c.is_ascii_graphic()) {
            return Err(at(&format!(
                "a message type's name is 1–{MAX_NAME_CHARS} printable ASCII characters, no spaces"
            )));
        }
        if builtin.names().iter().any(|b| b == n) {
            return Err(at("a built-in message type has this name"));
        }
        if names[..i].contains(n) {
            return Err(at("named twice"));
        }
    }
    Ok(names)
}

fn friction(v: f32) -> Result<f32, String> {
    if v.is_finite() && (0.0..=10.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("friction: {v} is outside 0–10"))
    }
}

/// One class, checked, its mesh loaded, a soft class built once in a scratch world.
fn class(c: ClassFile, dir: &Path, meshes: MeshPaths) -> Result<Class, String> {
    let mut auto = None;
    let soft = matches!(c.body, BodyFile::Soft(_) | BodyFile::Auto { .. });
    let shape = match c.shape {
        ShapeFile::Ball {
            radius,
            subdivisions,
        } => Shape::Ball {
            radius_m: size("shape.radius", radius)?,
            subdivisions: levels("shape.subdivisions", subdivisions, 3, 0, 5)?,
        },
        ShapeFile::Cuboid {
            half_extents,
            subdivisions,
        } => {
            let h = finite("shape.half_extents", half_extents)?;
            for x in h.to_array() {
                size("shape.half_extents", x)?;
            }
            Shape::Cuboid {
                half_extents_m: h,
                subdivisions: levels("shape.subdivisions", subdivisions, 2, 1, 16)?,
            }
        }
        ShapeFile::Cylinder {
            half_height,
            radius,
        } => {
            if soft {
                return Err(
                    "shape: a soft body is a Ball, a Cuboid or a Mesh (make a cylinder a mesh \
                     file)"
                        .into(),
                );
            }
            Shape::Cylinder {
                half_height_m: size("shape.half_height", half_height)?,
                radius_m: size("shape.radius", radius)?,
            }
        }
        ShapeFile::Mesh { file, size_m } => Shape::Mesh {
            file,
            size_m: size("shape.size_m", size_m)?,
        },
    };
    let mut body = match c.body {
        BodyFile::Rigid {
            density,
            friction: f,
        } => {
            if !(density.is_finite() && density > 0.0 && density <= 1e5) {
                return Err(format!(
                    "body.density: {density} kg/m³ is outside (0, 100000]"
                ));
            }
            BodyClass::Rigid {
                density,
                friction: friction(f).map_err(|e| format!("body.{e}"))?,
            }
        }
        BodyFile::Soft(cfg) => {
            cfg.validate().map_err(|e| format!("body: {e}"))?;
            BodyClass::Soft(Box::new(cfg))
        }
        BodyFile::Auto {
            soft: cfg,
            error_budget_mm,
            cost_budget_ms,
            resolutions,
            squeeze_mm,
            rest_s,
        } => {
            cfg.validate().map_err(|e| format!("body.soft: {e}"))?;
            let d = AutoSettings::default();
            let settings = AutoSettings {
                error_budget_mm: error_budget_mm.unwrap_or(d.error_budget_mm),
                cost_budget_ms: cost_budget_ms.unwrap_or(d.cost_budget_ms),
                resolutions: resolutions.unwrap_or(d.resolutions),
                squeeze_mm: squeeze_mm.unwrap_or(d.squeeze_mm),
                rest_s: rest_s.unwrap_or(d.rest_s),
                ..d
            };
            settings
                .validate()
                .map_err(|e| format!("body: {}", e.to_string().replace("auto.", "")))?;
            auto = Some(settings);
            BodyClass::Soft(Box::new(cfg))
        }
    };
    let mesh = match &shape {
        Shape::Mesh { file, size_m } => {
            if meshes == MeshPaths::Confined {
                super::bundle::check_path(file).map_err(|e| format!("shape.file: {e}"))?;
            }
            let path = dir.join(file);
            let mut m = Mesh::load(&path)
                .map_err(|e| format!("shape.file: cannot load {}: {e}", path.display()))?
                .fit_size(*size_m);
            m.recenter();
            if !soft && ColliderBuilder::convex_hull(&m.positions).is_none() {
                return Err(format!(
                    "shape.file: {} has no convex hull (flat or degenerate)",
                    path.display()
                ));
            }
            Some(m)
        }
        Shape::Ball {
            radius_m,
            subdivisions,
        } if soft => Some(Mesh::icosphere(*radius_m, *subdivisions)),
        Shape::Cuboid {
            half_extents_m,
            subdivisions,
        } if soft => Some(Mesh::cuboid(*half_extents_m, *subdivisions)),
        _ => None,
    };
    let mut auto_class = None;
    let mut material = None;
    if let (BodyClass::Soft(cfg), Some(m)) = (&mut body, &mesh) {
        if let Some(named) = cfg.material {
            // A cube of the class's size and clustering, measured: the nearest setting to the
            // named material (`softbody::methods::material`).
            let (lo, hi) = softsync_softbody::mesh::bounds(&m.positions);
            let size = (hi - lo).max_element();
            let setting = softsync_softbody::methods::material::particle_setting(cfg, size, &named)
                .map_err(|e| format!("body: {e}"))?;
            **cfg = setting.config.clone();
            material = Some(Box::new(setting));
        }
        // Built once now: a setting that fails only on a real mesh (too few particles, no
        // hull for the centre) stops the scene here, not at the first spawn.
        let mut world = PhysicsWorld::new();
        SoftBodySet::new()
            .insert(m, (**cfg).clone(), &mut world)
            .map_err(|e| format!("body: a soft body of this shape cannot be built: {e}"))?;
        if let Some(settings) = auto {
            let a = AutoClass::new(m, cfg, settings).map_err(|e| format!("body: {e}"))?;
            // objects spawn at the 1x level on every peer; their owner moves them from there
            **cfg = a.ladder.configs[a.base].clone();
            auto_class = Some(Box::new(a));
        }
    }
    Ok(Class {
        name: c.name,
        shape,
        body,
        colour: colour("colour", c.colour, [0.8, 0.8, 0.8])?,
        replication: c.replication,
        authority: c.authority,
        mesh,
        auto: auto_class,
        material,
    })
}

fn levels(field: &str, v: Option<u32>, default: u32, lo: u32, hi: u32) -> Result<u32, String> {
    match v {
        None => Ok(default),
        Some(x) if (lo..=hi).contains(&x) => Ok(x),
        Some(x) => Err(format!("{field}: {x} is outside {lo}–{hi}")),
    }
}

/// FNV-1a over what every peer must agree on: each class's name, shape, body and mesh, and
/// the fixed geometry. Placement and colours are left out (the host places; colours are a
/// renderer's).
fn digest(scene: &Scene) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h ^= u64::from(*b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for c in &scene.classes {
        eat(format!("{}|{:?}|{:?}|", c.name, c.shape, c.body).as_bytes());
        if let Some(a) = &c.auto {
            // the ladder, not the probe's figures (they are this machine's)
            eat(format!("auto|{:?}|{:?}|", a.settings, a.ladder.configs).as_bytes());
        }
        if let Some(m) = &c.mesh {
            for p in &m.positions {
                for x in p.to_array() {
                    eat(&x.to_bits().to_le_bytes());
                }
            }
            for t in &m.triangles {
                for i in t {
                    eat(&i.to_le_bytes());
                }
            }
        }
    }
    for b in &scene.fixed {
        eat(format!("{:?}|{:?}|{}|", b.half_extents_m, b.at, b.friction).as_bytes());
    }
    h
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    fn assets() -> PathBuf {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets"))
    }

    fn room() -> String {
        std::fs::read_to_string(assets().join("thesis-room.ron")).unwrap()
    }

    /// The error `text` (the thesis room with one change) gives.
    fn err(text: &str) -> String {
        let e = Scene::parse(text, &assets().join("broken.ron")).unwrap_err();
        assert!(e.starts_with("scene "), "{e}");
        assert!(e.contains("broken.ron"), "{e}");
        e
    }

    fn swap(from: &str, to: &str) -> String {
        let t = room();
        assert!(t.contains(from), "the thesis room has no {from:?}");
        t.replacen(from, to, 1)
    }

    #[test]
    fn every_shipped_scene_loads() {
        let mut n = 0;
        for e in std::fs::read_dir(assets()).unwrap().flatten() {
            let p = e.path();
            if p.to_str().unwrap().ends_with(SCENE_EXTENSION) {
                let s = Scene::load(&p).unwrap();
                assert!(!s.objects.is_empty(), "{}", p.display());
                n += 1;
            }
        }
        assert!(n >= 2, "{n} scenes shipped");
    }

    /// A class that names a material loads with the setting found for it (measured on a cube
    /// of its size and clustering, within 2 % of the modulus and 0.03 of the ratio asked for);
    /// an out-of-range material is refused with the field named.
    #[test]
    fn a_material_class_loads_and_a_wrong_material_is_refused() {
        let text = swap(
            "stiffness: 20.0",
            "material: (young_kpa: 3.0, poisson: 0.4, rate_hz: 60.0)",
        );
        let scene = Scene::parse(&text, &assets().join("material.ron")).unwrap();
        let c = scene.classes.iter().find(|c| c.name == "bunny").unwrap();
        let setting = c.material.as_ref().expect("the material's setting");
        assert!(setting.young_err_pct.abs() < 2.0, "{setting}");
        assert!(setting.poisson_err.abs() < 0.03, "{setting}");
        let BodyClass::Soft(cfg) = &c.body else {
            panic!("the bunny is soft");
        };
        assert_eq!(cfg.stiffness, setting.config.stiffness);
        assert_ne!(cfg.stiffness, 20.0, "the setting was not applied");
        for (field, bad) in [
            ("young_kpa", "young_kpa: 0.0, poisson: 0.4"),
            ("poisson", "young_kpa: 3.0, poisson: 0.5"),
            ("rate_hz", "young_kpa: 3.0, poisson: 0.4, rate_hz: 1.0"),
        ] {
            let e = err(&swap("stiffness: 20.0", &format!("material: ({bad})")));
            assert!(
                e.contains(&format!("material.{field}")) && e.contains("\"bunny\""),
                "{e}"
            );
        }
    }

    #[test]
    fn a_broken_scene_says_where_and_what() {
        // Syntax, an unknown field, a wrong type: ron's line and column.
        let e = err(&swap("objects: [", "objects: [[["));
        assert!(e.contains(':'), "{e}");
        let e = err(&swap("density: 800.0", "densty: 800.0"));
        assert!(e.contains("densty") && e.contains(':'), "{e}");
        let line = room()
            .lines()
            .position(|l| l.contains("densty") || l.contains("density: 800.0"))
            .unwrap()
            + 1;
        assert!(e.contains(&format!("{line}:")), "line {line}: {e}");
        // Types are named as the file writes them, not as the code does.
        let e = err(&swap(
            "colour: (0.93, 0.93, 0.90)",
            "colr: (0.93, 0.93, 0.90)",
        ));
        assert!(e.contains("colr") && e.contains("`Class`"), "{e}");
        let e = err(&swap("density: 800.0", "density: \"heavy\""));
        assert!(e.contains("heavy") || e.contains("float"), "{e}");
        // A missing mesh names the class and the file.
        let e = err(&swap("bunny.obj", "rabbit.obj"));
        assert!(e.contains("\"bunny\"") && e.contains("rabbit.obj"), "{e}");
        // NaN and out-of-room placement, an unknown class.
        let e = err(&swap("at: (0.0, 0.761, 0.0)", "at: (NaN, 0.761, 0.0)"));
        assert!(e.contains("objects[0]") && e.contains("finite"), "{e}");
        let e = err(&swap("at: (0.0, 0.761, 0.0)", "at: (0.0, 99.0, 0.0)"));
        assert!(e.contains("objects[0]") && e.contains("bounds"), "{e}");
        let e = err(&swap("(class: \"plate\"", "(class: \"saucer\""));
        assert!(e.contains("saucer") && e.contains("softbox"), "{e}");
        // Soft settings out of range, a soft cylinder.
        let e = err(&swap("stiffness: 20.0", "stiffness: 50000.0"));
        assert!(e.contains("stiffness") && e.contains("\"bunny\""), "{e}");
        // Message types: twice, a built-in name, a blank name.
        let e = err(&swap(
            "classes: [",
            "messages: [\"bell\", \"bell\"], classes: [",
        ));
        assert!(e.contains("messages[1]") && e.contains("twice"), "{e}");
        let e = err(&swap(
            "classes: [",
            "messages: [\"softsync.say\"], classes: [",
        ));
        assert!(e.contains("built-in"), "{e}");
        let e = err(&swap("classes: [", "messages: [\"a b\"], classes: ["));
        assert!(e.contains("messages[0]"), "{e}");
        // Duplicate and reserved names.
        let e = err(&swap("name: \"block\"", "name: \"plate\""));
        assert!(e.contains("earlier"), "{e}");
        let e = err(&swap("name: \"block\"", "name: \"hand\""));
        assert!(e.contains("avatar"), "{e}");
        // Replication out of range.
        let e = err(&swap(
            "name: \"ball\",",
            "name: \"ball\", replication: (send_rate_hz: 0.0),",
        ));
        assert!(e.contains("send_rate_hz"), "{e}");
        // A soft cylinder.
        let e = err(&swap(
            "shape: Ball(radius: 0.06, subdivisions: 3)",
            "shape: Cylinder(half_height: 0.05, radius: 0.05)",
        ));
        assert!(e.contains("soft body is a Ball"), "{e}");
    }
}
