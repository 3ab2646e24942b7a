//! One app, either sync mode: the same two systems — one holds the right hand still at a
//! point in the room (`LocalDevice`), one prints the room's objects from their entities
//! (`NetObject` and `Transform`) — run in a state-sync room (`SoftsyncPlugin` and a `Room`)
//! or in a rollback room (`RollbackPlugin` and a `RollbackRoom`), chosen with `--sync`.
//!
//! ```sh
//! softsync host --room lab --bind 127.0.0.1:3536 --sync rollback --bot idle
//! cargo run -p softsync-bevy --example either_mode -- join lab ws://127.0.0.1:3536 --sync rollback
//! ```
#![allow(clippy::print_stdout, missing_docs)]

use bevy::app::ScheduleRunnerPlugin;
use bevy::prelude::*;
use softsync_bevy::peer::{DeviceFrame, Scene};
use softsync_bevy::prelude::*;
use softsync_bevy::rollback_core::RollbackConfig;
use softsync_bevy::{LocalDevice, RollbackHooks};

/// Where the right hand stays, room frame (metres).
const HAND_AT: [f32; 3] = [0.1, 1.05, 0.45];

#[derive(Resource)]
struct RunFor(f32);

fn main() -> Result<AppExit, Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |f: &str| {
        args.iter()
            .position(|a| a == f)
            .and_then(|i| args.get(i + 1))
    };
    let scene = Scene::load(
        flag("--scene")
            .map_or(
                concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/thesis-room.ron"),
                |s| s,
            )
            .as_ref(),
    )?;
    let seconds: f32 = flag("--seconds").map_or(Ok(20.0), |s| s.parse())?;
    let opts = RoomOptions::from_args(&args)?;
    let mut app = App::new();
    app.add_plugins(MinimalPlugins.set(ScheduleRunnerPlugin::run_loop(
        std::time::Duration::from_millis(5),
    )))
    .insert_resource(RunFor(seconds))
    // the same systems in either mode
    .add_systems(PreUpdate, hold_hand)
    .add_systems(Update, (report, stop));
    match flag("--sync").map(String::as_str) {
        None | Some("state") => {
            let room = Room::open(scene, opts)?;
            println!("peer={} sync=state", room.peer.me().0);
            app.add_plugins(SoftsyncPlugin::default()).add_room(room);
        }
        Some("rollback") => {
            let room = RollbackRoom::open(
                scene,
                opts,
                RollbackConfig::default(),
                RollbackHooks::default(),
            )?;
            println!("peer={} sync=rollback", room.me().0);
            app.add_plugins(RollbackPlugin::default())
                .insert_resource(room);
        }
        Some(other) => return Err(format!("--sync {other:?}: state or rollback").into()),
    }
    Ok(app.run())
}

/// The device: the right hand held still, open; the head above it.
fn hold_hand(mut device: ResMut<LocalDevice>) {
    let at = glam::Vec3::from_array(HAND_AT);
    device.0 = Some(DeviceFrame {
        head: Some((at + glam::Vec3::new(0.0, 0.5, 0.3), glam::Quat::IDENTITY)),
        hands: [None, Some((at, glam::Quat::IDENTITY))],
        ..DeviceFrame::default()
    });
}

/// Once a second: how many objects the room has, and where the first soft one is.
fn report(
    time: Res<Time>,
    mut next: Local<f32>,
    objects: Query<(&NetObject, &Transform, Option<&SoftBody>), Without<AvatarPart>>,
) {
    if time.elapsed_secs() < *next {
        return;
    }
    *next = time.elapsed_secs() + 1.0;
    let n = objects.iter().count();
    let soft = objects.iter().filter(|(_, _, s)| s.is_some()).count();
    println!("objects n={n} soft={soft}");
}

fn stop(time: Res<Time>, limit: Res<RunFor>, mut exit: MessageWriter<AppExit>) {
    if time.elapsed_secs() >= limit.0 {
        exit.write(AppExit::Success);
    }
}
