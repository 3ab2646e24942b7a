//! [`SoftsyncPlugin`]: the room in bevy's frame, its objects as entities, its news as bevy
//! messages.
//!
//! Frame order:
//! 1. `PreUpdate`, [`SoftsyncSet::NetIn`]: datagrams in, timers, the session's news; each
//!    peer event becomes a [`RoomEvent`], each application message of a registered type a
//!    [`Received<M>`]; [`RoomStats`] is refreshed. A peer that cannot go on writes
//!    [`RoomFailed`] (and ends the app with exit code 3 unless told not to).
//! 2. `FixedUpdate` (at the peer's `dt_s`): [`SoftsyncSet::Input`] is where an app sets the
//!    hands (`room.peer.set_hand_input`); [`SoftsyncSet::Step`] then steps soft bodies and
//!    rapier and publishes what we own.
//! 3. `Update`, [`SoftsyncSet::Mirror`]: one entity per networked object ([`NetObject`],
//!    a `Transform` at its drawn pose; [`SoftBody`] or [`AvatarPart`] where they apply),
//!    spawned and despawned with the object. A renderer adds meshes to these entities after
//!    this set.
//! 4. `PostUpdate`, [`SoftsyncSet::NetOut`]: datagrams out.
//! 5. `Last`, [`SoftsyncSet::Leave`]: on `AppExit`, a `Leave` to the room (a host is replaced
//!    at once, authority returns).
//!
//! Between frames (after `Last` until before `First`: rendering, the window's or headset's
//! wait) the [`Room`] is on the plugin's network thread ([`crate::pump::NetPump`],
//! [`SoftsyncPlugin::net_thread`]), which keeps reading and answering the network every 2 ms, so
//! a slow frame never slows the room. Systems of the frame see the room as usual; outside a
//! frame (a test between `app.update()` calls) reach it with [`SoftsyncApp::with_room`].

use std::collections::HashMap;
use std::marker::PhantomData;

use bevy::app::{
    App, AppExit, First, FixedUpdate, Last, MainScheduleOrder, Plugin, PostUpdate, PreUpdate,
    Update,
};
use bevy::ecs::entity::Entity;
use bevy::ecs::message::{Message, MessageReader, MessageWriter};
use bevy::ecs::prelude::{Commands, Component, Query, ResMut, Resource};
use bevy::ecs::schedule::{IntoScheduleConfigs, ScheduleLabel, SystemSet};
use bevy::ecs::system::{NonSend, NonSendMut};
use bevy::ecs::world::World;
use bevy::time::{Fixed, Time};
use bevy::transform::components::Transform;
use softsync_net::messages::Message as RoomMessage;
use softsync_net::{Delivery, MessageTarget, NetId, PeerId, Stats, Term};
use softsync_peer::{DeviceFrame, Event, Kind, LocalBody};

use crate::glue::transform;
use crate::pump::NetPump;
use crate::room::Room;

/// Where the plugin's systems run; order your own against these.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SoftsyncSet {
    /// `PreUpdate`: network in, events, messages, stats.
    NetIn,
    /// `FixedUpdate`, before [`Step`](Self::Step): set the hands here.
    Input,
    /// `FixedUpdate`: the peer's fixed step.
    Step,
    /// `Update`: the object entities follow the room.
    Mirror,
    /// `PostUpdate`: network out.
    NetOut,
    /// `Last`: leaving on `AppExit`.
    Leave,
}

/// Something that happened in the room (joins, leaves, host changes, authority, grabs,
/// messages, rejoins, warnings): the peer's [`Event`], as a bevy message.
#[derive(Message, Clone, Debug)]
pub struct RoomEvent(pub Event);

/// An application message of type `M` arrived (register `M` with
/// [`SoftsyncApp::add_room_message`]).
#[derive(Clone, Debug)]
pub struct Received<M> {
    /// Who sent it.
    pub from: PeerId,
    /// Whom it was sent to.
    pub to: MessageTarget,
    /// How.
    pub delivery: Delivery,
    /// The message.
    pub msg: M,
}

impl<M: Send + Sync + 'static> Message for Received<M> {}

