//! The fuzz targets' entry points (`net/fuzz`) on fixed inputs, in the normal test suite:
//! every file of the committed seed corpora (`net/fuzz/corpus/<target>/`), the seed scripts
//! checked for doing what their names say, the known issues checked to still reproduce, and
//! pseudo-random inputs from a fixed seed.
//!
//! The corpora are generated (`softsync_net::fuzzing::seed_corpus`); after a change to the
//! scripts or the wire format, write them again with
//! `SOFTSYNC_WRITE_CORPUS=1 cargo test -p softsync-net --test fuzz_sessions`.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use softsync_net::fuzzing::{
    decode_all, fixed_issue_scripts, known_issue_scripts, play_session, play_with, seed_corpus,
    seed_scripts, Checks, Outcome, Script, Setup, Step, KNOWN_ISSUES,
};
use softsync_net::rng::SeededRng;

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz")
}

/// The files of `dir`, sorted, with their bytes.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .collect();
    out.sort();
    out
}

#[test]
fn the_committed_corpora_and_artifacts_are_what_the_code_makes() {
    let write = std::env::var("SOFTSYNC_WRITE_CORPUS").is_ok_and(|v| v == "1");
    let mut wanted: Vec<(PathBuf, Vec<u8>)> = seed_corpus()
        .into_iter()
        .map(|(path, bytes)| (fuzz_dir().join("corpus").join(path), bytes))
        .collect();
    wanted.extend(known_issue_scripts().into_iter().map(|(name, _, script)| {
        let path = fuzz_dir().join("artifacts/play_session").join(name);
        (path, script.to_bytes())
    }));
    assert!(wanted.len() >= 40, "a few dozen seeds: {}", wanted.len());
    for (path, bytes) in &wanted {
        if write {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, bytes).unwrap();
        } else {
            let committed = std::fs::read(path).unwrap_or_default();
            assert!(
                committed == *bytes,
                "{} is not what the code makes: write the corpora again with \
                 SOFTSYNC_WRITE_CORPUS=1 cargo test -p softsync-net --test fuzz_sessions",
                path.display()
            );
        }
    }
}

#[test]
fn every_committed_play_session_input_plays() {
    // the seeds, and whatever a fuzzing run added and someone committed
    let inputs = files(&fuzz_dir().join("corpus/play_session"));
    assert!(inputs.len() >= 30, "{} inputs", inputs.len());
    for (name, bytes) in inputs {
        let r = std::panic::catch_unwind(|| play_session(&bytes));
        assert!(r.is_ok(), "corpus/play_session/{name} fails");
    }
}

#[test]
fn every_committed_decode_packet_input_decodes_and_survives_bit_flips() {
    let inputs = files(&fuzz_dir().join("corpus/decode_packet"));
    assert!(inputs.len() >= 8, "{} inputs", inputs.len());
    for (name, bytes) in inputs {
        decode_all(&bytes);
        assert!(
            softsync_net::wire::decode_datagram(&bytes).is_ok(),
            "corpus/decode_packet/{name} is a valid datagram"
        );
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 1 << (i % 8);
            decode_all(&b);
        }
    }
}

fn outcomes() -> Vec<(&'static str, Outcome)> {
    seed_scripts()
        .into_iter()
        .map(|(name, s)| (name, play_with(&s.to_bytes(), Checks::DEFAULT)))
        .collect()
}

