//! The message types every softsync room has, and the peer's side of application messages.
//!
//! An application registers its own types after [`builtin`]'s and configures the room with
//! the table ([`MessageTypes::configure`]) before it hosts or joins; the [`Peer`](crate::Peer)
//! reads the table back from its session, so [`Peer::send`](crate::Peer::send) and
//! [`Peer::decode`](crate::Peer::decode) take the types alone.

use serde::{Deserialize, Serialize};
pub use softsync_net::messages::{Message, MessageTypes, RegisterError};
use softsync_net::{NetId, PeerId};

/// A line of text to the room (the `softsync` binary logs it; a bot's `say` sends one).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Say {
    /// The text (the room's payload bound applies: at most ~900 bytes).
    pub text: String,
}

impl Message for Say {
    const NAME: &'static str = "softsync.say";
}

/// A new host serves the room's signaling itself (its predecessor embedded the room's server
/// and died): members register with `url` so that new peers find the room there.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignalingMoved {
    /// The signaling server's URL (`ws://…`).
    pub url: String,
}

impl Message for SignalingMoved {
    const NAME: &'static str = "softsync.signaling";
}

/// A remote hand (co-manipulation): a hand of the sender holds particle `particle` of soft
/// body `object`, which another peer simulates. Sent unreliably to the object's owner
/// (relayed by the host, [`softsync_net::MessageTarget::OwnerOf`]) every step the hand holds
/// it, latest wins; the owner drives the particle toward `pos` as it drives its own hands'
/// particles. A release is sent three times (`release`, with the throw in `vel`); an owner that
/// hears nothing of a hand for [`REMOTE_HAND_TIMEOUT_S`] lets it go without a throw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RemoteHand {
    /// The soft body.
    pub object: NetId,
    /// The sender's hand: 0 left, 1 right.
    pub hand: u8,
    /// The sender's grab number for this hand (from 1, one per grab): the owner ignores a
    /// grab older than one it saw released.
    pub grab: u32,
    /// The particle held.
    pub particle: u32,
    /// The hand's position, room frame, metres.
    pub pos: [f32; 3],
    /// The hand's velocity, m/s (the throw, in a release).
    pub vel: [f32; 3],
    /// The hand let go.
    pub release: bool,
}

impl Message for RemoteHand {
    const NAME: &'static str = "softsync.hand";
}

/// A hand that goes silent this long is let go by the owner (its peer died, or the link did).
pub const REMOTE_HAND_TIMEOUT_S: f64 = 0.5;

/// The owner's answer to a new remote hand (reliable, to its sender): refused when the class
/// is `Locked`, when an `OwnerMustAgree` owner says no, or when the hand is malformed.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct HandAnswer {
    /// The soft body.
    pub object: NetId,
    /// The sender's hand.
    pub hand: u8,
    /// Its grab number.
    pub grab: u32,
    /// Taken (the owner drives the particle) or refused.
    pub accepted: bool,
}

impl Message for HandAnswer {
    const NAME: &'static str = "softsync.hand.answer";
}

/// One hand on a body: whose, which, on what particle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Holder {
    /// The peer whose hand it is.
    pub peer: PeerId,
    /// Its hand: 0 left, 1 right.
    pub hand: u8,
    /// The particle it holds (`u32::MAX`: the body's center or a rigid body).
    pub particle: u32,
}

/// Who holds an object, as its owner applies the hands (its own and remote ones): retained
/// per object ([`softsync_net::Delivery::ObjectState`]), so a late joiner knows too. Sent by
/// the owner whenever the set changes; taken only from the object's owner.
#[derive(Clone, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Holders {
    /// The hands, sorted.
    pub hands: Vec<Holder>,
}

impl Message for Holders {
    const NAME: &'static str = "softsync.holders";
}

/// What a blade does to a soft body, in the room frame (metres): a tear segment (the tip
/// moved `from` → `to`; `blade` runs from the tip to the blade's back end), the end of a
/// stroke, or a plane cut.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Blade {
    /// One segment of a stroke.
    Tear {
        /// Where the tip was.
        from: [f32; 3],
        /// Where it is.
        to: [f32; 3],
        /// From the tip to the blade's back end.
        blade: [f32; 3],
    },
    /// The scalpel lifted: the stroke ends.
    Lift,
    /// A plane cut through `point` with normal `normal`.
    Cut {
        /// A point of the plane.
        point: [f32; 3],
        /// Its normal.
        normal: [f32; 3],
    },
}

/// A peer that does not own a soft body cuts or tears it: its blade's actions, in order,
/// reliably to the body's owner (relayed by the host, [`softsync_net::MessageTarget::OwnerOf`]),
/// which turns them into the room's topology events as if its own scalpel made them (its
/// rest frame, its stroke). At most [`MAX_BLADE_ACTIONS`] per message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BladeRequest {
    /// The soft body.
    pub object: NetId,
    /// What the blade did, oldest first.
    pub actions: Vec<Blade>,
}