/// The peer cannot go on: refused, timed out, or the room went on past rejoining.
#[derive(Message, Clone, Debug)]
pub struct RoomFailed {
    /// Why.
    pub reason: String,
}

/// The room as this peer sees it, refreshed every frame after the network.
#[derive(Resource, Clone, Debug, Default)]
pub struct RoomStats {
    /// This peer (none before a room is added).
    pub me: Option<PeerId>,
    /// The host, as far as we know.
    pub host: Option<PeerId>,
    /// Whether we are the host.
    pub is_host: bool,
    /// The room's term (it grows with every host change).
    pub term: Term,
    /// In the room (hosting, or welcomed).
    pub joined: bool,
    /// Members, us included.
    pub members: usize,
    /// Networked objects we know.
    pub objects: usize,
    /// Objects we own (avatar parts included).
    pub owned: usize,
    /// Simulated seconds.
    pub sim_time_s: f64,
    /// The session's traffic, drops and message counters.
    pub session: Stats,
}

/// This peer's tracked device for the next fixed steps (a headset's poses and buttons, the
/// mouse hands): write it in [`SoftsyncSet::Input`] or earlier. In a state-sync room the
/// plugin's step applies it to the peer's hands (unless a system of [`SoftsyncSet::Input`]
/// took it: the binary's driver composes it with a bot); in a rollback room
/// ([`crate::rollback::RollbackPlugin`]) it becomes the player's input. The same system drives
/// either.
#[derive(Resource, Clone, Debug, Default)]
pub struct LocalDevice(pub Option<DeviceFrame>);

/// A networked object's entity. Rigid objects and avatar parts carry a `Transform` at their
/// drawn pose; a soft body's `Transform` stays the identity (its particles and mesh are in
/// world space: [`Room::peer`]'s `soft_bodies()`).
#[derive(Component, Clone, Debug)]
pub struct NetObject {
    /// Its id in the room.
    pub id: NetId,
    /// Its class in the scene.
    pub kind: Kind,
    /// Its class's name.
    pub class: String,
    /// Who owns it now.
    pub owner: Option<PeerId>,
    /// Whether this peer owns it.
    pub mine: bool,
    /// Whether one of our hands hovers over it (in reach to grab).
    pub hovered: bool,
}

/// A soft body's entity (with [`NetObject`]).
#[derive(Component, Clone, Debug)]
pub struct SoftBody {
    /// Its particles now (the method may change it: thesis clustering, tears).
    pub particles: usize,
    /// Topology changes (cuts, tears, resolution changes) applied so far: a renderer rebuilds
    /// its triangles when this grows.
    pub topology: u32,
    /// `method: auto`: the resolution level it runs at (coarsest 0), `None` for its class's
    /// spawn level or a class without `auto`.
    pub level: Option<u8>,
    /// `method: auto`, its owner's view: the particles sleep (an untouched body at rest).
    pub asleep: bool,
}

/// One of this peer's own hands, on its avatar hand's entity (with [`NetObject`] and
/// [`AvatarPart`]): which hand and what it holds now. Drive it in [`SoftsyncSet::Input`]
/// with `room.peer.set_hand_input(index, …)` (a controller, the mouse, a `softsync_peer::Bot`).
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hand {
    /// 0 left, 1 right.
    pub index: usize,
    /// The object it holds, if any.
    pub holding: Option<NetId>,
}

/// An avatar part's entity (with [`NetObject`]): a head or a hand of some peer.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct AvatarPart {
    /// Whose avatar.
    pub of: PeerId,
    /// Head or hand.
    pub hand: bool,
}

/// Entities by networked id.
#[derive(Resource, Default, Debug)]
pub struct NetEntities(HashMap<NetId, Entity>);

impl NetEntities {
    /// The entity of an object.
    pub fn get(&self, id: NetId) -> Option<Entity> {
        self.0.get(&id).copied()
    }

    /// Every object's entity.
    pub fn iter(&self) -> impl Iterator<Item = (NetId, Entity)> + '_ {
        self.0.iter().map(|(k, v)| (*k, *v))
    }
}

