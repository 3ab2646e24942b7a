//! The host's recorder (`--record`): what happened in the room and how it looked, into the
//! keeper's batches ([`crate::record`] says what a recording holds).
//!
//! - Events: the peer's own, as the app sees them ([`Recorder::observe`]): members joining,
//!   leaving and kicked, migrations, authority changes, each object's first appearance with
//!   its first owner (whose avatar a part is), every topology entry (tears, lifts,
//!   cuts, resolution changes), application messages (a `Say` with its text) from every
//!   peer but the host itself (its own sends are not among its events), who holds what
//!   (`holders`: every hand on an object, local and remote), the host's own grabs and
//!   releases; and, noticed at sampling, authority changes and objects gone.
//! - States: every [`SAMPLE`] (the replication rate, 20 Hz) each object's shown state, when
//!   it changed since the last one recorded (a quarter of the objects every 12.5 ms, so a
//!   frame at 90 Hz reads a quarter of the room; a slow frame takes every quarter that came
//!   due, so no object is sampled later than its 50 ms plus a frame). An object that starts to move after resting
//!   gets its resting state again at the sample before, so reading between two samples never
//!   drifts through a rest.
//!
//! Times are room times ([`softsync_net::Session::room_time`]): a recording continues across
//! a reopen, and its events and a peer's log lines share one clock.

use std::collections::BTreeMap;
use std::time::Duration;

use softsync_net::{Instant, NetId, ObjectState};
use softsync_peer::messages::Say;
use softsync_peer::{Event, Peer};

use crate::codec::{encode_event, hex};
use crate::record::{RecEvent, RecStart, RecState, RecordBatch};

/// How often each object's shown state is sampled.
pub const SAMPLE: Duration = Duration::from_millis(50);

/// Objects are sampled a slice at a time (id modulo this), one slice every
/// `SAMPLE / SLICES`: each object every [`SAMPLE`], and a frame at 90 Hz reads a quarter of
/// the room (the whole room in one frame cost a hosting frame 0.7 ms at p99 in the frame
/// bench). A frame that comes late takes every slice that came due (a loaded machine's
/// frames once sampled a moved object 400 ms late: `tests/tests/replay_rooms.rs`).
const SLICES: u32 = 4;

/// What the recorder remembers of an object's last sample.
struct Seen {
    /// The state last recorded, and its room time.
    recorded: (ObjectState, u64),
    /// The room time of the last sample that saw it unchanged.
    seen_us: u64,
}

/// A recording under way.
pub(crate) struct Recorder {
    id: i64,
    started: bool,
    next_n: u64,
    pending: RecordBatch,
    next_sample: Option<Instant>,
    slice: u32,
    seen: BTreeMap<NetId, Seen>,
    /// Each object's owner at the last sample (authority changes are noticed there: the
    /// peer acts on the session's own news of them without passing it on).
    owners: BTreeMap<NetId, softsync_net::PeerId>,
}

/// The wall clock, Unix ms: a recording's id and start (when a person recorded it, for
/// retention), never the room's time.
#[allow(clippy::disallowed_methods)]
fn unix_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

impl Recorder {
    /// A recording that starts when the keeper first writes as host.
    pub fn new() -> Self {
        Recorder {
            id: 0,
            started: false,
            next_n: 0,
            pending: RecordBatch::default(),
            next_sample: None,
            slice: 0,
            seen: BTreeMap::new(),
            owners: BTreeMap::new(),
        }
    }

    fn room_us(peer: &Peer, now: Instant) -> u64 {
        peer.session()
            .room_time(now)
            .map_or(0, |t| t.as_micros() as u64)
    }

    fn push(
        &mut self,
        room_us: u64,
        kind: &str,
        p: Option<u64>,
        object: Option<NetId>,
        data: String,
    ) {
        self.pending.events.push(RecEvent {
            room_us,
            kind: kind.to_owned(),
            peer: p,
            object: object.map(|o| o.0),
            data,
        });
    }

    /// One of the peer's events, recorded if it is one a reviewer wants.
    pub fn observe(&mut self, now: Instant, peer: &Peer, e: &Event) {
        if !self.started {
            return;
        }
        use serde_json::json;
        use softsync_net::Event as Net;
        let t = Self::room_us(peer, now);
        match e {
            Event::Room(Net::PeerJoined(p)) => self.push(t, "join", Some(p.0), None, "{}".into()),
            Event::Room(Net::PeerLeft(p)) => self.push(t, "leave", Some(p.0), None, "{}".into()),
            Event::Room(Net::Kicked(p)) => self.push(t, "kick", Some(p.0), None, "{}".into()),
            Event::Room(Net::HostChanged { host, term }) => self.push(
                t,
                "migration",
                Some(host.0),
                None,
                json!({"term": term.0}).to_string(),
            ),
            Event::Room(Net::Topology { id, seq, event }) => {
                let (kind, fields) = encode_event(event);
                self.push(
                    t,
                    kind,
                    None,
                    Some(*id),
                    json!({"seq": seq, "event": fields}).to_string(),
                );
            }
            Event::Room(Net::Message(m)) => {
                let name = peer.message_types().name(m.kind).unwrap_or("?").to_owned();
                let text = peer.decode::<Say>(m).and_then(Result::ok).map(|s| s.text);
                self.push(
                    t,
                    "message",
                    Some(m.from.0),
                    None,
                    json!({"type": name, "delivery": format!("{:?}", m.delivery),
                           "payload": hex(&m.payload), "text": text})
                    .to_string(),
                );
            }
            Event::Holders { id, hands } => {
                let hands: Vec<_> = hands
                    .iter()
                    .map(|h| json!({"peer": h.peer.0, "hand": h.hand, "particle": h.particle}))
                    .collect();
                self.push(
                    t,
                    "holders",
                    None,
                    Some(*id),
                    json!({"hands": hands}).to_string(),
                );
            }
            Event::GrabStarted {
                id: object, hand, ..
            } => self.push(
                t,
                "grab",
                Some(peer.me().0),
                Some(*object),
                json!({"hand": hand}).to_string(),
            ),
            Event::GrabEnded {
                id: object,
                hand,
                speed,
            } => self.push(
                t,
                "release",
                Some(peer.me().0),
                Some(*object),
                json!({"hand": hand, "speed": speed}).to_string(),
            ),
            _ => {}
        }
    }

