//! A script: the room it starts with, its steps (every byte string reads as one), the
//! checks, and the entry points that play it.

use super::*;

/// Most steps one script plays.
pub const MAX_STEPS: usize = 256;

/// Most virtual time the steps of one script take (the room's start and the settling at the
/// end aside).
pub const MAX_VIRTUAL_TIME: Duration = Duration::from_secs(60);

/// The peer that hosts when a script starts; the first members are 2 to 4, peers that join
/// later 5 to [`MAX_HONEST_ID`].
pub const FIRST_HOST: PeerId = PeerId(1);

/// The highest id an honest peer gets.
pub const MAX_HONEST_ID: u64 = 8;

/// The hostile peer: what it sends is the script's (a modified client, as far as the room
/// can tell). Behind it runs a session of its own (the "puppet"), whose sequencing makes
/// its forged control messages arrive in order.
pub const HOSTILE: PeerId = PeerId(66);

/// Ids of further hostile senders (a flood of joiners, replays from made-up peers):
/// `STRANGERS + k`.
pub const STRANGERS: u64 = 1000;

/// The room's secret in a room with a key.
pub(super) const SECRET: &[u8] = b"the fuzzed room's secret, 32 bytes";

/// Datagrams remembered for replays and mutations.
pub(super) const CAPTURED: usize = 64;

/// Datagrams waiting for a frozen peer (more are lost, as a full socket buffer loses them).
pub(super) const INBOX: usize = 512;

/// Fresh sessions the honest peers may start after being dropped.
pub(super) const MAX_REJOINS: u32 = 32;

/// A joiner with no answer asks another peer after this long (what the peer layer does).
pub(super) const JOIN_RETRY: Duration = Duration::from_secs(2);

/// Delivery rounds per flush (each round delivers what the last one made peers send).
pub(super) const FLUSH_ROUNDS: usize = 32;

/// Datagrams one `poll_transmit` loop may give before it counts as never running dry.
pub(super) const MAX_BURST: usize = 50_000;

/// Steps between the slower checks ([`Session::leftovers`]).
pub(super) const LEFTOVERS_EVERY: usize = 32;

/// How long the room settles after the steps, the network healed, before the convergence
/// check.
pub(super) const SETTLE: Duration = Duration::from_secs(20);

/// How the room of a script is made: its first two bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Setup {
    /// The room has a key (bit 0).
    pub keyed: bool,
    /// Three members besides the host, not two (bit 1).
    pub three_members: bool,
    /// The hostile peer holds the room's key (bit 2): an insider.
    pub insider: bool,
    /// The hostile peer's own session takes part from the start (bit 3; step `Attach`
    /// toggles it).
    pub hostile_joins: bool,
    /// State goes straight from owners to members (bit 4).
    pub direct: bool,
    /// Every peer's uplink has a budget (bit 5).
    pub budget: bool,
    /// The adaptive failure detector with fast heartbeats (bit 6).
    pub adaptive: bool,
    /// Owners refuse when asked for their objects (bit 7; else they agree).
    pub refuse_asks: bool,
    /// Seed of the loss draws (second byte).
    pub seed: u8,
}

impl Setup {
    pub(super) fn from_bytes(b0: u8, b1: u8) -> Self {
        let bit = |i: u8| b0 & (1 << i) != 0;
        Setup {
            keyed: bit(0),
            three_members: bit(1),
            insider: bit(2),
            hostile_joins: bit(3),
            direct: bit(4),
            budget: bit(5),
            adaptive: bit(6),
            refuse_asks: bit(7),
            seed: b1,
        }
    }

    pub(super) fn to_bytes(self) -> [u8; 2] {
        let bits = [
            self.keyed,
            self.three_members,
            self.insider,
            self.hostile_joins,
            self.direct,
            self.budget,
            self.adaptive,
            self.refuse_asks,
        ];
        let b0 = bits
            .iter()
            .enumerate()
            .fold(0u8, |acc, (i, b)| acc | (u8::from(*b) << i));
        [b0, self.seed]
    }
}

