//! Tests of join tokens, the scene served to them and signaling proofs (`access.rs`).
#![allow(clippy::unwrap_used)]
use super::super::testkit::{config, Wire};
use super::super::Event;
use super::*;

const SECRET: &[u8] = b"the lab's room secret, 16+ bytes";
/// The hosts' wall clock at their time zero.
const T0: u64 = 1_800_000_000;

fn key(seed: u64) -> RoomKey {
    RoomKey::new(SECRET, seed).for_room("lab").with_clock(T0)
}

fn host_cfg(seed: u64) -> crate::SessionConfig {
    let mut c = config();
    c.room_key = Some(key(seed));
    c
}

fn token_cfg(t: &RoomToken) -> crate::SessionConfig {
    let mut c = config();
    c.room_token = Some(t.clone());
    c
}

fn refusal(w: &mut Wire, p: u64) -> Option<String> {
    w.events(p).into_iter().find_map(|e| match e {
        Event::Refused { reason } => Some(reason),
        _ => None,
    })
}

#[test]
fn a_token_admits_one_peer_that_may_come_back_and_nobody_else() {
    let t = key(9).issue_token(T0 + 3600, [1; 16]).unwrap();
    // the text form round-trips
    assert_eq!(t.to_string().parse::<RoomToken>().unwrap(), t);
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), host_cfg(1), w.now));
    w.add(Session::join(PeerId(2), PeerId(1), token_cfg(&t), w.now));
    w.settle();
    assert!(w.get(2).is_connected());
    // another peer with the same token (stolen, or shared): refused
    w.add(Session::join(PeerId(3), PeerId(1), token_cfg(&t), w.now));
    w.settle();
    let r = refusal(&mut w, 3).unwrap();
    assert!(r.contains("used by another peer"), "{r}");
    // peer 2 comes back with a fresh session and the same token: in again
    w.peers.remove(&PeerId(2));
    for _ in 0..30 {
        w.now += std::time::Duration::from_millis(100);
        let now = w.now;
        w.get(1).handle_timeout(now);
        w.settle();
    }
    w.add(Session::join(PeerId(2), PeerId(1), token_cfg(&t), w.now));
    w.settle();
    let ev = w.events(2);
    assert!(w.get(2).is_connected(), "{ev:?} {:?}", w.get(1).members());
    assert_eq!(w.get(1).members().len(), 2);
}

#[test]
fn an_expired_foreign_or_forged_token_is_refused_with_its_reason() {
    let good = key(9).issue_token(T0 + 3600, [2; 16]).unwrap();
    let expired = key(9).issue_token(T0 - 1, [3; 16]).unwrap();
    let other_room = RoomKey::new(SECRET, 9)
        .for_room("kitchen")
        .issue_token(T0 + 3600, [4; 16])
        .unwrap();
    let other_key = RoomKey::new(b"another secret of 16+ bytes", 9)
        .for_room("lab")
        .issue_token(T0 + 3600, [5; 16])
        .unwrap();
    let mut forged = good.clone();
    forged.expires_unix += 86_400; // a longer life, same signature
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), host_cfg(1), w.now));
    for (p, t, why) in [
        (2, &expired, "expired"),
        (3, &other_room, "not this room's"),
        (4, &other_key, "not this room's"),
        (5, &forged, "not this room's"),
    ] {
        w.add(Session::join(PeerId(p), PeerId(1), token_cfg(t), w.now));
        w.settle();
        let r = refusal(&mut w, p).unwrap_or_default();
        assert!(r.contains(why), "peer {p}: {r:?}");
    }
    assert_eq!(w.get(1).members().len(), 1);
    // a host whose key has no clock takes no tokens at all
    let mut w = Wire::new();
    let mut c = config();
    c.room_key = Some(RoomKey::new(SECRET, 1).for_room("lab"));
    w.add(Session::host(PeerId(1), c, w.now));
    w.add(Session::join(PeerId(2), PeerId(1), token_cfg(&good), w.now));
    w.settle();
    assert!(refusal(&mut w, 2).unwrap().contains("no clock"));
}

