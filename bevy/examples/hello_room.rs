//! A user's own bevy app on softsync: host or join a room by name with your scene file, send a
//! message of your own type, print what arrives and the room's objects. Headless (bevy's
//! `MinimalPlugins`); add bevy's renderer and draw the `NetObject` entities to see them.
//!
//! ```sh
//! cargo run -p softsync-bevy --example hello_room -- host lab 127.0.0.1:3536
//! cargo run -p softsync-bevy --example hello_room -- join lab ws://127.0.0.1:3536 --seconds 10
//! ```
//! The `softsync` binary can be either side: `softsync host --room lab --scene
//! bevy/examples/lab.ron` (it logs the greeting), and the example hears its bot's `say`.
#![allow(clippy::print_stdout, missing_docs)]

use bevy::app::ScheduleRunnerPlugin;
use bevy::prelude::*;
use serde::{Deserialize, Serialize};
use softsync_bevy::peer::{Say, Scene};
use softsync_bevy::prelude::*;

/// Our own message: a serde type with a name that the scene file lists under `messages`.
#[derive(Serialize, Deserialize, Clone, Debug)]
struct Greeting {
    text: String,
}
impl RoomMessage for Greeting {
    const NAME: &'static str = "example.greeting";
}

#[derive(Resource)]
struct RunFor(f32);

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
    let opts = RoomOptions::from_args(&args)?.with_message::<Greeting>()?;
    let room = Room::open(Scene::load(scene.as_ref())?, opts)?;
    println!("peer={} signal={}", room.peer.me().0, room.signal_url());
    Ok(App::new()
        .add_plugins(MinimalPlugins.set(ScheduleRunnerPlugin::run_loop(
            std::time::Duration::from_millis(2),
        )))
        .add_plugins(SoftsyncPlugin::default())
        .add_room(room)
        .add_room_message::<Greeting>()
        .add_room_message::<Say>() // the built-in chat line (a `softsync` bot's `say`)
        .insert_resource(RunFor(seconds))
        .add_systems(Update, (greet, listen, stop))
        .run())
}

/// Say hello once in the room; a host welcomes each newcomer.
fn greet(mut room: NonSendMut<Room>, mut events: MessageReader<RoomEvent>) {
    for RoomEvent(e) in events.read() {
        let (to, text) = match e {
            SoftsyncEvent::Room(RoomNews::Joined { host, .. }) => {
                println!("joined host={}", host.0);
                (MessageTarget::Everyone, "hello from a bevy app".to_owned())
            }
            SoftsyncEvent::Room(RoomNews::PeerJoined(p)) => {
                (MessageTarget::Peer(*p), format!("welcome, {}", p.0))
            }
            _ => continue,
        };
        if let Err(why) = room.send(to, Delivery::Reliable, &Greeting { text }) {
            println!("greeting refused: {why}");
        }
    }
}

fn listen(
    mut greetings: MessageReader<Received<Greeting>>,
    mut says: MessageReader<Received<Say>>,
) {
    for g in greetings.read() {
        println!("greeting from={} text={:?}", g.from.0, g.msg.text);
    }
    for s in says.read() {
        println!("say from={} text={:?}", s.from.0, s.msg.text);
    }
}

/// After `--seconds`: the objects as this app's entities have them, then exit.
fn stop(
    time: Res<Time>,
    limit: Res<RunFor>,
    objects: Query<(&NetObject, &Transform), Without<AvatarPart>>,
    mut exit: MessageWriter<AppExit>,
) {
    if time.elapsed_secs() < limit.0 {
        return;
    }
    let mut seen: Vec<_> = objects.iter().collect();
    seen.sort_by_key(|(o, _)| o.id.0);
    for (o, t) in seen {
        let p = t.translation;
        println!(
            "object id={} class={} pos={:.3},{:.3},{:.3}",
            o.id.0, o.class, p.x, p.y, p.z
        );
    }
    exit.write(AppExit::Success);
}
