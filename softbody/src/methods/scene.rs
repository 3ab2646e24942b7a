//! The scenarios of [`crate::scenario`] for any [`DeformableModel`]: drop on a floor, squeeze
//! between two plates, poke with a ball, rest; and a throw against a thin wall for the
//! stability maps. Props move the same way as in [`crate::scenario::Scenario`]; plates and
//! ball keep the model's contact thickness so every method's *surface* reaches the same depth.
//!
//! Holding the body: the particle method runs in local mode (fixed center), the others are
//! weightless in squeeze and poke, and in poke the far (−x) tenth of the body is pinned.

use glam::{Quat, Vec3};
use rapier3d::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle};

use crate::methods::builders::build_model;
use crate::methods::model::DeformableModel;
use crate::methods::pbd::{DistanceGroup, PbdBody, PbdParams, SolverKind, SurfaceMap, VolumeGroup};
use crate::methods::spec::MethodSpec;
use crate::metrics::rigid_fit_error;
use crate::scenario::{ramp, ScenarioKind, SceneFrame};
use crate::{Mesh, SoftBodyError};

/// Whether a run stayed sane (the stability maps' criteria).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sanity {
    /// A surface vertex became NaN or infinite.
    pub non_finite: bool,
    /// A vertex went further than twice the body's size from the centroid, or a particle
    /// faster than 100 m/s.
    pub exploded: bool,
    /// Some tets were inside out at the end.
    pub inverted: bool,
    /// Part of the surface ended on the far side of the thin wall.
    pub tunnelled: bool,
}

impl Sanity {
    /// True if nothing failed.
    pub fn ok(&self) -> bool {
        !(self.non_finite || self.exploded || self.inverted || self.tunnelled)
    }

    /// The first failure's name, or "ok".
    pub fn verdict(&self) -> &'static str {
        if self.non_finite {
            "nan"
        } else if self.exploded {
            "exploded"
        } else if self.inverted {
            "inverted"
        } else if self.tunnelled {
            "tunnelled"
        } else {
            "ok"
        }
    }
}

/// A world with one model and the props acting on it.
pub struct ModelScene {
    /// The rapier world (props; rapier-based models' bodies).
    pub world: PhysicsWorld,
    /// The model.
    pub model: Box<dyn DeformableModel>,
    frame: SceneFrame,
    thickness_m: f32,
    top_plate: Option<RigidBodyHandle>,
    bottom_plate: Option<RigidBodyHandle>,
    poker: Option<RigidBodyHandle>,
    /// Half-spaces `p · n > d` a vertex must never reach (the far side of a thin wall).
    beyond: Vec<(Vec3, f32)>,
    /// Seconds the squeeze's plates take to close.
    close_s: f32,
    /// How many times slower than the scenario's own timing the props move (1: as defined;
    /// [`paced`](Self::paced)).
    pace: f32,
    /// The fraction of the scenario's own action the props do (1: the plates close 70 % of
    /// the height, the poker goes 0.3 × the size deep; [`paced`](Self::paced)).
    amount: f32,
    rest_surface: Vec<Vec3>,
    rest_volume_m3: f32,
}

impl ModelScene {
    /// Sets up `kind` (rest, drop, squeeze or poke; pull is not supported) for `mesh`
    /// (re-centred at the origin) with the method `spec`, stepping at `dt_s`.
    pub fn new(
        kind: ScenarioKind,
        mesh: &Mesh,
        spec: &MethodSpec,
        dt_s: f32,
    ) -> Result<Self, SoftBodyError> {
        Self::setup(kind, mesh, spec, dt_s, kind != ScenarioKind::Drop)
    }