#[test]
fn a_signaling_proof_is_bound_to_room_key_and_time_and_tells_what_is_wrong() {
    let k = key(1);
    let p = k.signal_proof("lab", T0, [3; 16]);
    assert_eq!(
        k.check_signal_proof("lab", &p, T0 + 10),
        Ok(([3; 16], T0 + SIGNAL_PROOF_LIFETIME_S))
    );
    // another seed, the same secret: the same verdict
    assert!(key(2).check_signal_proof("lab", &p, T0).is_ok());
    assert_eq!(
        k.check_signal_proof("kitchen", &p, T0),
        Err("wrong room key")
    );
    let other = RoomKey::new(b"another secret of 16+ bytes", 1);
    assert_eq!(
        other.check_signal_proof("lab", &p, T0),
        Err("wrong room key")
    );
    let late = k.check_signal_proof("lab", &p, T0 + SIGNAL_PROOF_LIFETIME_S);
    assert!(late.unwrap_err().contains("expired"));
    let ahead = k.signal_proof("lab", T0 + 3600, [3; 16]);
    assert!(k
        .check_signal_proof("lab", &ahead, T0)
        .unwrap_err()
        .contains("future"));
    // a longer life under the same MAC, or a changed nonce: wrong
    let (e, rest) = p.split_once('.').unwrap();
    let longer = format!("{}.{rest}", e.parse::<u64>().unwrap() + 100);
    assert_eq!(
        k.check_signal_proof("lab", &longer, T0),
        Err("wrong room key")
    );
    for bad in [
        "",
        "1.2",
        "x.y.z",
        "1.2.3.4",
        &p[..p.len() - 2],
        &format!("{p}ff"),
    ] {
        assert!(k.check_signal_proof("lab", bad, T0).is_err(), "{bad:?}");
    }
}

#[test]
fn the_scene_goes_to_a_token_only_while_the_host_would_admit_it() {
    use crate::share::{BlobServer, ShareMsg, NEEDS_KEY};
    let t = key(9).issue_token(T0 + 3600, [7; 16]).unwrap();
    let expired = key(9).issue_token(T0 - 1, [8; 16]).unwrap();
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), host_cfg(1), w.now));
    w.add(Session::join(PeerId(2), PeerId(1), token_cfg(&t), w.now));
    w.settle();
    assert!(w.get(2).is_connected());
    let now = w.now;
    let mut server = BlobServer::new(vec![7; 3000]).with_key(Some(key(1)), PeerId(1));
    let ask = |t: &RoomToken| {
        ShareMsg::Request {
            offset: 0,
            len: 1024,
            proof: None,
            token: Some(t.clone()),
        }
        .encode()
    };
    let host = w.get(1);
    let mut answer = |from: u64, t: &RoomToken| {
        let p = PeerId(from);
        let d = server
            .handle_judged(now, p, &ask(t), |t| host.token_admits(t, p, now))
            .unwrap();
        matches!(
            ShareMsg::decode(&d.payload).unwrap(),
            ShareMsg::Chunk { .. }
        )
    };
    // the peer that used it: served; another peer with it, or an expired one: not
    assert!(answer(2, &t));
    assert!(!answer(3, &t));
    assert!(!answer(4, &expired));
    let no = server
        .handle_judged(now, PeerId(3), &ask(&t), |t| {
            host.token_admits(t, PeerId(3), now)
        })
        .unwrap();
    assert_eq!(
        ShareMsg::decode(&no.payload).unwrap(),
        ShareMsg::Unavailable(format!(
            "{}the join token was used by another peer",
            crate::share::TOKEN_REFUSED
        ))
    );
    let forged = RoomKey::new(b"another secret, 16 bytes or more", 1)
        .for_room("lab")
        .issue_token(T0 + 3600, [7; 16])
        .unwrap();
    let no = server.handle(now, PeerId(3), &ask(&forged)).unwrap();
    assert_eq!(
        ShareMsg::decode(&no.payload).unwrap(),
        ShareMsg::Unavailable(NEEDS_KEY.into())
    );
    // the plain handle takes the signature alone (a server outside any session)
    assert!(server.handle(now, PeerId(3), &ask(&t)).is_some());
}

