//! The signaling server's front gate: every TCP connection to a [`SignalServer`] meets it
//! first, with TLS or without.
//!
//! matchbox's server (axum) listens on loopback only; the gate takes the public port and lets
//! through only what a signaling client sends, within bounds:
//! - at most [`SignalLimits::max_sockets`] connections at once, and
//!   [`SignalLimits::max_per_source`] from one address (more are closed at once);
//! - the TLS handshake (for `wss://`) and the HTTP upgrade request within
//!   [`SignalLimits::upgrade_timeout`], the request's head at most [`MAX_HEAD_BYTES`], and only
//!   a websocket upgrade (`GET` with `Upgrade: websocket`; anything else gets HTTP 400);
//! - then the client's websocket frames, read as they pass: masked (RFC 6455 §5.3), no
//!   reserved bits or opcodes, control frames short, a message at most
//!   [`SignalLimits::max_message_bytes`] — a connection that breaks a rule is closed;
//! - at most [`SignalLimits::messages_per_s`] messages and [`SignalLimits::bytes_per_s`]
//!   bytes per second per connection (ten seconds' worth in a burst): a faster client is
//!   throttled (its bytes wait), and one throttled for [`SignalLimits::throttle_limit`] in all
//!   is closed;
//! - a connection silent for [`SignalLimits::idle_timeout`] is closed (matchbox's sockets
//!   send a keep-alive every 10 s).
//!
//! The server's bytes to the client pass unchanged. What the gate refused or closed is
//! counted in [`GateStats`] ([`SignalServer::gate_stats`]). One thread runs every connection
//! (an async executor), so a flood of connections costs sockets, not threads.
//!
//! [`SignalServer`]: crate::SignalServer
//! [`SignalServer::gate_stats`]: crate::SignalServer::gate_stats

use std::cell::RefCell;
use std::collections::HashMap;
use std::future::Future;
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::rc::Rc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use async_io::{Async, Timer};
use futures::future::Either;
use futures::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use softsync_net::PROTOCOL_VERSION;

use crate::signal::SignalLimits;
use crate::VERSION_HEADER;

/// Longest HTTP request head (request line and headers) the gate reads.
pub const MAX_HEAD_BYTES: usize = 16 * 1024;

/// What the gate has let in, refused and closed since the server started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GateStats {
    /// Connections accepted (past the count limits).
    pub accepted: u64,
    /// Connections open now.
    pub open: u64,
    /// Closed at once: the server had [`SignalLimits::max_sockets`] connections.
    pub refused_full: u64,
    /// Closed at once: their address had [`SignalLimits::max_per_source`] connections.
    pub refused_source: u64,
    /// TLS handshakes that failed or were too slow.
    pub tls_failed: u64,
    /// Requests whose head did not arrive within [`SignalLimits::upgrade_timeout`].
    pub slow: u64,
    /// Requests that were not a websocket upgrade, or whose head was too long (answered
    /// with HTTP 400 or 431).
    pub bad_request: u64,
    /// Websocket connections closed for a frame that breaks the rules (unmasked, reserved
    /// bits or opcode, a long control frame, a message too long).
    pub bad_frames: u64,
    /// Connections that were throttled at least once.
    pub throttled: u64,
    /// Connections closed after [`SignalLimits::throttle_limit`] of throttling.
    pub flood_dropped: u64,
    /// Connections closed for silence.
    pub idle_closed: u64,
}

#[derive(Debug, Default)]
struct Counters {
    accepted: AtomicU64,
    open: AtomicU64,
    refused_full: AtomicU64,
    refused_source: AtomicU64,
    tls_failed: AtomicU64,
    slow: AtomicU64,
    bad_request: AtomicU64,
    bad_frames: AtomicU64,
    throttled: AtomicU64,
    flood_dropped: AtomicU64,
    idle_closed: AtomicU64,
}

fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

impl Counters {
    fn snapshot(&self) -> GateStats {
        let g = |c: &AtomicU64| c.load(Ordering::Relaxed);
        GateStats {
            accepted: g(&self.accepted),
            open: g(&self.open),
            refused_full: g(&self.refused_full),
            refused_source: g(&self.refused_source),
            tls_failed: g(&self.tls_failed),
            slow: g(&self.slow),
            bad_request: g(&self.bad_request),
            bad_frames: g(&self.bad_frames),
            throttled: g(&self.throttled),
            flood_dropped: g(&self.flood_dropped),
            idle_closed: g(&self.idle_closed),
        }
    }
}

