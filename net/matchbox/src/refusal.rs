//! The server's refusals of a websocket upgrade, as [`ConnectError`]s: from matchbox's
//! socket (the transport) and from a bare websocket (the probe).

use matchbox_socket::SignalingError;

use crate::transport::{ConnectError, MatchboxConfig};
use crate::VERSION_HEADER;

/// The error for the server's HTTP answer `resp` to a websocket upgrade (status, body, and
/// the protocol version it names in [`VERSION_HEADER`]).
pub(crate) fn http_refusal(
    url: &str,
    room: &str,
    ours: u8,
    resp: &async_tungstenite::tungstenite::http::Response<Option<Vec<u8>>>,
) -> ConnectError {
    let body = resp
        .body()
        .as_ref()
        .map(|b| String::from_utf8_lossy(b).into_owned())
        .unwrap_or_default();
    let theirs = resp
        .headers()
        .get(VERSION_HEADER)
        .and_then(|v| v.to_str().ok())
        .map(str::to_owned);
    refusal(url, room, ours, resp.status().as_u16(), body, theirs)
}

/// The error for an HTTP refusal of the websocket upgrade: `status`, the server's `body`, and
/// the protocol version it named (`None`: no version header, not our server).
fn refusal(
    url: &str,
    room: &str,
    ours: u8,
    status: u16,
    body: String,
    theirs: Option<String>,
) -> ConnectError {
    let url = url.to_owned();
    match status {
        404 => ConnectError::RoomNotFound {
            room: room.to_owned(),
            url,
        },
        409 if body.contains("is full") => ConnectError::Refused { url, status, body },
        409 => ConnectError::RoomExists {
            room: room.to_owned(),
            url,
        },
        426 => ConnectError::VersionMismatch {
            ours,
            theirs: theirs.unwrap_or_else(|| "an unknown version".into()),
            url,
        },
        // Not our signaling server at all (no version header): say so.
        _ if theirs.is_none() => ConnectError::Refused {
            url,
            status,
            body: format!("{body} (not a softsync signaling server?)"),
        },
        _ => ConnectError::Refused { url, status, body },
    }
}

pub(crate) fn classify(err: &matchbox_socket::Error, cfg: &MatchboxConfig) -> ConnectError {
    let url = cfg.signal_url.clone();
    let sig = match err {
        matchbox_socket::Error::ConnectionFailed(s) | matchbox_socket::Error::Disconnected(s) => s,
    };
    let sig = match sig {
        SignalingError::NegotiationFailed(inner) => inner.as_ref(),
        other => other,
    };
    if let SignalingError::WebSocket(ws) = sig {
        if let async_tungstenite::tungstenite::Error::Http(resp) = ws {
            return http_refusal(&url, &cfg.room, cfg.protocol_version, resp);
        }
        return ConnectError::Unreachable {
            url,
            detail: ws.to_string(),
        };
    }
    ConnectError::Unreachable {
        url,
        detail: sig.to_string(),
    }
}
