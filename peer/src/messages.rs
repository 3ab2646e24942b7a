//! The message types every softsync room has, and the peer's side of application messages.
//!
//! An application registers its own types after [`builtin`]'s and configures the room with
//! the table ([`MessageTypes::configure`]) before it hosts or joins; the [`Peer`](crate::Peer)
//! reads the table back from its session, so [`Peer::send`](crate::Peer::send) and
//! [`Peer::decode`](crate::Peer::decode) take the types alone.

use serde::{Deserialize, Serialize};
pub use softsync_net::messages::{Message, MessageTypes, RegisterError};

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

/// The built-in message types ([`Say`], [`SignalingMoved`]), in their fixed order; register
/// yours after them.
pub fn builtin() -> MessageTypes {
    let mut t = MessageTypes::new();
    // A fresh table holds no name yet, so these cannot collide.
    let _ = t.register::<Say>();
    let _ = t.register::<SignalingMoved>();
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
        assert_eq!(t.register::<Valve>().unwrap().0, 2);
        assert!(t.register::<Say>().is_err());
    }
}
