//! The signaling server under hostile input: connection floods, slow and junk requests,
//! websocket frames that break the rules, message floods and signals across rooms — each
//! bounded in count and time — while honest clients of a room keep signaling. The attackers
//! connect from 127.0.0.2, the honest clients from 127.0.0.1 (both loopback: nothing leaves
//! the machine).
// The server runs on real threads: the attacks wait on real sockets.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use softsync_net::rng::SeededRng;
use softsync_net::PROTOCOL_VERSION;
use softsync_net_matchbox::{ProbeEvent, Role, SignalLimits, SignalProbe, SignalServer};
use tungstenite::Message;

const ATTACKER: [u8; 4] = [127, 0, 0, 2];

fn limits() -> SignalLimits {
    SignalLimits {
        max_sockets: 64,
        max_per_source: 16,
        upgrade_timeout: Duration::from_secs(1),
        max_message_bytes: 16 * 1024,
        messages_per_s: 50,
        bytes_per_s: 64 * 1024,
        throttle_limit: Duration::from_secs(2),
        ..SignalLimits::default()
    }
}

/// A TCP connection to `to` from the attacker's address.
fn attacker_tcp(to: SocketAddr) -> std::io::Result<TcpStream> {
    let s = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None)?;
    s.bind(&SocketAddr::from((ATTACKER, 0)).into())?;
    s.connect_timeout(&to.into(), Duration::from_secs(2))?;
    let s: TcpStream = s.into();
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    Ok(s)
}

/// A websocket of the attacker's, upgraded for `room`.
fn attacker_ws(server: &SignalServer, room: &str, role: &str) -> tungstenite::WebSocket<TcpStream> {
    let url = format!(
        "{}/{room}?softsync={PROTOCOL_VERSION}&role={role}",
        server.url()
    );
    let tcp = attacker_tcp(server.addr()).unwrap();
    let (ws, _) = tungstenite::client(url.as_str(), tcp).unwrap();
    ws
}

/// Everything the server says until it closes the connection (within 5 s).
fn read_to_close(s: &mut TcpStream) -> (String, Duration) {
    let t = Instant::now();
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => out.extend_from_slice(&buf[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                panic!("the server kept the connection open for 5 s");
            }
            Err(_) => break, // reset: closed too
        }
    }
    (String::from_utf8_lossy(&out).into_owned(), t.elapsed())
}

/// Whether the server has closed `ws` (within 5 s).
fn closed(ws: &mut tungstenite::WebSocket<TcpStream>) -> bool {
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(5) {
        match ws.read() {
            Ok(Message::Close(_)) => return true,
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return false
            }
            Err(_) => return true,
        }
    }
    false
}

/// A masked websocket frame from a client.
fn frame(b0: u8, payload: &[u8], masked: bool) -> Vec<u8> {
    let n = payload.len();
    let m = if masked { 0x80 } else { 0 };
    let mut f = vec![b0];
    if n < 126 {
        f.push(m | n as u8);
    } else if n < 65536 {
        f.push(m | 126);
        f.extend_from_slice(&(n as u16).to_be_bytes());
    } else {
        f.push(m | 127);
        f.extend_from_slice(&(n as u64).to_be_bytes());
    }
    let key = [0x11, 0x22, 0x33, 0x44];
    if masked {
        f.extend_from_slice(&key);
        f.extend(payload.iter().enumerate().map(|(i, b)| b ^ key[i % 4]));
    } else {
        f.extend_from_slice(payload);
    }
    f
}

/// The honest pair signals both ways, each message arriving within `within`.
fn honest_pair_signals(h: &mut SignalProbe, j: &mut SignalProbe, tag: &str, within: Duration) {
    honest_pair_signals_counting(h, j, tag, within, &std::cell::Cell::new(0));
}