/// One step of a script. Its bytes: an opcode (its position in this list, modulo the list's
/// length), then its operands in order (a `Raw` datagram's bytes length-prefixed); missing
/// bytes read as zero. Operands pick among what exists (`peer` modulo the live peers,
/// `object` modulo the objects that peer knows), so every byte string is a script.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Step {
    /// `(ms + 1) × 10` ms pass; datagrams among the room are lost with chance
    /// `[0, 5 %, 20 %, 50 %][loss % 4]` from now on.
    Wait {
        /// Time.
        ms: u8,
        /// Loss.
        loss: u8,
    },
    /// An honest peer spawns a rigid, a soft (1 to 12 particles, its owner must agree to
    /// hand it over) or a locked object.
    Spawn {
        /// Which peer.
        peer: u8,
        /// Class, particles, place.
        shape: u8,
    },
    /// An honest peer asks for an object's authority.
    Grab {
        /// Which peer.
        peer: u8,
        /// Which of its objects.
        object: u8,
    },
    /// An honest peer lets go of an object.
    Release {
        /// Which peer.
        peer: u8,
        /// Which of its objects.
        object: u8,
    },
    /// An honest peer despawns an object.
    Despawn {
        /// Which peer.
        peer: u8,
        /// Which of its objects.
        object: u8,
    },
    /// An honest peer moves an object it owns (publishes a new state).
    Move {
        /// Which peer.
        peer: u8,
        /// Which of the objects it owns.
        object: u8,
        /// Where to.
        to: u8,
    },
    /// An honest peer sends an application message.
    Say {
        /// Which peer.
        peer: u8,
        /// Delivery, target and kind.
        how: u8,
        /// Payload length (modulo 64).
        len: u8,
    },
    /// An honest peer asks for a topology change of an object it owns (tear, lift, cut,
    /// resolution).
    Reshape {
        /// Which peer.
        peer: u8,
        /// Which of the objects it owns.
        object: u8,
        /// What change.
        how: u8,
    },
    /// An honest peer leaves (says `Leave`, then is gone).
    Leave {
        /// Which peer.
        peer: u8,
    },
    /// An honest peer crashes (gone without a word).
    Crash {
        /// Which peer.
        peer: u8,
    },
    /// A new honest peer joins through a live one (which may redirect it).
    Join {
        /// Its contact.
        contact: u8,
    },
    /// An honest peer's loop stalls, or resumes (datagrams for it wait meanwhile).
    Freeze {
        /// Which peer.
        peer: u8,
    },
    /// The link between two honest peers is cut, or restored.
    Cut {
        /// One end.
        a: u8,
        /// The other.
        b: u8,
    },
    /// The hostile peer (or, bit 6 of `from`, a made-up sender) sends raw bytes, behind a
    /// valid header of the recipient's term if bit 7 of `from` is set.
    Raw {
        /// Recipient.
        to: u8,
        /// Sender and header.
        from: u8,
        /// The bytes (at most 255).
        bytes: Vec<u8>,
    },
    /// A datagram of the room's, captured, goes again: as it was (a duplicate, to its
    /// recipient), or from the hostile peer (to the same or another recipient, or from a
    /// made-up sender), or changed (a bit flipped, a byte overwritten, cut short, its
    /// sections repeated).
    Replay {
        /// Which captured datagram.
        pick: u8,
        /// What is done to it.
        how: u8,
        /// Where in it.
        at: u8,
        /// With what.
        value: u8,
        /// Recipient, when it changes.
        to: u8,
    },
    /// The hostile peer sends a control message of its choosing (its puppet's reliable
    /// channel sequences it): any `Control`, made of what the recipient knows and the
    /// operands.
    Forge {
        /// Recipient.
        to: u8,
        /// Which message.
        what: u8,
        /// Its fields.
        args: [u8; 4],
    },
    /// `count % 48 + 1` made-up peers say `Hello` to an honest peer (a wrong digest if bit
    /// 7 is set).
    Hellos {
        /// Recipient.
        to: u8,
        /// How many.
        count: u8,
    },
    /// The hostile peer sends a beacon of a made-up room.
    Beacon {
        /// Recipient.
        to: u8,
        /// Term, summary, tag.
        args: [u8; 3],
    },
    /// The hostile peer's own session starts, or stops, taking part (its datagrams are
    /// delivered, its timers run).
    Attach,
}

/// Opcodes: a step's position in [`Step`].
pub(super) const OPCODES: u8 = 19;

