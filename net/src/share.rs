//! Sharing a blob (the room's scene, with its meshes) from the room's host to a peer that is
//! not in the room yet, before it has a session: a sans-IO pull protocol beside the session's.
//!
//! A joiner without the scene asks the first peer it reaches ([`BlobFetch`]); a member that
//! is not the host names the host ([`ask_host`]), and the host serves the scene it runs
//! ([`BlobServer`]). The fetcher asks for fixed-size chunks by offset,
//! a window of them at a time, asks again for any that do not come within a retry interval,
//! and takes the blob only when it is whole and its SHA-256 matches the digest every chunk
//! carries; a chunk that names another digest or size than the first one is a failure (the
//! source changed, or lies), a blob over the fetcher's size bound is refused before anything
//! is allocated, and the whole fetch has a deadline. The server answers each request with one
//! chunk, at most [`SERVE_BYTES_PER_S`] per requester, so a request costs it bounded work.
//!
//! # Wire
//! Datagrams that start with [`SHARE_MARKER`] (never a session's first byte: that is the
//! protocol version, or 0 for a refusal). Then a kind byte:
//! - `1` request: varint offset, varint length, and in a room with a key a 32-byte proof
//!   ([`RoomKey::scene_proof`]);
//! - `2` chunk: 32-byte SHA-256 of the whole blob, varint total length, varint offset, the
//!   bytes (the rest of the datagram);
//! - `3` unavailable: a UTF-8 reason (the rest, ≤ 200 bytes);
//! - `4` ask the host: the room's host id (u64 LE). A member that is not the host sends no
//!   chunk: a joiner takes the scene from the room's host only.
//!
//! Decoding never panics and never allocates more than the datagram's own length.

use std::collections::BTreeMap;
use std::time::Duration;

use crate::bits::{write_varint, ByteReader};
use crate::error::{decode_err, NetError};
use crate::ids::PeerId;
use crate::session::RoomKey;
use crate::time::Instant;
use crate::transport::Transmit;
use crate::wire::RoomToken;

/// First byte of every share datagram.
pub const SHARE_MARKER: u8 = crate::door::SHARE;
/// Bytes of blob per chunk (a chunk datagram is at most this plus 48 bytes).
pub const CHUNK_BYTES: usize = 1024;
/// What a server sends one requester at most, bytes per second.
pub const SERVE_BYTES_PER_S: f64 = 8.0 * 1024.0 * 1024.0;
/// What a peer that is not in the room yet (another joiner) answers a request with: the
/// fetcher asks the next peer.
pub const NOT_IN_ROOM: &str = "not in the room yet";
/// Longest token text a request carries.
const MAX_TOKEN_TEXT: usize = 200;

/// The reason a member of a room with a key that holds no key itself (it joined with a join
/// token) gives every request: it cannot check them; ask another peer.
pub const CANNOT_CHECK: &str = "this peer holds no room key to check yours: ask another peer";

/// The reason a server with a key gives a request without a valid proof.
pub const NEEDS_KEY: &str = "the room needs its key";
/// How the reason for refusing a request's join token starts (the session's reason follows:
/// expired, used by another peer).
pub const TOKEN_REFUSED: &str = "the room refuses the join token: ";
/// Longest reason an `unavailable` answer carries.
pub const MAX_REASON: usize = 200;

const KIND_REQUEST: u8 = 1;
const KIND_CHUNK: u8 = 2;
const KIND_UNAVAILABLE: u8 = 3;
const KIND_ASK_HOST: u8 = 4;

/// SHA-256 of `bytes`.
pub fn sha256(bytes: &[u8]) -> [u8; 32] {
    let d = ring::digest::digest(&ring::digest::SHA256, bytes);
    let mut out = [0u8; 32];
    out.copy_from_slice(d.as_ref());
    out
}

/// Whether a datagram is one of this protocol's (the rest are the session's).
pub fn is_share(datagram: &[u8]) -> bool {
    crate::door::classify(datagram) == crate::door::Door::Share
}