/// [`honest_pair_signals`], counting the spam the joiner hears on the way.
fn honest_pair_signals_counting(
    h: &mut SignalProbe,
    j: &mut SignalProbe,
    tag: &str,
    within: Duration,
    spam: &std::cell::Cell<usize>,
) {
    let (hid, jid) = (h.id().to_owned(), j.id().to_owned());
    let t = Instant::now();
    h.signal(&jid, &format!("h-{tag}")).unwrap();
    let got = j
        .wait_for(within, |e| {
            if matches!(e, ProbeEvent::Signal { data, .. } if data.contains("spam")) {
                spam.set(spam.get() + 1);
            }
            matches!(e, ProbeEvent::Signal { from, data } if *from == hid && data.contains(&format!("h-{tag}")))
        })
        .unwrap();
    assert!(
        got.is_some(),
        "{tag}: the joiner did not hear its host within {within:?}"
    );
    j.signal(&hid, &format!("j-{tag}")).unwrap();
    let got = h
        .wait_for(within, |e| {
            matches!(e, ProbeEvent::Signal { from, data } if *from == jid && data.contains(&format!("j-{tag}")))
        })
        .unwrap();
    assert!(
        got.is_some(),
        "{tag}: the host did not hear its joiner within {within:?}"
    );
    eprintln!(
        "{tag}: the honest pair signalled both ways in {:?}",
        t.elapsed()
    );
}

