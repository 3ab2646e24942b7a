//! The seed corpus (valid sessions: joins, keyed joins, migrations, authority moves,
//! spawns) and the known issues' smallest scripts.

use super::*;

/// `(ms + 1) × 10` ms without loss.
pub(super) fn wait(ms: u8) -> Step {
    Step::Wait { ms, loss: 0 }
}

/// The named scripts the `play_session` corpus starts from: valid sessions (joins, keyed
/// joins, migrations, authority moving, spawns, messages, topology, partitions, stalls) and
/// a few of each hostile move. Peers are picked by index among the running ones: 0 is the
/// first host, 1 to 3 the first members.
pub fn seed_scripts() -> Vec<(&'static str, Script)> {
    use Step::*;
    let room = Setup::default();
    let keyed = Setup {
        keyed: true,
        three_members: true,
        ..room
    };
    let four = Setup {
        three_members: true,
        ..room
    };
    let hostile = Setup {
        hostile_joins: true,
        ..room
    };
    let soft8 = 22; // class 22 % 3 = 1 (soft), 1 + 22 / 3 % 12 = 8 particles
    let script = |setup: Setup, steps: Vec<Step>| Script { setup, steps };
    let mut seeds = vec![
        ("join", script(room, vec![wait(50)])),
        ("join_keyed", script(keyed, vec![wait(50)])),
        (
            "join_late_via_a_member",
            script(
                room,
                vec![Join { contact: 1 }, wait(50), Join { contact: 0 }, wait(50)],
            ),
        ),
        (
            "spawn_each_class",
            script(
                room,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    Spawn {
                        peer: 1,
                        shape: soft8,
                    },
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
                        to: 40,
                    },
                    wait(30),
                ],
            ),
        ),
        (
            "grab_move_release",
            script(
                room,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(20),
                    Grab { peer: 1, object: 0 },
                    wait(20),
                    Move {
                        peer: 1,
                        object: 0,
                        to: 3,
                    },
                    wait(10),
                    Move {
                        peer: 1,
                        object: 0,
                        to: 77,
                    },
                    wait(20),
                    Release { peer: 1, object: 0 },
                    wait(20),
                ],
            ),
        ),
        (
            "grab_of_a_held_object_is_denied",
            script(
                room,
                vec![
                    Spawn { peer: 1, shape: 0 },
                    wait(20),
                    Grab { peer: 2, object: 0 },
                    Grab { peer: 0, object: 0 },
                    wait(20),
                ],
            ),
        ),
        (
            "owner_asked_agrees",
            script(
                room,
                vec![
                    Spawn {
                        peer: 1,
                        shape: soft8,
                    },
                    wait(20),
                    Grab { peer: 2, object: 0 },
                    wait(20),
                    Move {
                        peer: 2,
                        object: 0,
                        to: 5,
                    },
                    wait(20),
                ],
            ),
        ),
        (
            "owner_asked_refuses",
            script(
                Setup {
                    refuse_asks: true,
                    ..room
                },
                vec![
                    Spawn {
                        peer: 1,
                        shape: soft8,
                    },
                    wait(20),
                    Grab { peer: 2, object: 0 },
                    wait(20),
                ],
            ),
        ),
        (
            "locked_stays_with_the_host",
            script(
                room,
                vec![
                    Spawn { peer: 0, shape: 2 },
                    wait(20),
                    Grab { peer: 1, object: 0 },
                    wait(20),
                ],
            ),
        ),
        (
            "despawns",
            script(
                room,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    Spawn { peer: 1, shape: 3 },
                    wait(20),
                    Despawn { peer: 0, object: 0 },
                    Despawn { peer: 1, object: 0 },
                    wait(20),
                ],
            ),
        ),
        (
            "host_leaves",
            script(
                four,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    Spawn {
                        peer: 1,
                        shape: soft8,
                    },
                    wait(20),
                    Leave { peer: 0 },
                    wait(150),
                ],
            ),
        ),
        (
            "host_crashes",
            script(
                four,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    Spawn { peer: 2, shape: 0 },
                    wait(20),
                    Grab { peer: 1, object: 0 },
                    wait(20),
                    Crash { peer: 0 },
                    wait(250),
                ],
            ),
        ),
        (
            "member_crashes_and_its_objects_return",
            script(
                room,
                vec![
                    Spawn { peer: 1, shape: 0 },
                    wait(20),
                    Crash { peer: 1 },
                    wait(200),
                ],
            ),
        ),
        (
            "keyed_migration_then_a_late_join",
            script(
                keyed,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(20),
                    Crash { peer: 0 },
                    wait(250),
                    Join { contact: 0 },
                    wait(100),
                ],
            ),
        ),
        (
            "handoff_in_flight_when_the_host_dies",
            script(
                four,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(20),
                    Step::Wait { ms: 0, loss: 2 },
                    Grab { peer: 2, object: 0 },
                    Crash { peer: 0 },
                    Step::Wait { ms: 250, loss: 1 },
                ],
            ),
        ),
        (
            "messages",
            script(
                room,
                vec![
                    Spawn { peer: 1, shape: 0 },
                    wait(20),
                    Say {
                        peer: 0,
                        how: 0,
                        len: 10,
                    },
                    Say {
                        peer: 1,
                        how: 1,
                        len: 3,
                    },
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
                        len: 9,
                    },
                    wait(30),
                ],
            ),
        ),
        (
            "retained_state_reaches_a_late_joiner",
            script(
                room,
                vec![
                    Say {
                        peer: 1,
                        how: 2,
                        len: 12,
                    },
                    wait(20),
                    Join { contact: 0 },
                    wait(50),
                ],
            ),
        ),
        (
            "tear_lift_cut_resolution",
            script(
                room,
                vec![
                    Spawn {
                        peer: 1,
                        shape: soft8,
                    },
                    wait(20),
                    Reshape {
                        peer: 1,
                        object: 0,
                        how: 0,
                    },
                    Reshape {
                        peer: 1,
                        object: 0,
                        how: 4,
                    },
                    Reshape {
                        peer: 1,
                        object: 0,
                        how: 1,
                    },
                    wait(20),
                    Reshape {
                        peer: 1,
                        object: 0,
                        how: 7,
                    },
                    wait(20),
                    Reshape {
                        peer: 1,
                        object: 0,
                        how: 2,
                    },
                    wait(30),
                ],
            ),
        ),
        (
            "lossy_room",
            script(
                Setup { seed: 7, ..four },
                vec![
                    Step::Wait { ms: 10, loss: 2 },
                    Spawn { peer: 0, shape: 0 },
                    Spawn {
                        peer: 1,
                        shape: soft8,
                    },
                    Step::Wait { ms: 30, loss: 2 },
                    Grab { peer: 2, object: 0 },
                    Move {
                        peer: 1,
                        object: 0,
                        to: 33,
                    },
                    Step::Wait { ms: 100, loss: 3 },
                    Say {
                        peer: 3,
                        how: 0,
                        len: 8,
                    },
                    Step::Wait { ms: 50, loss: 1 },
                ],
            ),
        ),
        (
            "partition_heals",
            script(
                four,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(10),
                    Cut { a: 0, b: 1 },
                    Cut { a: 0, b: 2 },
                    Cut { a: 0, b: 3 },
                    wait(250),
                    Cut { a: 0, b: 1 },
                    Cut { a: 0, b: 2 },
                    Cut { a: 0, b: 3 },
                    wait(250),
                ],
            ),
        ),
        (
            "host_stalls_and_resumes",
            script(
                room,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(10),
                    Freeze { peer: 0 },
                    wait(200),
                    Freeze { peer: 0 },
                    wait(200),
                ],
            ),
        ),
        (
            "member_leaves",
            script(
                room,
                vec![
                    Spawn { peer: 2, shape: 0 },
                    wait(10),
                    Leave { peer: 2 },
                    wait(50),
                ],
            ),
        ),
        (
            "direct_route",
            script(
                Setup {
                    direct: true,
                    ..four
                },
                vec![
                    Spawn {
                        peer: 1,
                        shape: soft8,
                    },
                    wait(20),
                    Move {
                        peer: 1,
                        object: 0,
                        to: 50,
                    },
                    wait(20),
                ],
            ),
        ),
        (
            "uplink_budget",
            script(
                Setup {
                    budget: true,
                    ..four
                },
                vec![
                    Spawn {
                        peer: 0,
                        shape: soft8,
                    },
                    Spawn { peer: 1, shape: 0 },
                    Spawn { peer: 2, shape: 25 },
                    wait(20),
                    Move {
                        peer: 0,
                        object: 0,
                        to: 60,
                    },
                    Grab { peer: 3, object: 1 },
                    wait(40),
                ],
            ),
        ),
        (
            "adaptive_detector_host_crash",
            script(
                Setup {
                    adaptive: true,
                    ..room
                },
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(10),
                    Crash { peer: 0 },
                    wait(100),
                ],
            ),
        ),
        // ---- hostile
        (
            "hostile_member",
            script(
                hostile,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(20),
                    Forge {
                        to: 0,
                        what: 10,
                        args: [0; 4],
                    },
                    Forge {
                        to: 0,
                        what: 8,
                        args: [1, 0, 0, 0],
                    },
                    wait(20),
                ],
            ),
        ),
        (
            "hostile_without_the_key",
            script(
                Setup {
                    hostile_joins: true,
                    ..keyed
                },
                vec![
                    wait(30),
                    Forge {
                        to: 0,
                        what: 27,
                        args: [3; 4],
                    },
                    wait(10),
                ],
            ),
        ),
        (
            "hostile_insider_claims_after_migration",
            script(
                Setup {
                    hostile_joins: true,
                    insider: true,
                    ..keyed
                },
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(20),
                    Crash { peer: 0 },
                    wait(150),
                    Forge {
                        to: 0,
                        what: 17,
                        args: [0, 0, 0, 1],
                    },
                    wait(20),
                ],
            ),
        ),
        (
            "hello_flood",
            script(
                room,
                vec![
                    Hellos { to: 0, count: 47 },
                    wait(150),
                    Hellos { to: 1, count: 200 },
                ],
            ),
        ),
        (
            "forged_new_host_and_owner",
            script(
                hostile,
                vec![
                    Spawn { peer: 0, shape: 0 },
                    wait(20),
                    Forge {
                        to: 1,
                        what: 16,
                        args: [0, 0, 1, 0],
                    },
                    Forge {
                        to: 1,
                        what: 13,
                        args: [0, 1, 0, 2],
                    },
                    Forge {
                        to: 2,
                        what: 30,
                        args: [0; 4],
                    },
                    wait(20),
                ],
            ),
        ),
        (
            "raw_datagrams",
            script(
                room,
                vec![
                    Raw {
                        to: 0,
                        from: 0x80,
                        bytes: vec![2, 0, 0, 3, 0, 1, 2],
                    },
                    Raw {
                        to: 1,
                        from: 0x41,
                        bytes: vec![5, 0, 0, 0, 0, 6, 200, 1],
                    },
                    wait(5),
                ],
            ),
        ),
        (
            "replays_and_mutations",
            script(
                Setup { seed: 3, ..room },
                vec![
                    Spawn {
                        peer: 0,
                        shape: soft8,
                    },
                    wait(20),
                ]
                .into_iter()
                .chain((0..8).map(|how| Replay {
                    pick: 60 - how * 5,
                    how,
                    at: how * 3,
                    value: 0x5a,
                    to: how,
                }))
                .chain([wait(20)])
                .collect(),
            ),
        ),
        (
            "beacons",
            script(
                room,
                vec![
                    Beacon {
                        to: 0,
                        args: [1, 0, 9],
                    },
                    Beacon {
                        to: 1,
                        args: [0x61, 2, 3],
                    },
                    wait(5),
                ],
            ),
        ),
    ];
    // every forged control message once, to the host and to a member
    let every: Vec<Step> = (0..31)
        .flat_map(|what| {
            [
                Forge {
                    to: 0,
                    what,
                    args: [what, 1, 0, 0],
                },
                Forge {
                    to: 1,
                    what,
                    args: [0, what, 1, 1],
                },
            ]
        })
        .chain([wait(30)])
        .collect();
    seeds.push((
        "forged_every_control",
        script(
            hostile,
            [
                Spawn {
                    peer: 0,
                    shape: soft8,
                },
                wait(20),
            ]
            .into_iter()
            .chain(every)
            .collect(),
        ),
    ));
    seeds
}
