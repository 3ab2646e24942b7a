//! Deterministic scenarios shared by tests, benchmarks and (later) the network tests: rest,
//! drop on a floor, squeeze between two plates, poke with a moving sphere, pull one particle
//! and let go. Time advances only through [`Scenario::step`].

use glam::Vec3;
use rapier3d::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle};
use serde::{Deserialize, Serialize};

use crate::metrics::{measure, ShapeMetrics};
use crate::{
    Mesh, SimulationSpace, SoftBody, SoftBodyConfig, SoftBodyError, SoftBodyHandle, SoftBodySet,
};

/// Which scenario to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScenarioKind {
    /// Local mode, nothing touches the body.
    Rest,
    /// World mode, dropped from 0.5 m (bottom to floor) onto a fixed floor.
    Drop,
    /// Local mode; two plates close until they are 30 % of the body's height apart (plus a
    /// particle radius each), hold, and open from 1.5 s.
    Squeeze,
    /// Local mode; a 0.2·size ball pushes 30 % of the size into the +x side and leaves.
    Poke,
    /// Local mode; the particle farthest along +x is pulled out by 30 % of the size over
    /// 0.3 s, held until 0.75 s, then let go.
    Pull,
}

impl ScenarioKind {
    /// All kinds.
    pub const ALL: [ScenarioKind; 5] = [
        ScenarioKind::Rest,
        ScenarioKind::Drop,
        ScenarioKind::Squeeze,
        ScenarioKind::Poke,
        ScenarioKind::Pull,
    ];

    /// Name for tables.
    pub fn name(&self) -> &'static str {
        match self {
            ScenarioKind::Rest => "rest",
            ScenarioKind::Drop => "drop",
            ScenarioKind::Squeeze => "squeeze",
            ScenarioKind::Poke => "poke",
            ScenarioKind::Pull => "pull",
        }
    }

    /// Default length of the scenario, seconds (interaction, then time to recover).
    pub fn duration_s(&self) -> f32 {
        match self {
            ScenarioKind::Rest => 10.0,
            ScenarioKind::Drop => 3.0,
            ScenarioKind::Squeeze => 3.5,
            ScenarioKind::Poke => 3.0,
            ScenarioKind::Pull => 3.0,
        }
    }

    /// Time at which the interaction ends and the body is free to recover, seconds.
    pub fn release_s(&self) -> f32 {
        match self {
            ScenarioKind::Rest => 0.0,
            ScenarioKind::Drop => 0.0,
            ScenarioKind::Squeeze => 1.5,
            ScenarioKind::Poke => 1.0,
            ScenarioKind::Pull => 0.75,
        }
    }
}

/// A world with a fixed floor whose top is y = 0 (40 m wide, friction 0.5) and `mesh`, moved
/// by `at`, as a world-mode body of `config` moving rigidly at `linvel` and spinning at
/// `angvel`: a push, a roll or a throw (rolling resistance's test and bench).
pub fn on_floor(
    mesh: &Mesh,
    mut config: SoftBodyConfig,
    at: Vec3,
    linvel: Vec3,
    angvel: Vec3,
) -> Result<(PhysicsWorld, SoftBodySet, SoftBodyHandle), SoftBodyError> {
    let mut world = PhysicsWorld::new();
    let floor = world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, -0.5, 0.0)));
    world.insert_collider(
        ColliderBuilder::cuboid(20.0, 0.5, 20.0).friction(0.5),
        Some(floor),
    );
    let mut mesh = mesh.clone();
    for p in &mut mesh.positions {
        *p += at;
    }
    config.space = SimulationSpace::World;
    let mut set = SoftBodySet::new();
    let h = set.insert(&mesh, config, &mut world)?;
    set.get(h)
        .ok_or(SoftBodyError::InvalidHandle(h))?
        .set_rigid_velocity(&mut world, linvel, angvel)?;
    Ok((world, set, h))
}

/// The drop scenario's setting: a fixed floor whose top is y = 0, and the mesh lifted so its
/// bottom (`lowest_y`) is 0.5 m above it.
pub(crate) fn drop_floor(world: &mut PhysicsWorld, mesh: &mut Mesh, lowest_y: f32) {
    let floor = world.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(0.0, -0.5, 0.0)));
    world.insert_collider(
        ColliderBuilder::cuboid(50.0, 0.5, 50.0).friction(0.8),
        Some(floor),
    );
    let lift = 0.5 - lowest_y;
    for p in &mut mesh.positions {
        p.y += lift;
    }
}

/// What every scene keeps of its setting, whatever simulates the body: the scenario, the
/// fixed step and how many were taken, and the body's rest bounds after re-centring.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SceneFrame {
    /// The scenario.
    pub(crate) kind: ScenarioKind,
    /// The fixed step, seconds.
    pub(crate) dt_s: f32,
    /// Steps taken.
    pub(crate) steps: u64,
    /// Half the body's rest height, metres.
    pub(crate) half_height_m: f32,
    /// Largest rest extent, metres.
    pub(crate) size_m: f32,
    /// Rest bounds, low corner.
    pub(crate) lo: Vec3,
    /// Rest bounds, high corner.
    pub(crate) hi: Vec3,
}