#[test]
fn the_seed_scripts_do_what_their_names_say() {
    let all = outcomes();
    let get = |name: &str| &all.iter().find(|(n, _)| *n == name).unwrap().1;
    for (name, o) in &all {
        assert!(o.steps > 0 && o.datagrams > 0, "{name}: {o:?}");
        if !o.hostile {
            // every valid script ends with the live honest peers in one room
            assert!(o.converged.is_some_and(|n| n >= 2), "{name}: {o:?}");
            assert_eq!(o.refused, 0, "{name}: {o:?}");
        }
    }
    assert_eq!(get("join").converged, Some(3));
    assert_eq!(get("join_keyed").converged, Some(4));
    assert_eq!(get("join_late_via_a_member").converged, Some(5));
    let g = get("grab_move_release");
    assert!(g.authority_changes >= 2 && g.denied == 0, "{g:?}");
    assert_eq!(get("grab_of_a_held_object_is_denied").denied, 2);
    let a = get("owner_asked_agrees");
    assert!(a.authority_changes >= 1 && a.denied == 0, "{a:?}");
    assert_eq!(get("owner_asked_refuses").denied, 1);
    assert_eq!(get("locked_stays_with_the_host").denied, 1);
    let d = get("despawns");
    assert!(d.despawned == d.spawned && d.spawned == 6, "{d:?}");
    for name in [
        "host_leaves",
        "host_crashes",
        "keyed_migration_then_a_late_join",
        "handoff_in_flight_when_the_host_dies",
        "adaptive_detector_host_crash",
    ] {
        // the survivors saw a new host, and the room has every survivor
        assert!(get(name).host_changes >= 2, "{name}: {:?}", get(name));
    }
    assert_eq!(get("host_leaves").converged, Some(3));
    assert_eq!(get("keyed_migration_then_a_late_join").converged, Some(4));
    assert_eq!(
        get("member_crashes_and_its_objects_return").converged,
        Some(2)
    );
    assert!(get("messages").messages >= 8);
    assert!(get("retained_state_reaches_a_late_joiner").messages >= 3);
    let t = get("tear_lift_cut_resolution");
    assert!(
        t.topology >= 9 && t.despawned >= 3,
        "a cut replaces its object: {t:?}"
    );
    let p = get("partition_heals");
    assert!(p.dropped >= 1 && p.converged == Some(4), "{p:?}");
    assert!(get("host_stalls_and_resumes").dropped >= 1);
    assert!(get("lossy_room").authority_changes >= 1);
    for name in [
        "hello_flood",
        "forged_every_control",
        "replays_and_mutations",
    ] {
        assert!(get(name).hostile, "{name}");
    }
}

#[test]
fn the_fixed_issues_pass_every_check() {
    for (name, issue, script) in fixed_issue_scripts() {
        let out = play_with(&script.to_bytes(), Checks::STRICT);
        eprintln!("fixed issue {issue} ({name}): {out:?}");
    }
}

#[test]
fn the_known_issues_still_reproduce_and_nothing_else_fails_on_them() {
    let scripts = known_issue_scripts();
    let mut found: Vec<usize> = scripts.iter().map(|s| s.1).collect();
    found.sort_unstable();
    assert_eq!(found, KNOWN_ISSUES.iter().map(|k| k.0).collect::<Vec<_>>());
    for (name, issue, script) in scripts {
        let bytes = script.to_bytes();
        play_with(&bytes, Checks::DEFAULT);
        let strict = std::panic::catch_unwind(|| play_with(&bytes, Checks::STRICT));
        assert!(
            strict.is_err(),
            "known issue {issue} ({name}) no longer reproduces: if it is fixed, remove it from \
             KNOWN_ISSUES, its lines in forgive_*, and its script"
        );
    }
}

/// A script of `n` steps drawn from `rng`: mostly the room's own life (waits, spawns,
/// grabs, moves, crashes), some hostile moves.
fn random_script(rng: &mut SeededRng, n: usize) -> Script {
    let mut b = || rng.next_u64() as u8;
    let setup = Setup {
        keyed: b() % 3 == 0,
        three_members: b() % 2 == 0,
        insider: b() % 4 == 0,
        hostile_joins: b() % 3 == 0,
        direct: b() % 4 == 0,
        budget: b() % 4 == 0,
        adaptive: b() % 4 == 0,
        refuse_asks: b() % 3 == 0,
        seed: b(),
    };
    let mut steps = Vec::new();
    for _ in 0..n {
        let (p, o, x) = (b(), b(), b());
        steps.push(match b() % 24 {
            0..=5 => Step::Wait {
                ms: x % 120,
                loss: o,
            },
            6 | 7 => Step::Spawn { peer: p, shape: x },
            8 => Step::Grab { peer: p, object: o },
            9 => Step::Release { peer: p, object: o },
            10 => Step::Despawn { peer: p, object: o },
            11 => Step::Move {
                peer: p,
                object: o,
                to: x,
            },
            12 => Step::Say {
                peer: p,
                how: o,
                len: x,
            },
            13 => Step::Reshape {
                peer: p,
                object: o,
                how: x,
            },
            14 => match x % 4 {
                0 => Step::Leave { peer: p },
                1 => Step::Crash { peer: p },
                2 => Step::Freeze { peer: p },
                _ => Step::Cut { a: p, b: o },
            },
            15 => Step::Join { contact: p },
            16 => Step::Forge {
                to: p,
                what: o,
                args: [x, b(), b(), b()],
            },
            17 => Step::Replay {
                pick: p,
                how: o,
                at: x,
                value: b(),
                to: b(),
            },
            18 => Step::Raw {
                to: p,
                from: o,
                bytes: (0..x % 40).map(|_| b()).collect(),
            },
            19 => Step::Hellos { to: p, count: x },
            20 => Step::Beacon {
                to: p,
                args: [o, x, b()],
            },
            21 => Step::Attach,
            _ => Step::Wait {
                ms: x % 30,
                loss: 0,
            },
        });
    }
    Script { setup, steps }
}