/// The gate in front of one signaling server: runs until dropped.
#[derive(Debug)]
pub(crate) struct Gate {
    addr: SocketAddr,
    counters: Arc<Counters>,
    stop: Option<futures::channel::oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

struct Config {
    backend: SocketAddr,
    tls: Option<futures_rustls::TlsAcceptor>,
    limits: SignalLimits,
    counters: Arc<Counters>,
    per_source: RefCell<HashMap<IpAddr, usize>>,
}

impl Gate {
    /// Take `listener` (the public port) and pass what the rules allow to `backend`, over TLS
    /// when `tls` is given.
    pub(crate) fn start(
        listener: TcpListener,
        backend: SocketAddr,
        tls: Option<futures_rustls::TlsAcceptor>,
        limits: SignalLimits,
    ) -> std::io::Result<Self> {
        let addr = listener.local_addr()?;
        let listener = Async::new(listener)?;
        let counters = Arc::new(Counters::default());
        let (stop, stopped) = futures::channel::oneshot::channel::<()>();
        let c2 = counters.clone();
        let thread = std::thread::Builder::new()
            .name("signaling-gate".into())
            .spawn(move || {
                let cfg = Rc::new(Config {
                    backend,
                    tls,
                    limits,
                    counters: c2,
                    per_source: RefCell::new(HashMap::new()),
                });
                let ex = Rc::new(async_executor::LocalExecutor::new());
                let ex2 = ex.clone();
                async_io::block_on(ex.run(accept_loop(listener, cfg, ex2, stopped)));
                // dropping the executor closes every connection still open
            })?;
        Ok(Gate {
            addr,
            counters,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The public address.
    pub(crate) fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// What it has counted.
    pub(crate) fn stats(&self) -> GateStats {
        self.counters.snapshot()
    }
}

impl Drop for Gate {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

async fn accept_loop(
    listener: Async<TcpListener>,
    cfg: Rc<Config>,
    ex: Rc<async_executor::LocalExecutor<'static>>,
    mut stopped: futures::channel::oneshot::Receiver<()>,
) {
    loop {
        let accepted = {
            let accept = std::pin::pin!(listener.accept());
            match futures::future::select(accept, &mut stopped).await {
                Either::Left((r, _)) => r,
                Either::Right(_) => return,
            }
        };
        let (conn, from) = match accepted {
            Ok(x) => x,
            Err(_) => {
                // out of file descriptors, or the like: wait rather than spin
                Timer::after(Duration::from_millis(50)).await;
                continue;
            }
        };
        let c = &cfg.counters;
        if c.open.load(Ordering::Relaxed) >= cfg.limits.max_sockets as u64 {
            bump(&c.refused_full);
            let why = format!(
                "the signaling server is full ({} connections)\n",
                cfg.limits.max_sockets
            );
            refuse_now(&conn, cfg.tls.is_none(), "503 Service Unavailable", &why);
            continue;
        }
        {
            let mut per = cfg.per_source.borrow_mut();
            let n = per.entry(from.ip()).or_insert(0);
            if *n >= cfg.limits.max_per_source {
                bump(&c.refused_source);
                let why = format!(
                    "too many connections from {} ({} at once)\n",
                    from.ip(),
                    cfg.limits.max_per_source
                );
                refuse_now(&conn, cfg.tls.is_none(), "429 Too Many Requests", &why);
                continue;
            }
            *n += 1;
        }
        bump(&c.accepted);
        c.open.fetch_add(1, Ordering::Relaxed);
        let slot = Slot {
            cfg: cfg.clone(),
            ip: from.ip(),
        };
        ex.spawn(async move {
            serve(conn, &slot.cfg).await;
            drop(slot);
        })
        .detach();
    }
}

fn response(status: &str, body: &str) -> String {
    format!(
        "HTTP/1.1 {status}\r\nconnection: close\r\ncontent-type: text/plain\r\n{VERSION_HEADER}: {PROTOCOL_VERSION}\r\ncontent-length: {}\r\n\r\n{body}",
        body.len()
    )
}

/// Refuse a connection without waiting for it: on plain `ws://` the answer is written if the
/// socket's buffer takes it at once (a few hundred bytes always fit), then it is closed.
fn refuse_now(conn: &Async<TcpStream>, plain: bool, status: &str, body: &str) {
    if plain {
        use std::io::Write;
        let _ = conn.get_ref().write(response(status, body).as_bytes());
    }
}

/// One connection's place in the counts, given back however the connection ends.
struct Slot {
    cfg: Rc<Config>,
    ip: IpAddr,
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.cfg.counters.open.fetch_sub(1, Ordering::Relaxed);
        let mut per = self.cfg.per_source.borrow_mut();
        if let Some(n) = per.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                per.remove(&self.ip);
            }
        }
    }
}

/// `f`, or `None` if it takes longer than `d`.
async fn within<T>(d: Duration, f: impl Future<Output = T>) -> Option<T> {
    let f = std::pin::pin!(f);
    match futures::future::select(f, Timer::after(d)).await {
        Either::Left((v, _)) => Some(v),
        Either::Right(_) => None,
    }
}

async fn serve(conn: Async<TcpStream>, cfg: &Config) {
    let deadline = Instant::now() + cfg.limits.upgrade_timeout;
    match &cfg.tls {
        Some(acceptor) => match within(cfg.limits.upgrade_timeout, acceptor.accept(conn)).await {
            Some(Ok(tls)) => relay(tls, deadline, cfg).await,
            _ => bump(&cfg.counters.tls_failed),
        },
        None => relay(conn, deadline, cfg).await,
    }
}

async fn answer<S: AsyncWrite + Unpin>(client: &mut S, status: &str, body: &str) {
    let msg = response(status, body);
    let _ = within(Duration::from_secs(2), client.write_all(msg.as_bytes())).await;
    let _ = within(Duration::from_secs(1), client.flush()).await;
}

/// Whether a request head asks for a websocket upgrade with `GET`.
fn is_upgrade(head: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(head) else {
        return false;
    };
    let mut lines = text.split("\r\n");
    let first = lines.next().unwrap_or("");
    if !first.starts_with("GET /") || !first.ends_with(" HTTP/1.1") {
        return false;
    }
    lines.any(|l| {
        l.split_once(':').is_some_and(|(k, v)| {
            k.trim().eq_ignore_ascii_case("upgrade") && v.trim().eq_ignore_ascii_case("websocket")
        })
    })
}

fn find_end(head: &[u8]) -> Option<usize> {
    head.windows(4)
        .position(|w| w == b"\r\n\r\n")
        .map(|i| i + 4)
}

async fn relay<S: AsyncRead + AsyncWrite + Unpin>(mut client: S, deadline: Instant, cfg: &Config) {
    let c = &cfg.counters;
    let mut head = Vec::with_capacity(1024);
    let mut buf = vec![0u8; 16 * 1024];
    let end = loop {
        match find_end(&head) {
            Some(end) if end <= MAX_HEAD_BYTES => break end,
            None if head.len() <= MAX_HEAD_BYTES => {}
            _ => {
                bump(&c.bad_request);
                answer(
                    &mut client,
                    "431 Request Header Fields Too Large",
                    "softsync signaling: the request's head is too long\n",
                )
                .await;
                return;
            }
        }
        let left = deadline.saturating_duration_since(Instant::now());
        match within(left, client.read(&mut buf)).await {
            None => {
                bump(&c.slow);
                return;
            }
            Some(Ok(0)) | Some(Err(_)) => return,
            Some(Ok(n)) => head.extend_from_slice(&buf[..n]),
        }
    };
    if !is_upgrade(&head[..end]) {
        bump(&c.bad_request);
        answer(
            &mut client,
            "400 Bad Request",
            "softsync signaling takes websocket upgrades only (GET /ROOM with Upgrade: websocket)\n",
        )
        .await;
        return;
    }
    let Ok(mut backend) = Async::<TcpStream>::connect(cfg.backend).await else {
        answer(
            &mut client,
            "503 Service Unavailable",
            "softsync signaling is stopping\n",
        )
        .await;
        return;
    };
    if backend.write_all(&head[..end]).await.is_err() {
        return;
    }
    let early = head[end..].to_vec();
    drop(head);
    let (client_r, mut client_w) = client.split();
    let (backend_r, backend_w) = backend.split();
    let down = futures::io::copy(backend_r, &mut client_w);
    let up = pump_frames(client_r, backend_w, early, buf, cfg);
    let _ = futures::future::select(std::pin::pin!(down), std::pin::pin!(up)).await;
}

/// The client's bytes to the server, frame rules and rates checked on the way.
async fn pump_frames<R: AsyncRead + Unpin, W: AsyncWrite + Unpin>(
    mut r: R,
    mut w: W,
    early: Vec<u8>,
    mut buf: Vec<u8>,
    cfg: &Config,
) {
    let c = &cfg.counters;
    let l = &cfg.limits;
    let mut frames = FrameCheck::new(l.max_message_bytes as u64);
    let mut rate = Rate::new(l.messages_per_s, l.bytes_per_s, Instant::now());
    let mut throttled_for = Duration::ZERO;
    let mut first = Some(early);
    loop {
        let owned;
        let data: &[u8] = match first.take() {
            Some(e) if !e.is_empty() => {
                owned = e;
                &owned
            }
            _ => match within(l.idle_timeout, r.read(&mut buf)).await {
                None => {
                    bump(&c.idle_closed);
                    return;
                }
                Some(Ok(0)) | Some(Err(_)) => return,
                Some(Ok(n)) => &buf[..n],
            },
        };
        let messages = match frames.feed(data) {
            Ok(m) => m,
            Err(_) => {
                bump(&c.bad_frames);
                return;
            }
        };
        let wait = rate.charge(Instant::now(), messages, data.len());
        if !wait.is_zero() {
            if throttled_for.is_zero() {
                bump(&c.throttled);
            }
            throttled_for += wait;
            if throttled_for > l.throttle_limit {
                bump(&c.flood_dropped);
                return;
            }
            Timer::after(wait).await;
        }
        if w.write_all(data).await.is_err() {
            return;
        }
    }
}

/// Two token buckets, messages and bytes, each holding ten seconds' worth; they go into
/// debt, and the debt is the wait.
#[derive(Debug)]
struct Rate {
    per_s: [f64; 2],
    tokens: [f64; 2],
    at: Instant,
}

impl Rate {
    const BURST_S: f64 = 10.0;