impl SceneFrame {
    /// Checks `dt_s` and re-centres a copy of `mesh` at the origin; returns the frame, that
    /// mesh and an empty world stepping at `dt_s`.
    pub(crate) fn new(
        kind: ScenarioKind,
        mesh: &Mesh,
        dt_s: f32,
    ) -> Result<(Self, Mesh, PhysicsWorld), SoftBodyError> {
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 0.1) {
            return Err(SoftBodyError::Config(format!(
                "dt_s = {dt_s} must be in (0, 0.1]"
            )));
        }
        let mut mesh = mesh.clone();
        mesh.recenter();
        let (lo, hi) = crate::mesh::bounds(&mesh.positions);
        let half_height_m = (hi.y - lo.y) * 0.5;
        let size_m = (hi - lo).max_element();
        let mut world = PhysicsWorld::new();
        world.integration_parameters.dt = dt_s;
        let frame = SceneFrame {
            kind,
            dt_s,
            steps: 0,
            half_height_m,
            size_m,
            lo,
            hi,
        };
        Ok((frame, mesh, world))
    }

    /// Simulated time, seconds.
    pub(crate) fn time_s(&self) -> f32 {
        self.steps as f32 * self.dt_s
    }

    /// True until the step that reaches `t_s` has been taken.
    pub(crate) fn before(&self, t_s: f32) -> bool {
        self.time_s() + 0.5 * self.dt_s < t_s
    }
}

/// How far (0 → 1) a motion starting at `start_s` and lasting `len_s` is at time `t_s`.
pub(crate) fn ramp(t_s: f32, start_s: f32, len_s: f32) -> f32 {
    ((t_s - start_s) / len_s).clamp(0.0, 1.0)
}

/// A running scenario: its own rapier world with one soft body and the props that act on it.
pub struct Scenario {
    /// The rapier world.
    pub world: PhysicsWorld,
    /// The soft bodies (one).
    pub set: SoftBodySet,
    /// The soft body.
    pub body: SoftBodyHandle,
    frame: SceneFrame,
    max_particle_radius_m: f32,
    plate_travel_m: f32,
    median_particle_radius_m: f32,
    top_plate: Option<RigidBodyHandle>,
    bottom_plate: Option<RigidBodyHandle>,
    poker: Option<RigidBodyHandle>,
    pulled: Option<(usize, Vec3, Vec3)>,
}

