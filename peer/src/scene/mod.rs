//! Scenes are data: a room's object classes, its fixed geometry and the objects the host
//! spawns, read from a RON file ([`file`]) and checked whole before anything starts.
//!
//! Class ids on the wire are indices into the scene's class table: 0 and 1 are the avatar's
//! head and hands (every room has them), then the file's classes in order. Every peer of a
//! room loads the same scene; the session's digest covers the class table, the soft bodies'
//! settings and meshes (see [`Scene::content_digest`]), so a joiner with another scene is
//! refused at the handshake with a clear reason.

pub mod body;
mod bundle;
pub mod cache;
mod file;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

pub use bundle::MAX_BUNDLE_BYTES;

use glam::{EulerRot, Quat, Vec3};
use softsync_net::{
    AuthorityPolicy, ClassConfig, ClassId, SendPolicy, SessionConfig, SoftBodyMode,
};
use softsync_softbody::methods::auto::{AutoMode, AutoSettings, Ladder};
use softsync_softbody::rapier3d::prelude::*;
use softsync_softbody::{Mesh, SoftBodyConfig, SoftBodyPlan, StageClock};

pub use file::{ReplicationFile, SCENE_EXTENSION};

/// A class of networked object: an index into the scene's class table (its [`ClassId`] on
/// the wire). [`Kind::HEAD`] and [`Kind::HAND`] are every room's avatar parts; the scene's own
/// classes follow. Names, shapes and bodies are the scene's: [`Scene::class`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Kind(pub u16);

impl Kind {
    /// An avatar's head (a pose, no body).
    pub const HEAD: Kind = Kind(0);
    /// An avatar's hand (a pose, no body).
    pub const HAND: Kind = Kind(1);
    /// How many class ids the avatar takes before the scene's classes.
    pub const AVATAR_CLASSES: u16 = 2;

    /// Its class id.
    pub fn class(self) -> ClassId {
        ClassId(self.0)
    }

    /// The kind of a class id (whether the scene has it: [`Scene::class`]).
    pub fn of_class(c: ClassId) -> Kind {
        Kind(c.0)
    }

    /// Part of an avatar.
    pub fn is_avatar(self) -> bool {
        self.0 < Self::AVATAR_CLASSES
    }
}

/// A class's collision and drawing shape. Sizes in metres.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A sphere (soft: an icosphere of `subdivisions` levels).
    Ball {
        /// Radius.
        radius_m: f32,
        /// Icosphere levels of a soft ball.
        subdivisions: u32,
    },
    /// A box (soft: `subdivisions` cells per edge on each face).
    Cuboid {
        /// Half its size on each axis.
        half_extents_m: Vec3,
        /// Cells per edge of a soft box.
        subdivisions: u32,
    },
    /// An upright cylinder (rigid only).
    Cylinder {
        /// Half its height.
        half_height_m: f32,
        /// Radius.
        radius_m: f32,
    },
    /// A mesh file (OBJ, glTF, GLB or PLY), scaled so its largest extent is `size_m` and
    /// centred on its vertices' centroid (rigid: its convex hull).
    Mesh {
        /// The file as the scene names it, relative to the scene file's directory.
        file: String,
        /// Its largest extent in the room.
        size_m: f32,
    },
}

/// How a class's objects are simulated.
#[derive(Clone, Debug, PartialEq)]
pub enum BodyClass {
    /// An avatar part: a pose, no body.
    Avatar,
    /// A rigid body.
    Rigid {
        /// kg/m³.
        density: f32,
        /// Contact friction.
        friction: f32,
    },
    /// A soft body with these settings (the particle method, thesis chapter 3).
    Soft(Box<SoftBodyConfig>),
}

