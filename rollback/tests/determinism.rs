//! The world steps bit-identically from the same inputs; a non-determinism is caught by
//! ggrs's checksums; a snapshot restarts every member in the same state.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use ggrs::{GgrsError, GgrsRequest, SessionBuilder};
use softsync_net::PeerId;
use softsync_peer::Scene;
use softsync_rollback::script::SqueezeThrow;
use softsync_rollback::{GgrsConfig, PlayerInput, RollbackWorld};

fn scene() -> Scene {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    Scene::by_name("thesis-room", &assets).unwrap()
}

const DT: f32 = 1.0 / 60.0;
const PLAYERS: [PeerId; 2] = [PeerId(3), PeerId(6)];

/// Two bots' inputs recorded from a world as it runs, and the checksum once a second.
fn record(frames: i32) -> (Vec<[PlayerInput; 2]>, Vec<u128>, RollbackWorld) {
    let mut w = RollbackWorld::new(&scene(), DT, &PLAYERS).unwrap();
    let mut bots = [
        SqueezeThrow::new(PLAYERS[0], 1),
        SqueezeThrow::new(PLAYERS[1], 3),
    ];
    let mut inputs = Vec::new();
    let mut sums = Vec::new();
    for f in 0..frames {
        let i = [bots[0].input(&w), bots[1].input(&w)];
        w.step(&i);
        inputs.push(i);
        if f % 60 == 59 {
            sums.push(w.checksum());
        }
    }
    (inputs, sums, w)
}

#[test]
fn two_fresh_worlds_fed_the_same_inputs_for_60_s_end_bit_identical_with_bodies_squeezed_and_thrown()
{
    let (inputs, sums, a) = record(3600);
    // The recording did things: the soft ball was held, squeezed and thrown.
    let grips = inputs
        .iter()
        .filter(|i| i[0].grip[1] > 0 || i[1].grip[1] > 0)
        .count();
    assert!(grips > 600, "{grips} frames with a grip");
    let mut b = RollbackWorld::new(&scene(), DT, &PLAYERS).unwrap();
    let start = b.object_pose(1).unwrap().0;
    let mut moved = 0.0f32;
    for (f, i) in inputs.iter().enumerate() {
        b.step(i);
        moved = moved.max(b.object_pose(1).unwrap().0.distance(start));
        if f % 60 == 59 {
            assert_eq!(
                b.checksum(),
                sums[f / 60],
                "worlds differ after frame {}",
                f + 1
            );
        }
    }
    assert!(moved > 0.1, "the soft ball moved at most {moved} m");
    assert_eq!(a.checksum(), b.checksum());
    assert_eq!(a.snapshot(), b.snapshot());
}

#[test]
fn a_world_rebuilt_from_a_snapshot_goes_on_exactly_like_every_other_rebuilt_from_it() {
    let (inputs, _, a) = record(300);
    let snap = a.snapshot();
    let mut x = RollbackWorld::from_snapshot(&scene(), DT, &PLAYERS, &snap).unwrap();
    let mut y = RollbackWorld::from_snapshot(&scene(), DT, &PLAYERS, &snap).unwrap();
    assert_eq!(x.frame(), 300);
    for i in inputs.iter().take(240) {
        x.step(i);
        y.step(i);
    }
    assert_eq!(x.checksum(), y.checksum());
    // A snapshot of another scene (or damaged) is refused, not half-applied.
    let mut bad = snap.clone();
    bad.bodies.pop();
    assert!(RollbackWorld::from_snapshot(&scene(), DT, &PLAYERS, &bad).is_err());
    let mut nan = snap;
    nan.bodies[0][0] = f32::NAN.to_bits();
    assert!(RollbackWorld::from_snapshot(&scene(), DT, &PLAYERS, &nan).is_err());
}

/// ggrs's sync test: every frame rolled back `check` frames and re-simulated, the checksums
/// compared. Returns the first mismatch.
fn sync_test(world: &mut RollbackWorld, frames: i32) -> Result<(), GgrsError> {
    let mut s = SessionBuilder::<GgrsConfig>::new()
        .with_num_players(2)?
        .with_check_distance(4)
        .add_player(ggrs::PlayerType::Local, 0)?
        .add_player(ggrs::PlayerType::Local, 1)?
        .start_synctest_session()?;
    let mut bots = [
        SqueezeThrow::new(PLAYERS[0], 1),
        SqueezeThrow::new(PLAYERS[1], 0),
    ];
    for _ in 0..frames {
        let i = [bots[0].input(world), bots[1].input(world)];
        s.add_local_input(0, i[0])?;
        s.add_local_input(1, i[1])?;
        for r in s.advance_frame()? {
            match r {
                GgrsRequest::SaveGameState { cell, frame } => cell.save(
                    frame,
                    Some(std::rc::Rc::new(world.save())),
                    Some(world.checksum()),
                ),
                GgrsRequest::LoadGameState { cell, .. } => world.load(&cell.load().unwrap()),
                GgrsRequest::AdvanceFrame { inputs } => {
                    let i: Vec<PlayerInput> = inputs.iter().map(|x| x.0).collect();
                    world.step(&i)
                }
            }
        }
    }
    Ok(())
}

#[test]
fn rolling_back_and_resimulating_gives_the_same_checksums_and_an_injected_nondeterminism_is_caught()
{
    let mut w = RollbackWorld::new(&scene(), DT, &PLAYERS).unwrap();
    sync_test(&mut w, 150).unwrap();
    let mut bad = RollbackWorld::new(&scene(), DT, &PLAYERS).unwrap();
    bad.inject_nondeterminism();
    match sync_test(&mut bad, 150) {
        Err(GgrsError::MismatchedChecksum { .. }) => {}
        other => panic!("the injected non-determinism was not caught: {other:?}"),
    }
}
