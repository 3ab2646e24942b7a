#![allow(clippy::unwrap_used)]

use std::collections::VecDeque;
use std::time::Duration;

use proptest::prelude::*;

use super::*;
use crate::rng::SeededRng as SplitMix64;

const HOST: PeerId = PeerId(1);
const JOINER: PeerId = PeerId(2);

fn blob(n: usize, seed: u64) -> Vec<u8> {
    let mut r = SplitMix64::new(seed);
    (0..n).map(|_| r.next_u64() as u8).collect()
}

/// A fetch against a server over a link that loses, duplicates and reorders, on virtual time
/// in 5 ms steps; the outcome and the fetch's request count.
fn run(data: &[u8], seed: u64, loss: f64, max: u64) -> (Result<Vec<u8>, FetchError>, u64) {
    let mut rng = SplitMix64::new(seed);
    let mut server = BlobServer::new(data.to_vec());
    let mut fetch = BlobFetch::new(Instant::ZERO, HOST, max, Duration::from_secs(30));
    // (due, to server?, bytes)
    let mut wire: VecDeque<(Instant, bool, Vec<u8>)> = VecDeque::new();
    let mut now = Instant::ZERO;
    loop {
        if let Some(o) = fetch.outcome() {
            return (o, fetch.requests);
        }
        while let Some(t) = fetch.poll_transmit(now) {
            assert_eq!(t.to, HOST);
            wire.push_back((now, true, t.payload));
        }
        let mut later = VecDeque::new();
        while let Some((due, to_server, bytes)) = wire.pop_front() {
            if due > now {
                later.push_back((due, to_server, bytes));
                continue;
            }
            if rng.next_f64() < loss {
                continue;
            }
            // Reordering: a tenth of the datagrams wait another 20 ms; a twentieth twice over.
            if rng.next_f64() < 0.1 {
                later.push_back((now + Duration::from_millis(20), to_server, bytes.clone()));
                continue;
            }
            let copies = if rng.next_f64() < 0.05 { 2 } else { 1 };
            for _ in 0..copies {
                if to_server {
                    if let Some(t) = server.handle(now, JOINER, &bytes) {
                        later.push_back((now + Duration::from_millis(2), false, t.payload));
                    }
                } else {
                    fetch.handle(HOST, &bytes);
                }
            }
        }
        wire = later;
        now += Duration::from_millis(5);
    }
}

#[test]
fn a_blob_arrives_whole_and_verified_through_loss_reordering_and_duplicates() {
    let data = blob(100_000 + 17, 3);
    for (seed, loss) in [(1, 0.0), (2, 0.05), (3, 0.2)] {
        let (out, requests) = run(&data, seed, loss, 1 << 20);
        assert_eq!(out.unwrap(), data, "seed {seed}");
        let chunks = data.len().div_ceil(CHUNK_BYTES) as u64;
        if loss > 0.0 {
            assert!(requests > chunks, "lost chunks are asked for again");
        } else {
            assert_eq!(requests, chunks);
        }
    }
    // The empty blob and one of exactly one chunk.
    assert_eq!(run(&[], 4, 0.1, 10).0.unwrap(), Vec::<u8>::new());
    let one = blob(CHUNK_BYTES, 5);
    assert_eq!(run(&one, 6, 0.1, 1 << 20).0.unwrap(), one);
}

#[test]
fn a_blob_over_the_bound_is_refused_before_anything_is_allocated() {
    let (out, _) = run(&blob(5000, 1), 1, 0.0, 4999);
    assert_eq!(
        out.unwrap_err(),
        FetchError::TooLarge {
            total: 5000,
            max: 4999
        }
    );
    // A hostile chunk claiming an enormous blob.
    let mut f = BlobFetch::new(Instant::ZERO, HOST, 1 << 20, Duration::from_secs(5));
    let _ = f.poll_transmit(Instant::ZERO);
    let lie = ShareMsg::Chunk {
        digest: [0; 32],
        total: u64::MAX,
        offset: 0,
        data: &[1, 2, 3],
    };
    f.handle(HOST, &lie.encode());
    assert!(matches!(
        f.outcome(),
        Some(Err(FetchError::TooLarge { .. }))
    ));
}