/// Runs the [`Room`] an app added with [`SoftsyncApp::add_room`] (or later, with
/// `insert_non_send`): see the module docs for what runs where.
#[derive(Clone, Debug)]
pub struct SoftsyncPlugin {
    /// End the app (exit code 3) when the peer cannot go on; false to handle [`RoomFailed`]
    /// yourself (e.g. back to a menu).
    pub exit_on_failure: bool,
    /// Keep an entity per networked object ([`SoftsyncSet::Mirror`]).
    pub mirror_entities: bool,
    /// Pump the network on a thread of its own between frames (see the module docs), so the
    /// room's heartbeats, RTT and relaying do not depend on the frame rate. False: only the
    /// frame pumps it (one pump per frame; a frame of 300 ms is then an RTT of 300 ms, and a
    /// host that stalls longer than the peers' timeout is taken for dead).
    pub net_thread: bool,
}

impl Default for SoftsyncPlugin {
    fn default() -> Self {
        SoftsyncPlugin {
            exit_on_failure: true,
            mirror_entities: true,
            net_thread: true,
        }
    }
}

#[derive(Resource, Clone, Copy)]
struct PluginSettings {
    exit_on_failure: bool,
}

impl Plugin for SoftsyncPlugin {
    fn build(&self, app: &mut App) {
        app.add_message::<RoomEvent>()
            .add_message::<RoomFailed>()
            .init_resource::<RoomStats>()
            .init_resource::<NetEntities>()
            .init_resource::<LocalDevice>()
            .insert_resource(PluginSettings {
                exit_on_failure: self.exit_on_failure,
            })
            .configure_sets(FixedUpdate, SoftsyncSet::Input.before(SoftsyncSet::Step))
            .add_systems(
                PreUpdate,
                (net_in, update_stats).chain().in_set(SoftsyncSet::NetIn),
            )
            .add_systems(FixedUpdate, step.in_set(SoftsyncSet::Step))
            .add_systems(PostUpdate, net_out.in_set(SoftsyncSet::NetOut))
            .add_systems(Last, leave_on_exit.in_set(SoftsyncSet::Leave));
        if self.mirror_entities {
            app.add_systems(Update, mirror.in_set(SoftsyncSet::Mirror));
        }
        if self.net_thread {
            match NetPump::start() {
                Ok(pump) => {
                    app.insert_resource(Pump(pump))
                        .init_schedule(RoomBack)
                        .init_schedule(RoomAway)
                        .add_systems(RoomBack, take_back)
                        .add_systems(RoomAway, hand_off);
                    let mut order = app.world_mut().resource_mut::<MainScheduleOrder>();
                    order.insert_before(First, RoomBack);
                    order.insert_after(Last, RoomAway);
                }
                // the room still runs, pumped by the frame alone
                Err(e) => eprintln!("softsync: no network thread ({e}); the frame pumps the room"),
            }
        }
    }
}

/// The plugin's network thread.
#[derive(Resource)]
struct Pump(NetPump);

/// Before `First`: the room back from the network thread.
#[derive(ScheduleLabel, Clone, Debug, PartialEq, Eq, Hash)]
struct RoomBack;

/// After `Last`: the room to the network thread until the next frame.
#[derive(ScheduleLabel, Clone, Debug, PartialEq, Eq, Hash)]
struct RoomAway;

fn take_back(world: &mut World) {
    if let Some(room) = world.get_resource::<Pump>().and_then(|p| p.0.take_back()) {
        world.insert_non_send(room);
    }
}

fn hand_off(world: &mut World) {
    if !world.contains_resource::<Pump>() {
        return;
    }
    if let Some(room) = world.remove_non_send::<Room>() {
        if let Some(p) = world.get_resource::<Pump>() {
            p.0.hand_off(room);
        }
    }
}

