//! Bodies built off the frame. A body with a history — a cut's piece, a torn body a late
//! joiner receives — is its class's plan replayed through that history: tears, the cut that
//! made the piece (planning a piece clusters its mesh, ~6 ms on the thesis's bunny), a
//! resolution change. [`BodyBuild`] runs that replay on a worker thread in a private world;
//! the frame only moves the finished body into its own world
//! ([`SoftBodySet::move_body`]: copying its rapier bodies, a fraction of a millisecond).
//!
//! The replay is the same arithmetic, in the same order, as replaying the history in the
//! frame ([`BuildStep::apply`] is what both call), from the same plan placed the same way, so
//! the body that lands is the body the frame would have built: every peer that replays one
//! history ends with the same mesh, whichever thread did the work and whenever it finished.

use std::sync::mpsc::{Receiver, TryRecvError};

use glam::{Quat, Vec3};
use rapier3d::prelude::PhysicsWorld;

use super::handle::SoftBodyHandle;
use super::set::SoftBodySet;
use super::SoftBodyPlan;
use crate::cut::{CutPlane, TearSegment};
use crate::SoftBodyConfig;

/// One entry of a body's topology history, in its rest frame.
#[derive(Clone, Debug)]
pub enum BuildStep {
    /// A tear segment ([`SoftBodySet::tear`]).
    Tear(TearSegment),
    /// The scalpel lifted ([`SoftBodySet::end_tear_stroke`]).
    Lift,
    /// The cut that made this body piece `keep` of the cut by `plane`
    /// ([`SoftBodySet::cut_keep`]).
    Cut {
        /// The plane, rest frame.
        plane: CutPlane,
        /// Which piece, in [`SoftBodySet::cut`]'s order.
        keep: usize,
    },
    /// Another resolution of the same rest mesh ([`SoftBodySet::reconfigure`]), which must
    /// have `particles` particles if given.
    Reconfigure {
        /// The resolution's settings.
        config: SoftBodyConfig,
        /// The particle count the history's author had.
        particles: Option<usize>,
    },
}

impl BuildStep {
    /// Applies this step to body `h` of `set` in `world`; the body's handle after it (a cut or
    /// a resolution change replaces the body). Refused with what went wrong, changing nothing.
    pub fn apply(
        &self,
        set: &mut SoftBodySet,
        world: &mut PhysicsWorld,
        h: SoftBodyHandle,
    ) -> Result<SoftBodyHandle, String> {
        match self {
            BuildStep::Tear(seg) => {
                set.tear(h, world, seg).map_err(|e| e.to_string())?;
                Ok(h)
            }
            BuildStep::Lift => match set.end_tear_stroke(h) {
                true => Ok(h),
                false => Err(format!("soft body {h:?} is not in this set")),
            },
            BuildStep::Cut { plane, keep } => set
                .cut_keep(h, world, plane, *keep)
                .map_err(|e| e.to_string()),
            BuildStep::Reconfigure { config, particles } => {
                let new = set
                    .reconfigure(h, world, config.clone())
                    .map_err(|e| e.to_string())?;
                let n = set.get(new).map_or(0, |b| b.num_particles());
                match particles {
                    Some(p) if *p != n => Err(format!(
                        "the resolution has {n} particles here, {p} at its author"
                    )),
                    _ => Ok(new),
                }
            }
        }
    }
}

/// What a worker hands back: the body in its private world.
type Built = Result<(SoftBodySet, PhysicsWorld, SoftBodyHandle), String>;

/// A body being built off the frame: `plan` placed at a pose, at rest, then `steps` replayed,
/// on a worker thread. [`land`](Self::land) moves it into a world. Dropping it lets the worker
/// finish and throws its body away.
pub struct BodyBuild {
    rx: Option<Receiver<Built>>,
    /// The worker's result once received; or the inputs, when no thread could be started
    /// (then `land` builds in the caller's thread).
    done: Option<Built>,
    inline: Option<(SoftBodyPlan, Vec3, Quat, Vec<BuildStep>)>,
}

impl std::fmt::Debug for BodyBuild {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BodyBuild")
            .field("done", &self.done.is_some())
            .finish()
    }
}

impl BodyBuild {
    /// Starts building a body of `plan` with its center at `pos`, turned by `rot`, at rest,
    /// then `steps` applied in order, on a worker thread.
    pub fn start(plan: SoftBodyPlan, pos: Vec3, rot: Quat, steps: Vec<BuildStep>) -> Self {
        let (tx, rx) = std::sync::mpsc::channel();
        let job = (plan.clone(), pos, rot, steps.clone());
        let spawned = std::thread::Builder::new()
            .name("softsync-body-build".into())
            .spawn(move || {
                let _ = tx.send(build(&plan, pos, rot, &steps));
            });
        match spawned {
            Ok(_) => BodyBuild {
                rx: Some(rx),
                done: None,
                inline: None,
            },
            Err(_) => BodyBuild {
                rx: None,
                done: None,
                inline: Some(job),
            },
        }
    }

    /// Whether [`land`](Self::land) would return at once.
    pub fn is_ready(&mut self) -> bool {
        if self.done.is_some() || self.inline.is_some() {
            return true;
        }
        let Some(rx) = &self.rx else {
            return true;
        };
        match rx.try_recv() {
            Ok(b) => {
                self.done = Some(b);
                true
            }
            Err(TryRecvError::Empty) => false,
            Err(TryRecvError::Disconnected) => {
                self.done = Some(Err("the body's worker thread died".into()));
                true
            }
        }
    }

    /// Moves the finished body into `set` and `world` (waiting for the worker if it is not
    /// done) and returns its handle there; or what went wrong replaying its history.
    pub fn land(
        mut self,
        set: &mut SoftBodySet,
        world: &mut PhysicsWorld,
    ) -> Result<SoftBodyHandle, String> {
        let built = match (self.done.take(), self.inline.take(), self.rx.take()) {
            (Some(b), ..) => b,
            (None, Some((plan, pos, rot, steps)), _) => build(&plan, pos, rot, &steps),
            (None, None, Some(rx)) => rx
                .recv()
                .unwrap_or_else(|_| Err("the body's worker thread died".into())),
            (None, None, None) => Err("the build has landed already".into()),
        };
        let (mut from, mut from_world, h) = built?;
        from.move_body(h, &mut from_world, set, world)
            .ok_or_else(|| "the built body is gone".to_string())
    }
}

/// The replay itself: what [`BodyBuild`] runs on its worker, and what a caller would run in
/// its frame.
fn build(plan: &SoftBodyPlan, pos: Vec3, rot: Quat, steps: &[BuildStep]) -> Built {
    let (mut set, mut world) = (SoftBodySet::new(), PhysicsWorld::new());
    let mut h = set
        .insert_plan_at(plan, &mut world, pos, rot)
        .map_err(|e| e.to_string())?;
    for (i, step) in steps.iter().enumerate() {
        h = step
            .apply(&mut set, &mut world, h)
            .map_err(|e| format!("history entry {i}: {e}"))?;
    }
    Ok((set, world, h))
}
