//! Static problems whose answer is unique, solved with our accuracy reference's material —
//! stable Neo-Hookean XPBD tets ([`NeoHookeanGroup`], the energy of
//! [`MethodKind::NeoHookean`](super::MethodKind::NeoHookean)) — and brought to static
//! equilibrium by damped steps. An independent finite-element code solves the same problems
//! (`scripts/fem-reference`, scikit-fem; its answers are committed in
//! `docs/results/methods/fem/answers.json`), so our reference is checked by code nobody here
//! wrote, where the answer does not depend on chaos (a bounce, a slip) as whole scenarios do.
//!
//! The problems (SI units; ν = [`NU`] everywhere, density 1000 kg/m³):
//! - **cantilever**: a 0.16 × 0.04 × 0.04 m box clamped at x = 0, sagging under gravity; the
//!   answer is the tip's sag (the mean y-displacement of the nodes of the face x = 0.16).
//! - **compress**: a cube of side [`CUBE_M`] (E = [`CUBE_YOUNG_PA`], no gravity) between
//!   frictionless plates, compressed by a strain s (the top plate moved down by s × the side),
//!   a quarter of a larger block (symmetry planes x = 0 and z = 0). The answers: the plates'
//!   reaction force and the bulge (the mean x-displacement of the face x = side). The
//!   deformation is homogeneous, so every mesh has the exact answer: this checks the material
//!   and the solver, not the discretization.
//! - **indent**: a slab [`SLAB_M`] thick (E = [`SLAB_YOUNG_PA`], no gravity), a quarter of a
//!   wider one (symmetry planes x = 0 and z = 0, its base y = 0 clamped), indented by a rigid
//!   frictionless sphere of radius [`INDENTER_R_M`] centred above the origin, by a depth d.
//!   Contact is nodal (no node inside the sphere). The answer: the sphere's reaction, N (× 4:
//!   the whole sphere), against d; at small depth Hertz's `F = 4/3 · E/(1 − ν²) · √R · d^{3/2}`
//!   holds for a half-space, which the slab (contact radius up to a fifth of its thickness,
//!   clamped base) only approaches.
//! - **bunny**: the Stanford bunny ([`BUNNY_SIZE_M`]) as our reference meshes it — a Kuhn
//!   lattice of cells `cell_frac` × its size, each tet weighted by the fraction of it inside
//!   the surface (stiffness and mass alike) — its base (the nodes within [`BUNNY_BASE_FRAC`]
//!   of its height from the bottom) fixed, sagging under gravity. The answer is the
//!   displacement of every node. The FEM solves the same weighted tets (`bunny_mesh` writes
//!   them), so the comparison is of solvers on one discretization; the FEM's refinement
//!   (quadratic elements, split tets) says how far that discretization is from its continuum.

use glam::Vec3;
use rapier3d::prelude::PhysicsWorld;

use crate::methods::pbd::{
    tet_volume, NeoHookeanGroup, PbdBody, PbdParams, Slide, SolverKind, SphereObstacle, SurfaceMap,
};

/// Poisson's ratio of every static problem (the FEM script's too).
pub const NU: f32 = 0.4;
/// Density, kg/m³.
pub const DENSITY_KG_M3: f32 = 1000.0;
/// The cantilever's size, metres (x along the beam, y up).
pub const BEAM_M: Vec3 = Vec3::new(0.16, 0.04, 0.04);

/// The compression's cube side, metres.
pub const CUBE_M: f32 = 0.04;
/// The compression's Young's modulus, Pa.
pub const CUBE_YOUNG_PA: f32 = 2e5;

/// The indented slab's side (a quarter block: x, y, z in [0, side]), metres.
pub const SLAB_M: f32 = 0.03;
/// The indented slab's Young's modulus, Pa.
pub const SLAB_YOUNG_PA: f32 = 1e5;
/// The indenter's radius, metres.
pub const INDENTER_R_M: f32 = 0.01;

/// Hertz's force, N, of a rigid sphere of radius `r_m` pressed `depth_m` into an elastic
/// half-space of Young's modulus `young_pa` and Poisson's ratio `nu`.
pub fn hertz_force_n(young_pa: f32, nu: f32, r_m: f32, depth_m: f32) -> f32 {
    4.0 / 3.0 * young_pa / (1.0 - nu * nu) * r_m.sqrt() * depth_m.max(0.0).powf(1.5)
}

