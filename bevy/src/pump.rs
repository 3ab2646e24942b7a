//! [`NetPump`]: the room's network pumped on a thread of its own while the frame is elsewhere,
//! so a slow frame (a software renderer, a headset dropping frames, a long asset load) never
//! slows the room: heartbeats, pings, the host's relaying and the data of others keep their
//! own schedule, and the RTT a peer shows is the network's, not its frame time's.
//!
//! The frame and the thread take turns with the [`Room`] — it is moved, never shared: the
//! plugin hands it to the thread after `Last` and takes it back before `First`, so every
//! system of the frame sees a plain `NonSendMut<Room>`, and between frames (rendering, the
//! window's or headset's wait) the thread reads the network every [`PUMP_PERIOD`]. What it
//! receives meanwhile is kept for the next frame: events in the room's queue, objects' states
//! in their interpolation buffers; a failure (refused, timed out) is reported by the next
//! frame's [`Room::network_in`].

// The I/O layer: a thread and its wait.
#![allow(clippy::disallowed_methods)]

use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::room::Room;

/// How often the pump thread reads the network while it holds the room (a heartbeat is
/// 50 ms at the fastest: this keeps an answer's delay small against an RTT, and a relayed
/// state's within a frame). 4 ms, not 2: in a room of 16 every wake-up is paid 16 times
/// over on one machine, and an idle viewer's pump thread was a sixth of its CPU at 2 ms.
pub const PUMP_PERIOD: Duration = Duration::from_millis(4);

#[derive(Default)]
struct Slot {
    room: Option<Room>,
    stop: bool,
}

type Shared = Arc<(Mutex<Slot>, Condvar)>;

fn lock(m: &Mutex<Slot>) -> MutexGuard<'_, Slot> {
    // a panic on the pump thread leaves the room as it was after its last whole pump
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A thread that pumps the room's network while the room is handed to it.
pub struct NetPump {
    shared: Shared,
    thread: Option<JoinHandle<()>>,
}

impl NetPump {
    /// Start the thread (it waits for a room).
    pub fn start() -> std::io::Result<NetPump> {
        let shared: Shared = Arc::new((Mutex::new(Slot::default()), Condvar::new()));
        let s = shared.clone();
        let thread = std::thread::Builder::new()
            .name("softsync-net".into())
            .spawn(move || run(&s))?;
        Ok(NetPump {
            shared,
            thread: Some(thread),
        })
    }

    /// Pump `room` until [`take_back`](Self::take_back).
    pub fn hand_off(&self, room: Room) {
        let (m, cv) = &*self.shared;
        lock(m).room = Some(room);
        cv.notify_one();
    }

    /// The room back (waiting at most for the pump in progress), if it was handed off.
    pub fn take_back(&self) -> Option<Room> {
        lock(&self.shared.0).room.take()
    }

    /// Whether the thread holds a room now.
    pub fn holds_room(&self) -> bool {
        lock(&self.shared.0).room.is_some()
    }
}

impl Drop for NetPump {
    fn drop(&mut self) {
        let (m, cv) = &*self.shared;
        lock(m).stop = true;
        cv.notify_one();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl std::fmt::Debug for NetPump {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NetPump")
            .field("holds_room", &self.holds_room())
            .finish()
    }
}

fn run(shared: &Shared) {
    let (m, cv) = &**shared;
    let mut slot = lock(m);
    loop {
        if slot.stop {
            return;
        }
        slot = match slot.room.as_mut() {
            Some(room) => {
                room.pump_between_frames();
                // the lock is free while we wait: the frame takes the room back at once
                cv.wait_timeout(slot, PUMP_PERIOD)
                    .unwrap_or_else(PoisonError::into_inner)
                    .0
            }
            None => cv.wait(slot).unwrap_or_else(PoisonError::into_inner),
        };
    }
}