/// One class of the scene.
#[derive(Clone)]
pub struct Class {
    /// Its name: bot scripts, dumps, the HUD, `--focus`.
    pub name: String,
    /// Shape.
    pub shape: Shape,
    /// Body.
    pub body: BodyClass,
    /// Colour (linear sRGB components in 0–1) a renderer draws it with.
    pub colour: [f32; 3],
    /// Replication settings that differ from the room's defaults.
    pub replication: ReplicationFile,
    /// Who may take its objects' authority.
    pub authority: AuthorityPolicy,
    /// A soft class's mesh, sized and centred, or a rigid mesh class's points (loaded with
    /// the scene, so a missing file stops the scene, not the first spawn).
    mesh: Option<Mesh>,
    /// A soft class with `method: auto`: its resolution ladder.
    pub auto: Option<Box<AutoClass>>,
    /// A soft class that named a material (`body: Soft(material: (young_kpa: …, poisson: …))`):
    /// the setting found for it and how near it is (printed when the scene loads).
    pub material: Option<Box<softsync_softbody::methods::material::ParticleSetting>>,
}

/// A soft class's `method: auto` (see `softbody::methods::auto`): the ladder of resolutions,
/// probed on this machine ([`Scene::probe_auto`]), and the level objects spawn at.
#[derive(Clone, Debug)]
pub struct AutoClass {
    /// Budgets and hysteresis.
    pub settings: AutoSettings,
    /// The levels, what the probe measured, the touch and squeeze levels it picked.
    pub ladder: Ladder,
    /// The level objects spawn at on every peer (the one nearest 1×).
    pub base: usize,
}

impl AutoClass {
    /// Builds the ladder of `base` for `mesh` (each level clustered once); until
    /// [`Scene::probe_auto`], both picks are the spawn level.
    pub fn new(mesh: &Mesh, base: &SoftBodyConfig, settings: AutoSettings) -> Result<Self, String> {
        let ladder = Ladder::new(mesh, base, &settings).map_err(|e| e.to_string())?;
        let base = ladder.touch;
        Ok(AutoClass {
            settings,
            ladder,
            base,
        })
    }

    /// The level for a mode.
    pub fn level(&self, mode: AutoMode) -> usize {
        self.ladder.level(mode)
    }
}

impl std::fmt::Debug for Class {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Class")
            .field("name", &self.name)
            .field("shape", &self.shape)
            .field("body", &self.body)
            .field("colour", &self.colour)
            .field("replication", &self.replication)
            .field("authority", &self.authority)
            .field(
                "mesh",
                &self
                    .mesh
                    .as_ref()
                    .map(|m| (m.positions.len(), m.triangles.len())),
            )
            .finish()
    }
}

impl Class {
    /// A soft body.
    pub fn is_soft(&self) -> bool {
        matches!(self.body, BodyClass::Soft(_))
    }

    /// The class's mesh as loaded and sized (a `Mesh` shape, or a soft ball or box), in its
    /// own frame.
    pub fn mesh(&self) -> Option<&Mesh> {
        self.mesh.as_ref()
    }
}

/// A fixed box of the room (the floor, a table top, its legs): built on every peer.
#[derive(Clone, Debug, PartialEq)]
pub struct FixedBox {
    /// Half its size on each axis, metres.
    pub half_extents_m: Vec3,
    /// Its center.
    pub at: Vec3,
    /// Contact friction.
    pub friction: f32,
    /// Colour a renderer draws it with.
    pub colour: [f32; 3],
}

/// An object the host spawns when the room opens.
#[derive(Clone, Copy, Debug)]
pub struct Placed {
    /// Class.
    pub kind: Kind,
    /// Where.
    pub pos: Vec3,
    /// How it is turned.
    pub rot: Quat,
}

/// A scene: its classes, its fixed geometry (built on every peer) and its objects (spawned by
/// the host).
#[derive(Clone, Debug)]
pub struct Scene {
    /// Name.
    pub name: String,
    /// The file it came from.
    pub path: PathBuf,
    /// Class table, indexed by [`Kind`]: the avatar's two, then the file's.
    pub classes: Vec<Class>,
    /// Fixed geometry.
    pub fixed: Vec<FixedBox>,
    /// Objects the host spawns.
    pub objects: Vec<Placed>,
    /// The box positions are quantized in (every class's bounds), metres.
    pub bounds: (Vec3, Vec3),
    /// The application's message types the room relays, by name, after the built-in ones
    /// (the file's `messages`): peers with the same scene can talk in them whether or not
    /// they know the types (the `softsync` binary relays and logs a bell it cannot decode).
    pub messages: Vec<String>,
    content_digest: u64,
    /// Soft classes planned once (see [`Scene::soft_plan`]), shared by the scene's clones.
    soft_plans: SoftPlans,
}