impl Scenario {
    /// Sets up `kind` for `mesh` (object space, any placement: it is re-centred at the origin)
    /// with `config` (its `space` is overridden: world for drop, local otherwise), stepping at
    /// `dt_s`.
    pub fn new(
        kind: ScenarioKind,
        mesh: &Mesh,
        mut config: SoftBodyConfig,
        dt_s: f32,
    ) -> Result<Self, SoftBodyError> {
        let (frame, mut mesh, mut world) = SceneFrame::new(kind, mesh, dt_s)?;
        let SceneFrame { lo, hi, size_m, .. } = frame;
        let mut set = SoftBodySet::new();
        config.space = if kind == ScenarioKind::Drop {
            SimulationSpace::World
        } else {
            SimulationSpace::Local
        };
        let mut top_plate = None;
        let mut bottom_plate = None;
        let mut poker = None;
        let plate_half = Vec3::new(size_m * 2.0, 0.05, size_m * 2.0);
        match kind {
            ScenarioKind::Drop => drop_floor(&mut world, &mut mesh, lo.y),
            ScenarioKind::Squeeze => {
                let gap = 0.01 * size_m;
                let t = world.insert_body(
                    RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(
                        0.0,
                        hi.y + gap + plate_half.y,
                        0.0,
                    )),
                );
                world.insert_collider(
                    ColliderBuilder::cuboid(plate_half.x, plate_half.y, plate_half.z),
                    Some(t),
                );
                let b = world.insert_body(
                    RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(
                        0.0,
                        lo.y - gap - plate_half.y,
                        0.0,
                    )),
                );
                world.insert_collider(
                    ColliderBuilder::cuboid(plate_half.x, plate_half.y, plate_half.z),
                    Some(b),
                );
                top_plate = Some(t);
                bottom_plate = Some(b);
            }
            ScenarioKind::Poke => {
                let r = 0.1 * size_m;
                let h = world.insert_body(
                    RigidBodyBuilder::kinematic_position_based().translation(Vec3::new(
                        hi.x + r + 0.01 * size_m,
                        0.0,
                        0.0,
                    )),
                );
                world.insert_collider(ColliderBuilder::ball(r), Some(h));
                poker = Some(h);
            }
            ScenarioKind::Rest | ScenarioKind::Pull => {}
        }
        let body = set.insert(&mesh, config, &mut world)?;
        let max_particle_radius_m = set
            .get(body)
            .map(|b| b.particle_radii_m().iter().copied().fold(0.0, f32::max))
            .unwrap_or(0.0);
        let median_particle_radius_m = set
            .get(body)
            .map(|b| {
                let mut r = b.particle_radii_m().to_vec();
                r.sort_unstable_by(f32::total_cmp);
                r.get(r.len() / 2).copied().unwrap_or(0.0)
            })
            .unwrap_or(0.0);
        // Props start clear of the particle colliders.
        for (h, y) in [
            (
                top_plate,
                hi.y + max_particle_radius_m + 0.01 * size_m + plate_half.y,
            ),
            (
                bottom_plate,
                lo.y - max_particle_radius_m - 0.01 * size_m - plate_half.y,
            ),
        ] {
            if let Some(b) = h.and_then(|h| world.bodies.get_mut(h)) {
                b.set_translation(Vec3::new(0.0, y, 0.0), false);
            }
        }
        if let Some(b) = poker.and_then(|h| world.bodies.get_mut(h)) {
            let r = 0.1 * size_m;
            b.set_translation(
                Vec3::new(hi.x + r + max_particle_radius_m + 0.01 * size_m, 0.0, 0.0),
                false,
            );
        }
        let mut pulled = None;
        if kind == ScenarioKind::Pull {
            if let Some(b) = set.get(body) {
                let pos = b.particle_positions(&world);
                let (i, p) = pos
                    .iter()
                    .enumerate()
                    .max_by(|a, b| a.1.x.total_cmp(&b.1.x))
                    .map(|(i, p)| (i, *p))
                    .unwrap_or((0, Vec3::ZERO));
                pulled = Some((i, p, p + Vec3::X * 0.3 * size_m));
            }
        }
        Ok(Scenario {
            world,
            set,
            body,
            frame,
            max_particle_radius_m,
            plate_travel_m: 0.0,
            median_particle_radius_m,
            top_plate,
            bottom_plate,
            poker,
            pulled,
        })
    }

    /// Simulated time, seconds.
    pub fn time_s(&self) -> f32 {
        self.frame.time_s()
    }

    /// The scenario's kind.
    pub fn kind(&self) -> ScenarioKind {
        self.frame.kind
    }

    /// The soft body.
    pub fn soft_body(&self) -> &SoftBody {
        // The handle was returned by our own set and never removed.
        self.set
            .get(self.body)
            .unwrap_or_else(|| unreachable!("scenario body is never removed"))
    }

    /// Metrics of the body now.
    pub fn metrics(&self) -> ShapeMetrics {
        measure(self.soft_body(), &self.world)
    }

    /// Moves the props for the current time, then steps the body and the world once.
    pub fn step(&mut self) {
        let t = self.time_s();
        let frame = self.frame;
        let release = frame.kind.release_s();
        match frame.kind {
            ScenarioKind::Squeeze => {
                // Each plate closes over 0.8 s until its surface is a particle radius beyond
                // 30 % of the rest height, holds until the release, then opens over 0.3 s.
                let close = ramp(t, 0.0, 0.8) - ramp(t, release, 0.3);
                let full =
                    frame.half_height_m * 0.7 + self.max_particle_radius_m + 0.01 * frame.size_m
                        - self.median_particle_radius_m;
                self.plate_travel_m = close * full;
                for (h, sign) in [(self.top_plate, 1.0f32), (self.bottom_plate, -1.0)] {
                    if let Some(b) = h.and_then(|h| self.world.bodies.get_mut(h)) {
                        let open = if sign > 0.0 { frame.hi.y } else { frame.lo.y }
                            + sign * (self.max_particle_radius_m + 0.01 * frame.size_m);
                        let surface = open - sign * self.plate_travel_m;
                        b.set_next_kinematic_translation(Vec3::new(
                            0.0,
                            surface + sign * 0.05,
                            0.0,
                        ));
                    }
                }
            }
            ScenarioKind::Poke => {
                let depth = (ramp(t, 0.0, 0.5) - ramp(t, release, 0.5)) * 0.3 * frame.size_m;
                if let Some(b) = self.poker.and_then(|h| self.world.bodies.get_mut(h)) {
                    let r = 0.1 * frame.size_m;
                    let x0 = frame.hi.x + r + self.max_particle_radius_m + 0.01 * frame.size_m;
                    b.set_next_kinematic_translation(Vec3::new(x0 - depth, 0.0, 0.0));
                }
            }
            ScenarioKind::Pull => {
                // The hand moves out over 0.3 s (a hand does not teleport), holds, lets go.
                let out = ramp(t, 0.0, 0.3);
                if let (Some((i, start, goal)), Some(body)) =
                    (self.pulled, self.set.get_mut(self.body))
                {
                    let at = start + (goal - start) * out;
                    body.set_particle_drive(i, if t < release { Some(at) } else { None });
                }
            }
            ScenarioKind::Rest | ScenarioKind::Drop => {}
        }
        self.set.step(&mut self.world, self.frame.dt_s);
        self.frame.steps += 1;
    }

    /// Runs until `t_s` seconds of simulated time.
    pub fn run_until(&mut self, t_s: f32) {
        while self.frame.before(t_s) {
            self.step();
        }
    }
}
