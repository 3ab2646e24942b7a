//! `softsync-bevy`: softsync rooms in a bevy app.
//!
//! Open a [`Room`] (host one, or join one by name through a signaling server) with your
//! scene file, add it and [`SoftsyncPlugin`] to your app, and the room runs in bevy's frame:
//! every networked object is an entity ([`NetObject`], with [`SoftBody`], [`AvatarPart`] or
//! our own [`Hand`] where they apply, and a `Transform` that follows the room), what happens arrives as
//! [`RoomEvent`] bevy messages, your own message types as [`Received<M>`], and [`RoomStats`]
//! says how the room is doing. The `softsync` binary is built on this crate.
//!
//! # Quick start
//!
//! ```no_run
//! use bevy::prelude::*;
//! use serde::{Deserialize, Serialize};
//! use softsync_bevy::peer::Scene;
//! use softsync_bevy::prelude::*;
//!
//! /// Your own message: any serde type with a name the scene file lists under `messages`.
//! #[derive(Serialize, Deserialize, Clone, Debug)]
//! struct Greeting {
//!     text: String,
//! }
//! impl RoomMessage for Greeting {
//!     const NAME: &'static str = "example.greeting";
//! }
//!
//! fn main() -> Result<(), Box<dyn std::error::Error>> {
//!     let scene = Scene::load("my-room.ron".as_ref())?;
//!     let room = Room::open(scene, RoomOptions::host("my-room").with_message::<Greeting>()?)?;
//!     App::new()
//!         .add_plugins(MinimalPlugins)
//!         .add_plugins(SoftsyncPlugin::default())
//!         .add_room(room)
//!         .add_room_message::<Greeting>()
//!         .add_systems(Update, greet)
//!         .run();
//!     Ok(())
//! }
//!
//! fn greet(mut room: NonSendMut<Room>, mut joins: MessageReader<RoomEvent>,
//!          mut greetings: MessageReader<Received<Greeting>>) {
//!     for RoomEvent(e) in joins.read() {
//!         if let SoftsyncEvent::Room(RoomNews::PeerJoined(p)) = e {
//!             let hi = Greeting { text: format!("welcome, {}", p.0) };
//!             let _ = room.send(MessageTarget::Peer(*p), Delivery::Reliable, &hi);
//!         }
//!     }
//!     for g in greetings.read() {
//!         println!("{} says {}", g.from.0, g.msg.text);
//!     }
//! }
//! ```
//!
//! A joiner needs no copy of the scene: [`Room::open_fetching_scene`] receives the room's scene
//! file and meshes from the room's host (a member it reaches first names the host; SHA-256
//! verified, paths checked, kept under [`RoomOptions::scene_cache`]); the host's `Room` serves
//! the scene it runs, in a room with a key only to peers that prove it or hold a valid token.
//!
//! The crate is headless (bevy's app, ECS, time and transforms): draw the entities with
//! bevy's renderer, or not at all (a bot, a server). `docs/GUIDE.md` walks through a room of
//! your own from `cargo add` on; `examples/` has two programs.

pub mod connect;
pub mod glue;
mod keep;
pub mod options;
pub mod plugin;
pub mod pump;
pub mod rollback;
pub mod room;
mod scene_fetch;
mod signal_move;
pub mod voice;

pub use connect::{connect, first_contact, scene_server, ConnectTimes, Connected};
pub use plugin::{
    AvatarPart, Hand, LocalDevice, NetEntities, NetObject, Received, RoomEvent, RoomFailed,
    RoomStats, SoftBody, SoftsyncApp, SoftsyncPlugin, SoftsyncSet,
};
pub use rollback::{
    RollbackHooks, RollbackObject, RollbackPlugin, RollbackRoom, RollbackRoomEvent, RollbackView,
    TickInfo,
};
pub use room::{wall_ms, Clock, OpenError, Room, RoomOptions, LEAVE_GRACE};
pub use scene_fetch::FetchedScene;
/// The networking crate (sessions, wire format, policies).
pub use softsync_net as net;
/// The engine-agnostic peer (scenes, hands, bots, the built-in messages).
pub use softsync_peer as peer;
/// Rollback rooms (ggrs): the peer, its world and inputs.
pub use softsync_rollback as rollback_core;
pub use softsync_store::keeper::{Keeper, StoreOptions};

/// What an app on this crate uses most.
pub mod prelude {
    pub use crate::plugin::{
        AvatarPart, Hand, LocalDevice, NetEntities, NetObject, Received, RoomEvent, RoomFailed,
        RoomStats, SoftBody, SoftsyncApp, SoftsyncPlugin, SoftsyncSet,
    };
    pub use crate::rollback::{RollbackPlugin, RollbackRoom, RollbackRoomEvent};
    pub use crate::room::{Room, RoomOptions};
    pub use softsync_net::messages::Message as RoomMessage;
    pub use softsync_net::Event as RoomNews;
    pub use softsync_net::{Delivery, MessageTarget, NetId, PeerId};
    pub use softsync_peer::Event as SoftsyncEvent;
}
