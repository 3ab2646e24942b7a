//! The plugin in two bevy apps of one process, on net's in-memory hub (the WebRTC path is
//! `tests/tests/examples.rs`): a joiner is welcomed, both apps keep the same entities for the
//! room's objects, a message of the app's own type arrives as `Received<M>`, the stats
//! resource follows the room, leaving on `AppExit` is seen by the host, and a joiner the room
//! refuses gets `RoomFailed` and exit code 3.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::path::Path;
use std::time::{Duration, Instant as WallInstant};

use bevy::app::{App, AppExit, Update};
use bevy::ecs::message::{MessageReader, Messages};
use bevy::ecs::prelude::{ResMut, Resource};
use bevy::MinimalPlugins;
use serde::{Deserialize, Serialize};
use softsync_bevy::peer::{Peer, Scene};
use softsync_bevy::prelude::*;
use softsync_bevy::{RoomFailed, RoomOptions as Opts};
use softsync_net::{Instant, MemoryHub, Session};

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct Greeting {
    text: String,
}
impl RoomMessage for Greeting {
    const NAME: &'static str = "example.greeting";
}

const HOST: PeerId = PeerId(7);
const JOINER: PeerId = PeerId(8);

fn scene() -> Scene {
    Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/lab.ron")).unwrap()
}

/// A room of `me` on the hub: a host, or a joiner through the host.
fn room(hub: &MemoryHub, me: PeerId, opts: &Opts) -> Room {
    let scene = scene();
    let cfg = opts.session_config(&scene).unwrap();
    let (session, contact) = if me == HOST {
        (Session::host(me, cfg, Instant::ZERO), None)
    } else {
        (Session::join(me, HOST, cfg, Instant::ZERO), Some(HOST))
    };
    let mut peer = Peer::new(Instant::ZERO, session, contact, scene, opts.peer.clone()).unwrap();
    if me == HOST {
        peer.open(Instant::ZERO).unwrap();
    }
    Room::with_transport("lab", peer, Box::new(hub.endpoint(me)))
}

#[derive(Resource, Default)]
struct Seen {
    greetings: Vec<(PeerId, Greeting)>,
    joined: bool,
    peers_joined: Vec<PeerId>,
    peers_left: Vec<PeerId>,
}

fn collect(
    mut seen: ResMut<Seen>,
    mut events: MessageReader<RoomEvent>,
    mut greetings: MessageReader<Received<Greeting>>,
) {
    for RoomEvent(e) in events.read() {
        match e {
            SoftsyncEvent::Room(RoomNews::Joined { .. }) => seen.joined = true,
            SoftsyncEvent::Room(RoomNews::PeerJoined(p)) => seen.peers_joined.push(*p),
            SoftsyncEvent::Room(RoomNews::PeerLeft(p)) => seen.peers_left.push(*p),
            _ => {}
        }
    }
    for g in greetings.read() {
        seen.greetings.push((g.from, g.msg.clone()));
    }
}

fn app(room: Room) -> App {
    app_with(room, SoftsyncPlugin::default())
}

fn app_with(room: Room, plugin: SoftsyncPlugin) -> App {
    let mut app = App::new();
    app.add_plugins(MinimalPlugins)
        .add_plugins(plugin)
        .add_room(room)
        .add_room_message::<Greeting>()
        .init_resource::<Seen>()
        .add_systems(Update, collect);
    app
}

