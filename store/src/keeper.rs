//! A room kept in a store while it runs (`softsync host --store`, softsync-bevy's
//! `RoomOptions::store`).
//!
//! The host opens the store before anything connects: a store of another scene is refused
//! with the reason (or emptied with `reset`), a store that keeps a room has it reopened
//! ([`softsync_peer::Peer::reopen`]). While the room runs, the [`Keeper`] looks at the room
//! every [`StoreOptions::flush`] (100 ms): topology changes, arrivals and departures go to the
//! store then; every [`StoreOptions::checkpoint`] (1 s) the states that moved go too. The
//! writes run on the store's own thread ([`crate::StoreWriter`]): a frame only takes
//! the room's image and hands the batch over.
//!
//! A joiner given a store writes to it from the moment it becomes host (a migration), if it
//! can open it (the dead host's lock went with its process); if it cannot — another machine,
//! a file still held — it says so once and the room goes on unkept, and the store keeps the
//! room as the old host last wrote it. A write that fails (full disk, lost server) is said
//! once per distinct error; the store keeps its last whole write, and the next write that
//! succeeds brings the whole room.

use std::time::Duration;

use crate::{RoomIdentity, StoreWriter, Tracker, WriterStatus};
use softsync_net::{Instant, RoomImage, SessionConfig};
use softsync_peer::{Event, Peer, Scene};

/// Where and how often a room is kept.
#[derive(Clone, Debug)]
pub struct StoreOptions {
    /// The store: a SQLite file (created if missing).
    pub target: String,
    /// Start the room afresh, dropping what the store kept (of this or another scene).
    pub reset: bool,
    /// How often every moved state is written.
    pub checkpoint: Duration,
    /// How often the room is looked at for topology changes, arrivals and departures.
    pub flush: Duration,
    /// Record the session for review (`crate::record`): its events and the objects' shown
    /// states, while this peer hosts.
    pub record: bool,
    /// Delete recordings older than this when the store opens (recordings of people are
    /// personal data); `None`: keep them.
    pub keep_recordings: Option<Duration>,
}

impl StoreOptions {
    /// Keep the room in `target`, checkpoints every second.
    pub fn new(target: impl Into<String>) -> Self {
        StoreOptions {
            target: target.into(),
            reset: false,
            checkpoint: Duration::from_secs(1),
            flush: Duration::from_millis(100),
            record: false,
            keep_recordings: None,
        }
    }
}

/// The room's identity in a store: its scene's bundle hash and its message table.
fn identity(scene: &Scene, cfg: &SessionConfig) -> Result<(RoomIdentity, Vec<u8>), String> {
    let bundle = scene.bundle()?;
    let messages = RoomIdentity::messages(&cfg.messages.kinds);
    Ok((RoomIdentity::of(&bundle, messages), bundle))
}

/// Opens the store for a room of `scene` under `cfg`: the writer, and the room it kept
/// (`None` for a new or reset store, or one that kept an empty room).
pub fn open_store(
    opts: &StoreOptions,
    scene: &Scene,
    cfg: &SessionConfig,
) -> Result<(StoreWriter, Option<RoomImage>), String> {
    let mut store = crate::open(&opts.target).map_err(|e| e.to_string())?;
    let (id, bundle) = identity(scene, cfg).map_err(|e| format!("store {}: {e}", opts.target))?;
    store
        .begin(&id, &bundle, opts.reset)
        .map_err(|e| e.to_string())?;
    if let Some(keep) = opts.keep_recordings {
        // recordings are aged on the wall clock (their ids are their start, Unix ms)
        #[allow(clippy::disallowed_methods)]
        let now_ms = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as i64);
        crate::prune_recordings(store.as_mut(), now_ms - keep.as_millis() as i64)
            .map_err(|e| e.to_string())?;
    }
    let image = store.load().map_err(|e| e.to_string())?;
    let kept = (!image.objects.is_empty() || !image.retained.is_empty()).then_some(image);
    Ok((StoreWriter::spawn(store), kept))
}

/// Keeps a running room in its store.
pub struct Keeper {
    opts: StoreOptions,
    writer: Option<StoreWriter>,
    tracker: Tracker,
    last_look: Option<Instant>,
    last_checkpoint: Option<Instant>,
    /// We tried to open the store after becoming host and could not.
    unreachable: bool,
    /// The last error said (each said once).
    said: Option<String>,
    /// The session's recording, with `record`.
    recorder: Option<crate::recorder::Recorder>,
}

impl std::fmt::Debug for Keeper {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Keeper")
            .field("target", &self.opts.target)
            .finish()
    }
}

impl Keeper {
    /// A keeper writing through `writer` (a host that opened its store).
    pub fn hosting(opts: StoreOptions, writer: StoreWriter) -> Self {
        Keeper {
            writer: Some(writer),
            ..Keeper::joining(opts)
        }
    }

