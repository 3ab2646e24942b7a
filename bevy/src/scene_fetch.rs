//! A joiner without the room's scene receives it before it says `Hello`
//! ([`crate::Room::open_fetching_scene`]) from the room's host: a member it reaches first
//! names the host (the scene is taken from nobody else), another joiner says it has none.

// The I/O layer: this machine's clock and the wait for the scene's chunks.
#![allow(clippy::disallowed_methods)]

use std::time::Duration;

use softsync_net::share::{self, BlobFetch, FetchError};
use softsync_net::{Instant, PeerEvent, PeerId, Transport};
use softsync_net_matchbox::MatchboxTransport;
use softsync_peer::scene::MAX_BUNDLE_BYTES;
use softsync_peer::Scene;

use crate::room::{Clock, OpenError, RoomOptions};

/// How a joiner received the room's scene ([`Room::open_fetching_scene`](crate::Room::open_fetching_scene)).
#[derive(Clone, Debug)]
pub struct FetchedScene {
    /// The peer that sent it.
    pub from: PeerId,
    /// The bundle's size (the scene file and its meshes).
    pub bytes: u64,
    /// From the first request to the verified bundle.
    pub fetch: Duration,
    /// Requests sent (more than the chunks when some were lost).
    pub requests: u64,
}

/// How long a contact may stay silent before a joiner asks the next one for the scene (another
/// joiner that reached us first has no scene to give and says so at once; this is for one
/// that says nothing).
const SCENE_CONTACT_PATIENCE: Duration = Duration::from_millis(1500);
/// Members' "ask the host" answers followed at most (a migration may move the host meanwhile).
const MAX_REDIRECTS: u32 = 16;

/// Fetch the room's scene before we have a session, from `first` or, when it has none to give
/// (a joiner like us) or stays silent, from the next peer we have a data channel to; link
/// news seen meanwhile go to `link_news` for the peer. Another joiner's request is answered
/// that we are not in the room yet; other datagrams are dropped (nobody sends us the
/// session's before our `Hello`). The verified bundle is written under the cache and loaded.
pub(crate) fn fetch_scene(
    transport: &mut MatchboxTransport,
    first: PeerId,
    opts: &RoomOptions,
    started: std::time::Instant,
    link_news: &mut Vec<PeerEvent>,
) -> Result<(Scene, FetchedScene), OpenError> {
    let clock = Clock::start();
    let me = transport.local_id();
    let remaining = || opts.connect_timeout.saturating_sub(started.elapsed());
    let start_fetch = |from: PeerId, now: Instant| {
        BlobFetch::new(now, from, MAX_BUNDLE_BYTES, remaining())
            .with_key(opts.room_key.as_ref(), me)
            .with_token(opts.room_token.clone())
    };
    let mut contacts: Vec<PeerId> = vec![first];
    let mut tried = 1;
    let mut fetch = start_fetch(first, clock.now());
    let mut asked_at = clock.now();
    let mut redirects = 0;
    let blob = loop {
        let now = clock.now();
        while let Some(e) = transport.poll_peer_event() {
            if let PeerEvent::Connected(p) = e {
                if !contacts.contains(&p) {
                    contacts.push(p);
                }
            }
            link_news.push(e);
        }
        while let Some(t) = fetch.poll_transmit(now) {
            transport.send(now, &t);
        }
        while let Some((peer, bytes)) = transport.recv(now) {
            // the front door: only the scene share is spoken before our `Hello`
            if softsync_net::door::classify(&bytes) != softsync_net::door::Door::Share {
                continue;
            }
            match share::ShareMsg::decode(&bytes) {
                Ok(share::ShareMsg::Request { .. }) => {
                    let no = share::ShareMsg::Unavailable(share::NOT_IN_ROOM.into());
                    transport.send(
                        now,
                        &softsync_net::Transmit {
                            to: peer,
                            payload: no.encode(),
                            reliable: true,
                        },
                    );
                }
                Ok(_) => fetch.handle(peer, &bytes),
                Err(_) => {}
            }
        }
        let from = fetch.source();
        let unable = match fetch.outcome() {
            Some(Ok(blob)) => break blob,
            // a member, not the host: the scene comes from the host it names (a bounded
            // number of times: members that disagree about the host are asked round and round)
            Some(Err(FetchError::AskHost(host))) if host != me && redirects < MAX_REDIRECTS => {
                redirects += 1;
                if !contacts.contains(&host) {
                    contacts.push(host);
                }
                fetch = start_fetch(host, now);
                asked_at = now;
                false
            }
            Some(Err(FetchError::AskHost(_))) => true,
            Some(Err(FetchError::Unavailable(why)))
                if why == share::NOT_IN_ROOM || why == share::CANNOT_CHECK =>
            {
                true
            }
            Some(Err(e)) => {
                return Err(match e {
                    // the host's word on our join token, as the handshake would say it
                    FetchError::Unavailable(why) if why.starts_with(share::TOKEN_REFUSED) => {
                        OpenError::Peer(format!(
                            "room {:?}: {}",
                            opts.name,
                            &why[share::TOKEN_REFUSED.len()..]
                        ))
                    }
                    // Said as the handshake says it.
                    FetchError::Unavailable(why) if why == share::NEEDS_KEY => {
                        OpenError::Peer(match (&opts.room_key, &opts.room_token) {
                            (None, None) => format!(
                                "room {:?}: the room needs a key and this peer has none \
                                 (--room-key-file, or SOFTSYNC_ROOM_KEY, or a join token: \
                                 --room-token)",
                                opts.name
                            ),
                            (Some(_), _) => format!("room {:?}: wrong room key", opts.name),
                            (None, Some(_)) => {
                                format!("room {:?}: the join token is not this room's", opts.name)
                            }
                        })
                    }
                    e => OpenError::Connect(format!(
                        "room {:?}: the scene from peer {}: {e}",
                        opts.name, from.0
                    )),
                });
            }
            None => {
                fetch.progress().1.is_none()
                    && now.saturating_since(asked_at) > SCENE_CONTACT_PATIENCE
            }
        };
        if unable {
            // The next contact (round and round: one that had nothing may be in the room by now).
            let next = contacts[tried % contacts.len()];
            tried += 1;
            fetch = start_fetch(next, now);
            asked_at = now;
        }
        if started.elapsed() > opts.connect_timeout {
            return Err(OpenError::Connect(format!(
                "room {:?}: no peer sent the room's scene within {:?} (asked {} of them)",
                opts.name,
                opts.connect_timeout,
                contacts.len()
            )));
        }
        if let Some(why) = transport.closed() {
            return Err(OpenError::Connect(format!(
                "signaling lost while receiving the scene: {why}"
            )));
        }
        std::thread::sleep(Duration::from_millis(2));
    };
    let from = fetch.source();
    let fetched = FetchedScene {
        from,
        bytes: blob.len() as u64,
        fetch: Duration::from_micros(clock.now().as_micros()),
        requests: fetch.requests,
    };
    let scene = Scene::from_bundle(&blob, &opts.scene_cache)
        .map_err(|e| OpenError::Config(format!("the scene peer {} sent: {e}", from.0)))?;
    Ok((scene, fetched))
}