    fn setup(
        kind: ScenarioKind,
        mesh: &Mesh,
        spec: &MethodSpec,
        dt_s: f32,
        anchored: bool,
    ) -> Result<Self, SoftBodyError> {
        let (frame, mut mesh, mut world) = SceneFrame::new(kind, mesh, dt_s)?;
        if kind == ScenarioKind::Pull {
            return Err(SoftBodyError::Config(
                "pull is a particle-method scenario".into(),
            ));
        }
        let SceneFrame { lo, size_m, .. } = frame;
        if kind != ScenarioKind::Drop {
            world.gravity = Vec3::ZERO;
        }
        let plate_half = Vec3::new(size_m * 2.0, 0.05f32.max(0.5 * size_m), size_m * 2.0);
        let (mut top_plate, mut bottom_plate, mut poker) = (None, None, None);
        match kind {
            ScenarioKind::Drop => crate::scenario::drop_floor(&mut world, &mut mesh, lo.y),
            ScenarioKind::Squeeze => {
                for slot in [&mut top_plate, &mut bottom_plate] {
                    // Placed clear of everything; moved to their start in the first step.
                    let b = world.insert_body(
                        RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(
                            0.0,
                            10.0 * size_m,
                            0.0,
                        )),
                    );
                    world.insert_collider(
                        ColliderBuilder::cuboid(plate_half.x, plate_half.y, plate_half.z),
                        Some(b),
                    );
                    *slot = Some(b);
                }
            }
            ScenarioKind::Poke => {
                let b = world.insert_body(
                    RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(
                        10.0 * size_m,
                        0.0,
                        0.0,
                    )),
                );
                world.insert_collider(ColliderBuilder::ball(0.1 * size_m), Some(b));
                poker = Some(b);
            }
            ScenarioKind::Rest | ScenarioKind::Pull => {}
        }
        let mut model = build_model(spec, &mesh, &mut world, anchored)?;
        if kind == ScenarioKind::Poke {
            model.pin_region(
                &mut world,
                Vec3::splat(-1e3),
                Vec3::new(lo.x + 0.1 * size_m, 1e3, 1e3),
            );
        }
        let thickness_m = model.contact_thickness_m();
        let rest_surface = model.surface().to_vec();
        let rest_volume_m3 = crate::mesh::enclosed_volume(&rest_surface, model.triangles());
        let mut s = ModelScene {
            world,
            model,
            frame,
            thickness_m,
            top_plate,
            bottom_plate,
            poker,
            beyond: Vec::new(),
            close_s: 0.8,
            pace: 1.0,
            amount: 1.0,
            rest_surface,
            rest_volume_m3,
        };
        s.place_props(true);
        Ok(s)
    }

    /// A throw: the body (weightless) flies along +x at `speed_mps` into a fixed wall 1 cm
    /// thick whose near face is 2 cm beyond the body.
    pub fn impact(
        mesh: &Mesh,
        spec: &MethodSpec,
        dt_s: f32,
        speed_mps: f32,
    ) -> Result<Self, SoftBodyError> {
        let mut s = Self::setup(ScenarioKind::Rest, mesh, spec, dt_s, false)?;
        s.world.gravity = Vec3::ZERO;
        let half_t = 0.005;
        let near = s.frame.hi.x + 0.02;
        let wall = s
            .world
            .insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(near + half_t, 0.0, 0.0)));
        s.world.insert_collider(
            ColliderBuilder::cuboid(half_t, 2.0 * s.frame.size_m, 2.0 * s.frame.size_m)
                .friction(0.5),
            Some(wall),
        );
        s.beyond.push((Vec3::X, near + 2.0 * half_t));
        s.model.set_velocity(&mut s.world, Vec3::X * speed_mps);
        Ok(s)
    }

    /// A throw into a corner: under gravity, the body (2 cm over a wide fixed floor 1 cm thick) flies at `speed_mps` diagonally into the corner of two fixed walls 1 cm thick
    /// (+x and +z, 2 cm beyond the body). Nothing may end beyond a wall or below the floor.
    pub fn corner_throw(
        mesh: &Mesh,
        spec: &MethodSpec,
        dt_s: f32,
        speed_mps: f32,
    ) -> Result<Self, SoftBodyError> {
        let mut s = Self::setup(ScenarioKind::Rest, mesh, spec, dt_s, false)?;
        let floor_top = s.frame.lo.y - 0.02;
        s.world.gravity = Vec3::new(0.0, -9.81, 0.0);
        let half_t = 0.005;
        let size = s.frame.size_m;
        let slab = |world: &mut PhysicsWorld, at: Vec3, half: Vec3| {
            let b = world.insert_body(RigidBodyBuilder::fixed().translation(at));
            world.insert_collider(
                ColliderBuilder::cuboid(half.x, half.y, half.z).friction(0.5),
                Some(b),
            );
        };
        // The floor reaches far beyond the corner: a body that bounces back must not fall off
        // its edge within the run (that read as tunnelling under it).
        slab(
            &mut s.world,
            Vec3::new(0.0, floor_top - half_t, 0.0),
            Vec3::new(20.0, half_t, 20.0),
        );
        let near_x = s.frame.hi.x + 0.02;
        let near_z = s.frame.hi.z + 0.02;
        slab(
            &mut s.world,
            Vec3::new(near_x + half_t, floor_top + size, 0.0),
            Vec3::new(half_t, 2.0 * size, 3.0 * size),
        );
        slab(
            &mut s.world,
            Vec3::new(0.0, floor_top + size, near_z + half_t),
            Vec3::new(3.0 * size, 2.0 * size, half_t),
        );
        s.beyond.push((Vec3::X, near_x + 2.0 * half_t));
        s.beyond.push((Vec3::Z, near_z + 2.0 * half_t));
        s.beyond.push((-Vec3::Y, -(floor_top - 2.0 * half_t)));
        let dir = Vec3::new(1.0, 0.0, 1.0).normalize();
        s.model.set_velocity(&mut s.world, dir * speed_mps);
        Ok(s)
    }

    /// The squeeze with plates that close in `close_s` instead of 0.8 s (a fast squeeze).
    pub fn fast_squeeze(
        mesh: &Mesh,
        spec: &MethodSpec,
        dt_s: f32,
        close_s: f32,
    ) -> Result<Self, SoftBodyError> {
        let mut s = Self::new(ScenarioKind::Squeeze, mesh, spec, dt_s)?;
        s.close_s = close_s.max(dt_s);
        Ok(s)
    }

    /// The squeeze or the poke with its props moving `pace` times slower (`pace` ≥ 1) and
    /// doing `amount` (in (0, 1]) of their action: the plates close over `0.8·pace` s by
    /// `amount` × 70 % of the height, the poker reaches `amount` × 0.3 × the size deep in
    /// `0.5·pace` s, and both let go at `pace` times the scenario's release time. A slow,
    /// shallow action is closer to the static answer, which is unique below the strain where
    /// the body buckles: its predictable window (how long a 5 % change of the step stays
    /// within the tolerance) can hold the whole action where the scenario's own does not.
    pub fn paced(
        kind: ScenarioKind,
        mesh: &Mesh,
        spec: &MethodSpec,
        dt_s: f32,
        pace: f32,
        amount: f32,
    ) -> Result<Self, SoftBodyError> {
        if !(pace.is_finite() && (1.0..=100.0).contains(&pace)) {
            return Err(SoftBodyError::Config(format!(
                "pace {pace}: must be in [1, 100]"
            )));
        }
        if !(amount.is_finite() && amount > 0.0 && amount <= 1.0) {
            return Err(SoftBodyError::Config(format!(
                "amount {amount}: must be in (0, 1]"
            )));
        }
        let mut s = Self::new(kind, mesh, spec, dt_s)?;
        s.pace = pace;
        s.amount = amount;
        s.close_s = 0.8 * pace;
        Ok(s)
    }

    /// When the props reach their full action (the plates closed, the poker at its depth),
    /// seconds; `None` for a scenario without props.
    pub fn action_done_s(&self) -> Option<f32> {
        match self.frame.kind {
            ScenarioKind::Squeeze => Some(self.close_s),
            ScenarioKind::Poke => Some(0.5 * self.pace),
            _ => None,
        }
    }

    /// When the props let go, seconds.
    pub fn release_s(&self) -> f32 {
        self.frame.kind.release_s() * self.pace
    }

    fn place_props(&mut self, teleport: bool) {
        let t = self.time_s();
        let frame = self.frame;
        let release = self.release_s();
        let th = self.thickness_m + 0.01 * frame.size_m;
        let plate_half_y = 0.05f32.max(0.5 * frame.size_m);
        match frame.kind {
            ScenarioKind::Squeeze => {
                // Close over `close_s` (0.8 s) until the surfaces are at 30 % of the height, hold, open.
                let close = ramp(t, 0.0, self.close_s) - ramp(t, release, 0.3);
                let full = self.amount * (frame.half_height_m * 0.7 + 0.01 * frame.size_m);
                for (h, sign) in [(self.top_plate, 1.0f32), (self.bottom_plate, -1.0)] {
                    if let Some(b) = h.and_then(|h| self.world.bodies.get_mut(h)) {
                        let open = if sign > 0.0 { frame.hi.y } else { frame.lo.y } + sign * th;
                        let y = open - sign * close * full + sign * plate_half_y;
                        let p = Vec3::new(0.0, y, 0.0);
                        if teleport {
                            b.set_translation(p, false);
                        } else {
                            b.set_next_kinematic_translation(p);
                        }
                    }
                }
            }
            ScenarioKind::Poke => {
                let depth = (ramp(t, 0.0, 0.5 * self.pace) - ramp(t, release, 0.5 * self.pace))
                    * 0.3
                    * self.amount
                    * frame.size_m;
                if let Some(b) = self.poker.and_then(|h| self.world.bodies.get_mut(h)) {
                    let r = 0.1 * frame.size_m;
                    let p = Vec3::new(frame.hi.x + r + th - depth, 0.0, 0.0);
                    if teleport {
                        b.set_translation(p, false);
                    } else {
                        b.set_next_kinematic_translation(p);
                    }
                }
            }
            _ => {}
        }
    }

    /// Simulated time, seconds.
    pub fn time_s(&self) -> f32 {
        self.frame.time_s()
    }

    /// The scenario kind.
    pub fn kind(&self) -> ScenarioKind {
        self.frame.kind
    }

    /// Largest extent of the body at rest, metres.
    pub fn size_m(&self) -> f32 {
        self.frame.size_m
    }

    /// Moves the props for the current time and steps the world and the model once.
    pub fn step(&mut self) {
        self.place_props(false);
        crate::methods::model::step_models(
            &mut self.world,
            std::slice::from_mut(&mut self.model),
            self.frame.dt_s,
        );
        self.frame.steps += 1;
    }

    /// Runs until `t_s`.
    pub fn run_until(&mut self, t_s: f32) {
        while self.frame.before(t_s) {
            self.step();
        }
    }

    /// Enclosed volume of the surface / its rest volume.
    pub fn volume_ratio(&self) -> f32 {
        crate::mesh::enclosed_volume(self.model.surface(), self.model.triangles())
            / self.rest_volume_m3
    }

    /// RMS and max distance of the surface to its rest shape after the best rigid fit, metres.
    pub fn rest_error_m(&self) -> (f32, f32) {
        rigid_fit_error(self.model.surface(), &self.rest_surface, Quat::IDENTITY)
    }

    /// The stability criteria now.
    pub fn sanity(&self) -> Sanity {
        let s = self.model.surface();
        let non_finite = s.iter().any(|p| !p.is_finite());
        let c = s.iter().copied().sum::<Vec3>() / s.len().max(1) as f32;
        let far = s.iter().map(|p| p.distance(c)).fold(0.0f32, f32::max);
        let exploded =
            !non_finite && (far > 2.0 * self.frame.size_m || self.model.max_speed_mps() > 100.0);
        let tunnelled = self
            .beyond
            .iter()
            .any(|&(n, d)| s.iter().any(|p| p.dot(n) > d));
        Sanity {
            non_finite,
            exploded,
            inverted: self.model.inverted_elements() > 0,
            tunnelled,
        }
    }
}

