//! The `thesis-room` scene: the user-study room of the thesis (a table with a plate, three soft
//! bodies and a few rigid props) and the object classes every peer shares.

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use softsync_net::{ClassConfig, ClassId, SendPolicy, SessionConfig, SoftBodyMode};
use softsync_softbody::rapier3d::prelude::*;
use softsync_softbody::{ClusterMethod, Mesh, SimulationSpace, SoftBodyConfig};

/// What a networked object is. The class id on the wire is the index in [`Kind::ALL`], so
/// every peer builds the same body for a spawned id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    /// An avatar's head (a pose, no body).
    Head,
    /// An avatar's hand (a pose, no body).
    Hand,
    /// The plate on the table (rigid).
    Plate,
    /// A wooden block (rigid).
    Block,
    /// A can (rigid cylinder).
    Can,
    /// A ball (rigid).
    Ball,
    /// The Stanford bunny (soft).
    Bunny,
    /// An icosphere (soft).
    SoftBall,
    /// A box (soft).
    SoftBox,
}

impl Kind {
    /// Every kind, in class-id order.
    pub const ALL: [Kind; 9] = [
        Kind::Head,
        Kind::Hand,
        Kind::Plate,
        Kind::Block,
        Kind::Can,
        Kind::Ball,
        Kind::Bunny,
        Kind::SoftBall,
        Kind::SoftBox,
    ];

    /// Its class id.
    pub fn class(self) -> ClassId {
        ClassId(Kind::ALL.iter().position(|k| *k == self).unwrap_or(0) as u16)
    }

    /// The kind of a class id.
    pub fn of_class(c: ClassId) -> Option<Kind> {
        Kind::ALL.get(c.0 as usize).copied()
    }

    /// Name (dumps, bot scripts).
    pub fn name(self) -> &'static str {
        match self {
            Kind::Head => "head",
            Kind::Hand => "hand",
            Kind::Plate => "plate",
            Kind::Block => "block",
            Kind::Can => "can",
            Kind::Ball => "ball",
            Kind::Bunny => "bunny",
            Kind::SoftBall => "softball",
            Kind::SoftBox => "softbox",
        }
    }

    /// Kind by name.
    pub fn from_name(s: &str) -> Option<Kind> {
        Kind::ALL.iter().copied().find(|k| k.name() == s)
    }

    /// Part of an avatar.
    pub fn is_avatar(self) -> bool {
        matches!(self, Kind::Head | Kind::Hand)
    }

    /// A soft body.
    pub fn is_soft(self) -> bool {
        matches!(self, Kind::Bunny | Kind::SoftBall | Kind::SoftBox)
    }
}

/// The session configuration every peer of a `thesis-room` uses (its digest is checked when
/// joining). `rate_hz` and the thresholds are the thesis's replication policies (5.3).
pub fn session_config(avatar: SendPolicy, soft: SendPolicy, rigid: SendPolicy) -> SessionConfig {
    let classes = Kind::ALL
        .iter()
        .map(|k| {
            let mut c = if k.is_soft() {
                let mut c = ClassConfig::soft_body(k.name(), soft.clone(), SoftBodyMode::Particles);
                c.particle_extent_m = 0.4;
                c
            } else if k.is_avatar() {
                ClassConfig::rigid(k.name(), avatar.clone())
            } else {
                ClassConfig::rigid(k.name(), rigid.clone())
            };
            c.bounds_min = [-8.0, -2.0, -8.0];
            c.bounds_max = [8.0, 6.0, 8.0];
            c
        })
        .collect();
    SessionConfig {
        classes,
        ..SessionConfig::default()
    }
}

/// Height of the table top.
pub const TABLE_TOP_Y: f32 = 0.75;

/// An object the host spawns when the room opens.
#[derive(Clone, Copy, Debug)]
pub struct Placed {
    /// Kind.
    pub kind: Kind,
    /// Where.
    pub pos: Vec3,
}

/// A scene: its static geometry is built on every peer; its objects are spawned by the host.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Name.
    pub name: String,
    /// Objects the host spawns.
    pub objects: Vec<Placed>,
    /// Where the bunny mesh is.
    pub assets: PathBuf,
}

impl Scene {
    /// A scene by name (`thesis-room`, or `bench-ball`: one soft ball on the table, for the
    /// live benchmark).
    pub fn by_name(name: &str, assets: &Path) -> Result<Scene, String> {
        let y = TABLE_TOP_Y;
        let objects = match name {
            "thesis-room" => vec![
                Placed {
                    kind: Kind::Plate,
                    pos: Vec3::new(0.0, y + 0.011, 0.0),
                },
                Placed {
                    kind: Kind::SoftBall,
                    pos: Vec3::new(0.0, y + 0.09, 0.0),
                },
                Placed {
                    kind: Kind::Bunny,
                    pos: Vec3::new(-0.32, y + 0.09, 0.05),
                },
                Placed {
                    kind: Kind::SoftBox,
                    pos: Vec3::new(0.32, y + 0.07, 0.05),
                },
                Placed {
                    kind: Kind::Block,
                    pos: Vec3::new(0.3, y + 0.031, -0.22),
                },
                Placed {
                    kind: Kind::Can,
                    pos: Vec3::new(-0.3, y + 0.051, -0.22),
                },
                Placed {
                    kind: Kind::Ball,
                    pos: Vec3::new(0.0, y + 0.036, -0.25),
                },
            ],
            "bench-ball" => vec![Placed {
                kind: Kind::SoftBall,
                pos: Vec3::new(0.0, y + 0.08, 0.0),
            }],
            other => {
                return Err(format!(
                    "unknown scene {other:?}: the scenes are thesis-room and bench-ball"
                ))
            }
        };
        let scene = Scene {
            name: name.to_owned(),
            objects,
            assets: assets.to_owned(),
        };
        // Fail now, not when the first peer spawns the bunny.
        if scene.objects.iter().any(|o| o.kind == Kind::Bunny) {
            scene.soft_mesh(Kind::Bunny)?;
        }
        Ok(scene)
    }