/// The bunny's size (largest extent), metres.
pub const BUNNY_SIZE_M: f32 = 0.2;
/// The bunny's fixed base: nodes within this fraction of its height from its lowest node.
pub const BUNNY_BASE_FRAC: f32 = 0.08;

/// Bulk modulus for Young's modulus `young_pa` and Poisson's ratio `nu`.
pub fn bulk_pa(young_pa: f32, nu: f32) -> f32 {
    young_pa / (3.0 * (1.0 - 2.0 * nu))
}

/// A box of `size` from the origin split into `cells` cells, six tets each (around each
/// cell's main diagonal, positively oriented): nodes and tets.
pub fn box_tets(size: Vec3, cells: [usize; 3]) -> (Vec<Vec3>, Vec<[u32; 4]>) {
    let [nx, ny, nz] = cells.map(|c| c.max(1));
    let step = size / Vec3::new(nx as f32, ny as f32, nz as f32);
    let id = |i: usize, j: usize, k: usize| (i * (ny + 1) * (nz + 1) + j * (nz + 1) + k) as u32;
    let mut x = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for i in 0..=nx {
        for j in 0..=ny {
            for k in 0..=nz {
                x.push(Vec3::new(i as f32, j as f32, k as f32) * step);
            }
        }
    }
    let mut tets = Vec::with_capacity(nx * ny * nz * 6);
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let c = [
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i, j + 1, k),
                    id(i + 1, j + 1, k),
                    id(i, j, k + 1),
                    id(i + 1, j, k + 1),
                    id(i, j + 1, k + 1),
                    id(i + 1, j + 1, k + 1),
                ];
                for t in [
                    [0, 1, 3, 7],
                    [0, 1, 7, 5],
                    [0, 5, 7, 4],
                    [0, 3, 2, 7],
                    [0, 2, 6, 7],
                    [0, 6, 4, 7],
                ] {
                    let mut tet = t.map(|q| c[q]);
                    if tet_volume(tet.map(|q| x[q as usize])) < 0.0 {
                        tet.swap(2, 3);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    (x, tets)
}

/// Lumped masses: each tet's mass (times its material fraction) shared by its four nodes.
fn lumped_masses(x: &[Vec3], tets: &[[u32; 4]], weight: &[f32], density: f32) -> Vec<f32> {
    let mut m = vec![0.0f32; x.len()];
    for (t, w) in tets.iter().zip(weight) {
        let v = tet_volume(t.map(|q| x[q as usize])).abs();
        for q in t {
            m[*q as usize] += density * v * w / 4.0;
        }
    }
    m
}

/// The body every static problem solves: stable Neo-Hookean XPBD tets (each tet's stiffness
/// and mass scaled by its `weight`), lumped masses of [`DENSITY_KG_M3`], no contacts, no
/// sleep, `solve`'s budget and damping.
fn static_body(
    name: &str,
    x: &[Vec3],
    tets: Vec<[u32; 4]>,
    weight: &[f32],
    young_pa: f32,
    solve: StaticSolve,
) -> PbdBody {
    let mass = lumped_masses(x, &tets, weight, DENSITY_KG_M3);
    let params = PbdParams {
        solver: SolverKind::Xpbd,
        substeps: solve.substeps,
        iterations: solve.iterations,
        damping_per_s: solve.damping_per_s,
        contact_radius_m: 0.0,
        sleep_after_s: 0.0,
        two_way: false,
        ..Default::default()
    };
    let mut b = PbdBody::new(
        name,
        params,
        x.to_vec(),
        &mass,
        SurfaceMap::Direct,
        Vec::new(),
    );
    b.neo_hookean = Some(NeoHookeanGroup::new(
        tets,
        x,
        weight,
        young_pa,
        bulk_pa(young_pa, NU),
    ));
    b
}

/// How a static solve by damped steps went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StaticAnswer {
    /// The answer (its unit is the problem's).
    pub value: f32,
    /// Steps of 1/60 s taken.
    pub steps: usize,
    /// Fastest particle speed at the end, m/s (the equilibrium's residual).
    pub max_speed_mps: f32,
    /// Nodes and tets.
    pub nodes: usize,
    /// Tets.
    pub tets: usize,
}

