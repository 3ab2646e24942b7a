//! Particle soft bodies on rapier3d: the method of the thesis (chapter 3), made sound, with
//! mesh loading, clustering, the particle map, deformation, metrics and test scenarios.
//!
//! The crate knows nothing of networking, rendering or clocks: `dt` is a parameter and every
//! random choice takes a seed.

mod body;
pub mod cluster;
mod config;
pub mod cut;
mod error;
pub mod mesh;
pub mod methods;
pub mod metrics;
pub mod scenario;

pub use body::build::{BodyBuild, BuildStep};
pub use body::handle::SoftBodyHandle;
pub use body::set::{SoftBodySet, SoftPart};
pub use body::{Activity, BodyWork, SoftBody, SoftBodyPlan, StageClock, TearTimings};
pub use cluster::{build_particle_map, ClusterMethod, ParticleMap, WeightedRows};
pub use config::{
    CenterCollider, ContinuousCollision, ParticleCollider, RestoringScheme, SimulationSpace,
    SoftBodyConfig, SoftRegion, INCISION_WIDTH_M,
};
pub use error::SoftBodyError;
pub use mesh::{Mesh, MeshSource, Placement, WeldedMesh};
pub use rapier3d;
