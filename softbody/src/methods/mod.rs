//! Speed against accuracy: every soft-body method behind one small trait
//! ([`DeformableModel`]), so scenarios, metrics, stability sweeps and the automatic choice
//! treat them alike.
//!
//! | module | method |
//! |---|---|
//! | [`pbd`] | the XPBD / PBD solver core (ISPC paper Algorithm 1): distance (eq. 1–3), dihedral bending (eq. 4), tet volume, shape-matching clusters, contacts against the rapier world |
//! | [`ispc`] | internal shape-preserving links (ISPC paper Algorithm 2) |
//! | [`tets`] | XPBD tets on parry's `volume_mesh` cover (Apache-2.0), surface embedded |
//! | [`lattice`] | a well-shaped Kuhn lattice of tets weighted by inside fraction (the reference's mesh) |
//! | [`reference`](mod@reference) | the verified accuracy reference: stable Neo-Hookean tets, its spec and convergence |
//! | [`spec`] | what a method is: [`MethodKind`], [`MethodSpec`] (resolution, budget), [`spec::Material`] |
//! | [`builders`] | one constructor per method and resolution ([`build_model`]) |
//! | [`particle`] | the thesis's particle method ([`crate::SoftBodySet`]) as a model |
//! | [`native`] | rapier 0.36's own soft bodies as a model |
//! | [`scene`] | rest / drop / squeeze / poke / impact scenarios for any model |
//! | [`choice`] | cheapest method meeting an error and frame budget, from measured curves |
//! | [`material`] | a named material (Young's modulus, Poisson's ratio) as the particle method's knobs, fitted on the static compression |
//! | [`statics`] | static problems with unique answers (cantilever, compression) for the independent FEM check |
//! | [`auto`] | `method: auto` at run time: a resolution ladder probed at load, a per-body controller |

pub mod auto;
pub mod builders;
pub mod choice;
pub mod ispc;
pub mod lattice;
pub mod material;
pub mod model;
pub mod native;
pub mod particle;
pub mod pbd;
pub mod reference;
pub mod scene;
pub mod spec;
pub mod statics;
pub mod tets;

pub use builders::build_model;
pub use model::{step_models, DeformableModel};
pub use spec::{MethodKind, MethodSpec};