#[test]
fn chunks_that_lie_about_the_blob_fail_the_fetch() {
    let data = blob(3000, 9);
    let good = sha256(&data);
    let chunk = |digest: [u8; 32], total: u64, offset: u64| {
        let start = offset as usize;
        let end = (start + CHUNK_BYTES).min(data.len());
        ShareMsg::Chunk {
            digest,
            total,
            offset,
            data: &data[start..end],
        }
        .encode()
    };
    // A wrong digest on every chunk: the whole blob does not match it.
    let mut f = BlobFetch::new(Instant::ZERO, HOST, 1 << 20, Duration::from_secs(5));
    for off in [0, 1024, 2048] {
        f.handle(HOST, &chunk([7; 32], 3000, off));
    }
    assert_eq!(
        f.outcome().unwrap().unwrap_err(),
        FetchError::DigestMismatch
    );
    // Another size halfway through.
    let mut f = BlobFetch::new(Instant::ZERO, HOST, 1 << 20, Duration::from_secs(5));
    f.handle(HOST, &chunk(good, 3000, 0));
    f.handle(HOST, &chunk(good, 3001, 1024));
    assert_eq!(f.outcome().unwrap().unwrap_err(), FetchError::Inconsistent);
    // Chunks from a stranger, misaligned or short are ignored; the honest ones complete it.
    let mut f = BlobFetch::new(Instant::ZERO, HOST, 1 << 20, Duration::from_secs(5));
    f.handle(PeerId(99), &chunk(good, 3000, 0));
    f.handle(HOST, &chunk(good, 3000, 0));
    let misaligned = ShareMsg::Chunk {
        digest: good,
        total: 3000,
        offset: 1,
        data: &data[1..1025],
    };
    f.handle(HOST, &misaligned.encode());
    let short = ShareMsg::Chunk {
        digest: good,
        total: 3000,
        offset: 1024,
        data: &data[1024..1030],
    };
    f.handle(HOST, &short.encode());
    assert_eq!(f.ignored, 3);
    assert!(f.outcome().is_none());
    f.handle(HOST, &chunk(good, 3000, 1024));
    f.handle(HOST, &chunk(good, 3000, 2048));
    assert_eq!(f.outcome().unwrap().unwrap(), data);
}

#[test]
fn a_peer_with_nothing_to_share_says_why_and_a_silent_one_times_out() {
    let mut server = BlobServer::unavailable("this peer runs a scene built in code");
    let mut f = BlobFetch::new(Instant::ZERO, HOST, 1 << 20, Duration::from_secs(5));
    let req = f.poll_transmit(Instant::ZERO).unwrap();
    let answer = server.handle(Instant::ZERO, JOINER, &req.payload).unwrap();
    f.handle(HOST, &answer.payload);
    assert_eq!(
        f.outcome().unwrap().unwrap_err(),
        FetchError::Unavailable("this peer runs a scene built in code".into())
    );
    let mut f = BlobFetch::new(Instant::ZERO, HOST, 1 << 20, Duration::from_secs(2));
    let mut now = Instant::ZERO;
    let mut asked = 0;
    while f.outcome().is_none() {
        while f.poll_transmit(now).is_some() {
            asked += 1;
        }
        now += Duration::from_millis(50);
    }
    assert!(matches!(
        f.outcome(),
        Some(Err(FetchError::TimedOut(_, 0, 0)))
    ));
    // Asked again every retry interval, one request at a time (the size is unknown).
    assert!((5..=8).contains(&asked), "{asked}");
}

#[test]
fn a_server_answers_a_flood_within_its_rate_and_ignores_junk() {
    let data = blob(50_000, 1);
    let mut s = BlobServer::new(data);
    let req = ShareMsg::Request {
        offset: 0,
        len: 1 << 30,
        proof: None,
        token: None,
    }
    .encode();
    let mut bytes = 0;
    for _ in 0..20_000 {
        if let Some(t) = s.handle(Instant::ZERO, JOINER, &req) {
            let ShareMsg::Chunk { data, .. } = ShareMsg::decode(&t.payload).unwrap() else {
                panic!("not a chunk")
            };
            assert!(t.payload.len() <= CHUNK_BYTES + 48);
            bytes += data.len();
        }
    }
    // One second's budget at once, then nothing until time passes.
    assert!(bytes as f64 <= SERVE_BYTES_PER_S, "{bytes}");
    assert!(
        bytes as f64 >= SERVE_BYTES_PER_S - CHUNK_BYTES as f64,
        "{bytes}"
    );
    assert!(s.refused > 10_000);
    let later = Instant::ZERO + Duration::from_millis(100);
    assert!(s.handle(later, JOINER, &req).is_some());
    // Another requester has its own budget.
    assert!(s.handle(Instant::ZERO, PeerId(5), &req).is_some());
    // Past the end, junk, and a chunk sent to a server.
    let past = ShareMsg::Request {
        offset: 50_000,
        len: 10,
        proof: None,
        token: None,
    };
    assert!(s.handle(later, PeerId(6), &past.encode()).is_none());
    assert!(s.handle(later, PeerId(6), &[SHARE_MARKER, 9, 9]).is_none());
    assert!(s.handle(later, PeerId(6), &[]).is_none());
}