impl Step {
    pub(super) fn opcode(&self) -> u8 {
        match self {
            Step::Wait { .. } => 0,
            Step::Spawn { .. } => 1,
            Step::Grab { .. } => 2,
            Step::Release { .. } => 3,
            Step::Despawn { .. } => 4,
            Step::Move { .. } => 5,
            Step::Say { .. } => 6,
            Step::Reshape { .. } => 7,
            Step::Leave { .. } => 8,
            Step::Crash { .. } => 9,
            Step::Join { .. } => 10,
            Step::Freeze { .. } => 11,
            Step::Cut { .. } => 12,
            Step::Raw { .. } => 13,
            Step::Replay { .. } => 14,
            Step::Forge { .. } => 15,
            Step::Hellos { .. } => 16,
            Step::Beacon { .. } => 17,
            Step::Attach => 18,
        }
    }

    /// Append the step's bytes.
    pub fn encode(&self, out: &mut Vec<u8>) {
        out.push(self.opcode());
        match self {
            Step::Wait { ms, loss } => out.extend([*ms, *loss]),
            Step::Spawn { peer, shape } => out.extend([*peer, *shape]),
            Step::Grab { peer, object }
            | Step::Release { peer, object }
            | Step::Despawn { peer, object } => out.extend([*peer, *object]),
            Step::Move { peer, object, to } => out.extend([*peer, *object, *to]),
            Step::Say { peer, how, len } => out.extend([*peer, *how, *len]),
            Step::Reshape { peer, object, how } => out.extend([*peer, *object, *how]),
            Step::Leave { peer } | Step::Crash { peer } | Step::Freeze { peer } => out.push(*peer),
            Step::Join { contact } => out.push(*contact),
            Step::Cut { a, b } => out.extend([*a, *b]),
            Step::Raw { to, from, bytes } => {
                let bytes = bytes.get(..bytes.len().min(255)).unwrap_or_default();
                out.extend([*to, *from, bytes.len() as u8]);
                out.extend_from_slice(bytes);
            }
            Step::Replay {
                pick,
                how,
                at,
                value,
                to,
            } => out.extend([*pick, *how, *at, *value, *to]),
            Step::Forge { to, what, args } => {
                out.extend([*to, *what]);
                out.extend(args);
            }
            Step::Hellos { to, count } => out.extend([*to, *count]),
            Step::Beacon { to, args } => {
                out.push(*to);
                out.extend(args);
            }
            Step::Attach => {}
        }
    }

    pub(super) fn decode(r: &mut Reader<'_>) -> Step {
        match r.u8() % OPCODES {
            0 => Step::Wait {
                ms: r.u8(),
                loss: r.u8(),
            },
            1 => Step::Spawn {
                peer: r.u8(),
                shape: r.u8(),
            },
            2 => Step::Grab {
                peer: r.u8(),
                object: r.u8(),
            },
            3 => Step::Release {
                peer: r.u8(),
                object: r.u8(),
            },
            4 => Step::Despawn {
                peer: r.u8(),
                object: r.u8(),
            },
            5 => Step::Move {
                peer: r.u8(),
                object: r.u8(),
                to: r.u8(),
            },
            6 => Step::Say {
                peer: r.u8(),
                how: r.u8(),
                len: r.u8(),
            },
            7 => Step::Reshape {
                peer: r.u8(),
                object: r.u8(),
                how: r.u8(),
            },
            8 => Step::Leave { peer: r.u8() },
            9 => Step::Crash { peer: r.u8() },
            10 => Step::Join { contact: r.u8() },
            11 => Step::Freeze { peer: r.u8() },
            12 => Step::Cut {
                a: r.u8(),
                b: r.u8(),
            },
            13 => {
                let to = r.u8();
                let from = r.u8();
                let n = usize::from(r.u8());
                Step::Raw {
                    to,
                    from,
                    bytes: r.take(n).to_vec(),
                }
            }
            14 => Step::Replay {
                pick: r.u8(),
                how: r.u8(),
                at: r.u8(),
                value: r.u8(),
                to: r.u8(),
            },
            15 => Step::Forge {
                to: r.u8(),
                what: r.u8(),
                args: [r.u8(), r.u8(), r.u8(), r.u8()],
            },
            16 => Step::Hellos {
                to: r.u8(),
                count: r.u8(),
            },
            17 => Step::Beacon {
                to: r.u8(),
                args: [r.u8(), r.u8(), r.u8()],
            },
            _ => Step::Attach,
        }
    }
}