/// A decoded share datagram.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ShareMsg<'a> {
    /// Please send `len` bytes from `offset`.
    Request {
        /// Where.
        offset: u64,
        /// How many (the server sends at most [`CHUNK_BYTES`]).
        len: u32,
        /// In a room with a key: [`RoomKey::scene_proof`] of the requester and the server.
        proof: Option<[u8; 32]>,
        /// Or, from a peer that holds no key, a join token of the room (its text form).
        token: Option<RoomToken>,
    },
    /// Bytes of the blob.
    Chunk {
        /// SHA-256 of the whole blob.
        digest: [u8; 32],
        /// The blob's length.
        total: u64,
        /// Where these bytes start.
        offset: u64,
        /// The bytes.
        data: &'a [u8],
    },
    /// The peer has nothing to share (or will not), and why.
    Unavailable(String),
    /// The peer is a member, not the room's host: ask the host, this peer.
    AskHost(PeerId),
}

impl ShareMsg<'_> {
    /// The datagram.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = vec![SHARE_MARKER];
        match self {
            ShareMsg::Request {
                offset,
                len,
                proof,
                token,
            } => {
                out.push(KIND_REQUEST);
                write_varint(&mut out, *offset);
                write_varint(&mut out, u64::from(*len));
                if let Some(p) = proof {
                    out.extend_from_slice(p);
                } else if let Some(t) = token {
                    out.extend_from_slice(t.to_string().as_bytes());
                }
            }
            ShareMsg::Chunk {
                digest,
                total,
                offset,
                data,
            } => {
                out.push(KIND_CHUNK);
                out.extend_from_slice(digest);
                write_varint(&mut out, *total);
                write_varint(&mut out, *offset);
                out.extend_from_slice(data);
            }
            ShareMsg::Unavailable(why) => {
                out.push(KIND_UNAVAILABLE);
                let mut end = why.len().min(MAX_REASON);
                while !why.is_char_boundary(end) {
                    end -= 1;
                }
                out.extend_from_slice(&why.as_bytes()[..end]);
            }
            ShareMsg::AskHost(host) => {
                out.push(KIND_ASK_HOST);
                out.extend_from_slice(&host.0.to_le_bytes());
            }
        }
        out
    }

    /// Parse a share datagram (bounded, never panics).
    pub fn decode(bytes: &[u8]) -> Result<ShareMsg<'_>, NetError> {
        let mut r = ByteReader::new(bytes);
        if r.u8()? != SHARE_MARKER {
            return Err(decode_err(0, "not a share datagram"));
        }
        let at = r.pos();
        match r.u8()? {
            KIND_REQUEST => {
                let offset = r.varint()?;
                let len = r.varint_u32()?;
                let (mut proof, mut token) = (None, None);
                match bytes.len() - r.pos() {
                    0 => {}
                    32 => {
                        let mut p = [0u8; 32];
                        p.copy_from_slice(r.take(32)?);
                        proof = Some(p);
                    }
                    n if n <= MAX_TOKEN_TEXT => {
                        let at = r.pos();
                        let text = std::str::from_utf8(r.take(n)?)
                            .map_err(|_| decode_err(at, "a request's token is not text"))?;
                        token = Some(
                            text.parse::<RoomToken>()
                                .map_err(|_| decode_err(at, "a request's token is malformed"))?,
                        );
                    }
                    _ => {
                        return Err(decode_err(
                            r.pos(),
                            "a request's proof is 32 bytes, a token at most 200",
                        ))
                    }
                };
                Ok(ShareMsg::Request {
                    offset,
                    len,
                    proof,
                    token,
                })
            }
            KIND_CHUNK => {
                let mut digest = [0u8; 32];
                digest.copy_from_slice(r.take(32)?);
                let total = r.varint()?;
                let offset = r.varint()?;
                let data = r.take(bytes.len() - r.pos())?;
                if data.len() > CHUNK_BYTES {
                    return Err(decode_err(r.pos(), "chunk longer than a chunk"));
                }
                if offset
                    .checked_add(data.len() as u64)
                    .is_none_or(|end| end > total)
                {
                    return Err(decode_err(at, "chunk beyond the blob's end"));
                }
                Ok(ShareMsg::Chunk {
                    digest,
                    total,
                    offset,
                    data,
                })
            }
            KIND_UNAVAILABLE => {
                let rest = r.take(bytes.len() - r.pos())?;
                if rest.len() > MAX_REASON {
                    return Err(decode_err(at, "reason too long"));
                }
                let why =
                    std::str::from_utf8(rest).map_err(|_| decode_err(at, "reason not UTF-8"))?;
                Ok(ShareMsg::Unavailable(why.to_owned()))
            }
            KIND_ASK_HOST => {
                let b = r.take(8)?;
                if !r.is_empty() {
                    return Err(decode_err(r.pos(), "bytes after the host's id"));
                }
                let mut id = [0u8; 8];
                id.copy_from_slice(b);
                Ok(ShareMsg::AskHost(PeerId(u64::from_le_bytes(id))))
            }
            _ => Err(decode_err(at, "unknown share kind")),
        }
    }
}