/// The soft bodies a scene has planned: per class, the mesh and config it was planned with
/// (a class changed since is planned again) and the plan.
#[derive(Clone, Default)]
struct SoftPlans(Arc<Mutex<Vec<Planned>>>);

/// A class's plan and what it was planned from.
type Planned = (Kind, Mesh, SoftBodyConfig, SoftBodyPlan);

impl std::fmt::Debug for SoftPlans {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.0.lock().map_or(0, |p| p.len());
        write!(f, "SoftPlans({n} planned)")
    }
}

/// Height of the thesis room's table top, metres (where the desktop camera looks at first).
pub const TABLE_TOP_Y: f32 = 0.75;

/// The scene a host opens unless told otherwise (shipped in `assets/`).
pub const DEFAULT_SCENE: &str = "thesis-room";

impl Scene {
    /// A scene by file path, or by name: `NAME` is `ASSETS/NAME.ron` (the shipped ones:
    /// `thesis-room`, the default, and `bench-ball`: one soft ball on the table, for the live
    /// benchmark).
    pub fn by_name(name: &str, assets: &Path) -> Result<Scene, String> {
        let path = if name.ends_with(SCENE_EXTENSION) || name.contains('/') {
            PathBuf::from(name)
        } else {
            assets.join(format!("{name}{SCENE_EXTENSION}"))
        };
        if !path.is_file() && !name.contains('/') && !name.ends_with(SCENE_EXTENSION) {
            let shipped = std::fs::read_dir(assets)
                .map(|d| {
                    let mut names: Vec<String> = d
                        .flatten()
                        .filter_map(|e| {
                            e.file_name()
                                .to_str()?
                                .strip_suffix(SCENE_EXTENSION)
                                .map(str::to_owned)
                        })
                        .collect();
                    names.sort();
                    names.join(", ")
                })
                .unwrap_or_default();
            return Err(format!(
                "unknown scene {name:?}: no {} (scenes in {}: {shipped}; or give a path to a \
                 {SCENE_EXTENSION} file)",
                path.display(),
                assets.display()
            ));
        }
        Scene::load(&path)
    }

    /// Reads, checks and prepares the scene file at `path` (meshes are loaded and every soft
    /// class is built once): an error names the file, the line or field, and what is wrong.
    pub fn load(path: &Path) -> Result<Scene, String> {
        Scene::load_with(path, file::MeshPaths::Any)
    }

    fn load_with(path: &Path, meshes: file::MeshPaths) -> Result<Scene, String> {
        let text =
            std::fs::read_to_string(path).map_err(|e| format!("scene {}: {e}", path.display()))?;
        file::parse(&text, path, meshes).map_err(|e| format!("scene {}: {e}", path.display()))
    }

    /// [`load`](Self::load) of `text` as if read from `path` (meshes relative to its
    /// directory).
    pub fn parse(text: &str, path: &Path) -> Result<Scene, String> {
        file::parse(text, path, file::MeshPaths::Any)
            .map_err(|e| format!("scene {}: {e}", path.display()))
    }

    /// The kind of a class name (not the avatar's).
    pub fn kind(&self, name: &str) -> Option<Kind> {
        self.classes
            .iter()
            .position(|c| c.name == name)
            .map(|i| Kind(i as u16))
            .filter(|k| !k.is_avatar())
    }

    /// A class.
    pub fn class(&self, kind: Kind) -> Option<&Class> {
        self.classes.get(kind.0 as usize)
    }

    /// A class's name (`?` for a class this scene does not have).
    pub fn name_of(&self, kind: Kind) -> &str {
        self.class(kind).map_or("?", |c| c.name.as_str())
    }

    /// Whether `kind` is a soft body.
    pub fn is_soft(&self, kind: Kind) -> bool {
        self.class(kind).is_some_and(Class::is_soft)
    }