/// A script: how the room is made, and the steps played in it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Script {
    /// The room.
    pub setup: Setup,
    /// The steps (at most [`MAX_STEPS`] are played).
    pub steps: Vec<Step>,
}

impl Script {
    /// The script's bytes (what [`play_session`] reads).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = self.setup.to_bytes().to_vec();
        for s in &self.steps {
            s.encode(&mut out);
        }
        out
    }

    /// The script `data` encodes (every byte string is one).
    pub fn from_bytes(data: &[u8]) -> Script {
        let mut r = Reader { data, pos: 0 };
        let setup = Setup::from_bytes(r.u8(), r.u8());
        let mut steps = Vec::new();
        while !r.done() && steps.len() < MAX_STEPS {
            steps.push(Step::decode(&mut r));
        }
        Script { setup, steps }
    }
}

/// Bytes read one at a time; zeros past the end.
pub(super) struct Reader<'a> {
    pub(super) data: &'a [u8],
    pub(super) pos: usize,
}

impl Reader<'_> {
    pub(super) fn u8(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    pub(super) fn take(&mut self, n: usize) -> &[u8] {
        let start = self.pos.min(self.data.len());
        let end = (self.pos + n).min(self.data.len());
        self.pos += n;
        self.data.get(start..end).unwrap_or_default()
    }

    pub(super) fn done(&self) -> bool {
        self.pos >= self.data.len()
    }
}

/// What the checks beyond the design's promises look at (see [`play_with`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Checks {
    /// State kept for objects a session no longer knows, or peers it keeps no link to
    /// ([`Session::leftovers`]), must be none.
    pub leftovers: bool,
    /// After a script in which nothing hostile happened, a healed network must make one
    /// room again: every live honest peer in it, agreeing on the host, the objects and their
    /// owners.
    pub converge: bool,
    /// Also fail on the issues this fuzzer found that are not fixed yet ([`KNOWN_ISSUES`]);
    /// off, their figures are left out of the checks.
    pub strict: bool,
}

impl Checks {
    /// Every check, the known issues left out: what the fuzz target and the tests run.
    pub const DEFAULT: Checks = Checks {
        leftovers: true,
        converge: true,
        strict: false,
    };

    /// Every check, the known issues included: fails until they are fixed.
    pub const STRICT: Checks = Checks {
        strict: true,
        ..Checks::DEFAULT
    };
}

/// Issues this fuzzer found that are not fixed yet, by their number in
/// `net/fuzz/artifacts/README.md` (0-11 are fixed; their scripts stay as regression seeds,
/// [`fixed_issue_scripts`](super::fixed_issue_scripts)); [`Checks::DEFAULT`] leaves their
/// figures out, so the fuzzer goes on looking for others. Remove an entry with its fix.
pub const KNOWN_ISSUES: &[(usize, &str)] = &[
    (
        12,
        "a peer that rejoins a host that had welcomed and then dropped its joining session never \
     gets in: the host takes the session's term-0 datagrams for a fresh session's and resets \
     its link (`receive`, session/recv.rs), but the session is not fresh, and the two ends' \
     reliable sequences no longer meet (no session number in the header); the limit beneath \
     the fixed issue 7",
    ),
    (
        13,
        "a partition's two rooms never merge when the losing room lost none of the winning \
     room's peers (the winner's host joined, or was known, only on the other side): the \
     winner's beacons reach the loser from a stranger, whose summary may never make a room \
     yield (issue 32), and the loser beacons only the peers it lost (session/heal.rs)",
    ),
];