/// A member's answer to a share `datagram` from `from` when it is not the room's host: the
/// host's id, so the joiner asks there (`None` for what is not a request).
pub fn ask_host(from: PeerId, datagram: &[u8], host: PeerId) -> Option<Transmit> {
    matches!(ShareMsg::decode(datagram), Ok(ShareMsg::Request { .. })).then(|| Transmit {
        to: from,
        payload: ShareMsg::AskHost(host).encode(),
        reliable: true,
    })
}

/// Serves one blob to whoever asks, chunk by chunk, each requester within a byte rate.
#[derive(Debug)]
pub struct BlobServer {
    blob: Result<(Vec<u8>, [u8; 32]), String>,
    /// A room with a key: requests must prove it, for this server's id.
    key: Option<(RoomKey, PeerId)>,
    budget: BTreeMap<PeerId, (Instant, f64)>,
    /// Requests answered with a chunk.
    pub served: u64,
    /// Requests dropped: malformed, out of range, or over a requester's rate.
    pub refused: u64,
}

impl BlobServer {
    /// Serve `blob`.
    pub fn new(blob: Vec<u8>) -> Self {
        let digest = sha256(&blob);
        BlobServer {
            blob: Ok((blob, digest)),
            key: None,
            budget: BTreeMap::new(),
            served: 0,
            refused: 0,
        }
    }

    /// Answer every request with `unavailable` and `why`.
    pub fn unavailable(why: impl Into<String>) -> Self {
        BlobServer {
            blob: Err(why.into()),
            key: None,
            budget: BTreeMap::new(),
            served: 0,
            refused: 0,
        }
    }

    /// Serve only requests that prove the room's key ([`RoomKey::scene_proof`] of the
    /// requester and `me`); others are told the room needs its key.
    pub fn with_key(mut self, key: Option<RoomKey>, me: PeerId) -> Self {
        self.key = key.map(|k| (k, me));
        self
    }

    /// The blob's digest, if there is one.
    pub fn digest(&self) -> Option<[u8; 32]> {
        self.blob.as_ref().ok().map(|(_, d)| *d)
    }

    /// The answer to a share datagram from `from`, if it deserves one. A join token is
    /// taken on its signature alone: a member of a room uses
    /// [`handle_judged`](Self::handle_judged) with its session's word on it.
    pub fn handle(&mut self, now: Instant, from: PeerId, datagram: &[u8]) -> Option<Transmit> {
        self.handle_judged(now, from, datagram, |_| Ok(()))
    }

    /// [`handle`](Self::handle), a request's join token (signed for this room) also put to
    /// `token_ok`: whether it is unexpired and not used by another peer
    /// ([`Session::token_admits`](crate::session::Session::token_admits) of the requester),
    /// whose reason a refused requester is told (after [`TOKEN_REFUSED`]).
    pub fn handle_judged(
        &mut self,
        now: Instant,
        from: PeerId,
        datagram: &[u8],
        token_ok: impl FnOnce(&RoomToken) -> Result<(), &'static str>,
    ) -> Option<Transmit> {
        let Ok(ShareMsg::Request {
            offset,
            len,
            proof,
            token,
        }) = ShareMsg::decode(datagram)
        else {
            self.refused += 1;
            return None;
        };
        let proven = match (&self.key, proof, token) {
            (None, _, _) => Ok(()),
            (Some((key, me)), Some(p), _) if key.verify_scene_proof(from, *me, &p) => Ok(()),
            // a token of this room, signed with its key, unexpired and nobody else's
            (Some((key, _)), None, Some(t)) if key.token_is_ours(&t) => {
                token_ok(&t).map_err(|why| format!("{TOKEN_REFUSED}{why}"))
            }
            _ => Err(NEEDS_KEY.to_owned()),
        };
        let msg = match &self.blob {
            _ if proven.is_err() => {
                self.refused += 1;
                ShareMsg::Unavailable(proven.err().unwrap_or_default())
            }
            Err(why) => ShareMsg::Unavailable(why.clone()),
            Ok((blob, digest)) => {
                let total = blob.len() as u64;
                let len = (len as usize).min(CHUNK_BYTES);
                if offset > total || (offset == total && total > 0) {
                    self.refused += 1;
                    return None;
                }
                // A token bucket per requester: a second's worth at most.
                let (at, tokens) = self
                    .budget
                    .get(&from)
                    .copied()
                    .unwrap_or((now, SERVE_BYTES_PER_S));
                let dt = now.saturating_since(at).as_secs_f64();
                let tokens = (tokens + dt * SERVE_BYTES_PER_S).min(SERVE_BYTES_PER_S);
                if tokens < len as f64 {
                    self.budget.insert(from, (now, tokens));
                    self.refused += 1;
                    return None;
                }
                self.budget.insert(from, (now, tokens - len as f64));
                if self.budget.len() > 1024 {
                    // Forget the longest-idle requester rather than grow without bound.
                    if let Some(k) = self.budget.iter().min_by_key(|(_, v)| v.0).map(|(k, _)| *k) {
                        self.budget.remove(&k);
                    }
                }
                let start = offset as usize;
                let end = (start + len).min(blob.len());
                ShareMsg::Chunk {
                    digest: *digest,
                    total,
                    offset,
                    data: blob.get(start..end).unwrap_or(&[]),
                }
            }
        };
        self.served += 1;
        Some(Transmit {
            to: from,
            payload: msg.encode(),
            reliable: true,
        })
    }
}