/// Settings of a static solve by damped steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StaticSolve {
    /// Substeps per 1/60 s step.
    pub substeps: u32,
    /// Gauss–Seidel iterations per substep.
    pub iterations: u32,
    /// Velocity damping, 1/s.
    pub damping_per_s: f32,
    /// Stop once the answer changes by less than this (relative) over half a second, twice.
    pub rest_rel: f32,
    /// Most steps.
    pub max_steps: usize,
}

impl Default for StaticSolve {
    fn default() -> Self {
        Self {
            substeps: 80,
            iterations: 2,
            damping_per_s: 30.0,
            rest_rel: 1e-4,
            max_steps: 1800,
        }
    }
}

/// The cantilever ([`BEAM_M`], clamped at x = 0) of Young's modulus `young_pa` at `k` cells
/// across its 0.04 m section (4k along it), sagging under gravity: the tip's sag, mm.
pub fn cantilever_tip_mm(young_pa: f32, k: usize, solve: StaticSolve) -> StaticAnswer {
    let (x, tets) = box_tets(BEAM_M, [4 * k, k, k]);
    let n_tets = tets.len();
    let mut b = static_body("cantilever", &x, tets, &vec![1.0; n_tets], young_pa, solve);
    b.pin_box(Vec3::splat(-1.0), Vec3::new(1e-6, 1.0, 1.0));
    let tip: Vec<usize> = (0..x.len())
        .filter(|i| (x[*i].x - BEAM_M.x).abs() < 1e-6)
        .collect();
    let world = PhysicsWorld::new();
    let sag_mm = |b: &PbdBody| {
        1000.0
            * tip
                .iter()
                .map(|i| x[*i].y - b.positions()[*i].y)
                .sum::<f32>()
            / tip.len().max(1) as f32
    };
    let (steps, max_speed) = settle(&mut b, &world, solve, sag_mm);
    StaticAnswer {
        value: sag_mm(&b),
        steps,
        max_speed_mps: max_speed,
        nodes: x.len(),
        tets: n_tets,
    }
}

/// The compression's answer at one strain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compression {
    /// The strain s: the top plate moved down by s × [`CUBE_M`].
    pub strain: f32,
    /// The plates' reaction, N (positive in compression).
    pub force_n: f32,
    /// The mean x-displacement of the face x = [`CUBE_M`], mm.
    pub bulge_mm: f32,
    /// Tets turned inside out at the end (the exact answer has none).
    pub inverted: usize,
    /// The solve at this strain (its `value` is the force).
    pub solve: StaticAnswer,
}

/// The compression ([`CUBE_M`], E = [`CUBE_YOUNG_PA`], `k`³ cells) at each of `strains`, in
/// order: the top plate moves to the next strain over a quarter second, then the body settles
/// (on the force). Frictionless plates and symmetry planes are [`Slide`]s; the force is the
/// sum of the elastic forces on the top face's particles ([`NeoHookeanGroup::elastic_forces`]).
pub fn compress_cube(k: usize, strains: &[f32], solve: StaticSolve) -> Vec<Compression> {
    let (x, tets) = box_tets(Vec3::splat(CUBE_M), [k, k, k]);
    let n_tets = tets.len();
    let mut b = static_body("cube", &x, tets, &vec![1.0; n_tets], CUBE_YOUNG_PA, solve);
    let on = |i: usize, axis: usize, at: f32| (x[i][axis] - at).abs() < 1e-7;
    let top: Vec<usize> = (0..x.len()).filter(|&i| on(i, 1, CUBE_M)).collect();
    let side: Vec<usize> = (0..x.len()).filter(|&i| on(i, 0, CUBE_M)).collect();
    for i in 0..x.len() {
        for (axis, at) in [(1u8, 0.0), (1, CUBE_M), (0, 0.0), (2, 0.0)] {
            if on(i, usize::from(axis), at) {
                b.slides.push(Slide {
                    node: i as u32,
                    axis,
                    at_m: at,
                });
            }
        }
    }
    let mut world = PhysicsWorld::new();
    world.gravity = Vec3::ZERO;
    let mut forces = Vec::new();
    let mut force_n = move |b: &PbdBody| {
        let Some(g) = &b.neo_hookean else {
            return f32::NAN;
        };
        g.elastic_forces(b.positions(), &mut forces);
        top.iter().map(|&i| forces[i].y).sum::<f32>()
    };
    let bulge_mm = |b: &PbdBody| {
        1000.0
            * side
                .iter()
                .map(|&i| b.positions()[i].x - CUBE_M)
                .sum::<f32>()
            / side.len().max(1) as f32
    };
    let mut out = Vec::with_capacity(strains.len());
    let mut at = CUBE_M;
    for &s in strains {
        let goal = CUBE_M * (1.0 - s);
        let (steps, max_speed) = ramp_then_settle(
            &mut b,
            &world,
            solve,
            |b, f| move_top(b, at + (goal - at) * f),
            &mut force_n,
        );
        at = goal;
        let force = force_n(&b);
        out.push(Compression {
            strain: s,
            force_n: force,
            bulge_mm: bulge_mm(&b),
            inverted: b.count_inverted(),
            solve: StaticAnswer {
                value: force,
                steps,
                max_speed_mps: max_speed,
                nodes: x.len(),
                tets: n_tets,
            },
        });
    }
    out
}