/// Adding a room and its message types to an app.
pub trait SoftsyncApp {
    /// Run `room` (insert it; the fixed step follows its peer's `dt_s`). Add
    /// [`SoftsyncPlugin`] too.
    fn add_room(&mut self, room: Room) -> &mut Self;
    /// Deliver messages of type `M` as [`Received<M>`] bevy messages (`M` must be in the
    /// room's message table: the scene's `messages` or [`crate::RoomOptions::with_message`]).
    fn add_room_message<M: RoomMessage + Send + Sync + 'static>(&mut self) -> &mut Self;
    /// Run `f` on the room outside a frame (between `app.update()` calls the room may be on
    /// the plugin's network thread, which pauses for it). `None` without a room.
    fn with_room<R>(&mut self, f: impl FnOnce(&mut Room) -> R) -> Option<R>;
}

impl SoftsyncApp for App {
    fn add_room(&mut self, room: Room) -> &mut Self {
        let dt = f64::from(room.peer.config().dt_s);
        self.insert_resource(Time::<Fixed>::from_seconds(dt))
            .insert_non_send(room)
    }

    fn with_room<R>(&mut self, f: impl FnOnce(&mut Room) -> R) -> Option<R> {
        let world = self.world_mut();
        if let Some(mut room) = world.get_non_send_mut::<Room>() {
            return Some(f(&mut room));
        }
        let mut room = world.get_resource::<Pump>()?.0.take_back()?;
        let r = f(&mut room);
        if let Some(p) = world.get_resource::<Pump>() {
            p.0.hand_off(room);
        }
        Some(r)
    }

    fn add_room_message<M: RoomMessage + Send + Sync + 'static>(&mut self) -> &mut Self {
        self.add_message::<Received<M>>().add_systems(
            PreUpdate,
            decode::<M>
                .after(SoftsyncSet::NetIn)
                .in_set(DecodeSet(PhantomData::<fn() -> M>)),
        )
    }
}

/// One decode system per message type.
#[derive(SystemSet)]
struct DecodeSet<M>(PhantomData<fn() -> M>);

impl<M> Clone for DecodeSet<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for DecodeSet<M> {}
impl<M> PartialEq for DecodeSet<M> {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
impl<M> Eq for DecodeSet<M> {}
impl<M> std::hash::Hash for DecodeSet<M> {
    fn hash<H: std::hash::Hasher>(&self, _: &mut H) {}
}
impl<M> std::fmt::Debug for DecodeSet<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "DecodeSet<{}>", std::any::type_name::<M>())
    }
}

fn net_in(
    room: Option<NonSendMut<Room>>,
    settings: bevy::ecs::prelude::Res<PluginSettings>,
    mut events: MessageWriter<RoomEvent>,
    mut failed: MessageWriter<RoomFailed>,
    mut exit: MessageWriter<AppExit>,
) {
    let Some(mut room) = room else { return };
    let result = room.network_in();
    events.write_batch(room.drain_events().map(RoomEvent));
    if let Err(e) = result {
        failed.write(RoomFailed {
            reason: e.to_string(),
        });
        if settings.exit_on_failure {
            exit.write(AppExit::from_code(e.exit_code()));
        }
    }
}

fn update_stats(room: Option<NonSend<Room>>, mut stats: ResMut<RoomStats>) {
    let Some(room) = room else { return };
    let p = &room.peer;
    let s = p.session();
    let me = p.me();
    stats.me = Some(me);
    stats.host = s.host_id();
    stats.is_host = s.is_host();
    stats.term = s.term();
    stats.joined = p.joined();
    stats.members = s.members().len();
    stats.objects = p.objects().len();
    stats.owned = p
        .objects()
        .keys()
        .filter(|id| s.owner(**id) == Some(me))
        .count();
    stats.sim_time_s = p.sim_time();
    stats.session.clone_from(s.stats());
}

fn decode<M: RoomMessage + Send + Sync + 'static>(
    room: Option<NonSend<Room>>,
    mut events: MessageReader<RoomEvent>,
    mut out: MessageWriter<Received<M>>,
) {
    let Some(room) = room else {
        events.clear();
        return;
    };
    for RoomEvent(e) in events.read() {
        let Event::Room(softsync_net::Event::Message(m)) = e else {
            continue;
        };
        match room.peer.decode::<M>(m) {
            Some(Ok(msg)) => {
                out.write(Received {
                    from: m.from,
                    to: m.to,
                    delivery: m.delivery,
                    msg,
                });
            }
            // The host checked the kind, not the bytes: a peer of another build of the same
            // type. Said once per message, never a panic.
            Some(Err(why)) => eprintln!(
                "softsync: message {} from peer {}: {why}",
                M::NAME,
                m.from.0
            ),
            None => {}
        }
    }
}

