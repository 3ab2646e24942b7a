//! `softsync bench …`: the benchmarks' subcommands (each runs rooms of real processes or the
//! library in-process and writes `docs/results/`).

use std::path::PathBuf;

use clap::Subcommand;

use super::values::*;

#[derive(Subcommand, Debug)]
pub(super) enum BenchSub {
    /// Bandwidth and error of a live two-peer room under send policies and link conditions.
    NetLive {
        /// Output directory.
        #[arg(long, default_value = "docs/results/live")]
        out: PathBuf,
        /// Seconds measured per configuration.
        #[arg(long, default_value_t = 8.0, value_parser = positive::<600>)]
        seconds: f64,
        /// Fewer configurations.
        #[arg(long)]
        quick: bool,
        /// Only centre-only sync against per-particle sync (thesis §5.4.1): the 60-particle
        /// ball dragged by a bot, both modes, `RESULT centre_only.live`.
        #[arg(long)]
        centre_only: bool,
    },
    /// `method: auto` against every soft body at its finest and at its 1x level: the
    /// thesis room (assets/thesis-room-auto.ron) in-process, one bot script, step cost and
    /// the error each soft body shows (`RESULT framework.auto`).
    Auto {
        /// Output directory.
        #[arg(long, default_value = "docs/results/auto")]
        out: PathBuf,
        /// Seconds of the script (it takes 15; less cuts it short).
        #[arg(long, default_value_t = 16.0, value_parser = positive::<600>)]
        seconds: f64,
        /// Where the shipped scenes and meshes are (default: ./assets, or next to the binary).
        #[arg(long)]
        assets: Option<PathBuf>,
    },
    /// Several hands from several processes on the thesis room's bunny (remote hands): own
    /// response, remote-hand lag, gap, agreement (`RESULT comanip.live`). Run it in a network
    /// namespace (scripts/bench-comanip).
    Comanip {
        /// Output directory.
        #[arg(long, default_value = "docs/results/comanip")]
        out: PathBuf,
        /// Two rooms instead of four.
        #[arg(long)]
        quick: bool,
    },
    /// A live room of four honest peers and one hostile process (`softsync-hostile`, built
    /// from the test crate): one attack after another, each after a window of the honest room
    /// alone (`RESULT abuse.host`). Run it in a network namespace (scripts/bench-abuse).
    Abuse {
        /// Output directory.
        #[arg(long, default_value = "docs/results/abuse")]
        out: PathBuf,
        /// Seconds per attack (and per honest window before it).
        #[arg(long, default_value_t = 60.0, value_parser = positive::<600>)]
        seconds: f64,
        /// Attacks, comma-separated: hello-flood, never-ack, request-flood, junk, idents,
        /// beacons (default: all).
        #[arg(long, value_parser = attacks)]
        attacks: Option<Attacks>,
        /// The hostile client (default: `softsync-hostile` beside this binary).
        #[arg(long, value_name = "PATH")]
        hostile: Option<PathBuf>,
    },
    /// Rooms of growing size.
    RoomLoad {
        /// Output directory.
        #[arg(long, default_value = "docs/results/live")]
        out: PathBuf,
        /// Seconds measured per room.
        #[arg(long, default_value_t = 10.0, value_parser = positive::<600>)]
        seconds: f64,
        /// Room sizes (peers, host included), comma-separated, each 2-32.
        #[arg(long, default_value = "2,4,8", value_parser = room_sizes)]
        peers: Sizes,
        /// Which way object state travels in the rooms (every peer gets the same).
        #[arg(long, value_enum, default_value = "relay")]
        state_route: Route,
    },
    /// Many rooms through signaling behind HAProxy (three instances, the room's path hashed):
    /// rooms of light signaling clients and a few of real peers, then one instance killed;
    /// every room must take a new joiner (`RESULT lb.*`; exits 1 if one does not). Needs
    /// haproxy; run it in a network namespace (scripts/bench-signal-lb): it binds
    /// 127.0.0.1:3536 and 3601-3603.
    SignalLb {
        /// Output directory.
        #[arg(long, default_value = "docs/results/live")]
        out: PathBuf,
        /// Rooms of light clients (a host and a joiner each).
        #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u16).range(1..=2000))]
        rooms: u16,
        /// Rooms of real peers (WebRTC) besides.
        #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u16).range(0..=16))]
        real_rooms: u16,
        /// Rooms opened at once.
        #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u16).range(1..=256))]
        parallel: u16,
        /// The HAProxy configuration.
        #[arg(long, default_value = "deploy/haproxy/signal.cfg")]
        config: PathBuf,
    },
    /// A churn soak: a room of bots for a bounded time while a seeded scheduler joins,
    /// leaves, kills and stops peers and the host; the room's invariants are checked every
    /// second from the dumps (`RESULT soak … violations=…`; exits 1 on a violation).
    Soak {
        /// Output directory (timeline CSV and chart, the event log).
        #[arg(long, default_value = "docs/results/soak")]
        out: PathBuf,
        /// Minutes of churn (after an 8 s warm-up).
        #[arg(long, default_value_t = 10.0, value_parser = positive::<120>)]
        minutes: f64,
        /// The scheduler's seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Processes at the start, the host counted (2-16).
        #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u16).range(2..=16))]
        peers: u16,
        /// Never more processes than this (the start counted; 2-16).
        #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u16).range(2..=16))]
        max_peers: u16,
        /// Threads that spin for the whole soak, beside the room (1 on 2 cores: half the
        /// CPU), so the peers' processes are starved as on a loaded machine.
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u16).range(0..=64))]
        busy_loops: u16,
    },
}
