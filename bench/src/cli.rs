//! `softsync-bench`'s command line: one subcommand per bench (each writes `docs/results/`).

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// softsync's benchmarks: rooms in one process, and rooms of real `softsync` processes on
/// real WebRTC (run those in a network namespace: the scripts under scripts/ do).
#[derive(Parser, Debug)]
#[command(name = "softsync-bench", version)]
pub struct Cli {
    /// The bench.
    #[command(subcommand)]
    pub bench: Sub,
}

/// The benches.
#[derive(Subcommand, Debug)]
pub enum Sub {
    /// The frame-budget room: 4 peers in one process, 11 soft bodies, two hands on one, a
    /// tear every 2 s, a cut every 10 s, the host stopped at 30 s; 60 s measured
    /// (`RESULT frame.budget`).
    Frame {
        /// Output directory.
        #[arg(long, default_value = "docs/results/frame")]
        out: PathBuf,
        /// 8 s, every kind of event in it (CI's smoke run).
        #[arg(long)]
        quick: bool,
        /// Where the shipped scenes and meshes are (default: the repository's assets/).
        #[arg(long)]
        assets: Option<PathBuf>,
    },
    /// Where a join's time goes: one `softsync host`, joiners one after another, each to
    /// its first state, phase by phase (`RESULT join.breakdown`). Run it in a network
    /// namespace (scripts/bench-net-live --join).
    Join {
        /// Output directory.
        #[arg(long, default_value = "docs/results/live")]
        out: PathBuf,
        /// Joins measured per build.
        #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u16).range(1..=1000))]
        joins: u16,
        /// A `softsync` build to measure, LABEL=PATH; several are measured in turn (default:
        /// the softsync beside this binary, as `this`).
        #[arg(long = "build", value_name = "LABEL=PATH", value_parser = build_arg)]
        builds: Vec<(String, PathBuf)>,
    },
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
    /// The room clock live: a host and two bots dump their room time, the host is SIGKILLed
    /// halfway; how far apart the peers read it before and after (`RESULT clock.room`). Run
    /// it in a network namespace (scripts/netns-run).
    RoomClock {
        /// Output directory.
        #[arg(long, default_value = "docs/results/clock")]
        out: PathBuf,
        /// Seconds before the kill, and after it.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
    },
    /// Voice live: mouth to ear, PESQ, bitrate and lip-sync skew at 0/50/150 ms one-way and
    /// 0/5/20 % loss (`RESULT voice.live`), and a room of 8 with two talking, mesh against
    /// relay (`RESULT voice.room`). Needs espeak-ng; PESQ through scripts/pesq. Run it in a
    /// network namespace (scripts/netns-run).
    Voice {
        /// Output directory.
        #[arg(long, default_value = "docs/results/voice")]
        out: PathBuf,
        /// One condition (50 ms, 5 %), two sayings, and shorter rooms of 8.
        #[arg(long)]
        quick: bool,
    },
    /// The microphone's processing (libspeexdsp) on speech: echo cancellation (an 80 ms +
    /// 60 ms echo path), double talk, noise suppression, gain control and the cost per frame
    /// (`RESULT voice.processing`, over five runs, medians). Needs espeak-ng; no network.
    VoiceProcessing {
        /// Output directory (writes processing.txt and processing.csv).
        #[arg(long, default_value = "docs/results/voice")]
        out: PathBuf,
    },
    /// The room store, SQLite and PostgreSQL side by side: reopening the thesis room with 100
    /// tear segments (`RESULT store.reopen`), and the frame-budget room written as it runs
    /// against the same room unkept, interleaved (`RESULT store.write`). PostgreSQL is a
    /// cluster of the bench's own (as the postgres user, unix socket) unless --postgres.
    Store {
        /// Output directory.
        #[arg(long, default_value = "docs/results/store")]
        out: PathBuf,
        /// A PostgreSQL database to use instead of a cluster of our own (it is emptied).
        #[arg(long, value_name = "URL")]
        postgres: Option<String>,
        /// Rounds of the write bench (each: unkept, SQLite, PostgreSQL).
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=100))]
        rounds: u16,
        /// Seconds measured per run of the write bench (the host stops half-way).
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// Reopens measured per back end.
        #[arg(long, default_value_t = 7, value_parser = clap::value_parser!(u16).range(1..=1000))]
        runs: u16,
        /// Where the shipped scenes and meshes are (default: the repository's assets/).
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
        /// A `softsync` build to run the rooms with, LABEL=PATH; several take turns, round
        /// after round (default: the softsync beside this binary, as `this`).
        #[arg(long = "build", value_name = "LABEL=PATH", value_parser = build_arg)]
        builds: Vec<(String, PathBuf)>,
        /// Rounds of every room size (each build once per round).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=20))]
        rounds: u16,
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