    /// Each frame while hosting: start the recording if it has not, and every [`SAMPLE`] the
    /// states that changed and the objects gone.
    pub fn sample(&mut self, now: Instant, peer: &mut Peer) {
        let t = Self::room_us(peer, now);
        if !self.started {
            self.started = true;
            self.id = unix_ms();
            self.pending.recording = self.id;
            self.pending.start = Some(RecStart {
                id: self.id,
                room_us: t,
                host: peer.me().0,
                image: peer.room_image(now),
            });
        }
        // every slice whose time has come (a slow frame takes several, up to the whole room:
        // no object is sampled later than its 50 ms and a frame)
        let mut due = [false; SLICES as usize];
        let mut any = false;
        for _ in 0..SLICES {
            if self.next_sample.is_some_and(|s| now < s) {
                break;
            }
            due[self.slice as usize] = true;
            any = true;
            self.slice = (self.slice + 1) % SLICES;
            self.next_sample = Some(self.next_sample.unwrap_or(now) + SAMPLE / SLICES);
        }
        if !any {
            return;
        }
        if self.next_sample.is_some_and(|s| s <= now) {
            // a whole round late: every slice was taken; start the next from now
            self.next_sample = Some(now + SAMPLE / SLICES);
        }
        let ids: Vec<NetId> = peer.objects().keys().copied().collect();
        let gone: Vec<NetId> = self
            .seen
            .keys()
            .filter(|id| !ids.contains(id))
            .copied()
            .collect();
        for id in gone {
            self.seen.remove(&id);
            self.owners.remove(&id);
            self.push(t, "gone", None, Some(id), "{}".into());
        }
        for id in &ids {
            let Some(owner) = peer.session().owner(*id) else {
                continue;
            };
            match self.owners.insert(*id, owner) {
                Some(o) if o != owner => {
                    let epoch = peer.session().epoch(*id);
                    let data = serde_json::json!({
                        "term": epoch.map(|e| e.term), "grant": epoch.map(|e| e.grant)
                    });
                    self.push(t, "authority", Some(owner.0), Some(*id), data.to_string());
                }
                // first seen: its class and first owner (whose avatar a part is)
                None => {
                    let class = peer.session().class_of(*id).map(|c| c.0);
                    let data = serde_json::json!({ "class": class });
                    self.push(t, "appear", Some(owner.0), Some(*id), data.to_string());
                }
                Some(_) => {}
            }
        }
        for id in ids.into_iter().filter(|id| due[(id.0 % SLICES) as usize]) {
            let (Some(class), Some(state)) =
                (peer.session().class_of(id), peer.shown_state(now, id))
            else {
                continue;
            };
            match self.seen.get_mut(&id) {
                Some(s) if s.recorded.0 == state => s.seen_us = t,
                Some(s) => {
                    // moving again after a rest: the rest's last moment first
                    if s.seen_us > s.recorded.1 {
                        self.pending.states.push(RecState {
                            room_us: s.seen_us,
                            object: id,
                            class,
                            state: s.recorded.0.clone(),
                        });
                    }
                    s.recorded = (state.clone(), t);
                    s.seen_us = t;
                    self.pending.states.push(RecState {
                        room_us: t,
                        object: id,
                        class,
                        state,
                    });
                }
                None => {
                    self.seen.insert(
                        id,
                        Seen {
                            recorded: (state.clone(), t),
                            seen_us: t,
                        },
                    );
                    self.pending.states.push(RecState {
                        room_us: t,
                        object: id,
                        class,
                        state,
                    });
                }
            }
        }
        self.pending.end_us = self.pending.end_us.max(t);
    }

    /// What to write with the next batch (numbered on from the last).
    pub fn take(&mut self) -> Option<RecordBatch> {
        if self.pending.is_empty() && self.pending.end_us == 0 {
            return None;
        }
        let mut b = std::mem::take(&mut self.pending);
        b.recording = self.id;
        b.first_n = self.next_n;
        self.next_n += b.events.len() as u64;
        self.pending.recording = self.id;
        Some(b)
    }

    /// A batch the writer did not take: its record goes first next time.
    pub fn give_back(&mut self, mut b: RecordBatch) {
        self.next_n = b.first_n;
        b.append(std::mem::take(&mut self.pending));
        self.pending = b;
    }
}