#[test]
fn hostile_connections_and_frames_are_bounded_and_the_honest_room_keeps_signalling() {
    let server = SignalServer::start_with("127.0.0.1:0".parse().unwrap(), limits()).unwrap();
    let base = server.url();
    let addr = server.addr();
    let t = Duration::from_secs(5);
    let mut h = SignalProbe::connect(&base, "lab", Role::Host, t).unwrap();
    let mut j = SignalProbe::connect(&base, "lab", Role::Join, t).unwrap();
    honest_pair_signals(&mut h, &mut j, "before", Duration::from_secs(2));

    // 1. A connection flood: 40 idle connections; 16 are let in (the per-address cap) and
    //    closed once the upgrade time is up, the rest refused with a reason at once.
    let mut flood: Vec<TcpStream> = (0..40).map(|_| attacker_tcp(addr).unwrap()).collect();
    std::thread::sleep(Duration::from_millis(200));
    let gs = server.gate_stats();
    assert_eq!(gs.refused_source, 24, "{gs:?}");
    // an honest newcomer from another address is not held up
    let t0 = Instant::now();
    let k = SignalProbe::connect(&base, "lab2", Role::Host, t).unwrap();
    assert!(t0.elapsed() < Duration::from_secs(1), "{:?}", t0.elapsed());
    let mut refused = 0;
    for s in &mut flood {
        let (said, took) = read_to_close(s);
        if said.contains("429 Too Many Requests") {
            assert!(
                said.contains("too many connections from 127.0.0.2"),
                "{said}"
            );
            refused += 1;
        } else {
            assert!(said.is_empty(), "{said}");
            assert!(took <= Duration::from_secs(2), "{took:?}");
        }
    }
    assert_eq!(refused, 24);
    drop(flood);
    k.close();

    // 2. Slow requests (a byte at a time) and junk: closed within the upgrade time, or
    //    answered 400 or 431.
    let mut slow: Vec<TcpStream> = (0..8).map(|_| attacker_tcp(addr).unwrap()).collect();
    for _ in 0..8 {
        for s in &mut slow {
            let _ = s.write_all(b"G");
        }
        std::thread::sleep(Duration::from_millis(150));
    }
    for s in &mut slow {
        let (said, _) = read_to_close(s);
        assert!(said.is_empty(), "{said}");
    }
    let mut s = attacker_tcp(addr).unwrap();
    s.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    let (said, _) = read_to_close(&mut s);
    assert!(said.starts_with("HTTP/1.1 400"), "{said}");
    assert!(said.contains("websocket upgrades only"), "{said}");
    let mut s = attacker_tcp(addr).unwrap();
    let mut big = b"GET /lab HTTP/1.1\r\nUpgrade: websocket\r\n".to_vec();
    while big.len() < 20_000 {
        big.extend_from_slice(b"X-Pad: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\r\n");
    }
    let _ = s.write_all(&big);
    let (said, _) = read_to_close(&mut s);
    assert!(said.starts_with("HTTP/1.1 431"), "{said}");
    let mut rng = SeededRng::new(20261128);
    for i in 0..12 {
        let mut s = attacker_tcp(addr).unwrap();
        let n = 1 + (rng.next_u64() % 4096) as usize;
        let mut junk: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
        if i % 3 == 0 {
            junk.extend_from_slice(b"\r\n\r\n"); // a head of junk: answered at once
        }
        let _ = s.write_all(&junk);
        let (said, _) = read_to_close(&mut s);
        assert!(said.is_empty() || said.starts_with("HTTP/1.1 4"), "{said}");
    }
    honest_pair_signals(&mut h, &mut j, "after junk", Duration::from_secs(2));

    // 3. Websocket frames that break the rules: unmasked, reserved opcode, a message over the
    //    limit (in one frame, and in fragments). Each connection is closed.
    for bytes in [
        frame(0x81, b"\"KeepAlive\"", false),
        frame(0x83, b"x", true),
        frame(0x82, &vec![7u8; 20_000], true),
        [
            frame(0x01, &[b'a'; 9000], true),
            frame(0x80, &[b'a'; 9000], true),
        ]
        .concat(),
    ] {
        let mut ws = attacker_ws(&server, "lab", "member");
        ws.get_mut().write_all(&bytes).unwrap();
        assert!(closed(&mut ws), "a bad frame was let through");
    }

    // 4. A message flood in the room: junk JSON and signals to the joiner, far faster than the
    //    rate. The gate throttles it (the joiner hears at most the burst and the rate), then
    //    closes it; the honest pair is not held up.
    let mut spam = attacker_ws(&server, "lab", "member");
    let jid = j.id().to_owned();
    let sent_from = Instant::now();
    let mut sent = 0;
    spam.get_mut().set_nonblocking(true).unwrap();
    let mut spam_alive = true;
    while sent_from.elapsed() < Duration::from_secs(3) && spam_alive {
        for _ in 0..50 {
            let text = if sent % 2 == 0 {
                "{\"Signal\":{\"receiver\":\"nope\"".to_owned()
            } else {
                format!("{{\"Signal\":{{\"receiver\":\"{jid}\",\"data\":\"spam\"}}}}")
            };
            match spam.write(Message::text(text)) {
                Ok(()) => sent += 1,
                Err(tungstenite::Error::Io(e)) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    break
                }
                Err(_) => {
                    spam_alive = false;
                    break;
                }
            }
        }
        let _ = spam.flush();
        std::thread::sleep(Duration::from_millis(5));
    }
    let seen = std::cell::Cell::new(0);
    honest_pair_signals_counting(
        &mut h,
        &mut j,
        "during the flood",
        Duration::from_secs(2),
        &seen,
    );
    let mut spam_heard = seen.get();
    let mut host_news = 0;
    let until = Instant::now() + Duration::from_secs(2);
    while Instant::now() < until {
        match j.next_event(Duration::from_millis(100)).unwrap() {
            Some(ProbeEvent::Signal { data, .. }) if data.contains("spam") => spam_heard += 1,
            Some(_) => host_news += 1,
            None => {}
        }
    }
    let gs = server.gate_stats();
    eprintln!("flood: sent {sent}, the joiner heard {spam_heard} (+{host_news} other); {gs:?}");
    assert!(sent > 1000, "the flood was not a flood: {sent}");
    assert!(gs.throttled >= 1 && gs.flood_dropped >= 1, "{gs:?}");
    // the burst is 500 messages, half of them signals, plus 50/s for the ~2.5 s of throttling
    assert!((1..=400).contains(&spam_heard), "{spam_heard}");
    drop(spam);

    // 5. A signal to another room's peer does not cross: matchbox isolates rooms.
    let mut outsider = attacker_ws(&server, "elsewhere", "host");
    let hid = h.id().to_owned();
    let msg = format!("{{\"Signal\":{{\"receiver\":\"{hid}\",\"data\":\"cross\"}}}}");
    outsider.send(Message::text(msg)).unwrap();
    let got = h
        .wait_for(
            Duration::from_millis(800),
            |e| matches!(e, ProbeEvent::Signal { data, .. } if data.contains("cross")),
        )
        .unwrap();
    assert!(got.is_none(), "a signal crossed rooms: {got:?}");

    // 6. Seeded random frames, well formed, of random JSON-ish text and bytes: the server
    //    drops what it cannot parse and stays up.
    let pieces = [
        "{",
        "}",
        "\"Signal\"",
        ":",
        "\"receiver\"",
        "\"data\"",
        &jid,
        ",",
        "null",
        "[",
        "]",
        "\"KeepAlive\"",
        "1e999",
        "\u{fffd}",
    ];
    for c in 0..4 {
        let mut ws = attacker_ws(&server, "lab", "member");
        for _ in 0..60 {
            let n = (rng.next_u64() % 12) as usize;
            let text: String = (0..n)
                .map(|_| pieces[(rng.next_u64() % pieces.len() as u64) as usize])
                .collect();
            let bytes = if c % 2 == 0 {
                frame(0x81, text.as_bytes(), true)
            } else {
                let raw: Vec<u8> = (0..(rng.next_u64() % 300))
                    .map(|_| rng.next_u64() as u8)
                    .collect();
                frame(0x82, &raw, true)
            };
            if ws.get_mut().write_all(&bytes).is_err() {
                break;
            }
        }
    }
    drop(outsider);
    honest_pair_signals(&mut h, &mut j, "after all", Duration::from_secs(2));

    // Every attacker's connection is gone; only the honest pair is left.
    let t0 = Instant::now();
    loop {
        let gs = server.gate_stats();
        let rooms = server.rooms();
        if gs.open == 2 && rooms.len() == 1 && rooms[0].peers == 2 {
            eprintln!("{gs:?}");
            assert!(gs.slow >= 8 + 16, "{gs:?}");
            assert!(gs.bad_request >= 2, "{gs:?}");
            assert!(gs.bad_frames >= 4, "{gs:?}");
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "attackers still counted: {gs:?} {rooms:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A websocket that goes silent is closed after the idle time; one that sends keep-alives is
/// not.
#[test]
fn a_silent_websocket_is_closed_after_the_idle_time() {
    let limits = SignalLimits {
        idle_timeout: Duration::from_millis(600),
        ..SignalLimits::default()
    };
    let server = SignalServer::start_with("127.0.0.1:0".parse().unwrap(), limits).unwrap();
    let mut quiet = attacker_ws(&server, "lab", "host");
    let mut chatty = attacker_ws(&server, "lab", "join");
    chatty
        .get_mut()
        .set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        chatty.send(Message::text("\"KeepAlive\"")).unwrap();
        let _ = chatty.read(); // NewPeer and the like
        std::thread::sleep(Duration::from_millis(150));
    }
    assert!(closed(&mut quiet), "the silent socket is still open");
    assert_eq!(server.gate_stats().idle_closed, 1);
    chatty.send(Message::text("\"KeepAlive\"")).unwrap();
    assert_eq!(server.rooms().iter().map(|r| r.peers).sum::<usize>(), 1);
}

/// The gate's refusal when the whole server is full arrives as a reason, not a reset.
#[test]
fn a_full_server_says_so() {
    let limits = SignalLimits {
        max_sockets: 2,
        ..SignalLimits::default()
    };
    let server = SignalServer::start_with("127.0.0.1:0".parse().unwrap(), limits).unwrap();
    let _a = attacker_tcp(server.addr()).unwrap();
    let _b = attacker_tcp(server.addr()).unwrap();
    std::thread::sleep(Duration::from_millis(100));
    let mut c = attacker_tcp(server.addr()).unwrap();
    let (said, _) = read_to_close(&mut c);
    assert!(said.starts_with("HTTP/1.1 503"), "{said}");
    assert!(said.contains("signaling server is full"), "{said}");
    assert!(
        said.contains(&format!("x-softsync-protocol: {PROTOCOL_VERSION}")),
        "{said}"
    );
    assert_eq!(server.gate_stats().refused_full, 1);
}