/// Frames of both apps until `done` or 10 s of wall time.
#[track_caller]
fn run_until(apps: &mut [&mut App], mut done: impl FnMut(&mut [&mut App]) -> bool) {
    let start = WallInstant::now();
    while !done(apps) {
        assert!(start.elapsed() < Duration::from_secs(10), "timed out");
        for a in apps.iter_mut() {
            a.update();
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// (id, class, has a SoftBody component) of every non-avatar entity, sorted.
fn entities(app: &mut App) -> Vec<(u32, String, bool)> {
    let mut q = app
        .world_mut()
        .query::<(&NetObject, Option<&SoftBody>, Option<&AvatarPart>)>();
    let mut v: Vec<_> = q
        .iter(app.world())
        .filter(|(_, _, a)| a.is_none())
        .map(|(o, s, _)| (o.id.0, o.class.clone(), s.is_some()))
        .collect();
    v.sort();
    v
}

fn exit_code(app: &App) -> Option<u8> {
    let msgs = app.world().get_resource::<Messages<AppExit>>()?;
    msgs.iter_current_update_messages().next().map(|e| match e {
        AppExit::Success => 0,
        AppExit::Error(c) => c.get(),
    })
}

#[test]
fn two_apps_share_the_room_its_entities_and_a_message_of_their_own_type() {
    let hub = MemoryHub::new(1200);
    let opts = Opts::host("lab").with_message::<Greeting>().unwrap();
    let mut host = app(room(&hub, HOST, &opts));
    let mut joiner = app(room(&hub, JOINER, &opts));
    run_until(&mut [&mut host, &mut joiner], |a| {
        a[1].world().resource::<Seen>().joined && entities(a[1]).len() == 3
    });
    // The same objects, classes and kinds of body on both sides.
    let (h, j) = (entities(&mut host), entities(&mut joiner));
    assert_eq!(h, j);
    let classes: Vec<_> = h.iter().map(|(_, c, s)| (c.as_str(), *s)).collect();
    assert_eq!(
        classes,
        [("block", false), ("bell", false), ("softball", true)]
    );
    assert!(host
        .world()
        .resource::<Seen>()
        .peers_joined
        .contains(&JOINER));
    // The joiner's entities stand where the host's objects are.
    let mut q = joiner
        .world_mut()
        .query::<(&NetObject, &bevy::transform::components::Transform)>();
    let block = q
        .iter(joiner.world())
        .find(|(o, _)| o.class == "block")
        .unwrap()
        .1
        .translation;
    assert!(
        (block.x - 0.25).abs() < 0.01 && (block.y - 0.78).abs() < 0.02,
        "{block:?}"
    );
    // Stats on both sides.
    for (a, me, is_host) in [(&host, HOST, true), (&joiner, JOINER, false)] {
        let s = a.world().resource::<RoomStats>();
        assert_eq!(
            (s.me, s.host, s.is_host, s.members),
            (Some(me), Some(HOST), is_host, 2)
        );
        assert!(s.joined && s.objects >= 3);
    }
    // A message of our own type, from a system's point of view: sent on the room, received
    // as `Received<Greeting>` on the other app.
    let hi = Greeting {
        text: "hello".into(),
    };
    joiner
        .with_room(|r| r.send(MessageTarget::Host, Delivery::Reliable, &hi))
        .unwrap()
        .unwrap();
    run_until(&mut [&mut host, &mut joiner], |a| {
        !a[0].world().resource::<Seen>().greetings.is_empty()
    });
    assert_eq!(host.world().resource::<Seen>().greetings, [(JOINER, hi)]);
    // The joiner's app exits: the plugin says Leave, the host hears it at once (no timeout).
    joiner.world_mut().write_message(AppExit::Success);
    joiner.update();
    assert_eq!(joiner.with_room(|r| r.has_left()), Some(true));
    let left_at = WallInstant::now();
    run_until(&mut [&mut host], |a| {
        a[0].world().resource::<Seen>().peers_left.contains(&JOINER)
    });
    assert!(
        left_at.elapsed() < Duration::from_millis(500),
        "{:?}",
        left_at.elapsed()
    );
}

/// A host whose frames stop for 1.5 s (a slow render, a dropped headset frame, a load) while
/// the joiner runs on: (host seen by the joiner after, its RTT to the host then, host pumps
/// between frames).
fn stall_the_hosts_frames(net_thread: bool) -> (Option<PeerId>, Option<Duration>, u64) {
    let hub = MemoryHub::new(1200);
    let opts = Opts::host("lab");
    let plugin = SoftsyncPlugin {
        net_thread,
        ..SoftsyncPlugin::default()
    };
    let mut host = app_with(room(&hub, HOST, &opts), plugin.clone());
    let mut joiner = app_with(room(&hub, JOINER, &opts), plugin);
    run_until(&mut [&mut host, &mut joiner], |a| {
        a[1].world().resource::<Seen>().joined && entities(a[1]).len() == 3
    });
    // the peer timeout is 1 s: a stall of 1.5 s is a dead host unless something answers
    let stalled = WallInstant::now();
    while stalled.elapsed() < Duration::from_millis(1500) {
        joiner.update();
        std::thread::sleep(Duration::from_millis(2));
    }
    for _ in 0..50 {
        host.update();
        joiner.update();
        std::thread::sleep(Duration::from_millis(2));
    }
    let s = joiner.world().resource::<RoomStats>();
    let rtt = s.session.links.get(&HOST).and_then(|l| l.rtt);
    let pumps = host.with_room(|r| r.background_pumps()).unwrap();
    (s.host, rtt, pumps)
}

#[test]
fn a_hosts_slow_frames_do_not_slow_the_room_with_the_network_thread() {
    // The plugin's default: the host's network thread answers while its frames stall; the
    // joiner keeps it as host and reads a network's RTT, not the stall.
    let (host, rtt, pumps) = stall_the_hosts_frames(true);
    assert_eq!(host, Some(HOST), "the joiner took a stalled host for dead");
    let rtt = rtt.unwrap();
    assert!(rtt < Duration::from_millis(100), "rtt {rtt:?}");
    assert!(pumps > 100, "{pumps} pumps between frames");
    // The frame alone pumping: the same stall is a dead host to the joiner.
    let (host, _, pumps) = stall_the_hosts_frames(false);
    assert_eq!(host, Some(JOINER), "the joiner should have taken over");
    assert_eq!(pumps, 0);
}

#[test]
fn a_joiner_the_room_refuses_gets_room_failed_and_exit_code_3() {
    let hub = MemoryHub::new(1200);
    let mut host = app(room(&hub, HOST, &Opts::host("lab")));
    // Another message table: another room configuration, refused at the handshake.
    #[derive(Serialize, Deserialize)]
    struct Other;
    impl RoomMessage for Other {
        const NAME: &'static str = "other.type";
    }
    let mut joiner = app(room(
        &hub,
        JOINER,
        &Opts::host("lab").with_message::<Other>().unwrap(),
    ));
    joiner.add_systems(
        Update,
        |mut f: MessageReader<RoomFailed>, mut seen: ResMut<Seen>| {
            if f.read().next().is_some() {
                seen.peers_left.push(PeerId(0));
            }
        },
    );
    let mut code = None;
    run_until(&mut [&mut host, &mut joiner], |a| {
        code = code.or(exit_code(a[1]));
        code.is_some()
    });
    assert_eq!(code, Some(3));
    assert_eq!(joiner.world().resource::<Seen>().peers_left, [PeerId(0)]);
}

#[test]
fn the_small_apps_command_line_is_read_or_refused_with_its_usage() {
    let a = |s: &str| s.split_whitespace().map(String::from).collect::<Vec<_>>();
    let o = Opts::from_args(&a("host lab 127.0.0.1:0 --seconds 3")).unwrap();
    assert!(o.host && o.name == "lab" && o.bind.port() == 0 && o.signal.is_none());
    let o = Opts::from_args(&a("host lab --ring")).unwrap();
    assert_eq!(o.bind.port(), 3536);
    let o = Opts::from_args(&a("join lab ws://127.0.0.1:3536")).unwrap();
    assert!(!o.host && o.signal.as_deref() == Some("ws://127.0.0.1:3536"));
    for bad in ["", "join lab", "join lab --scene x", "visit lab", "host"] {
        let e = Opts::from_args(&a(bad)).unwrap_err().to_string();
        assert!(e.contains("usage"), "{bad:?}: {e}");
    }
    let e = Opts::from_args(&a("host lab nowhere"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("bind address \"nowhere\""), "{e}");
}

/// A joiner without the scene, speaking the share protocol to a room on the hub: the room's
/// `network_in` serves its scene, and in a room with a key only to a keyholder.
#[test]
fn a_room_serves_its_scene_and_in_a_keyed_room_only_to_a_keyholder() {
    use softsync_net::share::{BlobFetch, FetchError, NEEDS_KEY};
    use softsync_net::{RoomKey, Transport};
    let hub = MemoryHub::new(1200);
    let key = RoomKey::new(b"the lab's secret", 1);
    let mut opts = Opts::host("lab");
    opts.room_key = Some(key.clone());
    let mut host = room(&hub, HOST, &opts);
    let mut joiner = hub.endpoint(JOINER);
    let mut fetch = |k: Option<&RoomKey>| {
        let max = softsync_bevy::peer::scene::MAX_BUNDLE_BYTES;
        let mut f =
            BlobFetch::new(host.now(), HOST, max, Duration::from_secs(5)).with_key(k, JOINER);
        let start = WallInstant::now();
        loop {
            if let Some(o) = f.outcome() {
                return o;
            }
            assert!(start.elapsed() < Duration::from_secs(10), "no answer");
            let now = host.now();
            while let Some(t) = f.poll_transmit(now) {
                joiner.send(now, &t);
            }
            host.network_in().unwrap();
            while let Some((from, bytes)) = joiner.recv(host.now()) {
                f.handle(from, &bytes);
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    };
    for (k, why) in [
        (None, "no key"),
        (Some(&RoomKey::new(b"a guess", 1)), "another key"),
    ] {
        match fetch(k) {
            Err(FetchError::Unavailable(r)) => assert_eq!(r, NEEDS_KEY, "{why}"),
            other => panic!("{why}: {other:?}"),
        }
    }
    let blob = fetch(Some(&key)).unwrap();
    let dir = std::env::temp_dir().join(format!("softsync-plugin-share-{}", std::process::id()));
    let got = Scene::from_bundle(&blob, &dir).unwrap();
    assert_eq!(got.content_digest(), host.peer.scene().content_digest());
    assert_eq!(got.messages, ["example.greeting", "example.bell"]);
    // Every chunk once (no loss on the hub), and the two refusals answered.
    let chunks = blob.len().div_ceil(softsync_net::share::CHUNK_BYTES) as u64;
    assert_eq!(host.scene_requests(), (chunks + 2, 2));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Our own hands are entities with `Hand`: a bot driving them in `SoftsyncSet::Input` reaches
/// for the host's rigid block (kinematic on the joiner until it is granted) and grabs it
/// through the authority request, and the right hand's `holding` says so; the block's entity
/// is hovered on the way. (Until this test, a rigid prop another peer owned could not be
/// hovered at all: only dynamic bodies were targets.)
#[test]
fn a_bot_in_the_input_set_grabs_and_the_hand_entity_says_what_it_holds() {
    use bevy::app::FixedUpdate;
    use bevy::ecs::schedule::IntoScheduleConfigs;
    use bevy::ecs::system::NonSendMut;
    use softsync_bevy::peer::{bot, Bot};
    use softsync_bevy::{Hand, SoftsyncSet};
    let hub = MemoryHub::new(1200);
    let mut opts = Opts::host("lab");
    // A hand that reaches exactly, as the binary gives bots (a physical hand body would shove
    // the block it reaches for).
    opts.peer.hand.physical_controller = false;
    opts.peer.hand.hover_radius_m = 0.03;
    let mut host = app(room(&hub, HOST, &opts));
    let mut joiner = app(room(&hub, JOINER, &opts));
    let script = bot::parse("wait 0.3; reach right block in 1; grab right; wait 5").unwrap();
    joiner.insert_non_send(Bot::new(script)).add_systems(
        FixedUpdate,
        (|mut room: NonSendMut<Room>, mut bot: NonSendMut<Bot>| {
            if room.peer.joined() {
                let now = room.now();
                bot.step(now, &mut room.peer, None);
                while bot.poll_message().is_some() {}
            }
        })
        .in_set(SoftsyncSet::Input),
    );
    let hands = |a: &mut App| {
        let mut q = a.world_mut().query::<(&Hand, &NetObject)>();
        let mut v: Vec<(Hand, bool)> = q.iter(a.world()).map(|(h, o)| (*h, o.mine)).collect();
        v.sort_by_key(|(h, _)| h.index);
        v
    };
    run_until(&mut [&mut host, &mut joiner], |a| hands(a[1]).len() == 2);
    let h = hands(&mut joiner);
    assert_eq!(
        h,
        [
            (
                Hand {
                    index: 0,
                    holding: None
                },
                true
            ),
            (
                Hand {
                    index: 1,
                    holding: None
                },
                true
            )
        ]
    );
    let block = entities(&mut joiner)
        .iter()
        .find(|e| e.1 == "block")
        .unwrap()
        .0;
    let mut hovered = false;
    run_until(&mut [&mut host, &mut joiner], |a| {
        let mut q = a[1].world_mut().query::<&NetObject>();
        hovered |= q.iter(a[1].world()).any(|o| o.id.0 == block && o.hovered);
        let h = hands(a[1]);
        if std::env::var("DEBUG_HANDS").is_ok() {
            a[1].with_room(|r| {
                eprintln!(
                    "{:?} held {:?} hovered {:?}",
                    h,
                    r.peer.held(1).map(|x| x.0),
                    r.peer.hovered_ids()
                )
            });
        }
        h[1].0.holding.map(|id| id.0) == Some(block)
    });
    assert!(hovered, "the block was never hovered on the way");
    // The host sees the joiner own the block it holds.
    run_until(&mut [&mut host, &mut joiner], |a| {
        let mut q = a[0].world_mut().query::<&NetObject>();
        q.iter(a[0].world())
            .any(|o| o.id.0 == block && o.owner == Some(JOINER))
    });
}