#[test]
fn reasons_are_cut_on_a_character_boundary() {
    let why = "é".repeat(150); // 300 bytes
    let bytes = ShareMsg::Unavailable(why).encode();
    assert!(bytes.len() <= 2 + MAX_REASON);
    let ShareMsg::Unavailable(back) = ShareMsg::decode(&bytes).unwrap() else {
        panic!()
    };
    assert_eq!(back, "é".repeat(100));
}

proptest! {
    #[test]
    fn decoding_any_bytes_never_panics_and_what_decodes_encodes_back(
        body in proptest::collection::vec(any::<u8>(), 0..1200),
        kind in 0u8..5,
    ) {
        let mut bytes = vec![SHARE_MARKER, kind];
        bytes.extend_from_slice(&body);
        if let Ok(m) = ShareMsg::decode(&bytes) {
            let again = m.encode();
            prop_assert_eq!(ShareMsg::decode(&again).unwrap(), m);
        }
        let _ = ShareMsg::decode(&body);
        let mut f = BlobFetch::new(Instant::ZERO, HOST, 1 << 16, Duration::from_secs(1));
        f.handle(HOST, &bytes);
        let mut s = BlobServer::new(vec![1; 3000]);
        let _ = s.handle(Instant::ZERO, JOINER, &bytes);
    }
}

#[test]
fn a_room_with_a_key_shares_its_scene_only_with_a_keyholder() {
    let key = RoomKey::new(b"the room's secret", 1);
    let other = RoomKey::new(b"another secret", 1);
    let data = blob(2500, 8);
    let mut server = BlobServer::new(data.clone()).with_key(Some(key.clone()), HOST);
    let fetch_with = |k: Option<&RoomKey>, me: PeerId, server: &mut BlobServer| {
        let mut f =
            BlobFetch::new(Instant::ZERO, HOST, 1 << 20, Duration::from_secs(5)).with_key(k, me);
        let mut now = Instant::ZERO;
        loop {
            if let Some(o) = f.outcome() {
                return o;
            }
            while let Some(t) = f.poll_transmit(now) {
                if let Some(a) = server.handle(now, me, &t.payload) {
                    f.handle(HOST, &a.payload);
                }
            }
            now += Duration::from_millis(10);
        }
    };
    assert_eq!(fetch_with(Some(&key), JOINER, &mut server).unwrap(), data);
    for (k, why) in [(None, "no key"), (Some(&other), "another key")] {
        let e = fetch_with(k, JOINER, &mut server).unwrap_err();
        assert!(
            matches!(&e, FetchError::Unavailable(r) if r.contains("needs its key")),
            "{why}: {e}"
        );
    }
    // A proof is bound to the requester: another peer replaying it is refused.
    let stolen = key.scene_proof(JOINER, HOST);
    let req = ShareMsg::Request {
        offset: 0,
        len: 1024,
        proof: Some(stolen),
        token: None,
    }
    .encode();
    let a = server.handle(Instant::ZERO, PeerId(77), &req).unwrap();
    assert!(matches!(
        ShareMsg::decode(&a.payload).unwrap(),
        ShareMsg::Unavailable(_)
    ));
    // A request with a proof of the wrong length does not decode.
    let mut bad = ShareMsg::Request {
        offset: 0,
        len: 1024,
        proof: None,
        token: None,
    }
    .encode();
    bad.extend_from_slice(&[0; 31]);
    assert!(ShareMsg::decode(&bad).is_err());
}

#[test]
fn a_member_names_the_host_and_sends_nothing_of_the_scene() {
    const MEMBER: PeerId = PeerId(3);
    let mut fetch = BlobFetch::new(Instant::ZERO, MEMBER, 1 << 20, Duration::from_secs(5));
    let req = fetch.poll_transmit(Instant::ZERO).unwrap();
    assert_eq!(req.to, MEMBER);
    let a = ask_host(JOINER, &req.payload, HOST).unwrap();
    assert_eq!(a.to, JOINER);
    assert_eq!(
        ShareMsg::decode(&a.payload).unwrap(),
        ShareMsg::AskHost(HOST)
    );
    fetch.handle(MEMBER, &a.payload);
    assert_eq!(fetch.outcome(), Some(Err(FetchError::AskHost(HOST))));
    // only a request is answered so; a cut or padded answer does not decode
    assert!(ask_host(JOINER, &a.payload, HOST).is_none());
    assert!(ShareMsg::decode(&a.payload[..5]).is_err());
    let mut long = a.payload.clone();
    long.push(0);
    assert!(ShareMsg::decode(&long).is_err());
    // then the host, asked, serves the verified blob
    let data = blob(5000, 3);
    assert_eq!(run(&data, 1, 0.0, 1 << 20).0.unwrap(), data);
}
