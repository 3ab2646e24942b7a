//! The cut gesture: a hand whose tool is [`HandTool::Cutter`] cuts a soft body in two by
//! sweeping its blade through it with the trigger held. The plane is the tear paper's (§3.2):
//! through the point where the blade first met the body and the blade's two ends (its tip and
//! its back, [`SCALPEL_BLADE_M`] along the hand's +y) once the tip has moved
//! [`CUT_SWEEP_M`] from there; if those three points are nearly on one line (the hand moved
//! along its own blade) the plane waits for more motion ("the selected time step is
//! altered"). One cut per trigger press; the cut goes to [`Peer::cut`], so a body another
//! peer owns is cut through its owner. VR controllers and the desktop's mouse hand (the X key,
//! its blade pointing into the screen) drive it alike.

use glam::Vec3;
use softsync_net::{Instant, NetId};

use super::topology::{SCALPEL_BLADE_M, SCALPEL_TRIGGER};
use super::Peer;
use crate::events::Event;

/// What a hand's trigger does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HandTool {
    /// A scalpel: the hand's path through a soft body tears it (tear paper §3.1).
    #[default]
    Scalpel,
    /// A cutting blade: sweeping it through a soft body cuts the body in two by the plane
    /// of the sweep (tear paper §3.2).
    Cutter,
}

/// How far the tip moves from where the blade met the body before the plane is taken, m.
pub const CUT_SWEEP_M: f32 = 0.02;

/// The sweep's three points make a plane only if they are this far from one line: the sine
/// of the smallest angle between the sweep and the blade.
const CUT_MIN_SINE: f32 = 0.17; // 10°

/// One hand's sweep while its trigger is held.
#[derive(Clone, Debug, Default)]
pub(crate) struct Sweep {
    /// The body the blade met and where its tip was then.
    entered: Option<(NetId, Vec3)>,
    /// This press already cut (or gave up): nothing more until the trigger is released.
    done: bool,
}

/// The plane through the point `entry` and the blade's ends now (`tip`, `tip + blade`), as
/// (a point on it, its unit normal); `None` until the tip is [`CUT_SWEEP_M`] from `entry`
/// and the three points are not nearly on one line.
pub fn sweep_plane(entry: Vec3, tip: Vec3, blade: Vec3) -> Option<(Vec3, Vec3)> {
    let sweep = tip - entry;
    if sweep.length() < CUT_SWEEP_M || blade.length() < 1e-4 {
        return None;
    }
    let n = blade.normalize().cross(sweep.normalize());
    (n.length() >= CUT_MIN_SINE && n.is_finite()).then(|| (entry, n.normalize()))
}

impl Peer {
    /// Chooses what hand `hand`'s trigger does (0 left, 1 right). A sweep in progress ends.
    pub fn set_hand_tool(&mut self, hand: usize, tool: HandTool) {
        if let Some(t) = self.tools.get_mut(hand) {
            if *t != tool {
                *t = tool;
                self.sweeps[hand] = Sweep::default();
            }
        }
    }

    /// What hand `hand`'s trigger does.
    pub fn hand_tool(&self, hand: usize) -> HandTool {
        self.tools.get(hand).copied().unwrap_or_default()
    }

    /// Whether hand `hand` is sweeping its cutter through a body (trigger held, the blade
    /// in it, not yet cut): for a HUD.
    pub fn is_sweeping(&self, hand: usize) -> bool {
        self.sweeps
            .get(hand)
            .is_some_and(|s| s.entered.is_some() && !s.done)
    }

    /// Hand `hand`'s cutter this step: its tip at `tip`, its blade `blade` from the tip, its
    /// trigger at `trigger`.
    pub(super) fn use_cutter(
        &mut self,
        now: Instant,
        hand: usize,
        tip: Vec3,
        blade: Vec3,
        trigger: f32,
    ) {
        if trigger < SCALPEL_TRIGGER {
            self.sweeps[hand] = Sweep::default();
            return;
        }
        if self.sweeps[hand].done {
            return;
        }
        let (target, entry) = match self.sweeps[hand].entered {
            Some((id, entry)) if self.mirror.objects.contains_key(&id) => (id, entry),
            _ => match self.soft_body_at(tip) {
                Some(id) => {
                    self.sweeps[hand].entered = Some((id, tip));
                    return;
                }
                None => {
                    self.sweeps[hand].entered = None;
                    return;
                }
            },
        };
        let Some((point, normal)) = sweep_plane(entry, tip, blade) else {
            return;
        };
        self.sweeps[hand].done = true;
        self.counters.cut_gestures += 1;
        if let Err(e) = self.cut(now, target, point, normal) {
            self.events
                .push_back(Event::Warning(format!("cutter: {e}")));
        }
    }

    /// The blade of a hand turned by `rot`: from its tip along its +y.
    pub(super) fn blade_of(rot: glam::Quat) -> Vec3 {
        rot * Vec3::Y * SCALPEL_BLADE_M
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_plane_goes_through_the_entry_and_the_blades_ends_once_it_has_swept() {
        let blade = Vec3::Y * SCALPEL_BLADE_M;
        let entry = Vec3::new(0.1, 0.8, 0.0);
        // not far enough yet
        assert_eq!(sweep_plane(entry, entry + Vec3::Z * 0.01, blade), None);
        // a sweep along z with the blade up: the plane x = 0.1
        let (p, n) = sweep_plane(entry, entry + Vec3::Z * 0.03, blade).unwrap();
        assert_eq!(p, entry);
        assert!((n.abs() - Vec3::X).length() < 1e-5, "{n}");
        // the three points are on the plane
        for q in [
            entry,
            entry + Vec3::Z * 0.03,
            entry + Vec3::Z * 0.03 + blade,
        ] {
            assert!((q - p).dot(n).abs() < 1e-6);
        }
        // moving along the blade makes no plane; a slant does
        assert_eq!(sweep_plane(entry, entry + Vec3::Y * 0.05, blade), None);
        assert!(sweep_plane(entry, entry + Vec3::new(0.0, 0.05, 0.02), blade).is_some());
        // a blade of nothing or a NaN makes none
        assert_eq!(sweep_plane(entry, entry + Vec3::Z * 0.03, Vec3::ZERO), None);
        assert_eq!(
            sweep_plane(entry, entry + Vec3::new(f32::NAN, 0.0, 0.05), blade),
            None
        );
    }
}