/// The indentation's answer at one depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Indentation {
    /// The depth d, mm.
    pub depth_mm: f32,
    /// The sphere's reaction, N, for the whole sphere (4 × the quarter model's).
    pub force_n: f32,
    /// Hertz's force at this depth, N.
    pub hertz_n: f32,
    /// The largest distance from the axis of a node touching the sphere, mm.
    pub contact_radius_mm: f32,
    /// Tets turned inside out at the end.
    pub inverted: usize,
    /// The solve at this depth (its `value` is the force).
    pub solve: StaticAnswer,
}

/// The indentation ([`SLAB_M`], E = [`SLAB_YOUNG_PA`], `k`³ cells) at each of `depths_mm`,
/// in order: the sphere moves to the next depth over a quarter second, then the body settles
/// (on the force). The base is pinned, the symmetry planes are [`Slide`]s, the sphere a
/// [`SphereObstacle`]; the force is the sum of the elastic forces' y over the nodes touching
/// it ([`NeoHookeanGroup::elastic_forces`]: at rest each is what the sphere holds back).
pub fn indent_slab(k: usize, depths_mm: &[f32], solve: StaticSolve) -> Vec<Indentation> {
    let (x, tets) = box_tets(Vec3::splat(SLAB_M), [k, k, k]);
    let n_tets = tets.len();
    let mut b = static_body("slab", &x, tets, &vec![1.0; n_tets], SLAB_YOUNG_PA, solve);
    let on = |i: usize, axis: usize, at: f32| (x[i][axis] - at).abs() < 1e-7;
    let base: Vec<u32> = (0..x.len() as u32)
        .filter(|&i| on(i as usize, 1, 0.0))
        .collect();
    b.pin_nodes(&base);
    for i in 0..x.len() {
        for axis in [0u8, 2] {
            if on(i, usize::from(axis), 0.0) {
                b.slides.push(Slide {
                    node: i as u32,
                    axis,
                    at_m: 0.0,
                });
            }
        }
    }
    let centre = |depth_m: f32| Vec3::new(0.0, SLAB_M + INDENTER_R_M - depth_m, 0.0);
    b.spheres.push(SphereObstacle {
        center_m: centre(0.0),
        radius_m: INDENTER_R_M,
    });
    let touching = |b: &PbdBody| -> Vec<usize> {
        let c = b.spheres[0].center_m;
        (0..x.len())
            .filter(|&i| b.positions()[i].distance(c) < INDENTER_R_M * (1.0 + 1e-4))
            .collect()
    };
    let mut forces = Vec::new();
    let mut force_n = move |b: &PbdBody| {
        let Some(g) = &b.neo_hookean else {
            return f32::NAN;
        };
        g.elastic_forces(b.positions(), &mut forces);
        4.0 * touching(b).iter().map(|&i| forces[i].y).sum::<f32>()
    };
    let world = PhysicsWorld::new();
    let mut out = Vec::with_capacity(depths_mm.len());
    let mut at = 0.0f32;
    for &d in depths_mm {
        let goal = d * 1e-3;
        let (steps, max_speed) = ramp_then_settle(
            &mut b,
            &world,
            solve,
            |b, f| b.spheres[0].center_m = centre(at + (goal - at) * f),
            &mut force_n,
        );
        at = goal;
        let force = force_n(&b);
        let contact_radius_mm = 1000.0
            * touching(&b)
                .iter()
                .map(|&i| {
                    let p = b.positions()[i];
                    (p.x * p.x + p.z * p.z).sqrt()
                })
                .fold(0.0f32, f32::max);
        out.push(Indentation {
            depth_mm: d,
            force_n: force,
            hertz_n: hertz_force_n(SLAB_YOUNG_PA, NU, INDENTER_R_M, goal),
            contact_radius_mm,
            inverted: b.count_inverted(),
            solve: StaticAnswer {
                value: force,
                steps,
                max_speed_mps: max_speed,
                nodes: x.len(),
                tets: n_tets,
            },
        });
    }
    out
}