/// What a played script did (tests check that a seed does what its name says).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Outcome {
    /// Steps played.
    pub steps: usize,
    /// Virtual time the steps took, ms.
    pub virtual_ms: u64,
    /// Datagrams delivered among the room (lost ones aside).
    pub datagrams: usize,
    /// `Joined` events of honest peers.
    pub joined: usize,
    /// `Refused` events of honest peers.
    pub refused: usize,
    /// `Dropped` events of honest peers (each joins again with a fresh session).
    pub dropped: usize,
    /// `HostChanged` events.
    pub host_changes: usize,
    /// `AuthorityChanged` events.
    pub authority_changes: usize,
    /// `AuthorityDenied` events.
    pub denied: usize,
    /// `Spawned` events.
    pub spawned: usize,
    /// `Despawned` events.
    pub despawned: usize,
    /// `Topology` events.
    pub topology: usize,
    /// `Message` events.
    pub messages: usize,
    /// Whether the hostile peer (or a made-up one) sent anything.
    pub hostile: bool,
    /// Honest peers in the room at the end, if the convergence check ran (it passed).
    pub converged: Option<usize>,
}

/// Play `data` as a [`Script`] with every check on: see [`play_with`].
pub fn play_session(data: &[u8]) {
    play_with(data, Checks::DEFAULT);
}

/// Play `data` as a [`Script`]: a host and two or three members, maybe with a room key, the
/// hostile peer, then the script's steps on virtual time (at most [`MAX_STEPS`] and
/// [`MAX_VIRTUAL_TIME`]). Every honest peer that is dropped joins again with a fresh
/// session. After every step it asserts:
///
/// - no two honest sessions that follow the same honest host in the same term each believe
///   they own one object at the same authority epoch (an epoch is granted once; a session
///   that missed a later grant still believes in an older epoch, which is allowed: it learns
///   of the grant on its ordered channel);
/// - no honest member holds an epoch of its host's term newer than the host's own record of
///   the object (only the host grants in its term);
/// - every honest session's [`Session::footprint`] is within its caps
///   ([`crate::session::Footprint::check`]);
/// - every replicated state is finite, as shown and as last received;
///
/// and, with `checks`, every 32 steps and at the end that no session keeps state for what
/// it no longer knows ([`Session::leftovers`]), and at the end of a script without hostile
/// traffic that the room converges once the network heals: within 20 s of virtual time
/// without loss, cuts or stalls, every live honest peer is in one room, whose host has them
/// all as members, and they agree on the objects, their owners and epochs. Without
/// `checks.strict`, the figures of [`KNOWN_ISSUES`] are left out: a convergence failure is
/// not reported while a peer that was not refused is still joining (issue 12).
pub fn play_with(data: &[u8], checks: Checks) -> Outcome {
    play_script(&Script::from_bytes(data), checks, false).0
}

/// [`play_with`], printing every step and every honest peer's events to stderr as they
/// happen (to see what led to a failure; `replay_an_input` in `net/tests/fuzz_sessions.rs`
/// does it for a file).
pub fn play_traced(data: &[u8], checks: Checks) -> Outcome {
    TRACE.with(|t| t.set(true));
    let r = std::panic::catch_unwind(|| play_with(data, checks));
    TRACE.with(|t| t.set(false));
    r.unwrap_or_else(|e| std::panic::resume_unwind(e))
}

thread_local! {
    static TRACE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Print a trace line, if tracing.
pub(super) fn trace(line: impl FnOnce() -> String) {
    if TRACE.with(std::cell::Cell::get) {
        eprintln!("{}", line());
    }
}

/// Play `script`; with `keep`, also every datagram sent among the room (for a corpus).
pub(super) fn play_script(script: &Script, checks: Checks, keep: bool) -> (Outcome, Vec<Vec<u8>>) {
    let mut room = Room::new(script.setup, keep);
    trace(|| format!("{:?}", script.setup));
    let start = room.now;
    for (i, step) in script.steps.iter().enumerate() {
        room.step = i;
        trace(|| format!("{:>8} ms  step {i}: {step:?}", room.now.as_micros() / 1000));
        room.play(step);
        room.check(checks);
        if checks.leftovers && i % LEFTOVERS_EVERY == LEFTOVERS_EVERY - 1 {
            room.check_leftovers(checks);
        }
    }
    room.outcome.steps = script.steps.len();
    room.outcome.virtual_ms = room.now.saturating_since(start).as_millis() as u64;
    room.outcome.hostile = room.hostile_spoke;
    if checks.leftovers {
        room.check_leftovers(checks);
    }
    if checks.converge && !room.hostile_spoke {
        room.settle_and_check_convergence(checks.strict);
    }
    (room.outcome, room.keep_all.unwrap_or_default())
}
