//! This peer's avatar: a head and two hands, networked objects it owns and poses every step
//! (from a bot or a tracked device), standing at its place around the table.
//!
//! A host spawns its parts at once; a client asks the host, and a part is ours when the
//! host's `Spawned` answers the request.

use std::collections::VecDeque;

use glam::{Quat, Vec3};
use softsync_net::{Instant, NetId, ObjectState, PeerId, Session};

use crate::events::Event;
use crate::mirror::{LocalBody, Mirror};
use crate::scene::Kind;

/// Where a peer stands: around the table, one of eight places by its id, facing the middle.
pub fn home(me: PeerId) -> (Vec3, Quat) {
    let angle = (me.0 % 8) as f32 * std::f32::consts::FRAC_PI_4;
    let rot = Quat::from_rotation_y(angle);
    (rot * Vec3::new(0.0, 1.6, 0.75), rot)
}

/// Where the avatar's parts start, from its home pose: head, left hand, right hand.
pub const PART_OFFSETS: [Vec3; 3] = [
    Vec3::ZERO,
    Vec3::new(-0.2, -0.45, -0.25),
    Vec3::new(0.2, -0.45, -0.25),
];

/// The avatar's parts (0 head, 1 left hand, 2 right hand): spawned, or asked for.
#[derive(Clone, Debug, Default)]
pub(crate) struct Avatar {
    /// The parts' network ids, once spawned.
    pub(crate) parts: [Option<NetId>; 3],
    /// Our spawn requests still unanswered.
    requests: [Option<u32>; 3],
}

impl Avatar {
    /// Spawn the parts we have neither spawned nor asked for.
    pub(crate) fn spawn(
        &mut self,
        now: Instant,
        session: &mut Session,
        mirror: &mut Mirror,
        events: &mut VecDeque<Event>,
    ) {
        let me = session.local_id();
        let (home_pos, home_rot) = home(me);
        for (i, off) in PART_OFFSETS.into_iter().enumerate() {
            if self.parts[i].is_some() || self.requests[i].is_some() {
                continue;
            }
            let kind = if i == 0 { Kind::HEAD } else { Kind::HAND };
            let pos = home_pos + home_rot * off;
            match session.spawn(now, kind.class(), ObjectState::rigid(pos, home_rot)) {
                Ok((id, request)) => {
                    if session.is_host() {
                        self.parts[i] = Some(id);
                        mirror.insert(id, kind, LocalBody::Pose, Some(me));
                        mirror.set_pose(id, pos, home_rot);
                    } else {
                        self.requests[i] = Some(request);
                    }
                }
                Err(e) => events.push_back(Event::Warning(format!("cannot spawn our avatar: {e}"))),
            }
        }
    }

    /// The host spawned `id` for our `request`: if it is one of our parts, it is ours now,
    /// at `pose`.
    pub(crate) fn on_spawned(
        &mut self,
        request: u32,
        id: NetId,
        pose: (Vec3, Quat),
        mirror: &mut Mirror,
    ) {
        if let Some(i) = self.requests.iter().position(|r| *r == Some(request)) {
            self.parts[i] = Some(id);
            self.requests[i] = None;
            mirror.set_pose(id, pose.0, pose.1);
        }
    }

    /// Forget every part and request (rejoining: the room spawns a new avatar).
    pub(crate) fn clear(&mut self) {
        *self = Avatar::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eight_places_around_the_table_each_facing_its_middle() {
        for k in 0..8 {
            let (pos, rot) = home(PeerId(k));
            assert!((pos.y - 1.6).abs() < 1e-6);
            assert!((Vec3::new(pos.x, 0.0, pos.z).length() - 0.75).abs() < 1e-5);
            // The hands reach in front: toward the middle.
            let hand = pos + rot * PART_OFFSETS[2];
            assert!(Vec3::new(hand.x, 0.0, hand.z).length() < 0.75);
        }
        assert_eq!(home(PeerId(3)), home(PeerId(11)), "eight places, by id");
    }
}
