//! `softsync-hostile`: a modified client for the abuse test and bench (issue 32). It enters a
//! room over real WebRTC as any peer would, then attacks its host in one of several ways. It is
//! built from the test crate only and is never part of the `softsync` binary users run.
//!
//! ```text
//! softsync-hostile --signal URL --room NAME --attack KIND [--seconds S] [--assets DIR]
//! ```
//! KIND:
//! - `hello-flood`: once a member, 80 `Hello`s every 10 ms (a whole snapshot each, if the host
//!   welcomed them all);
//! - `never-ack`: once a member, it stops reading (so acknowledges nothing) and keeps its
//!   heartbeats going: the host's reliable queue to it grows;
//! - `request-flood`: once a member, authority requests for every object at ten times the
//!   rate a member may make;
//! - `junk`: never joins; 2,000 datagrams a second of random bytes, unknown markers, cut
//!   session headers, share requests, and `Hello`s of a wrong configuration;
//! - `idents`: once a member, channel idents naming every other member and made-up ids, 200 a
//!   second;
//! - `beacons`: once a member, forged beacons of a bigger room with itself as host and forged
//!   epochs of a rollback room, 100 a second.
//!
//! It prints `hostile id N`, `joined` when the host welcomed it, `told: REASON` for a
//! refusal or drop notice it receives (the first five distinct reasons), and at the end how
//! many datagrams it sent and how many refusals came back. Exit 0 after `--seconds` (default 30), 2 on wrong arguments, 1 when it could not
//! connect.

// A process of its own, paced by the wall clock.
#![allow(clippy::disallowed_methods)]

use std::process::ExitCode;
use std::time::Duration;

use softsync_bevy::{connect, first_contact, Clock, Connected, RoomOptions};
use softsync_net::door::{self, Door};
use softsync_net::ids::{NetId, PeerId, Term};
use softsync_net::rng::SeededRng;
use softsync_net::wire::{
    decode_refusal, encode_beacon, Control, PacketHeader, RoomSummary, CHANNEL_IDENT,
    PROTOCOL_VERSION,
};
use softsync_net::{Event, Instant, Session, Transmit, Transport};
use softsync_peer::Scene;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Attack {
    HelloFlood,
    NeverAck,
    RequestFlood,
    Junk,
    Idents,
    Beacons,
}

impl Attack {
    fn parse(s: &str) -> Option<Attack> {
        Some(match s {
            "hello-flood" => Attack::HelloFlood,
            "never-ack" => Attack::NeverAck,
            "request-flood" => Attack::RequestFlood,
            "junk" => Attack::Junk,
            "idents" => Attack::Idents,
            "beacons" => Attack::Beacons,
            _ => return None,
        })
    }

    /// Whether it joins first.
    fn joins(self) -> bool {
        self != Attack::Junk
    }
}

struct Args {
    signal: String,
    room: String,
    attack: Attack,
    seconds: f64,
    assets: std::path::PathBuf,
}

fn args() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let (mut signal, mut room, mut attack, mut seconds) = (None, None, None, 30.0);
    let mut assets = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets"));
    while let Some(a) = it.next() {
        let mut val = || it.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--signal" => signal = Some(val()?),
            "--room" => room = Some(val()?),
            "--attack" => {
                let v = val()?;
                attack = Some(Attack::parse(&v).ok_or_else(|| format!("no attack {v:?}"))?);
            }
            "--seconds" => {
                seconds = val()?
                    .parse::<f64>()
                    .ok()
                    .filter(|s| s.is_finite() && *s > 0.0 && *s <= 3600.0)
                    .ok_or("--seconds takes 0-3600")?
            }
            "--assets" => assets = val()?.into(),
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    Ok(Args {
        signal: signal.ok_or("--signal URL is needed")?,
        room: room.ok_or("--room NAME is needed")?,
        attack: attack.ok_or("--attack KIND is needed")?,
        seconds,
        assets,
    })
}

fn main() -> ExitCode {
    let a = match args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    match run(&a) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}

