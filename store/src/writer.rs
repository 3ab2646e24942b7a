//! The store's writes on their own thread: the frame hands a [`Batch`] over and goes on. A
//! write that fails (a locked file, a full disk, a server gone) is reported in the status and
//! the store keeps what it had (each write is one transaction); the keeper then sends the
//! whole room with its next batch ([`crate::Tracker::resync`]), so the store catches up as
//! soon as a write succeeds again. At most [`QUEUE`] batches wait; a frame that finds the
//! queue full keeps its batch for the next try ([`StoreWriter::submit`] says so).

use std::sync::mpsc::{sync_channel, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::{Batch, RoomStore, StoreInfo};

/// Batches that may wait for the writer.
pub const QUEUE: usize = 8;

/// What the writer has done.
#[derive(Clone, Debug, Default)]
pub struct WriterStatus {
    /// Batches written.
    pub written: u64,
    /// Topology entries and object arrivals/removals written ([`Batch::events`]).
    pub events: u64,
    /// Object rows written.
    pub rows: u64,
    /// Payload bytes written ([`Batch::payload_bytes`]).
    pub bytes: u64,
    /// Checkpoints written.
    pub checkpoints: u64,
    /// Writes that failed.
    pub failures: u64,
    /// The last failure, until a write succeeds again.
    pub error: Option<String>,
    /// Failures the keeper has not acted on yet (it resyncs and clears this).
    pub unacknowledged_failures: u64,
    /// Time spent writing.
    pub busy: Duration,
    /// The room time of the last batch written.
    pub last_room_time: Duration,
}

/// The writer thread and its queue.
pub struct StoreWriter {
    tx: Option<SyncSender<Batch>>,
    status: Arc<Mutex<WriterStatus>>,
    thread: Option<JoinHandle<()>>,
    info: StoreInfo,
}

impl std::fmt::Debug for StoreWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StoreWriter")
            .field("info", &self.info)
            .finish()
    }
}

impl StoreWriter {
    /// Start writing to `store` on a thread of its own.
    pub fn spawn(mut store: Box<dyn RoomStore>) -> Self {
        let info = store.info();
        let (tx, rx) = sync_channel::<Batch>(QUEUE);
        let status = Arc::new(Mutex::new(WriterStatus::default()));
        let st = status.clone();
        let thread = std::thread::Builder::new()
            .name("softsync-store".into())
            .spawn(move || {
                while let Ok(b) = rx.recv() {
                    // a clock for the status only; the room's time is in the batch
                    #[allow(clippy::disallowed_methods)]
                    let t0 = std::time::Instant::now();
                    let r = store.write(&b);
                    let took = t0.elapsed();
                    let Ok(mut s) = st.lock() else { return };
                    s.busy += took;
                    match r {
                        Ok(()) => {
                            s.written += 1;
                            s.events += b.events() as u64;
                            s.rows += b.objects.len() as u64;
                            s.bytes += b.payload_bytes() as u64;
                            s.checkpoints += u64::from(b.checkpoint);
                            s.error = None;
                            s.last_room_time = b.room_time;
                        }
                        Err(e) => {
                            s.failures += 1;
                            s.unacknowledged_failures += 1;
                            s.error = Some(e.to_string());
                        }
                    }
                }
            })
            .ok();
        StoreWriter {
            tx: Some(tx),
            status,
            thread,
            info,
        }
    }

    /// Back end and schema of the store written to.
    pub fn info(&self) -> &StoreInfo {
        &self.info
    }

    /// Hand `batch` to the writer. `Err(batch)` when the queue is full (or the writer is
    /// gone): keep it and try again.
    pub fn submit(&self, batch: Batch) -> Result<(), Box<Batch>> {
        let Some(tx) = &self.tx else {
            return Err(Box::new(batch));
        };
        match tx.try_send(batch) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(b) | TrySendError::Disconnected(b)) => Err(Box::new(b)),
        }
    }

    /// What the writer has done so far.
    pub fn status(&self) -> WriterStatus {
        self.status.lock().map(|s| s.clone()).unwrap_or_default()
    }

    /// Failures since the last call (the caller resyncs its tracker if any).
    pub fn take_failures(&self) -> u64 {
        self.status
            .lock()
            .map(|mut s| std::mem::take(&mut s.unacknowledged_failures))
            .unwrap_or(0)
    }

    /// Write everything queued, then stop the thread.
    pub fn finish(mut self) -> WriterStatus {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.status()
    }
}

impl Drop for StoreWriter {
    fn drop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