/// Why a fetch failed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FetchError {
    /// The blob is larger than the fetcher accepts.
    #[error("the peer offers {total} bytes, more than the {max} this peer accepts")]
    TooLarge {
        /// What the peer offers.
        total: u64,
        /// The bound.
        max: u64,
    },
    /// Chunks disagree about the blob (its size or digest changed during the fetch).
    #[error("the peer's chunks describe different blobs")]
    Inconsistent,
    /// The whole blob's SHA-256 is not the one its chunks carry.
    #[error("the blob's SHA-256 does not match the digest the peer sent")]
    DigestMismatch,
    /// The peer has nothing to share.
    #[error("the peer has nothing to share: {0}")]
    Unavailable(String),
    /// The peer is not the room's host and names it: the scene comes from the host only.
    #[error("the peer is not the room's host: ask peer {}", .0 .0)]
    AskHost(PeerId),
    /// The deadline passed.
    #[error("no complete blob within {0:?} ({1} of {2} bytes)")]
    TimedOut(Duration, u64, u64),
}

/// Fetches one blob from one peer: requests out, chunks in, a verified blob at the end.
#[derive(Debug)]
pub struct BlobFetch {
    from: PeerId,
    max_total: u64,
    started: Instant,
    deadline: Duration,
    retry: Duration,
    window: usize,
    meta: Option<([u8; 32], u64)>,
    data: Vec<u8>,
    have: Vec<bool>,
    received: u64,
    /// Chunk index → when it was last asked for.
    asked: BTreeMap<u64, Instant>,
    next_chunk: u64,
    outcome: Option<Result<(), FetchError>>,
    proof: Option<[u8; 32]>,
    token: Option<RoomToken>,
    /// Requests sent (retries included).
    pub requests: u64,
    /// Datagrams ignored: malformed, from another peer, or a chunk not asked for.
    pub ignored: u64,
}

impl BlobFetch {
    /// Fetch from `from`, at most `max_total` bytes, within `deadline` of `now`.
    pub fn new(now: Instant, from: PeerId, max_total: u64, deadline: Duration) -> Self {
        BlobFetch {
            from,
            max_total,
            started: now,
            deadline,
            retry: Duration::from_millis(300),
            window: 32,
            meta: None,
            data: Vec::new(),
            have: Vec::new(),
            received: 0,
            asked: BTreeMap::new(),
            next_chunk: 0,
            outcome: None,
            proof: None,
            token: None,
            requests: 0,
            ignored: 0,
        }
    }

    /// In a room with a key: prove it ([`RoomKey::scene_proof`] of `me` and the source).
    pub fn with_key(mut self, key: Option<&RoomKey>, me: PeerId) -> Self {
        self.proof = key.map(|k| k.scene_proof(me, self.from));
        self
    }

    /// In a room with a key, holding none: show this join token instead.
    pub fn with_token(mut self, token: Option<RoomToken>) -> Self {
        self.token = token;
        self
    }

    /// The peer asked.
    pub fn source(&self) -> PeerId {
        self.from
    }

    /// Bytes received so far, and the blob's size once known.
    pub fn progress(&self) -> (u64, Option<u64>) {
        (self.received, self.meta.map(|m| m.1))
    }