/// The bunny problem's mesh: nodes (m), tets, each tet's material fraction, and which nodes
/// are fixed (the base), for `mesh` (the bunny, any size: it is fitted to [`BUNNY_SIZE_M`]
/// here) at cells of `cell_frac` × that size.
pub struct BunnyMesh {
    /// Nodes, metres.
    pub nodes: Vec<Vec3>,
    /// Positively oriented tets.
    pub tets: Vec<[u32; 4]>,
    /// Fraction of each tet inside the surface (its stiffness and mass are scaled by it).
    pub weight: Vec<f32>,
    /// The fixed nodes.
    pub fixed: Vec<u32>,
}

/// Meshes `mesh` for the bunny problem (see [`BunnyMesh`]).
pub fn bunny_mesh(mesh: &crate::Mesh, cell_frac: f32) -> Result<BunnyMesh, crate::SoftBodyError> {
    let m = mesh.clone().fit_size(BUNNY_SIZE_M);
    let w = m.weld(1e-6);
    let lt = crate::methods::lattice::lattice_tets(
        &w.positions,
        &w.triangles,
        cell_frac * BUNNY_SIZE_M,
    )?;
    let nodes = lt.mesh.nodes;
    let (lo, hi) = crate::mesh::bounds(&nodes);
    let cut = lo.y + BUNNY_BASE_FRAC * (hi.y - lo.y);
    let fixed = (0..nodes.len() as u32)
        .filter(|&i| nodes[i as usize].y <= cut)
        .collect();
    Ok(BunnyMesh {
        nodes,
        tets: lt.mesh.tets,
        weight: lt.inside_fraction,
        fixed,
    })
}

/// The bunny problem of Young's modulus `young_pa` on `mesh` (from [`bunny_mesh`]), brought
/// to rest under gravity: every node's displacement, metres, and the solve (its `value` is
/// the largest displacement, mm).
pub fn bunny_sag(mesh: &BunnyMesh, young_pa: f32, solve: StaticSolve) -> (Vec<Vec3>, StaticAnswer) {
    let mut b = static_body(
        "bunny",
        &mesh.nodes,
        mesh.tets.clone(),
        &mesh.weight,
        young_pa,
        solve,
    );
    b.pin_nodes(&mesh.fixed);
    let world = PhysicsWorld::new();
    let rest = mesh.nodes.clone();
    let largest_mm = |b: &PbdBody| {
        1000.0
            * b.positions()
                .iter()
                .zip(&rest)
                .map(|(p, q)| p.distance(*q))
                .fold(0.0f32, f32::max)
    };
    // Settled on the mean displacement: the largest is a fringe node's (tets almost all
    // outside the surface, light and soft alike), whose residual jitter would hold it back.
    let mean_mm = |b: &PbdBody| {
        1000.0
            * b.positions()
                .iter()
                .zip(&rest)
                .map(|(p, q)| p.distance(*q))
                .sum::<f32>()
            / rest.len().max(1) as f32
    };
    let (steps, max_speed) = settle(&mut b, &world, solve, mean_mm);
    let u: Vec<Vec3> = b
        .positions()
        .iter()
        .zip(&rest)
        .map(|(p, q)| *p - *q)
        .collect();
    let answer = StaticAnswer {
        value: largest_mm(&b),
        steps,
        max_speed_mps: max_speed,
        nodes: mesh.nodes.len(),
        tets: mesh.tets.len(),
    };
    (u, answer)
}