/// RMS and max distance between two surfaces with the same vertices, metres.
pub fn surface_distance_m(a: &[Vec3], b: &[Vec3]) -> (f32, f32) {
    let n = a.len().min(b.len());
    if n == 0 {
        return (0.0, 0.0);
    }
    let mut sum = 0.0f64;
    let mut max = 0.0f32;
    for (p, q) in a.iter().zip(b) {
        let d = p.distance(*q);
        sum += (d as f64).powi(2);
        max = max.max(d);
    }
    (((sum / n as f64).sqrt()) as f32, max)
}

/// A cantilever: a 0.4 × 0.1 × 0.1 m tet beam, clamped at x = 0, sagging under gravity.
pub fn cantilever_beam(
    solver: SolverKind,
    substeps: u32,
    iterations: u32,
    young_pa: f32,
) -> PbdBody {
    let (x, tets) = crate::methods::statics::box_tets(Vec3::new(0.4, 0.1, 0.1), [8, 2, 2]);
    let volume = 0.4 * 0.1 * 0.1;
    let mass = vec![1000.0 * volume / x.len() as f32; x.len()];
    let params = PbdParams {
        solver,
        substeps,
        iterations,
        damping_per_s: 4.0,
        sleep_after_s: 0.0,
        ..Default::default()
    };
    let mut b = PbdBody::new(
        "beam",
        params,
        x.clone(),
        &mass,
        SurfaceMap::Direct,
        Vec::new(),
    );
    b.distance.push(DistanceGroup::new(
        "tet_edges",
        crate::methods::tets::tet_edges(&tets),
        &x,
        young_pa,
        volume,
        0.3,
    ));
    b.volume = Some(VolumeGroup::new(tets, &x, young_pa, 0.3));
    b.pin_box(Vec3::splat(-1.0), Vec3::new(1e-4, 1.0, 1.0));
    b
}

/// Tip sag of [`cantilever_beam`] after 4 s at 60 Hz, metres.
pub fn cantilever_sag_m(solver: SolverKind, substeps: u32, iterations: u32, young_pa: f32) -> f32 {
    let world = PhysicsWorld::new();
    let mut b = cantilever_beam(solver, substeps, iterations, young_pa);
    for _ in 0..240 {
        b.step(&world, 1.0 / 60.0);
    }
    // The last 3 × 3 nodes are the free end.
    let n = b.positions().len();
    let tip: Vec<f32> = b.positions()[n - 9..].iter().map(|p| p.y).collect();
    let start = 0.05; // mean rest height of the tip nodes
    start - tip.iter().sum::<f32>() / tip.len() as f32
}
