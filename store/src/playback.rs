//! A recording read as a room over time: which objects exist at a moment of it, with what
//! log and in what state ([`Playback::room_at`]). `softsync replay --serve` plays this back
//! as a room spectators join: the room at the start of the recording ([`Recording::image`])
//! plus every topology entry the recording saw up to the moment (a tear appends to its
//! object's log; a cut's pieces arrive as objects whose logs are their parent's plus the
//! cut), and the objects whose recorded states reach that moment.

use std::collections::BTreeMap;

use softsync_net::wire::TopologyEvent;
use softsync_net::{KeptObject, NetId};

use crate::codec::decode_event;
use crate::record::{RecEvent, Recording, RecordingInfo};
use crate::{RoomStore, StoreError};

/// The topology event kinds a recording names (the row forms of [`crate::codec`]).
const TOPOLOGY_KINDS: [&str; 4] = ["tear", "lift", "cut", "resolution"];

/// One recording, ready to be read at any moment.
#[derive(Clone, Debug)]
pub struct Playback {
    info: RecordingInfo,
    /// Logs at the recording's start.
    start: BTreeMap<NetId, Vec<TopologyEvent>>,
    /// Every topology entry of the recording: (room time, object, its place in the log).
    entries: Vec<(u64, NetId, u32, TopologyEvent)>,
    /// Every event, in order.
    events: Vec<RecEvent>,
}

impl Playback {
    /// Recording `id` of `store`, its events read once. Errors: no such recording; an event
    /// row this build cannot read (a topology kind it does not know names itself).
    pub fn open(store: &mut dyn RoomStore, id: i64) -> Result<Playback, StoreError> {
        let Recording { info, image } = store
            .recording(id)?
            .ok_or_else(|| StoreError::Row(format!("no recording {id}")))?;
        let events = store.recording_events(id, info.start_us, info.end_us.saturating_add(1))?;
        let mut entries = Vec::new();
        for e in &events {
            if !TOPOLOGY_KINDS.contains(&e.kind.as_str()) {
                continue;
            }
            let bad =
                |why: &str| StoreError::Row(format!("{} event at {}: {why}", e.kind, e.room_us));
            let object = e.object.ok_or_else(|| bad("no object"))?;
            let v: serde_json::Value =
                serde_json::from_str(&e.data).map_err(|x| bad(&x.to_string()))?;
            let seq = v
                .get("seq")
                .and_then(serde_json::Value::as_u64)
                .and_then(|s| u32::try_from(s).ok())
                .ok_or_else(|| bad("no seq"))?;
            let fields = v
                .get("event")
                .and_then(serde_json::Value::as_str)
                .ok_or_else(|| bad("no event"))?;
            entries.push((
                e.room_us,
                NetId(object),
                seq,
                decode_event(&e.kind, fields)?,
            ));
        }
        let start = image
            .objects
            .iter()
            .map(|o| (o.id, o.topology.clone()))
            .collect();
        Ok(Playback {
            info,
            start,
            entries,
            events,
        })
    }

    /// What the store says of the recording.
    pub fn info(&self) -> &RecordingInfo {
        &self.info
    }

    /// Every event of the recording, in order.
    pub fn events(&self) -> &[RecEvent] {
        &self.events
    }

    /// Every object's log at room time `t_us`.
    pub fn logs_at(&self, t_us: u64) -> BTreeMap<NetId, Vec<TopologyEvent>> {
        let mut logs = self.start.clone();
        for (at, id, seq, e) in &self.entries {
            if *at > t_us {
                break;
            }
            let log = logs.entry(*id).or_default();
            // an entry rewrites the log from its place on (a piece's log arrives whole)
            log.truncate(*seq as usize);
            log.push(*e);
        }
        logs
    }

    /// The room at room time `t_us` of the recording: every object with a recorded state
    /// reaching it (interpolated there), with its log then, under its recorded id.
    pub fn room_at(
        &self,
        store: &mut dyn RoomStore,
        t_us: u64,
    ) -> Result<Vec<KeptObject>, StoreError> {
        let logs = self.logs_at(t_us);
        Ok(store
            .recording_state_at(self.info.id, t_us)?
            .into_iter()
            .map(|s| KeptObject {
                id: s.object,
                class: s.class,
                topology: logs.get(&s.object).cloned().unwrap_or_default(),
                state: s.state,
            })
            .collect())
    }
}
