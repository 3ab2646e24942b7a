//! The command lines of `softsync replay` and `softsync store` (recorded sessions).

use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, Subcommand};

/// `softsync replay`'s options.
#[derive(Args, Debug, Clone)]
pub struct ReplayArgs {
    /// The store the session was recorded in (a SQLite file or a postgresql:// URL).
    pub store: String,
    /// Which recording (an id `--list` prints; default: the newest).
    #[arg(long)]
    pub recording: Option<i64>,
    /// Start this many seconds into the recording (a seek).
    #[arg(long, value_name = "S", default_value_t = 0.0, value_parser = super::values::seconds)]
    pub from: f64,
    /// Stop this many seconds into it (default: its end).
    #[arg(long, value_name = "S", value_parser = super::values::seconds)]
    pub to: Option<f64>,
    /// Playback speed: 1 in real time, 4 four times as fast, 0 as fast as it reads.
    #[arg(long, default_value_t = 1.0, value_parser = super::values::seconds)]
    pub speed: f64,
    /// JSON lines of every object's state as recorded, --dump-hz times a recorded second
    /// (the same lines as a peer's --dump).
    #[arg(long, value_name = "FILE")]
    pub dump: Option<PathBuf>,
    /// Dump rate.
    #[arg(long, value_name = "HZ", default_value_t = 5.0, value_parser = super::values::positive::<240>)]
    pub dump_hz: f64,
    /// List the store's recordings and stop.
    #[arg(long)]
    pub list: bool,
    /// Write the recording as CSV into DIR (events.csv; tracks.csv: every object's recorded
    /// states) and stop.
    #[arg(long, value_name = "DIR")]
    pub export: Option<PathBuf>,
    /// From this peer's point of view (an id the recording's `join` events name): its head
    /// and hands go into every dump line, as `as`.
    #[arg(long = "as", value_name = "PEER")]
    pub as_peer: Option<u64>,
    /// Serve the replay as room ROOM, which spectators join (`softsync join --room ROOM
    /// --signal URL`, a desktop or VR peer, or a bot): the recording's objects, locked, move
    /// as recorded; a spectator's `ReplayControl` message pauses, seeks and sets the speed.
    #[arg(long, value_name = "ROOM")]
    pub serve: Option<String>,
    /// Watch it in a window (a desktop peer joined to the served replay, `--serve`'s room or
    /// one named `replay` on a free port): a timeline to pause (space), seek (left, right)
    /// and set the speed (up, down); with `--as`, the view is that peer's head. Serving
    /// stops when the window closes.
    #[arg(long)]
    pub desktop: bool,
    /// An argument for `--desktop`'s viewer (`softsync join --desktop …`), e.g.
    /// `--viewer-arg=--window --viewer-arg=1280x720`; repeat it for several.
    #[arg(long, value_name = "ARG", allow_hyphen_values = true)]
    pub viewer_arg: Vec<String>,
    /// Where the served room's signaling listens (port 0 picks a free one).
    #[arg(long, default_value = "127.0.0.1:3536")]
    pub bind: std::net::SocketAddr,
    /// The served room's key (spectators need it, or a token): a file with the secret, or
    /// SOFTSYNC_ROOM_KEY.
    #[arg(long, value_name = "FILE")]
    pub room_key_file: Option<PathBuf>,
    /// Keep serving this long after the recording's end (spectators may seek back).
    #[arg(long, value_name = "S", default_value_t = 5.0, value_parser = super::values::seconds)]
    pub linger: f64,
}

/// What `softsync store` does.
#[derive(Subcommand, Debug, Clone)]
pub enum StoreAction {
    /// List the recorded sessions.
    List {
        /// The store.
        store: String,
    },
    /// Delete one recorded session (the room's state stays).
    Delete {
        /// The store.
        store: String,
        /// The recording's id (`softsync store list`).
        #[arg(long)]
        session: i64,
    },
    /// Delete every recorded session older than D (e.g. 30d, 12h, 90m); the room's state
    /// stays.
    Prune {
        /// The store.
        store: String,
        /// The age: a number and d, h, m or s.
        #[arg(long, value_name = "D", value_parser = age)]
        older_than: Duration,
    },
}

/// `30d`, `12h`, `90m`, `45s`.
pub fn age(s: &str) -> Result<Duration, String> {
    let (n, unit) = s.split_at(s.len().saturating_sub(1));
    let secs = match unit {
        "d" => 86_400.0,
        "h" => 3_600.0,
        "m" => 60.0,
        "s" => 1.0,
        _ => return Err(format!("{s:?}: a number then d, h, m or s (e.g. 30d)")),
    };
    match n.parse::<f64>() {
        Ok(x) if x.is_finite() && x >= 0.0 && x * secs < 1e10 => {
            Ok(Duration::from_secs_f64(x * secs))
        }
        _ => Err(format!("{s:?}: a number then d, h, m or s (e.g. 30d)")),
    }
}
