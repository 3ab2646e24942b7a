//! `softsync-peer`: one peer of a softsync room, engine-agnostic and sans-IO.
//!
//! A [`Peer`] is what an app puts around a [`softsync_net::Session`] to be in a room: the
//! room's networked objects mirrored as bodies in a rapier world (soft bodies run the
//! particle method where this peer owns them, and show the owner's interpolated state where
//! it does not), two hands that grab them (asking the session for authority first), an
//! avatar, and the policy of getting in and staying in (join retries, the join timeout,
//! rejoining a room that went on without us). It knows no engine, reads no clock and owns no
//! socket, so a headless test can run two peers on virtual time, and a bevy app, a server or
//! another engine can drive one.
//!
//! Also here, because they are engine-agnostic and tests want them: scenes ([`scene`]: a
//! room's object classes, fixed geometry and objects, read from a RON file; the session
//! configuration they imply), bot scripts ([`bot`]) and one frame of a tracked device
//! ([`device`]).
//!
//! # Driving a peer
//!
//! The driver owns the transport and the clock. Each frame it feeds datagrams and link news
//! in, pumps timers and the session's news, runs the fixed steps, and sends what comes out;
//! [`Peer::poll_event`] says what happened. Leaving, it sends the `Leave` and waits a moment
//! before the process ends.
//!
//! ```no_run
//! use std::path::Path;
//! use std::time::Duration;
//!
//! use softsync_net::{Instant, SendPolicy, Session, Transport};
//! use softsync_peer::{Event, Peer, PeerConfig, Scene};
//!
//! fn host(
//!     transport: &mut dyn Transport,
//!     clock: impl Fn() -> Instant,
//! ) -> Result<(), Box<dyn std::error::Error>> {
//!     let scene = Scene::by_name("thesis-room", Path::new("assets"))?;
//!     let policy = SendPolicy::default();
//!     let cfg = scene.session_config(policy.clone(), policy.clone(), policy);
//!     let session = Session::host(transport.local_id(), cfg, clock());
//!     let mut peer = Peer::new(clock(), session, None, scene, PeerConfig::default())?;
//!     peer.open(clock())?;
//!     let dt = Duration::from_secs_f32(peer.config().dt_s);
//!     let mut next_step = clock();
//!     loop {
//!         let now = clock();
//!         while let Some((from, bytes)) = transport.recv(now) {
//!             peer.handle_datagram(now, from, &bytes);
//!         }
//!         while let Some(e) = transport.poll_peer_event() {
//!             peer.handle_link_event(e);
//!         }
//!         peer.pump(now)?;
//!         while now >= next_step {
//!             // A bot or a device sets the hands here (`Peer::set_hand_input`).
//!             peer.fixed_step(now);
//!             next_step += dt;
//!         }
//!         while let Some(t) = peer.poll_transmit(now) {
//!             transport.send(now, &t);
//!         }
//!         while let Some(e) = peer.poll_event() {
//!             if let Event::Room(softsync_net::Event::PeerJoined(p)) = e {
//!                 println!("{} joined", p.0);
//!             }
//!         }
//!     }
//! }
//! ```

pub mod avatar;
pub mod bot;
pub mod device;
pub mod dump;
pub mod events;
pub mod join;
pub mod messages;
pub mod mirror;
pub mod peer;
pub mod scene;

pub use bot::Bot;
pub use device::DeviceFrame;
pub use events::{Counters, Event, PeerError, TopologyError};
pub use messages::Say;
pub use mirror::{build_body, LocalBody, MirroredObject};
pub use peer::cost::{FrameCost, Phase};
pub use peer::cutter::HandTool;
pub use peer::keep::Reopened;
pub use peer::{Peer, PeerConfig};
pub use scene::{BodyClass, Class, FixedBox, Kind, Placed, Scene, Shape};
