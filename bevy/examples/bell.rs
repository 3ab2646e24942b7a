//! A custom event as room state: "ring the bell". Whoever rings it tells everyone, and the
//! room keeps the latest ring (`Delivery::Retained`), so a peer that joins later hears how
//! often it has rung and who rang it last. In a VR app the same `ring` runs from a controller
//! button; here `--ring` rings once on entering, and grabbing the scene's bell rings it too.
//!
//! ```sh
//! cargo run -p softsync-bevy --example bell -- host lab 127.0.0.1:3536
//! cargo run -p softsync-bevy --example bell -- join lab ws://127.0.0.1:3536 --ring
//! cargo run -p softsync-bevy --example bell -- join lab ws://127.0.0.1:3536   # later: hears it
//! ```
#![allow(clippy::print_stdout, missing_docs)]

use bevy::app::ScheduleRunnerPlugin;
use bevy::prelude::*;
use serde::{Deserialize, Serialize};
use softsync_bevy::peer::Scene;
use softsync_bevy::prelude::*;

/// The bell's state: how often it has rung, and who rang it last.
#[derive(Serialize, Deserialize, Clone, Copy, Debug, Default, Resource)]
struct BellRung {
    count: u32,
    by: u64,
}
impl RoomMessage for BellRung {
    const NAME: &'static str = "example.bell";
}

#[derive(Resource)]
struct Settings {
    ring_on_entry: bool,
    seconds: f32,
}

fn main() -> Result<AppExit, Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |f: &str| {
        args.iter()
            .position(|a| a == f)
            .and_then(|i| args.get(i + 1))
    };
    let scene = flag("--scene").map_or(
        concat!(env!("CARGO_MANIFEST_DIR"), "/examples/lab.ron"),
        |s| s,
    );
    let seconds: f32 = flag("--seconds").map_or(Ok(30.0), |s| s.parse())?;
    let opts = RoomOptions::from_args(&args)?.with_message::<BellRung>()?;
    let room = Room::open(Scene::load(scene.as_ref())?, opts)?;
    println!("peer={} signal={}", room.peer.me().0, room.signal_url());
    let ring_on_entry = args.iter().any(|a| a == "--ring");
    Ok(App::new()
        .add_plugins(MinimalPlugins.set(ScheduleRunnerPlugin::run_loop(
            std::time::Duration::from_millis(2),
        )))
        .add_plugins(SoftsyncPlugin::default())
        .add_room(room)
        .add_room_message::<BellRung>()
        .insert_resource(Settings {
            ring_on_entry,
            seconds,
        })
        .init_resource::<BellRung>()
        .add_systems(Update, (hear, press).chain())
        .run())
}

/// The bell as others ring it (the room does not echo our own rings back to us).
fn hear(mut rings: MessageReader<Received<BellRung>>, mut bell: ResMut<BellRung>) {
    for r in rings.read() {
        *bell = r.msg;
        println!(
            "bell count={} by={} from={}",
            r.msg.count, r.msg.by, r.from.0
        );
    }
}

/// The button: on entering (`--ring`) and whenever one of our hands grabs the bell.
fn press(
    mut room: NonSendMut<Room>,
    mut events: MessageReader<RoomEvent>,
    bells: Query<&NetObject>,
    mut bell: ResMut<BellRung>,
    settings: Res<Settings>,
    time: Res<Time>,
    mut exit: MessageWriter<AppExit>,
) {
    let mut ring = false;
    for RoomEvent(e) in events.read() {
        ring |= match e {
            SoftsyncEvent::Room(RoomNews::Joined { .. }) => settings.ring_on_entry,
            SoftsyncEvent::GrabStarted { id, .. } => {
                bells.iter().any(|o| o.id == *id && o.class == "bell")
            }
            _ => false,
        };
    }
    if ring {
        let me = room.peer.me().0;
        let rung = BellRung {
            count: bell.count + 1,
            by: me,
        };
        match room.send(MessageTarget::Everyone, Delivery::Retained, &rung) {
            Ok(_) => {
                *bell = rung;
                println!("rang the bell: count={}", rung.count);
            }
            Err(why) => println!("ring refused: {why}"),
        }
    }
    if time.elapsed_secs() >= settings.seconds {
        exit.write(AppExit::Success);
    }
}
