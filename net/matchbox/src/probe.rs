//! A light signaling client: one websocket that speaks the room server's protocol (matchbox's
//! JSON events and requests) and nothing else — no WebRTC. For load tests of signaling (many
//! rooms through a load balancer, `softsync bench signal-lb`) and for checking which peers a
//! server puts in a room: a joiner that hears its host's `NewPeer`, or a signal relayed from
//! it, reached the server instance that holds the room.

use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde_json::Value;
use softsync_net::PROTOCOL_VERSION;
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

use crate::transport::Role;
use crate::{ConnectError, ROLE_PARAM, VERSION_PARAM};

/// What the server said, as the probe reads it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ProbeEvent {
    /// Another socket entered the room.
    NewPeer(String),
    /// A socket of the room went away.
    PeerLeft(String),
    /// A signal relayed from another socket of the room.
    Signal {
        /// Its matchbox id.
        from: String,
        /// What it sent.
        data: String,
    },
}

/// One signaling websocket of a room.
pub struct SignalProbe {
    ws: WebSocket<MaybeTlsStream<TcpStream>>,
    id: String,
    last_sent: Instant,
}

impl std::fmt::Debug for SignalProbe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SignalProbe").field("id", &self.id).finish()
    }
}

/// matchbox's sockets send a keep-alive this often.
const KEEP_ALIVE: Duration = Duration::from_secs(10);

impl SignalProbe {
    /// Connect to `base` (`ws://ADDR`) for `room` in `role` and wait (up to `timeout`) for the
    /// id the server assigns. Refusals are the same typed errors as the real transport's.
    pub fn connect(
        base: &str,
        room: &str,
        role: Role,
        timeout: Duration,
    ) -> Result<SignalProbe, ConnectError> {
        let base = base.trim_end_matches('/');
        if !base.starts_with("ws://") {
            return Err(ConnectError::BadUrl(base.to_owned()));
        }
        if !crate::valid_room_name(room) {
            return Err(ConnectError::BadRoom(room.to_owned()));
        }
        let url = format!(
            "{base}/{room}?{VERSION_PARAM}={PROTOCOL_VERSION}&{ROLE_PARAM}={}",
            role.as_param()
        );
        let unreachable = |detail: String| ConnectError::Unreachable {
            url: base.to_owned(),
            detail,
        };
        let (ws, _) = match tungstenite::connect(url.as_str()) {
            Ok(x) => x,
            Err(tungstenite::Error::Http(resp)) => {
                return Err(crate::refusal::http_refusal(
                    base,
                    room,
                    PROTOCOL_VERSION,
                    &resp,
                ));
            }
            Err(e) => return Err(unreachable(e.to_string())),
        };
        let mut probe = SignalProbe {
            ws,
            id: String::new(),
            last_sent: Instant::now(),
        };
        probe
            .set_read_timeout(Some(Duration::from_millis(50)))
            .map_err(|e| unreachable(e.to_string()))?;
        let start = Instant::now();
        while start.elapsed() < timeout {
            match probe.read_raw() {
                Ok(Some(v)) => {
                    if let Some(id) = v.get("IdAssigned").and_then(Value::as_str) {
                        probe.id = id.to_owned();
                        return Ok(probe);
                    }
                }
                Ok(None) => {}
                Err(e) => return Err(unreachable(e)),
            }
        }
        Err(ConnectError::Timeout {
            url: base.to_owned(),
            timeout,
        })
    }

    /// The id the server assigned (matchbox's UUID, as text).
    pub fn id(&self) -> &str {
        &self.id
    }

    fn set_read_timeout(&mut self, t: Option<Duration>) -> std::io::Result<()> {
        match self.ws.get_mut() {
            MaybeTlsStream::Plain(s) => s.set_read_timeout(t),
            _ => Ok(()),
        }
    }

    /// One JSON message, `None` when nothing came within the read timeout; `Err` when the
    /// socket is closed or broken.
    fn read_raw(&mut self) -> Result<Option<Value>, String> {
        match self.ws.read() {
            Ok(Message::Text(t)) => Ok(serde_json::from_str(t.as_str()).ok()),
            Ok(Message::Close(_)) => Err("the server closed the socket".into()),
            Ok(_) => Ok(None),
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e.to_string()),
        }
    }

    /// The next event within `within`: `Ok(None)` if none came; `Err` once the socket is
    /// closed (the server died or dropped us). Sends the keep-alive when it is due.
    pub fn next_event(&mut self, within: Duration) -> Result<Option<ProbeEvent>, String> {
        let start = Instant::now();
        loop {
            if self.last_sent.elapsed() > KEEP_ALIVE {
                self.send_raw("\"KeepAlive\"".into())?;
            }
            if let Some(v) = self.read_raw()? {
                let s = |k: &str| v.get(k).and_then(Value::as_str).map(str::to_owned);
                if let Some(p) = s("NewPeer") {
                    return Ok(Some(ProbeEvent::NewPeer(p)));
                }
                if let Some(p) = s("PeerLeft") {
                    return Ok(Some(ProbeEvent::PeerLeft(p)));
                }
                if let Some(sig) = v.get("Signal") {
                    let from = sig.get("sender").and_then(Value::as_str).unwrap_or("");
                    let data = sig.get("data").map(Value::to_string).unwrap_or_default();
                    return Ok(Some(ProbeEvent::Signal {
                        from: from.to_owned(),
                        data,
                    }));
                }
            }
            if start.elapsed() >= within {
                return Ok(None);
            }
        }
    }

    /// Wait up to `within` for an event `f` accepts (others are dropped).
    pub fn wait_for(
        &mut self,
        within: Duration,
        f: impl Fn(&ProbeEvent) -> bool,
    ) -> Result<Option<ProbeEvent>, String> {
        let start = Instant::now();
        while start.elapsed() < within {
            let left = within.saturating_sub(start.elapsed());
            if let Some(e) = self.next_event(left.min(Duration::from_millis(200)))? {
                if f(&e) {
                    return Ok(Some(e));
                }
            }
        }
        Ok(None)
    }

    /// Relay `data` (any JSON-safe text) to socket `to` of the same room.
    pub fn signal(&mut self, to: &str, data: &str) -> Result<(), String> {
        let msg = serde_json::json!({ "Signal": { "receiver": to, "data": data } });
        self.send_raw(msg.to_string())
    }

    fn send_raw(&mut self, text: String) -> Result<(), String> {
        self.last_sent = Instant::now();
        self.ws.send(Message::text(text)).map_err(|e| e.to_string())
    }

    /// Close the socket (the server sees the peer leave).
    pub fn close(mut self) {
        let _ = self.ws.close(None);
        let _ = self.ws.flush();
    }
}