    fn chunks(&self) -> u64 {
        self.meta
            .map_or(1, |(_, total)| total.div_ceil(CHUNK_BYTES as u64).max(1))
    }

    /// The next request to send, if one is due (call until `None`).
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Transmit> {
        if self.outcome.is_some() {
            return None;
        }
        if now.saturating_since(self.started) > self.deadline {
            let total = self.meta.map_or(0, |m| m.1);
            self.outcome = Some(Err(FetchError::TimedOut(
                self.deadline,
                self.received,
                total,
            )));
            return None;
        }
        // A chunk asked for long ago is asked for again (the oldest first).
        let stale = self
            .asked
            .iter()
            .filter(|(_, at)| now.saturating_since(**at) >= self.retry)
            .min_by_key(|(_, at)| **at)
            .map(|(i, _)| *i);
        let chunk = match stale {
            Some(i) => i,
            None if self.asked.len() < self.window && self.next_chunk < self.chunks() => {
                // Before the first chunk arrives its size is unknown: one request only.
                if self.meta.is_none() && !self.asked.is_empty() {
                    return None;
                }
                let i = self.next_chunk;
                self.next_chunk += 1;
                i
            }
            None => return None,
        };
        self.asked.insert(chunk, now);
        self.requests += 1;
        let msg = ShareMsg::Request {
            offset: chunk * CHUNK_BYTES as u64,
            len: CHUNK_BYTES as u32,
            proof: self.proof,
            token: if self.proof.is_none() {
                self.token.clone()
            } else {
                None
            },
        };
        Some(Transmit {
            to: self.from,
            payload: msg.encode(),
            reliable: true,
        })
    }

    /// A share datagram arrived.
    pub fn handle(&mut self, from: PeerId, datagram: &[u8]) {
        if self.outcome.is_some() {
            return;
        }
        let msg = match ShareMsg::decode(datagram) {
            Ok(m) if from == self.from => m,
            _ => {
                self.ignored += 1;
                return;
            }
        };
        let (digest, total, offset, data) = match msg {
            ShareMsg::Chunk {
                digest,
                total,
                offset,
                data,
            } => (digest, total, offset, data),
            ShareMsg::Unavailable(why) => {
                self.outcome = Some(Err(FetchError::Unavailable(why)));
                return;
            }
            ShareMsg::AskHost(host) => {
                self.outcome = Some(Err(FetchError::AskHost(host)));
                return;
            }
            ShareMsg::Request { .. } => {
                self.ignored += 1;
                return;
            }
        };
        match self.meta {
            None => {
                if total > self.max_total {
                    self.outcome = Some(Err(FetchError::TooLarge {
                        total,
                        max: self.max_total,
                    }));
                    return;
                }
                self.meta = Some((digest, total));
                self.data = vec![0; total as usize];
                self.have = vec![false; self.chunks() as usize];
            }
            Some(m) if m != (digest, total) => {
                self.outcome = Some(Err(FetchError::Inconsistent));
                return;
            }
            Some(_) => {}
        }
        let chunk = offset / CHUNK_BYTES as u64;
        let expect = (total - chunk * CHUNK_BYTES as u64).min(CHUNK_BYTES as u64) as usize;
        if offset % CHUNK_BYTES as u64 != 0 || data.len() != expect {
            self.ignored += 1;
            return;
        }
        let Some(slot) = self.have.get_mut(chunk as usize) else {
            self.ignored += 1;
            return;
        };
        self.asked.remove(&chunk);
        if *slot {
            return; // a duplicate
        }
        *slot = true;
        let start = offset as usize;
        if let Some(dst) = self.data.get_mut(start..start + data.len()) {
            dst.copy_from_slice(data);
        }
        self.received += data.len() as u64;
        if self.have.iter().all(|h| *h) {
            self.outcome = Some(if sha256(&self.data) == digest {
                Ok(())
            } else {
                Err(FetchError::DigestMismatch)
            });
        }
    }

    /// `None` while fetching; the verified blob, or why there is none. Once only for the blob
    /// (later calls give an empty one).
    pub fn outcome(&mut self) -> Option<Result<Vec<u8>, FetchError>> {
        match self.outcome.as_ref()? {
            Ok(()) => Some(Ok(std::mem::take(&mut self.data))),
            Err(e) => Some(Err(e.clone())),
        }
    }
}

#[cfg(test)]
mod tests;