    fn new(messages_per_s: u32, bytes_per_s: u32, now: Instant) -> Self {
        let per_s = [f64::from(messages_per_s), f64::from(bytes_per_s)];
        Rate {
            per_s,
            tokens: [per_s[0] * Self::BURST_S, per_s[1] * Self::BURST_S],
            at: now,
        }
    }

    /// Take `messages` and `bytes`; how long the sender must wait before they may pass.
    fn charge(&mut self, now: Instant, messages: u32, bytes: usize) -> Duration {
        let dt = now.saturating_duration_since(self.at).as_secs_f64();
        self.at = now;
        let mut wait: f64 = 0.0;
        for (i, cost) in [f64::from(messages), bytes as f64].into_iter().enumerate() {
            let cap = self.per_s[i] * Self::BURST_S;
            self.tokens[i] = (self.tokens[i] + dt * self.per_s[i]).min(cap) - cost;
            if self.tokens[i] < 0.0 {
                wait = wait.max(-self.tokens[i] / self.per_s[i].max(1.0));
            }
        }
        Duration::from_secs_f64(wait.min(60.0))
    }
}

/// Why a client's websocket frame is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FrameError {
    Unmasked,
    Reserved,
    BadControl,
    TooLong,
}

/// Reads the client's websocket frame headers as bytes pass (RFC 6455 §5.2), skipping
/// payloads.
#[derive(Debug)]
struct FrameCheck {
    max_message: u64,
    head: [u8; 14],
    have: usize,
    need: usize,
    payload_left: u64,
    message: u64,
}

impl FrameCheck {
    fn new(max_message: u64) -> Self {
        FrameCheck {
            max_message,
            head: [0; 14],
            have: 0,
            need: 2,
            payload_left: 0,
            message: 0,
        }
    }