/// Moves the compression's top plate (the slides on y that are not at 0) to `y`.
fn move_top(b: &mut PbdBody, y: f32) {
    for s in &mut b.slides {
        if s.axis == 1 && s.at_m != 0.0 {
            s.at_m = y;
        }
    }
}

/// A load step of a static problem: `set(b, f)` moves the load a fraction `f` of the way to
/// its next value, over a quarter second (15 steps at 60 Hz, `f` = 1/15 … 1), then the body
/// settles on `answer` ([`settle`]): the steps taken in all and the fastest particle speed.
fn ramp_then_settle(
    b: &mut PbdBody,
    world: &PhysicsWorld,
    solve: StaticSolve,
    mut set: impl FnMut(&mut PbdBody, f32),
    answer: impl FnMut(&PbdBody) -> f32,
) -> (usize, f32) {
    const RAMP_STEPS: usize = 15;
    for r in 1..=RAMP_STEPS {
        set(b, r as f32 / RAMP_STEPS as f32);
        b.step(world, 1.0 / 60.0);
    }
    let (steps, speed) = settle(b, world, solve, answer);
    (steps + RAMP_STEPS, speed)
}

/// Steps `b` at 60 Hz until `answer` changes by less than `solve.rest_rel` (relative) over
/// half a second, twice in a row (or `max_steps`); the steps taken and the fastest particle
/// speed at the end (the equilibrium's residual motion).
fn settle(
    b: &mut PbdBody,
    world: &PhysicsWorld,
    solve: StaticSolve,
    mut answer: impl FnMut(&PbdBody) -> f32,
) -> (usize, f32) {
    let dt = 1.0 / 60.0;
    let mut calm = 0;
    let mut last = answer(b);
    let mut speed = f32::INFINITY;
    for step in 1..=solve.max_steps {
        let before = b.positions().to_vec();
        b.step(world, dt);
        if step % 30 != 0 {
            continue;
        }
        speed = b
            .positions()
            .iter()
            .zip(&before)
            .map(|(p, q)| p.distance(*q) / dt)
            .fold(0.0, f32::max);
        let now = answer(b);
        if !now.is_finite() {
            return (step, f32::INFINITY);
        }
        let change = (now - last).abs() / now.abs().max(1e-9);
        last = now;
        calm = if change < solve.rest_rel { calm + 1 } else { 0 };
        if calm >= 2 {
            return (step, speed);
        }
    }
    (solve.max_steps, speed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The compression is homogeneous: at a small strain, on the coarsest mesh, the force
    /// and bulge are the closed form's (`scripts/fem/reference.py`'s `uniaxial_analytic`,
    /// whose answers the FEM reproduces to 1e-11).
    #[test]
    fn a_cube_compressed_ten_percent_gives_the_closed_form_answer() {
        let c = compress_cube(1, &[0.1], StaticSolve::default());
        let (force, bulge) = (c[0].force_n, c[0].bulge_mm);
        assert!(
            (force - 35.10).abs() < 0.02 * 35.10,
            "force {force} N, {:?}",
            c[0]
        );
        assert!((bulge - 1.6926).abs() < 0.02 * 1.6926, "bulge {bulge} mm");
    }

    #[test]
    fn the_box_lattice_fills_the_box_with_positive_tets() {
        let size = Vec3::new(0.16, 0.04, 0.04);
        let (x, tets) = box_tets(size, [8, 2, 2]);
        assert_eq!(x.len(), 9 * 3 * 3);
        assert_eq!(tets.len(), 8 * 2 * 2 * 6);
        let vol: f32 = tets
            .iter()
            .map(|t| tet_volume(t.map(|q| x[q as usize])))
            .inspect(|v| assert!(*v > 0.0))
            .sum();
        assert!((vol - size.x * size.y * size.z).abs() < 1e-9);
        let m: f32 = lumped_masses(&x, &tets, &vec![1.0; tets.len()], DENSITY_KG_M3)
            .iter()
            .sum();
        assert!((m - 1000.0 * size.x * size.y * size.z).abs() < 1e-5);
    }
}