    /// The scene's classes that are not the avatar's, with their kinds.
    pub fn object_classes(&self) -> impl Iterator<Item = (Kind, &Class)> {
        self.classes
            .iter()
            .enumerate()
            .skip(Kind::AVATAR_CLASSES as usize)
            .map(|(i, c)| (Kind(i as u16), c))
    }

    /// A digest of everything two peers must agree on beyond the session's class table: each
    /// class's shape, body settings and mesh, and the fixed geometry (placement is the
    /// host's, so not in it).
    pub fn content_digest(&self) -> u64 {
        self.content_digest
    }

    /// The session configuration every peer of this scene uses: each class's send policy is
    /// `avatar`, `soft` or `rigid` with the class's own replication settings over it (thesis
    /// 5.3); its digest covers [`content_digest`](Self::content_digest). Its message table
    /// holds the built-in types ([`crate::messages::builtin`]), then the scene's
    /// [`messages`](Self::messages); an application with more of its own starts from that
    /// table ([`MessageTypes::from_config`](softsync_net::messages::MessageTypes::from_config)),
    /// registers them and configures the result over it.
    pub fn session_config(
        &self,
        avatar: SendPolicy,
        soft: SendPolicy,
        rigid: SendPolicy,
    ) -> SessionConfig {
        let classes = self
            .classes
            .iter()
            .map(|c| {
                let base = match c.body {
                    BodyClass::Avatar => &avatar,
                    BodyClass::Soft(_) => &soft,
                    BodyClass::Rigid { .. } => &rigid,
                };
                let send = c.replication.over(base);
                let mut cc = if c.is_soft() {
                    let mode = if c.replication.centre_only == Some(true) {
                        SoftBodyMode::CenterOnly
                    } else {
                        SoftBodyMode::Particles
                    };
                    let mut cc = ClassConfig::soft_body(&c.name, send, mode);
                    cc.particle_extent_m = c.replication.particle_extent_m.unwrap_or(0.4);
                    cc
                } else {
                    ClassConfig::rigid(&c.name, send)
                };
                cc.authority = c.authority;
                cc.bounds_min = self.bounds.0.to_array();
                cc.bounds_max = self.bounds.1.to_array();
                cc
            })
            .collect();
        let mut cfg = SessionConfig {
            classes,
            content_digest: self.content_digest,
            ..SessionConfig::default()
        };
        let mut types = crate::messages::builtin();
        for n in &self.messages {
            // Checked when the file was read: no name twice, none a built-in one.
            let _ = types.register_name(n);
        }
        types.configure(&mut cfg);
        cfg
    }

    /// The fixed geometry (bodies on every peer).
    pub fn build_static(&self, world: &mut PhysicsWorld) {
        for b in &self.fixed {
            let body = world.insert_body(RigidBodyBuilder::fixed().translation(b.at));
            let h = b.half_extents_m;
            world.insert_collider(
                ColliderBuilder::cuboid(h.x, h.y, h.z).friction(b.friction),
                Some(body),
            );
        }
    }

