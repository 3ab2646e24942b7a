//! The committed corpora: the seed scripts and the datagrams their sessions sent, and the
//! known issues' smallest scripts.

use super::*;

/// The committed seed corpora, as `(path under net/fuzz/corpus, bytes)`: the scripts of
/// [`seed_scripts`] for `play_session`, and for `decode_packet` one datagram of each kind
/// (its sections' tags, or a refusal) and size that the seeds' sessions sent.
pub fn seed_corpus() -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut kinds: BTreeMap<String, Vec<u8>> = BTreeMap::new();
    for (name, script) in seed_scripts() {
        let bytes = script.to_bytes();
        // what the room's sessions sent (the hostile peer's own bytes are never kept)
        let (_, datagrams) = play_script(&script, Checks::DEFAULT, true);
        for d in datagrams {
            let size = match d.len() {
                0..=31 => "small",
                32..=255 => "medium",
                _ => "large",
            };
            kinds
                .entry(format!("{}-{size}", datagram_kind(&d)))
                .or_insert(d);
        }
        out.push((format!("play_session/{name}"), bytes));
    }
    for (kind, d) in kinds {
        out.push((format!("decode_packet/{kind}"), d));
    }
    // the fixed issues' scripts: regression seeds
    for (name, _, script) in fixed_issue_scripts() {
        out.push((format!("play_session/{name}"), script.to_bytes()));
    }
    out
}

/// A datagram's kind for a file name: its sections' tags in order (`ack-reliable-state`),
/// or `refusal`.
pub(super) fn datagram_kind(d: &[u8]) -> String {
    match crate::wire::decode_datagram(d) {
        Ok(crate::wire::Datagram::Refusal(_)) => "refusal".into(),
        Ok(crate::wire::Datagram::Packet { sections, .. }) => {
            let mut names: Vec<&str> = sections
                .iter()
                .map(|s| match s {
                    Section::Ack { .. } => "ack",
                    Section::Reliable { .. } => "reliable",
                    Section::Ping { .. } => "ping",
                    Section::Pong { .. } => "pong",
                    Section::KeyframeRequest { .. } => "keyframes",
                    Section::State { .. } => "state",
                    Section::StateAck { .. } => "stateack",
                    Section::Message(_) => "message",
                    Section::Beacon(_) => "beacon",
                })
                .collect();
            names.dedup();
            if names.is_empty() {
                "empty".into()
            } else {
                names.join("-")
            }
        }
        Err(_) => "undecodable".into(),
    }
}

/// For each of [`KNOWN_ISSUES`], in order: a name, the issue's index, and the smallest script
/// found that shows it (with [`Checks::STRICT`]). Committed under
/// `net/fuzz/artifacts/play_session/`. Two now: 12 and 13 (0-11 are fixed,
/// [`fixed_issue_scripts`]).
pub fn known_issue_scripts() -> Vec<(&'static str, usize, Script)> {
    use Step::*;
    let lossy = |loss: u8| Wait { ms: 232, loss };
    // the fuzzer's script, three waits retimed when links between members were given slower
    // heartbeats (the original no longer met the race; a search over its waits found these)
    vec![
        (
            "known-12-rejoiner-out-of-step-with-its-host",
            12,
            Script {
                setup: Setup {
                    keyed: true,
                    three_members: true,
                    ..Setup::default()
                },
                steps: vec![
                    Release {
                        peer: 12,
                        object: 0,
                    },
                    wait(0),
                    Release { peer: 4, object: 0 },
                    Wait { ms: 13, loss: 204 },
                    Wait { ms: 0, loss: 232 },
                    Release { peer: 0, object: 0 },
                    Move {
                        peer: 4,
                        object: 0,
                        to: 0,
                    },
                    Despawn { peer: 3, object: 0 },
                    lossy(3),
                    Wait { ms: 0, loss: 216 },
                    Despawn { peer: 0, object: 0 },
                    Despawn { peer: 3, object: 0 },
                    Wait { ms: 16, loss: 3 },
                    wait(0),
                    Move {
                        peer: 0,
                        object: 0,
                        to: 232,
                    },
                    Release { peer: 0, object: 0 },
                    Despawn { peer: 3, object: 0 },
                    Wait { ms: 0, loss: 109 },
                    Leave { peer: 0 },
                ],
            },
        ),
        (
            "known-13-a-room-that-loses-to-a-host-it-never-knew",
            13,
            // the fuzzer's script as `scripts/fuzz --ci` found it (not minimised)
            Script {
                setup: Setup {
                    keyed: false,
                    three_members: false,
                    insider: false,
                    hostile_joins: false,
                    direct: false,
                    budget: false,
                    adaptive: false,
                    refuse_asks: false,
                    seed: 0,
                },
                steps: vec![
                    Spawn { peer: 1, shape: 0 },
                    Wait { ms: 20, loss: 69 },
                    Spawn {
                        peer: 201,
                        shape: 0,
                    },
                    Join { contact: 0 },
                    Spawn {
                        peer: 255,
                        shape: 0,
                    },
                    Wait { ms: 10, loss: 6 },
                    Spawn { peer: 1, shape: 3 },
                    Say {
                        peer: 2,
                        how: 2,
                        len: 30,
                    },
                    Say {
                        peer: 0,
                        how: 3,
                        len: 4,
                    },
                    Say {
                        peer: 1,
                        how: 4,
                        len: 5,
                    },
                    Say {
                        peer: 2,
                        how: 8,
                        len: 1,
                    },
                    Say {
                        peer: 0,
                        how: 12,
                        len: 7,
                    },
                    Say {
                        peer: 2,
                        how: 128,
                        len: 0,
                    },
                    Wait { ms: 225, loss: 255 },
                    Leave { peer: 8 },
                    Release {
                        peer: 11,
                        object: 0,
                    },
                    Wait { ms: 1, loss: 0 },
                    Wait { ms: 32, loss: 200 },
                    Crash { peer: 0 },
                ],
            },
        ),
    ]
}

