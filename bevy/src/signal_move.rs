//! Following the room's signaling when a new host serves it: only the host's notice counts.

use softsync_net::PeerId;
use softsync_peer::messages::SignalingMoved;

/// Whether to follow a `SignalingMoved` notice from `from`: only the room's host (as this peer
/// knows it: a new host sends it right after its `NewHost`) says where the room's signaling
/// is, with a `ws://` or `wss://` URL. A member's own notice would move everyone's signaling
/// to a server of its choosing, where it could harvest the room's signaling proof.
pub(crate) fn signaling_move(
    notice: Result<SignalingMoved, softsync_net::MessageRefusal>,
    from: PeerId,
    host: Option<PeerId>,
) -> Result<String, String> {
    match notice {
        Ok(SignalingMoved { url }) if url.starts_with("ws://") || url.starts_with("wss://") => {
            if Some(from) == host {
                Ok(url)
            } else {
                Err(format!(
                    "a signaling notice from peer {} ignored: only the host ({}) says where the \
                     room's signaling is",
                    from.0,
                    host.map_or(0, |h| h.0)
                ))
            }
        }
        _ => Err(format!("a malformed signaling notice from peer {}", from.0)),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn notice(url: &str) -> Result<SignalingMoved, softsync_net::MessageRefusal> {
        Ok(SignalingMoved { url: url.into() })
    }

    #[test]
    fn only_the_host_moves_the_rooms_signaling() {
        let host = Some(PeerId(1));
        assert_eq!(
            signaling_move(notice("ws://192.0.2.7:3536"), PeerId(1), host),
            Ok("ws://192.0.2.7:3536".to_owned())
        );
        // a member's notice (it would send everyone to its own server)
        let e = signaling_move(notice("ws://198.51.100.9:3536"), PeerId(5), host).unwrap_err();
        assert!(e.contains("only the host"), "{e}");
        // not while we know no host, and never a URL of another scheme
        assert!(signaling_move(notice("ws://192.0.2.7:3536"), PeerId(1), None).is_err());
        assert!(signaling_move(notice("http://192.0.2.7"), PeerId(1), host).is_err());
        assert!(signaling_move(notice("wsx:evil"), PeerId(1), host).is_err());
    }
}
