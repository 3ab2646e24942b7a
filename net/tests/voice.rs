//! Voice datagrams between real sessions of a room (virtual time): members hear each other
//! directly or through the host; strangers, forged relays, frames for a host that is not one,
//! lying lengths and floods are dropped and counted, and a flood is never relayed.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use softsync_net::harness::Harness;
use softsync_net::voice::{Heard, Route, VoiceDatagram, VoiceFrame, VoiceRouter, MAX_OPUS_BYTES};
use softsync_net::{ConditionerConfig, PeerId, Transmit};

fn frame(seq: u32, n: usize) -> VoiceFrame {
    VoiceFrame {
        seq,
        capture_ms: 1000 + seq * 20,
        level: 90,
        opus: vec![0x48; n],
        redundant: Vec::new(),
    }
}

/// Peer `i`'s router hears `bytes` from `from`: what it heard and what it relayed.
fn hear(
    h: &mut Harness,
    r: &mut VoiceRouter,
    i: usize,
    from: PeerId,
    bytes: &[u8],
) -> (Option<Heard>, Vec<Transmit>) {
    let now = h.now;
    let mut relay = Vec::new();
    let heard = r.handle(now, h.session(i), from, bytes, &mut relay);
    (heard, relay)
}

#[test]
fn members_are_heard_by_mesh_and_relay_and_everything_else_is_dropped_and_counted() {
    let mut h = room(3, ConditionerConfig::default());
    let host = h.host_index().unwrap();
    let (a, b) = {
        let others: Vec<usize> = (0..3).filter(|i| *i != host).collect();
        (others[0], others[1])
    };
    let id = |i: usize| h.peers[i].session.local_id();
    let (hid, aid, bid) = (id(host), id(a), id(b));

    // a speaks in a mesh: one copy to each other member
    let mut ra = VoiceRouter::default();
    let mut out = Vec::new();
    ra.send_frame(h.session(a), Route::Mesh, &frame(0, 60), &mut out);
    let mut to: Vec<PeerId> = out.iter().map(|t| t.to).collect();
    to.sort();
    let mut want = vec![hid, bid];
    want.sort();
    assert_eq!(to, want);
    assert!(out.iter().all(|t| !t.reliable));
    let mut rb = VoiceRouter::default();
    let (heard, relay) = hear(&mut h, &mut rb, b, aid, &out[0].payload);
    assert_eq!(
        heard,
        Some(Heard::Frame {
            speaker: aid,
            frame: frame(0, 60)
        })
    );
    assert!(relay.is_empty());

    // a speaks through the host: one copy, to the host, which plays it and relays it to b
    out.clear();
    ra.send_frame(h.session(a), Route::Relay, &frame(1, 60), &mut out);
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].to, hid);
    let mut rh = VoiceRouter::default();
    let (heard, relay) = hear(&mut h, &mut rh, host, aid, &out[0].payload);
    assert_eq!(
        heard,
        Some(Heard::Frame {
            speaker: aid,
            frame: frame(1, 60)
        })
    );
    assert_eq!(relay.len(), 1);
    assert_eq!(relay[0].to, bid);
    // b believes the host that a spoke
    let (heard, _) = hear(&mut h, &mut rb, b, hid, &relay[0].payload);
    assert_eq!(
        heard,
        Some(Heard::Frame {
            speaker: aid,
            frame: frame(1, 60)
        })
    );

    // hostile: a stranger's frame; a relay forged by a member (naming a as speaker); a relay
    // naming a stranger; a frame to relay sent to a member that is not the host; a relay
    // naming the listener itself; a lying length; an oversized payload
    let stranger = PeerId(0xBAD);
    let forged = VoiceDatagram::Relayed {
        speaker: aid,
        frame: frame(2, 40),
    }
    .encode();
    let of_stranger = VoiceDatagram::Relayed {
        speaker: stranger,
        frame: frame(3, 40),
    }
    .encode();
    let to_relay = VoiceDatagram::ToRelay(frame(4, 40)).encode();
    let of_self = VoiceDatagram::Relayed {
        speaker: bid,
        frame: frame(5, 40),
    }
    .encode();
    let mut lying = VoiceDatagram::Frame(frame(6, 40)).encode();
    lying[11] = 0xFF;
    let mut oversized = vec![0xF9, 1];
    oversized.extend_from_slice(&[0; 9]);
    oversized.extend_from_slice(&((MAX_OPUS_BYTES + 100) as u16).to_le_bytes());
    oversized.extend(vec![0u8; MAX_OPUS_BYTES + 100]);
    let good = VoiceDatagram::Frame(frame(7, 40)).encode();
    let before = rb.drops();
    assert_eq!(hear(&mut h, &mut rb, b, stranger, &good).0, None);
    assert_eq!(hear(&mut h, &mut rb, b, aid, &forged).0, None);
    assert_eq!(hear(&mut h, &mut rb, b, hid, &of_stranger).0, None);
    assert_eq!(hear(&mut h, &mut rb, b, aid, &to_relay).0, None);
    assert_eq!(hear(&mut h, &mut rb, b, hid, &of_self).0, None);
    assert_eq!(hear(&mut h, &mut rb, b, aid, &lying).0, None);
    assert_eq!(hear(&mut h, &mut rb, b, aid, &oversized).0, None);
    let d = rb.drops();
    assert_eq!(d.not_member - before.not_member, 1);
    assert_eq!(d.wrong_speaker - before.wrong_speaker, 3);
    assert_eq!(d.not_host - before.not_host, 1);
    assert_eq!(d.malformed - before.malformed, 2);
    assert_eq!(d.total() - before.total(), 7);

    // a flood through the host: the speaker's bucket lets a burst through, the rest is
    // dropped at the host and never relayed
    let mut relayed = 0;
    let mut heard = 0;
    for k in 0..500 {
        let bytes = VoiceDatagram::ToRelay(frame(100 + k, 40)).encode();
        let (hd, relay) = hear(&mut h, &mut rh, host, aid, &bytes);
        relayed += relay.len();
        heard += usize::from(hd.is_some());
    }
    assert!(heard <= 51, "{heard}");
    assert_eq!(relayed, heard);
    assert!(rh.drops().flood >= 449);
    // a second of speech later, the speaker is heard again
    h.advance(ms(1000));
    let bytes = VoiceDatagram::ToRelay(frame(1000, 40)).encode();
    assert!(hear(&mut h, &mut rh, host, aid, &bytes).0.is_some());
}

#[test]
fn before_joining_nothing_is_sent_or_heard() {
    let mut h = room(2, ConditionerConfig::default());
    let late = h.add_peer();
    // not yet welcomed: it sends nothing and hears nothing
    let mut r = VoiceRouter::default();
    let mut out = Vec::new();
    assert!(!h.session(late).is_connected());
    r.send_frame(h.session(late), Route::Mesh, &frame(0, 30), &mut out);
    assert!(out.is_empty());
    let host = h.host_index().unwrap();
    let hid = h.peers[host].session.local_id();
    let (heard, _) = hear(
        &mut h,
        &mut r,
        late,
        hid,
        &VoiceDatagram::Frame(frame(0, 30)).encode(),
    );
    assert_eq!(heard, None);
    assert_eq!(r.drops().not_member, 1);
    // once in, it hears the host
    h.advance(ms(1500));
    assert!(h.session(late).is_connected());
    let (heard, _) = hear(
        &mut h,
        &mut r,
        late,
        hid,
        &VoiceDatagram::Frame(frame(1, 30)).encode(),
    );
    assert!(heard.is_some());
}