    /// A rigid object's body and collider at `pos`, `rot`; `None` for a class that is not
    /// rigid.
    pub fn build_rigid(
        &self,
        kind: Kind,
        world: &mut PhysicsWorld,
        pos: Vec3,
        rot: Quat,
    ) -> Option<RigidBodyHandle> {
        let class = self.class(kind)?;
        let BodyClass::Rigid { density, friction } = class.body else {
            return None;
        };
        let collider = match &class.shape {
            Shape::Ball { radius_m, .. } => ColliderBuilder::ball(*radius_m),
            Shape::Cuboid { half_extents_m, .. } => {
                let h = half_extents_m;
                ColliderBuilder::cuboid(h.x, h.y, h.z)
            }
            Shape::Cylinder {
                half_height_m,
                radius_m,
            } => ColliderBuilder::cylinder(*half_height_m, *radius_m),
            // Checked at load: the hull exists.
            Shape::Mesh { .. } => {
                ColliderBuilder::convex_hull(class.mesh.as_ref().map_or(&[][..], |m| &m.positions))?
            }
        };
        let body = world.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(Pose::from_parts(pos, rot))
                .linear_damping(0.05)
                .angular_damping(0.2)
                .ccd_enabled(true),
        );
        world.insert_collider(collider.density(density).friction(friction), Some(body));
        Some(body)
    }

    /// A soft class's mesh, centred on the origin, at its size in the room.
    pub fn soft_mesh(&self, kind: Kind) -> Result<Mesh, String> {
        match self.class(kind) {
            Some(c) if c.is_soft() => c
                .mesh
                .clone()
                .ok_or_else(|| format!("class {} has no mesh", c.name)),
            Some(c) => Err(format!("{} is not a soft body", c.name)),
            None => Err(format!("class {} is not in scene {}", kind.0, self.name)),
        }
    }

    /// Probes every `method: auto` class's ladder on this machine (a few hundred steps of
    /// each level, timed with `clock`, in milliseconds: the I/O layer's, e.g. `Room::open`'s)
    /// and picks its touch and squeeze levels. Until then an auto body stays at its spawn
    /// level (it still sleeps at rest). Only the owner of an object decides its level, so
    /// peers whose machines pick differently still agree on every object.
    pub fn probe_auto(&mut self, clock: StageClock) -> Result<(), String> {
        for c in &mut self.classes {
            if let (Some(a), Some(mesh)) = (c.auto.as_deref_mut(), c.mesh.as_ref()) {
                a.ladder
                    .probe(mesh, &a.settings, clock)
                    .map_err(|e| format!("class {}: auto probe: {e}", c.name))?;
            }
        }
        Ok(())
    }

    /// A soft class's `method: auto`, if it has one.
    pub fn auto(&self, kind: Kind) -> Option<&AutoClass> {
        self.class(kind)?.auto.as_deref()
    }

    /// A soft class's settings at resolution `level` (`method: auto`; any other soft class
    /// has level 0 only).
    pub fn level_config(&self, kind: Kind, level: usize) -> Option<&SoftBodyConfig> {
        match self.auto(kind) {
            Some(a) => a.ladder.configs.get(level),
            None if level == 0 => self.soft_config(kind),
            None => None,
        }
    }

    /// Class `kind`'s soft body planned (welded, clustered): planned the first time, then
    /// copied — a body of the bunny is ~8 ms to plan and a fraction of a millisecond to put in
    /// a world from its plan, and a room builds many (spawns, a snapshot, a cut's pieces,
    /// rebuilds). Planned again if the class's mesh or config changed since.
    pub fn soft_plan(&self, kind: Kind) -> Result<SoftBodyPlan, String> {
        let config = self
            .soft_config(kind)
            .ok_or_else(|| format!("class {} is not a soft body", kind.0))?
            .clone();
        let mesh = self.soft_mesh(kind)?;
        let mut plans = self.soft_plans.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((.., plan)) = plans
            .iter()
            .find(|(k, m, c, _)| *k == kind && *c == config && *m == mesh)
        {
            return Ok(plan.clone());
        }
        let plan = SoftBodyPlan::new(&mesh, config.clone())
            .map_err(|e| format!("{}: {e}", self.name_of(kind)))?;
        plans.retain(|(k, ..)| *k != kind);
        plans.push((kind, mesh, config, plan.clone()));
        Ok(plan)
    }

    /// A soft class's settings (for `method: auto`, its spawn level's).
    pub fn soft_config(&self, kind: Kind) -> Option<&SoftBodyConfig> {
        match &self.class(kind)?.body {
            BodyClass::Soft(c) => Some(c),
            _ => None,
        }
    }
}

/// The rotation of Euler angles in degrees (about y, then x, then z: yaw, pitch, roll).
fn rotation_deg(r: [f32; 3]) -> Quat {
    let [x, y, z] = r.map(f32::to_radians);
    Quat::from_euler(EulerRot::YXZ, y, x, z)
}