/// The scripts of the issues this fuzzer found that are fixed (0-9 of
/// `net/fuzz/artifacts/README.md`: the leaks 0-2, the rooms that never converged 3-11): with
/// [`Checks::STRICT`] they pass now. Committed under `net/fuzz/corpus/play_session/` as seeds.
pub fn fixed_issue_scripts() -> Vec<(&'static str, usize, Script)> {
    use Step::*;
    let room = Setup::default();
    vec![
        (
            "fixed-0-link-stats-of-a-dropped-member",
            0,
            Script {
                setup: room,
                steps: vec![Crash { peer: 2 }, wait(150)],
            },
        ),
        (
            "fixed-1-delta-state-of-a-despawned-object",
            1,
            Script {
                setup: room,
                steps: vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(30),
                    Despawn { peer: 0, object: 0 },
                    wait(30),
                ],
            },
        ),
        (
            "fixed-2-asks-of-a-despawned-object",
            2,
            Script {
                setup: Setup {
                    refuse_asks: true,
                    ..room
                },
                steps: vec![
                    Spawn { peer: 1, shape: 1 },
                    wait(30),
                    Grab { peer: 2, object: 0 },
                    wait(30),
                    Despawn { peer: 1, object: 0 },
                    wait(30),
                ],
            },
        ),
        (
            "fixed-4-ghost-of-an-object-the-heir-never-saw",
            4,
            Script {
                setup: room,
                steps: vec![
                    Cut { a: 0, b: 1 },
                    Spawn { peer: 0, shape: 0 },
                    wait(10),
                    Leave { peer: 0 },
                    wait(200),
                ],
            },
        ),
        (
            "fixed-5-joiner-of-a-stalled-host-left-behind",
            5,
            Script {
                setup: room,
                steps: vec![Freeze { peer: 0 }, wait(200), Join { contact: 0 }],
            },
        ),
        (
            "fixed-6-member-cut-off-from-the-heir-left-behind",
            6,
            Script {
                setup: Setup {
                    three_members: true,
                    ..room
                },
                steps: vec![Crash { peer: 0 }, Cut { a: 0, b: 2 }, wait(250)],
            },
        ),
        (
            "fixed-7-restarted-member-never-welcomed",
            7,
            Script {
                setup: room,
                steps: vec![
                    Spawn { peer: 0, shape: 1 },
                    wait(6),
                    Freeze { peer: 0 },
                    wait(94),
                ],
            },
        ),
        (
            "fixed-8-member-ahead-of-the-new-host-s-epoch",
            8,
            Script {
                setup: Setup {
                    three_members: true,
                    ..room
                },
                steps: vec![
                    Spawn { peer: 1, shape: 0 },
                    wait(20),
                    // the owner's own grab waits in the frozen host's socket
                    Freeze { peer: 0 },
                    Grab { peer: 0, object: 0 },
                    Cut { a: 0, b: 1 },
                    Freeze { peer: 0 },
                    Crash { peer: 0 },
                    wait(250),
                ],
            },
        ),
        (
            "fixed-3-host-leaves-as-a-peer-joins",
            3,
            Script {
                setup: room,
                steps: vec![Join { contact: 0 }, Leave { peer: 0 }],
            },
        ),
        (
            "fixed-9-two-heirs-one-never-told",
            9,
            Script {
                setup: room,
                steps: vec![
                    Spawn { peer: 1, shape: 0 },
                    Wait { ms: 20, loss: 69 },
                    Spawn {
                        peer: 201,
                        shape: 0,
                    },
                    Join { contact: 0 },
                    Spawn {
                        peer: 255,
                        shape: 255,
                    },
                    Leave { peer: 250 },
                    Freeze { peer: 0 },
                    Wait { ms: 1, loss: 0 },
                    Wait { ms: 32, loss: 200 },
                    Crash { peer: 0 },
                ],
            },
        ),
        (
            "fixed-6-rival-room-kept-as-a-member",
            6,
            Script {
                setup: room,
                steps: vec![
                    Cut { a: 0, b: 1 },
                    wait(1),
                    wait(140),
                    Leave { peer: 0 },
                    wait(200),
                ],
            },
        ),
        (
            "fixed-11-host-defers-a-rejoiners-hello-behind-an-old-new-host",
            11,
            Script {
                setup: room,
                steps: {
                    let mut steps = vec![
                        Spawn { peer: 0, shape: 0 },
                        Spawn { peer: 1, shape: 22 },
                        Spawn { peer: 2, shape: 2 },
                        wait(30),
                        Move {
                            peer: 0,
                            object: 0,
                            to: 9,
                        },
                        Move {
                            peer: 1,
                            object: 0,
                            to: 247,
                        },
                    ];
                    // 14 long waits, almost every datagram lost: members time out, take over,
                    // yield and rejoin again and again
                    steps.extend((0..14).map(|_| Wait { ms: 247, loss: 247 }));
                    steps.extend([
                        Grab {
                            peer: 0,
                            object: 30,
                        },
                        wait(0),
                    ]);
                    steps
                },
            },
        ),
    ]
}