fn step(room: Option<NonSendMut<Room>>, device: bevy::ecs::system::Res<LocalDevice>) {
    if let Some(mut room) = room {
        if let Some(d) = &device.0 {
            d.apply(&mut room.peer);
        }
        room.step();
    }
}

fn net_out(room: Option<NonSendMut<Room>>) {
    if let Some(mut room) = room {
        room.flush();
    }
}

fn leave_on_exit(room: Option<NonSendMut<Room>>, mut exits: MessageReader<AppExit>) {
    if exits.read().next().is_none() {
        return;
    }
    if let Some(mut room) = room {
        room.leave();
    }
}

fn mirror(
    mut commands: Commands,
    room: Option<NonSendMut<Room>>,
    mut ents: ResMut<NetEntities>,
    mut q: Query<(
        &mut Transform,
        &mut NetObject,
        Option<&mut SoftBody>,
        Option<&mut Hand>,
    )>,
) {
    let Some(mut room) = room else { return };
    let now = room.now();
    let peer = &mut room.peer;
    let me = peer.me();
    ents.0.retain(|id, e| {
        let keep = peer.objects().contains_key(id);
        if !keep {
            commands.entity(*e).despawn();
        }
        keep
    });
    let ids: Vec<NetId> = peer.objects().keys().copied().collect();
    let hovered = peer.hovered_ids();
    let parts = peer.avatar_parts();
    let hand_of = |id: NetId| (0..2).find(|i| parts[1 + i] == Some(id));
    for id in ids {
        let Some(o) = peer.objects().get(&id).cloned() else {
            continue;
        };
        let owner = peer.session().owner(id);
        let soft = match o.body {
            LocalBody::Soft(h) => peer.soft_bodies().get(h).map(|b| SoftBody {
                particles: b.particles().len(),
                topology: o.topology,
                level: o.level,
                asleep: b.is_asleep(peer.world()),
            }),
            _ => None,
        };
        let pose = if soft.is_some() {
            Some(Transform::IDENTITY)
        } else {
            peer.drawn_pose(now, id).and_then(|(p, r)| transform(p, r))
        };
        let Some(&e) = ents.0.get(&id) else {
            let obj = NetObject {
                id,
                kind: o.kind,
                class: peer.scene().name_of(o.kind).to_owned(),
                owner,
                mine: owner == Some(me),
                hovered: hovered.contains(&id),
            };
            let mut ec = commands.spawn((obj, pose.unwrap_or(Transform::IDENTITY)));
            if let Some(s) = soft {
                ec.insert(s);
            }
            if let Some(of) = o.avatar_of {
                ec.insert(AvatarPart {
                    of,
                    hand: o.kind == Kind::HAND,
                });
            }
            if let Some(index) = hand_of(id) {
                ec.insert(Hand {
                    index,
                    holding: peer.held(index).map(|(h, _)| h),
                });
            }
            ents.0.insert(id, ec.id());
            continue;
        };
        let Ok((mut tf, mut obj, soft_c, hand_c)) = q.get_mut(e) else {
            continue;
        };
        if let (Some(mut h), Some(index)) = (hand_c, hand_of(id)) {
            let holding = peer.held(index).map(|(h, _)| h);
            if h.holding != holding {
                h.holding = holding;
            }
        }
        let is_hovered = hovered.contains(&id);
        if obj.hovered != is_hovered {
            obj.hovered = is_hovered;
        }
        if let Some(p) = pose {
            if *tf != p {
                *tf = p;
            }
        }
        if obj.owner != owner {
            obj.owner = owner;
            obj.mine = owner == Some(me);
        }
        if let (Some(mut c), Some(s)) = (soft_c, soft) {
            if c.topology != s.topology || c.particles != s.particles {
                *c = s;
            }
        }
    }
}