/// The avatar's two classes (sizes of the thesis's room: a head box and hand boxes).
fn avatar_classes() -> [Class; 2] {
    let part = |name: &str, half: Vec3| Class {
        name: name.to_owned(),
        shape: Shape::Cuboid {
            half_extents_m: half,
            subdivisions: 1,
        },
        body: BodyClass::Avatar,
        colour: [0.4, 0.6, 0.9],
        replication: ReplicationFile::default(),
        authority: AuthorityPolicy::Free,
        mesh: None,
        auto: None,
        material: None,
    };
    [
        part("head", Vec3::new(0.08, 0.1, 0.09)),
        part("hand", Vec3::new(0.025, 0.015, 0.045)),
    ]
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn assets() -> PathBuf {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets"))
    }

    #[test]
    fn a_soft_class_is_planned_once_and_again_when_it_changes() {
        let mut scene = Scene::by_name("bench-ball", &assets()).unwrap();
        let k = scene.kind("softball").unwrap();
        let a = scene.soft_plan(k).unwrap();
        assert_eq!(a.num_particles(), 60);
        let copy = scene.clone();
        assert_eq!(copy.soft_plan(k).unwrap().num_particles(), 60);
        assert_eq!(format!("{:?}", copy.soft_plans), "SoftPlans(1 planned)");
        // a changed class is planned anew
        if let BodyClass::Soft(c) = &mut scene.classes[usize::from(k.0)].body {
            c.cluster = softsync_softbody::ClusterMethod::PoissonDisk {
                radius_m: 0.012,
                seed: 1,
            };
        }
        assert!(scene.soft_plan(k).unwrap().num_particles() > 60);
        assert!(scene.soft_plan(scene.kind("block").unwrap()).is_err());
    }

    #[test]
    fn the_soft_ball_is_the_thesis_60_particle_body_and_every_class_builds() {
        let scene = Scene::by_name("thesis-room", &assets()).unwrap();
        let mut world = PhysicsWorld::new();
        let mut set = softsync_softbody::SoftBodySet::new();
        let names: Vec<&str> = scene
            .object_classes()
            .map(|(_, c)| c.name.as_str())
            .collect();
        assert_eq!(
            names,
            ["plate", "block", "can", "ball", "bunny", "softball", "softbox"]
        );
        for (k, c) in scene.object_classes() {
            assert_eq!(scene.kind(&c.name), Some(k));
            assert_eq!(Kind::of_class(k.class()), k);
            if !c.is_soft() {
                assert!(scene
                    .build_rigid(k, &mut world, Vec3::Y, Quat::IDENTITY)
                    .is_some());
                continue;
            }
            let h = set
                .insert(
                    &scene.soft_mesh(k).unwrap(),
                    scene.soft_config(k).unwrap().clone(),
                    &mut world,
                )
                .unwrap();
            let n = set.get(h).unwrap().num_particles();
            if c.name == "softball" {
                assert_eq!(n, 60);
            }
            assert!((20..=80).contains(&n), "{} has {n} particles", c.name);
        }
        assert_eq!(scene.objects.len(), 7);
        assert_eq!(scene.kind("head"), None);
        assert!(Kind::HEAD.is_avatar() && Kind::HAND.is_avatar());
        let err = Scene::by_name("moon", &assets()).unwrap_err();
        assert!(
            err.contains("thesis-room") && err.contains("bench-ball"),
            "{err}"
        );
    }

    #[test]
    fn the_digest_follows_the_content_and_not_the_placement() {
        let a = Scene::by_name("thesis-room", &assets()).unwrap();
        let text = std::fs::read_to_string(&a.path).unwrap();
        let moved = text.replacen("at: (0.0, 0.761, 0.0)", "at: (0.1, 0.761, 0.0)", 1);
        assert_ne!(moved, text);
        let b = Scene::parse(&moved, &a.path).unwrap();
        assert_eq!(a.content_digest(), b.content_digest());
        let stiffer = text.replacen("stiffness: 20.0", "stiffness: 30.0", 1);
        assert_ne!(stiffer, text);
        let c = Scene::parse(&stiffer, &a.path).unwrap();
        assert_ne!(a.content_digest(), c.content_digest());
        let p = SendPolicy::default();
        let (ca, cc) = (
            a.session_config(p.clone(), p.clone(), p.clone()),
            c.session_config(p.clone(), p.clone(), p),
        );
        assert_ne!(ca.digest(), cc.digest());
    }
}