impl Message for BladeRequest {
    const NAME: &'static str = "softsync.blade";
}

/// The most blade actions one [`BladeRequest`] carries.
pub const MAX_BLADE_ACTIONS: usize = 32;

/// A recorded session played back as a room (`softsync replay --serve`): a spectator asks
/// its host to pause or go on, to seek, or to play at another speed. Sent reliably to the
/// host; what is not set stays as it is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReplayControl {
    /// Pause (true) or play on (false).
    pub pause: Option<bool>,
    /// Go to this many seconds into the recording.
    pub seek_s: Option<f64>,
    /// Play at this speed (1 real time; 0.1 to 16).
    pub speed: Option<f64>,
}

impl Message for ReplayControl {
    const NAME: &'static str = "softsync.replay_control";
}

/// Where a played-back recording stands, from its host, retained (a joiner has it at once)
/// and sent again at every change and once a second: for a spectator's timeline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReplayClock {
    /// Seconds into the recording shown now.
    pub t_s: f64,
    /// The recording's length, seconds.
    pub length_s: f64,
    /// Paused.
    pub paused: bool,
    /// The playback speed.
    pub speed: f64,
    /// The object a spectator's view follows (`softsync replay --as PEER`: that peer's
    /// head, as this room names it), if any.
    pub follow: Option<NetId>,
}

impl Message for ReplayClock {
    const NAME: &'static str = "softsync.replay_clock";
}

/// A peer's voice state, sent by the peer whenever it changes (`softsync_bevy::voice`) as its
/// head's object state: a joiner learns with the head who is muted and who speaks.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct VoiceState {
    /// Its microphone is muted.
    pub muted: bool,
    /// It is speaking now.
    pub speaking: bool,
}

impl Message for VoiceState {
    const NAME: &'static str = "softsync.voice_state";
}

/// Who a peer is to the others: the name and colour it chose at join (`softsync join --name
/// … --colour …`), sent as its head's object state (a joiner gets it with the head; it goes
/// with the head). Front ends draw the name above the head and the avatar in the colour.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Presence {
    /// A display name (at most [`Presence::MAX_NAME`] characters, no control characters).
    pub name: String,
    /// sRGB colour.
    pub colour: [u8; 3],
}

impl Message for Presence {
    const NAME: &'static str = "softsync.presence";
}

impl Presence {
    /// The longest name kept, in characters.
    pub const MAX_NAME: usize = 32;

    /// The same with the name cut to [`Presence::MAX_NAME`] characters and control
    /// characters dropped (what a receiver shows, whatever a sender wrote).
    pub fn sanitized(mut self) -> Self {
        self.name = self
            .name
            .chars()
            .filter(|c| !c.is_control())
            .take(Self::MAX_NAME)
            .collect::<String>()
            .trim()
            .to_owned();
        self
    }
}

/// The built-in message types ([`Say`], [`SignalingMoved`], [`RemoteHand`], [`HandAnswer`],
/// [`Holders`], [`BladeRequest`], [`ReplayControl`], [`ReplayClock`], [`VoiceState`],
/// [`Presence`]), in their fixed order; register yours after them.
pub fn builtin() -> MessageTypes {
    let mut t = MessageTypes::new();
    // A fresh table holds no name yet, so these cannot collide.
    let _ = t.register::<Say>();
    let _ = t.register::<SignalingMoved>();
    let _ = t.register::<RemoteHand>();
    let _ = t.register::<HandAnswer>();
    let _ = t.register::<Holders>();
    let _ = t.register::<BladeRequest>();
    let _ = t.register::<ReplayControl>();
    let _ = t.register::<ReplayClock>();
    let _ = t.register::<VoiceState>();
    let _ = t.register::<Presence>();
    t
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_builtin_table_starts_with_say_and_takes_an_applications_types_after_it() {
        #[derive(Serialize, Deserialize)]
        struct Valve(f32);
        impl Message for Valve {
            const NAME: &'static str = "valve";
        }
        let mut t = builtin();
        assert_eq!(t.kind::<Say>().map(|k| k.0), Some(0));
        assert_eq!(t.kind::<SignalingMoved>().map(|k| k.0), Some(1));
        assert_eq!(t.kind::<Holders>().map(|k| k.0), Some(4));
        assert_eq!(t.kind::<BladeRequest>().map(|k| k.0), Some(5));
        assert_eq!(t.kind::<ReplayClock>().map(|k| k.0), Some(7));
        assert_eq!(t.kind::<VoiceState>().map(|k| k.0), Some(8));
        assert_eq!(t.kind::<Presence>().map(|k| k.0), Some(9));
        assert_eq!(t.register::<Valve>().unwrap().0, 10);
        let p = Presence {
            name: format!("  Dr\u{7}. Lee{}", "x".repeat(100)),
            colour: [1, 2, 3],
        }
        .sanitized();
        assert!(p.name.starts_with("Dr. Lee") && p.name.chars().count() <= Presence::MAX_NAME);
        assert!(t.register::<Say>().is_err());
    }
}