fn run(a: &Args) -> Result<(), String> {
    let scene = Scene::by_name("thesis-room", &a.assets)?;
    let opts = RoomOptions::join(a.room.clone(), a.signal.clone());
    let cfg = opts.session_config(&scene).map_err(|e| e.to_string())?;
    let digest = cfg.digest();
    let Connected {
        mut transport,
        started,
        ..
    } = connect(&opts).map_err(|e| e.to_string())?;
    let me = transport.local_id();
    println!("hostile id {}", me.0);
    let contact = first_contact(&mut transport, &opts, started).map_err(|e| e.to_string())?;
    let clock = Clock::start();
    let mut session = Session::join(me, contact, cfg, clock.now());
    let mut rng = SeededRng::new(me.0);
    let mut told: Vec<String> = Vec::new();
    let (mut sent, mut joined, mut deaf) = (0u64, false, false);
    let mut refusals = 0u64;
    let mut last_attack = clock.now();
    let end = Duration::from_secs_f64(a.seconds);
    while clock.now().saturating_since(Instant::ZERO) < end {
        let now = clock.now();
        while let Some((from, bytes)) = transport.recv(now) {
            // every refusal or drop notice is reported, whatever else we do with it
            if door::classify(&bytes) == Door::Refusal {
                if let Some(r) = decode_refusal(&bytes) {
                    refusals += 1;
                    note(&mut told, r.reason);
                }
            }
            if a.attack.joins() && !deaf {
                session.handle_packet(now, from, &bytes);
            }
        }
        while transport.poll_peer_event().is_some() {}
        session.handle_timeout(now);
        while let Some(e) = session.poll_event() {
            match e {
                Event::Joined { .. } if !joined => {
                    joined = true;
                    println!("joined");
                }
                Event::Refused { reason } | Event::Dropped { reason, .. } => {
                    note(&mut told, reason)
                }
                _ => {}
            }
        }
        // attack every 10 ms
        if now.saturating_since(last_attack) >= Duration::from_millis(10) {
            last_attack = now;
            let host = session.host_id().unwrap_or(contact);
            let mut raw = Vec::new();
            match a.attack {
                _ if a.attack.joins() && !joined => {}
                Attack::HelloFlood => {
                    let hello = Control::Hello {
                        protocol: PROTOCOL_VERSION,
                        config_digest: digest,
                    };
                    for _ in 0..80 {
                        session.send_raw_control(now, host, &hello);
                    }
                }
                Attack::NeverAck => deaf = true,
                Attack::RequestFlood => {
                    // 600 a second, spread over the objects (60 a second is a member's rate)
                    let ids = session.object_ids();
                    for k in 0..6 {
                        let id = ids.get(k % ids.len().max(1)).copied().unwrap_or(NetId(1));
                        session.send_raw_control(now, host, &Control::AuthorityRequest { id });
                    }
                }
                Attack::Junk => {
                    for k in 0..20 {
                        raw.push(junk(&mut rng, k, digest));
                    }
                }
                Attack::Idents => {
                    let mut ids: Vec<PeerId> = session.members().keys().copied().collect();
                    ids.push(PeerId(rng.next_u64()));
                    for id in ids.into_iter().filter(|p| *p != me) {
                        let mut d = CHANNEL_IDENT.to_vec();
                        d.extend_from_slice(&id.0.to_le_bytes());
                        d.push(1);
                        raw.push(d);
                    }
                }
                Attack::Beacons => {
                    let header = PacketHeader {
                        term: Term(session.term().0.saturating_add(1)),
                        seq: 0,
                        time_ms: 0,
                    };
                    let forged = RoomSummary {
                        digest,
                        host: me,
                        host_join: 0,
                        members: 200,
                        tag: None,
                    };
                    raw.push(encode_beacon(&header, &forged));
                    // a rollback room's epoch datagram of a far epoch (a state-sync room
                    // drops it at its front door)
                    raw.push(vec![door::ROLLBACK, 1, 0xFF, 0xFF, 0xFF, 0x7F, 1, 2, 3]);
                }
            }
            for payload in raw {
                let to = if a.attack == Attack::Idents || a.attack == Attack::Junk {
                    contact
                } else {
                    host
                };
                transport.send(
                    now,
                    &Transmit {
                        to,
                        payload,
                        reliable: rng.next_u64() % 2 == 0,
                    },
                );
                sent += 1;
            }
        }
        if a.attack.joins() {
            while let Some(t) = session.poll_transmit(now) {
                transport.send(now, &t);
                sent += 1;
            }
        }
        if let Some(why) = transport.closed() {
            println!("signaling lost: {why}");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    println!("sent {sent} datagrams; {refusals} refusal datagrams received");
    Ok(())
}

/// Print a reason the first time (the first five distinct ones only).
fn note(told: &mut Vec<String>, reason: String) {
    if told.len() < 5 && !told.contains(&reason) {
        println!("told: {reason}");
        told.push(reason);
    }
}

/// One junk datagram of kind `k` (of several), as a stranger.
fn junk(rng: &mut SeededRng, k: usize, digest: u64) -> Vec<u8> {
    let len = 1 + (rng.next_u64() % 1100) as usize;
    let mut d: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
    match k % 5 {
        // random bytes under a random first byte
        0 => {}
        // a session header, then noise
        1 => d[0] = PROTOCOL_VERSION,
        // an unregistered marker
        2 => d[0] = 0xF6,
        // a scene-share request of the far end of a blob
        3 => {
            d = vec![door::SHARE, 1, 0xFF, 0xFF, 0xFF, 0x0F, 0x80, 0x08];
        }
        // a Hello of another configuration, in a whole datagram
        _ => {
            let mut s = Session::join(
                PeerId(rng.next_u64()),
                PeerId(1),
                Default::default(),
                Instant::ZERO,
            );
            let _ = digest;
            s.handle_timeout(Instant::ZERO);
            if let Some(t) = s.poll_transmit(Instant::ZERO) {
                d = t.payload;
            }
        }
    }
    d
}