#[test]
fn a_host_full_of_valid_tokens_takes_no_new_one_and_forgets_none() {
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), host_cfg(1), w.now));
    let now = w.now;
    for i in 0..MAX_TOKENS_USED as u64 {
        let mut n = [0u8; 16];
        n[..8].copy_from_slice(&i.to_le_bytes());
        w.get(1)
            .note_token_used(now, n, PeerId(1000 + i), T0 + 3600);
    }
    let t = key(9).issue_token(T0 + 3600, [9; 16]).unwrap();
    w.add(Session::join(PeerId(2), PeerId(1), token_cfg(&t), w.now));
    w.settle();
    let r = refusal(&mut w, 2).unwrap_or_default();
    assert!(r.contains("as many join tokens"), "{r:?}");
    assert_eq!(w.get(1).challenges.tokens_used.len(), MAX_TOKENS_USED);
    // once some have expired, a new one is taken (the expired ones forgotten)
    let later = T0 + 3601;
    let mut w2 = Wire::new();
    w2.add(Session::host(PeerId(1), host_cfg(1), w2.now));
    let now = w2.now;
    for i in 0..MAX_TOKENS_USED as u64 {
        let mut n = [0u8; 16];
        n[..8].copy_from_slice(&i.to_le_bytes());
        let exp = if i % 2 == 0 { T0 + 1 } else { later + 3600 };
        w2.get(1).note_token_used(now, n, PeerId(1000 + i), exp);
    }
    w2.now += std::time::Duration::from_secs(2);
    w2.add(Session::join(PeerId(2), PeerId(1), token_cfg(&t), w2.now));
    w2.settle();
    assert!(w2.get(2).is_connected(), "{:?}", refusal(&mut w2, 2));
    assert_eq!(
        w2.get(1).challenges.tokens_used.len(),
        MAX_TOKENS_USED / 2 + 1
    );
}

#[test]
fn a_new_host_after_a_migration_refuses_a_replayed_token_and_a_token_holder_admits_nobody() {
    let t = key(9).issue_token(T0 + 3600, [6; 16]).unwrap();
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), host_cfg(1), w.now));
    w.add(Session::join(PeerId(2), PeerId(1), host_cfg(2), w.now)); // holds the key
    w.settle();
    w.add(Session::join(PeerId(3), PeerId(1), token_cfg(&t), w.now));
    w.settle();
    assert!(w.get(3).is_connected());
    // the host dies; peer 2 (the earliest joiner, with the key) takes over
    w.peers.remove(&PeerId(1));
    for _ in 0..30 {
        w.now += std::time::Duration::from_millis(100);
        let now = w.now;
        for s in w.peers.values_mut() {
            s.handle_timeout(now);
        }
        w.settle();
    }
    assert!(w.get(2).is_host());
    // the token peer 3 used does not admit peer 4 at the new host either
    w.add(Session::join(PeerId(4), PeerId(2), token_cfg(&t), w.now));
    w.settle();
    let r = refusal(&mut w, 4).unwrap();
    assert!(r.contains("used by another peer"), "{r}");
    // and a host that joined with a token (no key) admits nobody
    let mut w = Wire::new();
    w.add(Session::host(PeerId(1), token_cfg(&t), w.now));
    w.add(Session::join(PeerId(5), PeerId(1), config(), w.now));
    w.settle();
    assert!(refusal(&mut w, 5).unwrap().contains("holds no key"));
}