    /// The floor and the table (fixed bodies on every peer).
    pub fn build_static(&self, world: &mut PhysicsWorld) {
        let floor =
            world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, -0.5, 0.0)));
        world.insert_collider(
            ColliderBuilder::cuboid(10.0, 0.5, 10.0).friction(0.8),
            Some(floor),
        );
        let table = world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(
            0.0,
            TABLE_TOP_Y - 0.02,
            0.0,
        )));
        world.insert_collider(
            ColliderBuilder::cuboid(0.6, 0.02, 0.4).friction(0.8),
            Some(table),
        );
        for (x, z) in [(-0.55, -0.35), (0.55, -0.35), (-0.55, 0.35), (0.55, 0.35)] {
            let leg = world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(
                x,
                (TABLE_TOP_Y - 0.04) / 2.0,
                z,
            )));
            world.insert_collider(
                ColliderBuilder::cuboid(0.03, (TABLE_TOP_Y - 0.04) / 2.0, 0.03),
                Some(leg),
            );
        }
    }

    /// A rigid prop's body and collider at `pos`, `rot`.
    pub fn build_rigid(
        kind: Kind,
        world: &mut PhysicsWorld,
        pos: Vec3,
        rot: Quat,
    ) -> RigidBodyHandle {
        let body = world.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(Pose::from_parts(pos, rot))
                .linear_damping(0.05)
                .angular_damping(0.2)
                .ccd_enabled(true),
        );
        let collider = match kind {
            Kind::Plate => ColliderBuilder::cylinder(0.01, 0.12).density(800.0),
            Kind::Block => ColliderBuilder::cuboid(0.03, 0.03, 0.03).density(600.0),
            Kind::Can => ColliderBuilder::cylinder(0.05, 0.033).density(400.0),
            _ => ColliderBuilder::ball(0.035).density(300.0),
        };
        world.insert_collider(collider.friction(0.7), Some(body));
        body
    }

    /// A soft body's mesh, centred on the origin, at its size in the room.
    pub fn soft_mesh(&self, kind: Kind) -> Result<Mesh, String> {
        match kind {
            Kind::Bunny => {
                let path = self.assets.join("bunny.obj");
                let mesh = Mesh::load(&path)
                    .map_err(|e| format!("cannot load the bunny for scene {}: {e}", self.name))?;
                let mut mesh = mesh.fit_size(0.16);
                mesh.recenter();
                Ok(mesh)
            }
            Kind::SoftBall => Ok(Mesh::icosphere(0.06, 3)),
            Kind::SoftBox => Ok(Mesh::cuboid(Vec3::splat(0.045), 2)),
            other => Err(format!("{} is not a soft body", other.name())),
        }
    }

    /// A soft body's configuration (the thesis's defaults, particles 2-3 cm apart).
    pub fn soft_config(kind: Kind) -> SoftBodyConfig {
        let cluster = match kind {
            Kind::Bunny => ClusterMethod::Distance { radius_m: 0.03 },
            Kind::SoftBox => ClusterMethod::Distance { radius_m: 0.025 },
            // The thesis's 60-particle ball (Tables 9-11): Poisson-disk clusters, 60 exactly.
            _ => ClusterMethod::PoissonDisk {
                radius_m: 0.0215,
                seed: 1,
            },
        };
        SoftBodyConfig {
            cluster,
            // A dynamic center with its own collider: the body falls, rests and is thrown.
            space: SimulationSpace::World,
            ..SoftBodyConfig::default()
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_soft_ball_is_the_thesis_60_particle_body_and_every_kind_builds() {
        let scene = Scene::by_name(
            "thesis-room",
            Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets")),
        )
        .unwrap();
        let mut world = PhysicsWorld::new();
        let mut set = softsync_softbody::SoftBodySet::new();
        for k in [Kind::SoftBall, Kind::Bunny, Kind::SoftBox] {
            let h = set
                .insert(
                    &scene.soft_mesh(k).unwrap(),
                    Scene::soft_config(k),
                    &mut world,
                )
                .unwrap();
            let n = set.get(h).unwrap().num_particles();
            if k == Kind::SoftBall {
                assert_eq!(n, 60);
            }
            assert!((20..=80).contains(&n), "{} has {n} particles", k.name());
        }
        for k in Kind::ALL {
            assert_eq!(Kind::of_class(k.class()), Some(k));
            assert_eq!(Kind::from_name(k.name()), Some(k));
        }
        assert!(Scene::by_name("moon", Path::new(".")).is_err());
        assert!(Scene::by_name("thesis-room", Path::new("/nonexistent"))
            .unwrap_err()
            .contains("bunny"));
    }
}