    /// Check `data`, the next bytes from the client; the number of whole messages (and
    /// control frames) that ended in it.
    fn feed(&mut self, mut data: &[u8]) -> Result<u32, FrameError> {
        let mut messages = 0;
        while let Some((&b, rest)) = data.split_first() {
            if self.payload_left > 0 {
                let k = (self.payload_left.min(data.len() as u64)) as usize;
                self.payload_left -= k as u64;
                data = &data[k..];
                continue;
            }
            data = rest;
            self.head[self.have] = b;
            self.have += 1;
            if self.have == 2 {
                if self.head[1] & 0x80 == 0 {
                    return Err(FrameError::Unmasked);
                }
                let ext = match self.head[1] & 0x7f {
                    126 => 2,
                    127 => 8,
                    _ => 0,
                };
                self.need = 2 + ext + 4;
            }
            if self.have < self.need {
                continue;
            }
            let (b0, len7) = (self.head[0], self.head[1] & 0x7f);
            let len = match len7 {
                126 => u64::from(u16::from_be_bytes([self.head[2], self.head[3]])),
                127 => {
                    let mut x = [0u8; 8];
                    x.copy_from_slice(&self.head[2..10]);
                    u64::from_be_bytes(x)
                }
                n => u64::from(n),
            };
            let fin = b0 & 0x80 != 0;
            if b0 & 0x70 != 0 {
                return Err(FrameError::Reserved);
            }
            match b0 & 0x0f {
                0 => self.message = self.message.saturating_add(len),
                1 | 2 => self.message = len,
                8..=10 => {
                    if len > 125 || !fin {
                        return Err(FrameError::BadControl);
                    }
                }
                _ => return Err(FrameError::Reserved),
            }
            if self.message > self.max_message || len > self.max_message {
                return Err(FrameError::TooLong);
            }
            if fin {
                messages += 1; // a control frame counts as a message too
                if b0 & 0x0f <= 2 {
                    self.message = 0;
                }
            }
            self.payload_left = len;
            self.have = 0;
            self.need = 2;
        }
        Ok(messages)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn frame(b0: u8, payload: usize) -> Vec<u8> {
        let mut f = vec![b0];
        match payload {
            0..=125 => f.push(0x80 | payload as u8),
            126..=65535 => {
                f.push(0x80 | 126);
                f.extend_from_slice(&(payload as u16).to_be_bytes());
            }
            _ => {
                f.push(0x80 | 127);
                f.extend_from_slice(&(payload as u64).to_be_bytes());
            }
        }
        f.extend_from_slice(&[1, 2, 3, 4]);
        f.extend(std::iter::repeat_n(b'x', payload));
        f
    }

    #[test]
    fn whole_messages_are_counted_across_any_split_of_the_bytes() {
        let mut all = frame(0x81, 10);
        all.extend(frame(0x01, 200)); // a fragmented message: first part …
        all.extend(frame(0x89, 4)); // … a ping in between …
        all.extend(frame(0x80, 300)); // … and its end
        all.extend(frame(0x82, 70_000 / 2));
        for split in [1, 2, 3, 7, 64, 1000, all.len()] {
            let mut f = FrameCheck::new(64 * 1024);
            let n: u32 = all.chunks(split).map(|c| f.feed(c).unwrap()).sum();
            assert_eq!(n, 4, "split {split}"); // text, fragmented, ping, binary
        }
    }

    #[test]
    fn frames_that_break_the_rules_are_refused() {
        let mut f = FrameCheck::new(64 * 1024);
        assert_eq!(f.feed(&[0x81, 0x05]), Err(FrameError::Unmasked));
        let mut f = FrameCheck::new(64 * 1024);
        assert_eq!(f.feed(&frame(0xC1, 1)), Err(FrameError::Reserved));
        let mut f = FrameCheck::new(64 * 1024);
        assert_eq!(f.feed(&frame(0x83, 1)), Err(FrameError::Reserved));
        let mut f = FrameCheck::new(64 * 1024);
        assert_eq!(f.feed(&frame(0x89, 126)), Err(FrameError::BadControl));
        let mut f = FrameCheck::new(64 * 1024);
        assert_eq!(f.feed(&frame(0x81, 70_000)[..20]), Err(FrameError::TooLong));
        // the parts of a fragmented message add up
        let mut f = FrameCheck::new(1000);
        assert_eq!(f.feed(&frame(0x01, 600)), Ok(0));
        assert_eq!(f.feed(&frame(0x80, 600)[..8]), Err(FrameError::TooLong));
        // a length with its top bit set
        let mut f = FrameCheck::new(1000);
        let mut huge = vec![0x82, 0x80 | 127];
        huge.extend_from_slice(&u64::MAX.to_be_bytes());
        huge.extend_from_slice(&[0; 4]);
        assert_eq!(f.feed(&huge), Err(FrameError::TooLong));
    }

    #[test]
    fn the_rate_lets_a_burst_through_then_spaces_what_follows() {
        let t0 = Instant::now();
        let mut r = Rate::new(100, 1_000_000, t0);
        assert_eq!(r.charge(t0, 1000, 10), Duration::ZERO, "ten seconds' worth");
        let w = r.charge(t0, 50, 10);
        assert!((w.as_secs_f64() - 0.5).abs() < 1e-6, "{w:?}");
        // time pays the debt back
        assert_eq!(r.charge(t0 + Duration::from_secs(2), 0, 0), Duration::ZERO);
        let mut r = Rate::new(100, 1000, t0);
        let w = r.charge(t0, 1, 12_000);
        assert!(
            (w.as_secs_f64() - 2.0).abs() < 1e-6,
            "bytes count too: {w:?}"
        );
    }

    #[test]
    fn only_a_websocket_get_is_an_upgrade() {
        let ok = b"GET /lab?softsync=6 HTTP/1.1\r\nHost: x\r\nUpgrade: WebSocket\r\nConnection: Upgrade\r\n\r\n";
        assert!(is_upgrade(ok));
        assert!(!is_upgrade(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n"));
        assert!(!is_upgrade(
            b"POST /lab HTTP/1.1\r\nUpgrade: websocket\r\n\r\n"
        ));
        assert!(!is_upgrade(b"\xff\xfe junk\r\n\r\n"));
        assert_eq!(find_end(ok), Some(ok.len()));
    }
}