    /// A keeper for a joiner: it opens the store if it becomes host.
    pub fn joining(opts: StoreOptions) -> Self {
        Keeper {
            recorder: opts.record.then(crate::recorder::Recorder::new),
            opts,
            writer: None,
            tracker: Tracker::new(),
            last_look: None,
            last_checkpoint: None,
            unreachable: false,
            said: None,
        }
    }

    /// What the writer has done (nothing before we host).
    pub fn status(&self) -> Option<WriterStatus> {
        self.writer.as_ref().map(StoreWriter::status)
    }

    /// The store's path or URL.
    pub fn target(&self) -> &str {
        &self.opts.target
    }

    fn say(&mut self, events: &mut Vec<Event>, what: String) {
        if self.said.as_deref() != Some(what.as_str()) {
            events.push(Event::Warning(what.clone()));
            self.said = Some(what);
        }
    }

    /// Called each frame: when hosting, look at the room every `flush` and hand what changed
    /// to the writer (every `checkpoint`, the states too).
    pub fn tick(&mut self, now: Instant, peer: &mut Peer, events: &mut Vec<Event>) {
        if !peer.session().is_host() || self.unreachable {
            return;
        }
        if let (Some(r), true) = (&mut self.recorder, self.writer.is_some()) {
            r.sample(now, peer);
        }
        if self.last_look.is_some_and(|t| now < t + self.opts.flush) {
            return;
        }
        self.last_look = Some(now);
        if self.writer.is_none() {
            // we became host: keep the room where our predecessor did
            let cfg = peer.session().config();
            match open_store(
                &StoreOptions {
                    reset: false,
                    ..self.opts.clone()
                },
                peer.scene(),
                cfg,
            ) {
                Ok((w, _)) => {
                    events.push(Event::Warning(format!(
                        "hosting now: keeping the room in {}",
                        self.opts.target
                    )));
                    self.writer = Some(w);
                }
                Err(e) => {
                    self.unreachable = true;
                    self.say(
                        events,
                        format!("hosting now, but the room is not kept: {e} (the store keeps the room as the last host wrote it)"),
                    );
                    return;
                }
            }
        }
        let failed = self.writer.as_ref().map_or(0, StoreWriter::take_failures) > 0;
        if failed {
            self.tracker.resync();
            let e = self.status().and_then(|s| s.error).unwrap_or_default();
            self.say(
                events,
                format!("the room's store: {e} (the room goes on; the next write brings it whole)"),
            );
        }
        let Some(writer) = &self.writer else { return };
        let checkpoint = self
            .last_checkpoint
            .is_none_or(|t| now >= t + self.opts.checkpoint);
        let image = peer.room_image(now);
        let room = self.tracker.diff(&image, checkpoint);
        if room.as_ref().is_some_and(|b| b.checkpoint) {
            self.last_checkpoint = Some(now);
        }
        let record = self
            .recorder
            .as_mut()
            .and_then(crate::recorder::Recorder::take);
        let batch = match (room, record) {
            (Some(mut b), r) => {
                b.record = r;
                b
            }
            (None, Some(r)) => crate::Batch {
                record: Some(r),
                room_time: image.room_time,
                ..Default::default()
            },
            (None, None) => return,
        };
        if let Err(b) = writer.submit(batch).map_err(|b| *b) {
            // the writer is behind: the next batch carries the whole room, and the recording
            // goes with it
            self.tracker.resync();
            if let (Some(r), Some(rec)) = (&mut self.recorder, b.record) {
                r.give_back(rec);
            }
        }
    }

    /// One of the peer's events (the room calls this for each): recorded, while we host a
    /// recorded session.
    pub fn observe(&mut self, now: Instant, peer: &Peer, e: &Event) {
        if let (Some(r), true) = (&mut self.recorder, peer.session().is_host()) {
            r.observe(now, peer, e);
        }
    }

    /// The room leaves (or the process ends): a last checkpoint, then wait for the writer.
    pub fn finish(&mut self, now: Instant, peer: &Peer) -> Option<WriterStatus> {
        let writer = self.writer.take()?;
        if peer.session().is_host() {
            let image = peer.room_image(now);
            if let Some(mut b) = self.tracker.diff(&image, true) {
                b.record = self
                    .recorder
                    .as_mut()
                    .and_then(crate::recorder::Recorder::take);
                if writer.submit(b).is_err() {
                    self.tracker.resync();
                    if let Some(b) = self.tracker.diff(&image, true) {
                        // the queue was full: wait for it rather than lose the last state (the
                        // room is leaving: no frame waits)
                        #[allow(clippy::disallowed_methods)]
                        std::thread::sleep(Duration::from_millis(50));
                        let _ = writer.submit(b);
                    }
                }
            }
        }
        Some(writer.finish())
    }
}
