//! [`WatchedSignaller`]: matchbox's websocket signaller, with a flag that says when the
//! signaling connection is lost. matchbox keeps a socket's data channels working after its
//! signaling server goes away but tells nobody; the transport reads this flag to register the
//! room with the next server (`MatchboxConfig::fallback_urls`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use async_tungstenite::smol::{connect_async_with_tls_connector, ConnectStream};
use async_tungstenite::tungstenite::Message as WsMessage;
use async_tungstenite::WebSocketStream;
use futures::StreamExt;
use matchbox_socket::async_trait::async_trait;
use matchbox_socket::{PeerEvent, PeerRequest, SignalingError, Signaller, SignallerBuilder};

/// Builds [`WatchedSignaller`]s that raise `lost` when their websocket ends.
#[derive(Clone, Default)]
pub(crate) struct WatchedBuilder {
    pub(crate) lost: Arc<AtomicBool>,
    /// What `wss://` trusts (`None`: the web's roots only).
    pub(crate) tls: Option<futures_rustls::TlsConnector>,
}

impl std::fmt::Debug for WatchedBuilder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WatchedBuilder")
            .field("lost", &self.lost)
            .finish()
    }
}

struct WatchedSignaller {
    ws: WebSocketStream<ConnectStream>,
    lost: Arc<AtomicBool>,
}

#[async_trait]
impl SignallerBuilder for WatchedBuilder {
    async fn new_signaller(
        &self,
        mut attempts: Option<u16>,
        room_url: String,
    ) -> Result<Box<dyn Signaller>, SignalingError> {
        // as matchbox's own: `attempts` tries 3 s apart, the last error as NegotiationFailed
        let ws = loop {
            let tried = connect_async_with_tls_connector(&room_url, self.tls.clone()).await;
            match tried.map_err(SignalingError::from) {
                Ok((ws, _)) => break ws,
                Err(e) => match attempts.as_mut() {
                    Some(a) if *a <= 1 => {
                        self.lost.store(true, Ordering::Release);
                        return Err(SignalingError::NegotiationFailed(Box::new(e)));
                    }
                    Some(a) => {
                        *a -= 1;
                        async_io::Timer::after(Duration::from_secs(3)).await;
                    }
                    None => {
                        async_io::Timer::after(Duration::from_secs(3)).await;
                    }
                },
            }
        };
        Ok(Box::new(WatchedSignaller {
            ws,
            lost: self.lost.clone(),
        }))
    }
}

#[async_trait]
impl Signaller for WatchedSignaller {
    async fn send(&mut self, request: PeerRequest) -> Result<(), SignalingError> {
        let text = serde_json::to_string(&request).map_err(|_| SignalingError::UnknownFormat)?;
        let r = self
            .ws
            .send(WsMessage::Text(text.into()))
            .await
            .map_err(SignalingError::from);
        if r.is_err() {
            self.lost.store(true, Ordering::Release);
        }
        r
    }

    async fn next_message(&mut self) -> Result<PeerEvent, SignalingError> {
        let text = match self.ws.next().await {
            Some(Ok(WsMessage::Text(t))) => t,
            Some(Ok(_)) => return Err(SignalingError::UnknownFormat),
            Some(Err(e)) => {
                self.lost.store(true, Ordering::Release);
                return Err(SignalingError::from(e));
            }
            None => {
                self.lost.store(true, Ordering::Release);
                return Err(SignalingError::StreamExhausted);
            }
        };
        serde_json::from_str(&text).map_err(|_| SignalingError::UnknownFormat)
    }
}
