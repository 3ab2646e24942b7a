//! The signaling server's refusals, as a client sees them (websocket on loopback only: no
//! peer connections are made, so no WebRTC traffic).
// The server runs on real threads: polling it needs real sleeps.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::time::Duration;

use softsync_net::{Transport, PROTOCOL_VERSION};
use softsync_net_matchbox::{ConnectError, MatchboxConfig, MatchboxTransport, Role, SignalServer};

fn cfg(url: &str, room: &str, role: Role) -> MatchboxConfig {
    let mut c = MatchboxConfig::new(url, room, role);
    c.connect_timeout = Duration::from_secs(10);
    c
}

#[test]
fn refusals_are_typed_errors_with_clear_messages() {
    let server = SignalServer::start("127.0.0.1:0".parse().unwrap()).unwrap();
    let url = server.url();

    // Joining a room nobody is in.
    let e = MatchboxTransport::connect(&cfg(&url, "empty", Role::Join)).unwrap_err();
    assert!(matches!(e, ConnectError::RoomNotFound { .. }), "{e:?}");
    assert!(e.to_string().contains("room \"empty\" not found"), "{e}");

    // Another protocol version.
    let mut old = cfg(&url, "lab", Role::Host);
    old.protocol_version = PROTOCOL_VERSION.wrapping_add(7);
    let e = MatchboxTransport::connect(&old).unwrap_err();
    match &e {
        ConnectError::VersionMismatch { ours, theirs, .. } => {
            assert_eq!(*ours, PROTOCOL_VERSION.wrapping_add(7));
            assert_eq!(theirs, &PROTOCOL_VERSION.to_string());
        }
        other => panic!("{other:?}"),
    }
    assert!(e.to_string().contains("protocol version mismatch"), "{e}");

    // A host creates the room; the registry counts it; a second host is refused.
    let host = MatchboxTransport::connect(&cfg(&url, "lab", Role::Host)).unwrap();
    assert_ne!(host.local_id().0, 0);
    let mut seen = false;
    for _ in 0..200 {
        if server
            .rooms()
            .iter()
            .any(|r| r.name == "lab" && r.peers == 1)
        {
            seen = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(seen, "room not registered: {:?}", server.rooms());
    let e = MatchboxTransport::connect(&cfg(&url, "lab", Role::Host)).unwrap_err();
    assert!(matches!(e, ConnectError::RoomExists { .. }), "{e:?}");

    // The room disappears when its last socket leaves.
    drop(host);
    let mut gone = false;
    for _ in 0..300 {
        if server.rooms().is_empty() {
            gone = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(gone, "room still listed: {:?}", server.rooms());

    // Bad input never reaches the network.
    let e = MatchboxTransport::connect(&cfg(&url, "a/b", Role::Host)).unwrap_err();
    assert!(matches!(e, ConnectError::BadRoom(_)), "{e:?}");
    let e = MatchboxTransport::connect(&cfg("http://x", "lab", Role::Host)).unwrap_err();
    assert!(matches!(e, ConnectError::BadUrl(_)), "{e:?}");
}

#[test]
fn an_unreachable_server_is_reported_as_such() {
    // Bind and drop to get a port nothing listens on.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let e = MatchboxTransport::connect(&cfg(&format!("ws://127.0.0.1:{port}"), "lab", Role::Join))
        .unwrap_err();
    assert!(matches!(e, ConnectError::Unreachable { .. }), "{e:?}");
    assert!(e.to_string().contains("unreachable"), "{e}");
}

#[test]
fn a_busy_port_is_a_bind_error() {
    let s = SignalServer::start("127.0.0.1:0".parse().unwrap()).unwrap();
    let e = SignalServer::start(s.addr()).unwrap_err();
    assert!(e.to_string().contains("cannot listen on"), "{e}");
}

#[test]
fn limits_refuse_with_a_reason() {
    let limits = softsync_net_matchbox::SignalLimits {
        max_sockets: 2,
        max_per_room: 1,
        ..Default::default()
    };
    let server = SignalServer::start_with("127.0.0.1:0".parse().unwrap(), limits).unwrap();
    let url = server.url();
    let _a = MatchboxTransport::connect(&cfg(&url, "one", Role::Host)).unwrap();
    let e = MatchboxTransport::connect(&cfg(&url, "one", Role::Join)).unwrap_err();
    assert!(e.to_string().contains("room \"one\" is full"), "{e}");
    let _b = MatchboxTransport::connect(&cfg(&url, "two", Role::Host)).unwrap();
    let e = MatchboxTransport::connect(&cfg(&url, "three", Role::Host)).unwrap_err();
    assert!(e.to_string().contains("server is full"), "{e}");
}

/// A keyed server: a connection shows a fresh proof of the room's key (5 minutes, once); the
/// same URL again (a captured one), an old proof or a wrong key is refused with HTTP 403.
#[test]
fn a_keyed_server_takes_each_proof_once_and_refuses_stale_or_foreign_ones() {
    use softsync_net::RoomKey;
    let key = RoomKey::new(b"the lab's secret, 16 bytes or more", 1);
    let server = SignalServer::start_keyed(
        "127.0.0.1:0".parse().unwrap(),
        softsync_net_matchbox::SignalLimits::default(),
        Some(key.clone()),
    )
    .unwrap();
    let url = server.url();
    let mut open = Vec::new();
    let mut status = |u: &str| match tungstenite::connect(u) {
        Ok(ws) => {
            open.push(ws); // the room lives while its socket does
            101
        }
        Err(tungstenite::Error::Http(r)) => r.status().as_u16(),
        Err(e) => panic!("{e}"),
    };
    let mut host = cfg(&url, "lab", Role::Host);
    host.signal_key = Some(key.clone());
    let captured = host.room_url();
    assert_eq!(status(&captured), 101, "a fresh proof is let in");
    assert_eq!(status(&captured), 403, "the same URL again is refused");
    // the transport makes a fresh proof for every connection
    let mut join = cfg(&url, "lab", Role::Join);
    join.signal_key = Some(key.clone());
    let _a = MatchboxTransport::connect(&join).unwrap();
    let _b = MatchboxTransport::connect(&join).unwrap();
    // an old proof, another key's, or none
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    let base = format!("{url}/lab?softsync={PROTOCOL_VERSION}&role=join");
    let old = key.signal_proof("lab", now - 600, [1; 16]);
    assert_eq!(status(&format!("{base}&proof={old}")), 403);
    let other =
        RoomKey::new(b"somebody else's secret, 16+ bytes", 1).signal_proof("lab", now, [2; 16]);
    assert_eq!(status(&format!("{base}&proof={other}")), 403);
    assert_eq!(status(&base), 403);
    let mut keyless = cfg(&url, "lab", Role::Join);
    keyless.signal_key = None;
    let e = MatchboxTransport::connect(&keyless).unwrap_err();
    assert!(e.to_string().contains("needs its key"), "{e}");
}

/// Signaling over TLS: a server with a certificate speaks `wss://`; a client that trusts its
/// CA connects (and the server's refusals come through as before); one that does not is
/// refused by its own TLS check, with the reason.
#[test]
fn a_server_with_a_certificate_speaks_wss_to_clients_that_trust_it() {
    use softsync_net_matchbox::TlsIdentity;
    let data = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let id =
        TlsIdentity::from_pem_files(&data.join("server.pem"), &data.join("server.key")).unwrap();
    let server = SignalServer::start_secure(
        "127.0.0.1:0".parse().unwrap(),
        softsync_net_matchbox::SignalLimits::default(),
        None,
        Some(id),
    )
    .unwrap();
    let url = server.url();
    assert!(url.starts_with("wss://127.0.0.1:"), "{url}");
    let trusting = |room: &str, role: Role| {
        let mut c = cfg(&url, room, role);
        c.tls_ca = Some(data.join("ca.pem"));
        c
    };
    let e = MatchboxTransport::connect(&trusting("empty", Role::Join)).unwrap_err();
    assert!(matches!(e, ConnectError::RoomNotFound { .. }), "{e:?}");
    let host = MatchboxTransport::connect(&trusting("lab", Role::Host)).unwrap();
    assert_ne!(host.local_id().0, 0);
    // no CA given: the web's roots do not vouch for this certificate
    let e = MatchboxTransport::connect(&cfg(&url, "lab2", Role::Host)).unwrap_err();
    assert!(e.to_string().to_lowercase().contains("certificate"), "{e}");
    // a wrong file is a clear error before anything connects
    let mut bad = cfg(&url, "lab3", Role::Host);
    bad.tls_ca = Some(data.join("README.md"));
    let e = MatchboxTransport::connect(&bad).unwrap_err();
    assert!(matches!(e, ConnectError::Tls(_)), "{e:?}");
    assert!(
        TlsIdentity::from_pem_files(&data.join("ca.pem"), &data.join("ca.pem")).is_err(),
        "a certificate is no key"
    );
    drop(host);
    server.stop();
}