/// `--state-route` of `room-load`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Route {
    /// Through the host.
    Relay,
    /// From each owner to every member.
    Direct,
}

/// Room sizes of `room-load`.
#[derive(Clone, Debug)]
pub struct Sizes(pub Vec<usize>);

/// Attack names of `abuse`.
#[derive(Clone, Debug)]
pub struct Attacks(pub Vec<String>);

fn positive<const MAX: u32>(v: &str) -> Result<f64, String> {
    match v.parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 && s <= f64::from(MAX) => Ok(s),
        _ => Err(format!("{v:?} must be a number in (0, {MAX}]")),
    }
}

fn room_sizes(v: &str) -> Result<Sizes, String> {
    v.split(',')
        .map(|p| match p.trim().parse::<usize>() {
            Ok(n) if (2..=32).contains(&n) => Ok(n),
            _ => Err(format!("{p:?} must be 2-32")),
        })
        .collect::<Result<_, _>>()
        .map(Sizes)
}

fn attacks(v: &str) -> Result<Attacks, String> {
    v.split(',')
        .map(|a| {
            let a = a.trim();
            if crate::live::ATTACKS.contains(&a) {
                Ok(a.to_owned())
            } else {
                Err(format!(
                    "{a:?} is not an attack ({})",
                    crate::live::ATTACKS.join(", ")
                ))
            }
        })
        .collect::<Result<_, _>>()
        .map(Attacks)
}

fn build_arg(v: &str) -> Result<(String, PathBuf), String> {
    match v.split_once('=') {
        Some((label, path)) if !label.is_empty() && !path.is_empty() => {
            Ok((label.to_owned(), PathBuf::from(path)))
        }
        _ => Err(format!("{v:?} is not LABEL=PATH")),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn parse(s: &str) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("softsync-bench").chain(s.split_whitespace()))
    }

    #[test]
    fn every_bench_parses_with_its_defaults() {
        let Sub::RoomLoad { peers, seconds, .. } = parse("room-load --peers 2,4").unwrap().bench
        else {
            panic!()
        };
        assert_eq!((peers.0, seconds), (vec![2, 4], 10.0));
        let Sub::Soak {
            minutes,
            busy_loops,
            ..
        } = parse("soak").unwrap().bench
        else {
            panic!()
        };
        assert_eq!((minutes, busy_loops), (10.0, 0));
        let Sub::Join { joins, builds, .. } = parse("join --build before=/a --build after=/b")
            .unwrap()
            .bench
        else {
            panic!()
        };
        assert_eq!(joins, 20);
        assert_eq!(builds[1], ("after".to_owned(), PathBuf::from("/b")));
        assert!(matches!(
            parse("frame --quick").unwrap().bench,
            Sub::Frame { quick: true, .. }
        ));
    }

    #[test]
    fn bad_values_are_refused_with_what_is_wrong() {
        for (args, says) in [
            ("room-load --peers 2,64", "must be 2-32"),
            ("abuse --attacks junk,nope", "is not an attack"),
            ("join --build nolabel", "LABEL=PATH"),
            ("soak --minutes 0", "(0, 120]"),
            ("nosuch", "unrecognized subcommand"),
        ] {
            let e = parse(args).unwrap_err().to_string();
            assert!(e.contains(says), "{args}: {e}");
        }
    }
}
