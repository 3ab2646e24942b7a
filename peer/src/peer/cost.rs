//! Where a frame's time goes, phase by phase ([`Peer::set_stopwatch`]): what the frame-budget
//! bench (`softsync-bench frame`) charts. The peer reads no clock of its own: the caller lends
//! it one, and without it nothing is measured and nothing costs.

use super::Peer;

/// The phases of [`Peer::pump`] and [`Peer::fixed_step`], in the order they run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Phase {
    /// The session's timers (heartbeats, timeouts, migration) in `pump`.
    Timers,
    /// Acting on the session's events in `pump`: spawns, authority, topology (cuts, tears).
    Events,
    /// Landing bodies built off the frame, adopting orphans, in `pump`.
    Builds,
    /// Showing what others simulate (interpolated states applied, before and after the step).
    Shown,
    /// Hands: grabs, drives, remote hands.
    Hands,
    /// Scalpels and cut/tear requests.
    Blades,
    /// The soft bodies' restoring velocities (`SoftBodySet::pre_physics`).
    Restoring,
    /// rapier's step: contacts, solver, integration, new bodies' first broad phase.
    Rapier,
    /// The soft bodies' meshes deformed from their particles (`SoftBodySet::post_physics`).
    Deform,
    /// Automatic bodies, holders, and publishing what we own.
    Publish,
}

impl Phase {
    /// Every phase, in order.
    pub const ALL: [Phase; 10] = [
        Phase::Timers,
        Phase::Events,
        Phase::Builds,
        Phase::Shown,
        Phase::Hands,
        Phase::Blades,
        Phase::Restoring,
        Phase::Rapier,
        Phase::Deform,
        Phase::Publish,
    ];

    /// Its name in RESULT lines and CSV headers.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Timers => "timers",
            Phase::Events => "events",
            Phase::Builds => "builds",
            Phase::Shown => "shown",
            Phase::Hands => "hands",
            Phase::Blades => "blades",
            Phase::Restoring => "restoring",
            Phase::Rapier => "rapier",
            Phase::Deform => "deform",
            Phase::Publish => "publish",
        }
    }
}

/// Seconds spent per [`Phase`] since the last [`Peer::take_frame_cost`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameCost {
    /// Indexed like [`Phase::ALL`].
    pub seconds: [f64; 10],
}

impl FrameCost {
    /// Seconds in `phase`.
    pub fn of(&self, phase: Phase) -> f64 {
        self.seconds[phase as usize]
    }

    /// Seconds in every phase together.
    pub fn total(&self) -> f64 {
        self.seconds.iter().sum()
    }
}

/// The lent clock and what it measured.
#[derive(Default)]
pub(super) struct Stopwatch {
    clock: Option<fn() -> f64>,
    last: f64,
    cost: FrameCost,
}

impl Stopwatch {
    /// Starts timing a phase sequence (a no-op without a clock).
    pub(super) fn start(&mut self) {
        if let Some(c) = self.clock {
            self.last = c();
        }
    }

    /// The time since the last start or lap goes to `phase`.
    pub(super) fn lap(&mut self, phase: Phase) {
        if let Some(c) = self.clock {
            let t = c();
            self.cost.seconds[phase as usize] += (t - self.last).max(0.0);
            self.last = t;
        }
    }
}

impl Peer {
    /// Lends the peer a monotonic clock in seconds (`None`: stop measuring), to measure where
    /// each frame's time goes ([`Peer::take_frame_cost`]). It changes nothing the peer does.
    pub fn set_stopwatch(&mut self, clock: Option<fn() -> f64>) {
        self.stopwatch = Stopwatch {
            clock,
            ..Stopwatch::default()
        };
    }

    /// The time per phase since the last call (all zero without a stopwatch).
    pub fn take_frame_cost(&mut self) -> FrameCost {
        std::mem::take(&mut self.stopwatch.cost)
    }
}