#[test]
fn random_scripts_keep_every_invariant() {
    let mut rng = SeededRng::new(20_261_127);
    for i in 0..600 {
        let n = 1 + (rng.next_u64() % 24) as usize;
        let script = random_script(&mut rng, n);
        let bytes = script.to_bytes();
        assert_eq!(
            Script::from_bytes(&bytes),
            script,
            "the encoding round-trips"
        );
        let r = std::panic::catch_unwind(|| play_session(&bytes));
        assert!(r.is_ok(), "random script {i}: {bytes:?}\n{script:#?}");
    }
}

#[test]
fn random_bytes_keep_every_invariant_and_decode_safely() {
    let mut rng = SeededRng::new(7);
    for i in 0..2000 {
        let len = (rng.next_u64() % 128) as usize;
        let bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        let r = std::panic::catch_unwind(|| {
            play_session(&bytes);
            decode_all(&bytes);
        });
        assert!(r.is_ok(), "random input {i}: {bytes:?}");
    }
}

/// Replays one input with a trace of every step and event: `SOFTSYNC_FUZZ_INPUT=path cargo
/// test -p softsync-net --test fuzz_sessions replay_an_input -- --ignored --nocapture`
/// (`SOFTSYNC_FUZZ_STRICT=1`: with the known issues).
#[test]
#[ignore = "a tool: replays the input SOFTSYNC_FUZZ_INPUT names"]
fn replay_an_input() {
    let path = std::env::var("SOFTSYNC_FUZZ_INPUT").expect("SOFTSYNC_FUZZ_INPUT=path");
    let bytes = std::fs::read(path).unwrap();
    eprintln!("{:#?}", Script::from_bytes(&bytes));
    let strict = std::env::var("SOFTSYNC_FUZZ_STRICT").is_ok_and(|v| v == "1");
    let checks = if strict {
        Checks::STRICT
    } else {
        Checks::DEFAULT
    };
    eprintln!("{:?}", softsync_net::fuzzing::play_traced(&bytes, checks));
}
/// The message a play of `script` fails with, if it fails.
fn failure(script: &Script, checks: Checks) -> Option<String> {
    let r = std::panic::catch_unwind(|| play_with(&script.to_bytes(), checks));
    r.err().map(|e| {
        e.downcast_ref::<String>()
            .cloned()
            .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default()
    })
}

/// Shrinks a failing input step by step (drops every step whose removal keeps a failure
/// whose message contains SOFTSYNC_FUZZ_WANT), prints the script left and writes it to the
/// input's path + `.min`:
/// `SOFTSYNC_FUZZ_INPUT=path SOFTSYNC_FUZZ_WANT='both own' cargo test -p softsync-net --test
/// fuzz_sessions minimize_an_input -- --ignored --nocapture` (`SOFTSYNC_FUZZ_STRICT=1`: with
/// the known issues).
#[test]
#[ignore = "a tool: shrinks the input SOFTSYNC_FUZZ_INPUT names"]
fn minimize_an_input() {
    let path = std::env::var("SOFTSYNC_FUZZ_INPUT").expect("SOFTSYNC_FUZZ_INPUT=path");
    let want = std::env::var("SOFTSYNC_FUZZ_WANT").unwrap_or_default();
    let mut script = Script::from_bytes(&std::fs::read(&path).unwrap());
    let strict = std::env::var("SOFTSYNC_FUZZ_STRICT").is_ok_and(|v| v == "1");
    let checks = if strict {
        Checks::STRICT
    } else {
        Checks::DEFAULT
    };
    let fails = |s: &Script| failure(s, checks).is_some_and(|m| m.contains(&want));
    let quiet = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    assert!(fails(&script), "it does not fail that way");
    let mut shrunk = true;
    while shrunk {
        shrunk = false;
        for i in (0..script.steps.len()).rev() {
            let mut s = script.clone();
            s.steps.remove(i);
            if fails(&s) {
                script = s;
                shrunk = true;
            }
        }
    }
    std::panic::set_hook(quiet);
    eprintln!("{:?}\n{script:#?}", failure(&script, checks));
    std::fs::write(format!("{path}.min"), script.to_bytes()).unwrap();
}
