//! Rollback rooms in a bevy app: [`RollbackRoom`] runs a `softsync-rollback` peer on a thread
//! of its own at the fixed rate, and [`RollbackPlugin`] joins it to the frame. Choose the sync
//! mode when opening the room; the app's systems stay the same:
//! - **input**: write the device (a headset's poses and buttons, the mouse hands) to
//!   [`LocalDevice`] in [`SoftsyncSet::Input`] (or `PreUpdate`): the state-sync plugin applies it
//!   to the peer's hands, this one quantizes it into the player's rollback input;
//! - **objects**: each scene object is an entity with [`NetObject`] (its id is its index in the
//!   scene) and a `Transform` at its drawn pose, soft bodies with [`SoftBody`] too;
//! - **events**: [`RollbackRoomEvent`] (epochs, desyncs and their repair, the room's joins and
//!   leaves) and [`RoomFailed`].
//!
//! # Why a thread, and what is drawn
//! The simulation must not follow the frame rate: a 90 Hz headset and a 60 Hz tick do not
//! divide, and a slow frame (a software renderer takes 50–300 ms) would otherwise make the
//! peer send its inputs in bursts, so everyone else rolls back more and stalls at ggrs's
//! prediction window. The thread ticks at `1 / dt` whatever the frames do, and publishes after
//! each tick the newest predicted frame as [`RollbackView`] (poses, velocities, soft meshes,
//! everyone's hands). The rule for drawing: **the newest predicted tick, extrapolated to the
//! display's time** by each object's velocity (at most one tick ahead) — no interpolation
//! delay is added: what rollback buys (your own grab in the next frame) is kept.
//!
//! A rollback moves what was drawn: the re-simulated frame differs from the predicted one.
//! The thread measures how (`softsync_rollback::Correction`) and the view starts each object at
//! its old place and glides to the corrected one (the offset decays with a time constant of
//! [`SMOOTHING_S`]); a soft body's mesh moves and turns with its center. Cost: the thread
//! copies the drawn state once per tick (a memcpy of the soft meshes), the frame applies an
//! offset per vertex.

// The I/O layer: the thread's clock and its sleeps.
#![allow(clippy::disallowed_methods)]

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use bevy::app::{App, AppExit, FixedUpdate, Last, Plugin, PreUpdate, Update};
use bevy::ecs::message::{Message, MessageReader, MessageWriter};
use bevy::ecs::prelude::*;
use bevy::transform::components::Transform;
use glam::{Quat, Vec3};
use softsync_net::messages::MessageTypes;
use softsync_net::share::BlobServer;
use softsync_net::{door, Instant, LinkConditioner, NetId, PeerId, Session, Transport};
use softsync_peer::{DeviceFrame, Kind, Scene};
use softsync_rollback::room::register;
use softsync_rollback::{Correction, PlayerInput, RollbackConfig, RollbackEvent, RollbackPeer};

use crate::connect::{connect, first_contact, scene_server};
use crate::glue::{to_bevy, to_bevy_quat};
use crate::plugin::{LocalDevice, NetObject, RoomFailed, SoftBody, SoftsyncSet};
use crate::room::{Clock, OpenError, RoomOptions, LEAVE_GRACE};

/// Time constant of the glide that hides a rollback's correction, seconds.
pub const SMOOTHING_S: f32 = 0.1;

/// Events kept for the app between two frames at most (older ones are dropped).
const EVENT_QUEUE: usize = 1024;

/// What happened in a rollback room, as a bevy message.
#[derive(Message, Clone, Debug)]
pub struct RollbackRoomEvent(pub RollbackEvent);

/// A soft body as drawn: its render mesh in world space at the tick.
#[derive(Clone, Debug, Default)]
pub struct ShownSoft {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex normals.
    pub normals: Vec<Vec3>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Changes of the triangles so far (a renderer rebuilds its indices when this grows).
    pub topology: u32,
    /// Particles.
    pub particles: usize,
}

/// One scene object at the newest tick.
#[derive(Clone, Debug)]
pub struct ShownObject {
    /// Its class.
    pub kind: Kind,
    /// Center position and rotation.
    pub pos: Vec3,
    /// Rotation.
    pub rot: Quat,
    /// Linear velocity, m/s.
    pub linvel: Vec3,
    /// Angular velocity, rad/s.
    pub angvel: Vec3,
    /// The rollback correction still to glide through at the tick (see the module docs).
    pub offset: Correction,
    /// A soft body's mesh.
    pub soft: Option<ShownSoft>,
    /// Held by a hand of ours in our view.
    pub held_by_us: bool,
}

/// The newest predicted frame of a rollback room, as the thread published it.
#[derive(Clone, Debug, Default)]
pub struct RollbackView {
    /// Its frame (none drawn before the first epoch's world).
    pub frame: i32,
    /// When it was published (the display extrapolates from here).
    pub at: Option<std::time::Instant>,
    /// The step, seconds.
    pub dt_s: f32,
    /// The scene's objects, in scene order.
    pub objects: Vec<ShownObject>,
    /// The players of the running epoch and the device each stepped with last.
    pub players: Vec<(PeerId, DeviceFrame)>,
    /// The newest confirmed frame.
    pub confirmed: i32,
    /// The running epoch.
    pub epoch: u32,
    /// Members of the room (the session's).
    pub members: usize,
    /// The host.
    pub host: Option<PeerId>,
    /// Whether we are welcomed (or host).
    pub joined: bool,
    /// Rollbacks so far.
    pub rollbacks: u64,
    /// Frames simulated again after rollbacks so far.
    pub resimulated: u64,
    /// Desyncs seen so far.
    pub desyncs: u64,
    /// Desyncs repaired so far.
    pub repairs: u64,
    /// Datagram payload bytes sent so far.
    pub up_bytes: u64,
}

impl RollbackView {
    /// Object `i` where the display shows it `ahead_s` after the tick (at most one tick):
    /// extrapolated by its velocity, moved by what is left of a rollback's correction.
    pub fn shown_pose(&self, i: usize, ahead_s: f32) -> Option<(Vec3, Quat)> {
        let o = self.objects.get(i)?;
        let (off, ahead) = self.offset_at(o, ahead_s);
        let spin = Quat::from_scaled_axis(o.angvel * ahead);
        Some((
            o.pos + o.linvel * ahead + off.pos,
            (off.rot * spin * o.rot).normalize(),
        ))
    }

    /// The map from a soft body's tick positions to its shown ones (see
    /// [`shown_pose`](Self::shown_pose)): `p ↦ center + pos + rot·(p − center)`.
    pub fn shown_map(&self, i: usize, ahead_s: f32) -> Option<impl Fn(Vec3) -> Vec3> {
        let o = self.objects.get(i)?;
        let (off, ahead) = self.offset_at(o, ahead_s);
        let c = o.pos;
        let t = o.linvel * ahead + off.pos;
        let r = off.rot;
        Some(move |p: Vec3| c + t + r * (p - c))
    }

    fn offset_at(&self, o: &ShownObject, ahead_s: f32) -> (Correction, f32) {
        let ahead = ahead_s.clamp(0.0, self.dt_s.max(0.0));
        let k = (-ahead / SMOOTHING_S).exp();
        (
            Correction {
                pos: o.offset.pos * k,
                rot: Quat::IDENTITY.slerp(o.offset.rot, k),
            },
            ahead,
        )
    }
}

/// What an `after_tick` hook is told besides the peer.
pub struct TickInfo<'a> {
    /// The tick's events.
    pub events: &'a [RollbackEvent],
    /// The time of the tick.
    pub now: Instant,
    /// Datagram payload bytes sent so far (session, ggrs, snapshots).
    pub up_bytes: u64,
}

/// What the app adds to a rollback peer's thread: the input of each tick (a script; without
/// it, the [`LocalDevice`]'s), what happens after each tick (reports, dumps), and at the end.
/// They run on the room's thread, with the peer.
#[derive(Default)]
pub struct RollbackHooks {
    /// The input for the next tick, given the peer (a script may send it messages), this
    /// tick's device frame (if any) and the time.
    #[allow(clippy::type_complexity)]
    pub input: Option<
        Box<dyn FnMut(&mut RollbackPeer, Option<&DeviceFrame>, Instant) -> PlayerInput + Send>,
    >,
    /// After each tick: the peer, and the tick's events, time and traffic.
    #[allow(clippy::type_complexity)]
    pub after_tick: Option<Box<dyn FnMut(&RollbackPeer, &TickInfo<'_>) + Send>>,
    /// Once, after leaving.
    #[allow(clippy::type_complexity)]
    pub at_end: Option<Box<dyn FnOnce(&RollbackPeer) + Send>>,
}

struct Shared {
    device: Option<DeviceFrame>,
    view: RollbackView,
    events: VecDeque<RollbackEvent>,
    failure: Option<String>,
}

/// A rollback room running on its own thread (see the module docs). Dropping it leaves the
/// room (a `Leave`, then [`LEAVE_GRACE`] for it to go out) and joins the thread.
#[derive(Resource)]
pub struct RollbackRoom {
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    scene: Scene,
    me: PeerId,
    url: String,
    runs_signaling: bool,
    contact: Option<(PeerId, Duration)>,
    /// The embedded signaling server, if we run it (kept alive with the room).
    _signal: Option<softsync_net_matchbox::SignalServer>,
}

impl RollbackRoom {
    /// Host or join (as `opts` says) a rollback room of `scene`, stepping as `cfg` says; the
    /// peer runs on its own thread from here on. Connecting (signaling, a joiner's first
    /// contact) happens before it returns.
    pub fn open(
        scene: Scene,
        opts: RoomOptions,
        rcfg: RollbackConfig,
        hooks: RollbackHooks,
    ) -> Result<RollbackRoom, OpenError> {
        let mut cfg = opts.session_config(&scene)?;
        let mut types = MessageTypes::from_config(&cfg).ok_or_else(|| {
            OpenError::Config("the room's message table names a type twice".into())
        })?;
        register(&mut types);
        types.configure(&mut cfg);
        let conn = connect(&opts)?;
        let mut transport = conn.transport;
        let me = transport.local_id();
        let clock = Clock::start();
        let mut contact_after = None;
        let (session, contact) = if opts.host {
            (Session::host(me, cfg, clock.now()), None)
        } else {
            let c = first_contact(&mut transport, &opts, conn.started)?;
            contact_after = Some((c, conn.started.elapsed()));
            (Session::join(me, c, cfg, clock.now()), Some(c))
        };
        let transport: Box<dyn Transport + Send> = match opts.condition.clone() {
            Some(c) => Box::new(LinkConditioner::new(transport, c)),
            None => Box::new(transport),
        };
        let shared = Arc::new(Mutex::new(Shared {
            device: None,
            view: RollbackView {
                dt_s: rcfg.dt_s,
                ..RollbackView::default()
            },
            events: VecDeque::new(),
            failure: None,
        }));
        let stop = Arc::new(AtomicBool::new(false));
        // The peer holds `Rc`s (ggrs's socket): it is made on its thread and stays there.
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let thread = {
            let (shared, stop, scene) = (shared.clone(), stop.clone(), scene.clone());
            let host = opts.host;
            std::thread::Builder::new()
                .name("softsync-rollback".into())
                .spawn(move || {
                    let peer =
                        RollbackPeer::new(clock.now(), scene.clone(), rcfg, session, contact)
                            .and_then(|mut p| {
                                if host {
                                    p.open(clock.now())?;
                                }
                                Ok(p)
                            });
                    match peer {
                        Ok(peer) => {
                            let _ = ready_tx.send(Ok(()));
                            let mut t = Ticker {
                                peer,
                                transport,
                                clock,
                                scene,
                                share: None,
                                shared,
                                hooks,
                                up_bytes: 0,
                                events: Vec::new(),
                            };
                            t.run(&stop);
                        }
                        Err(e) => {
                            let _ = ready_tx.send(Err(e.to_string()));
                        }
                    }
                })
                .map_err(|e| OpenError::Connect(format!("the rollback thread: {e}")))?
        };
        match ready_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(OpenError::Config(e)),
            Err(_) => return Err(OpenError::Connect("the rollback thread ended".into())),
        }
        Ok(RollbackRoom {
            shared,
            stop,
            thread: Some(thread),
            scene,
            me,
            url: conn.url,
            runs_signaling: conn.signal.is_some(),
            contact: contact_after,
            _signal: conn.signal,
        })
    }

    fn lock(&self) -> MutexGuard<'_, Shared> {
        // a hook that panicked poisons nothing we cannot read on
        self.shared.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// This peer's id.
    pub fn me(&self) -> PeerId {
        self.me
    }

    /// The room's scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The signaling URL.
    pub fn signal_url(&self) -> &str {
        &self.url
    }

    /// Whether this peer runs the room's signaling server.
    pub fn runs_signaling(&self) -> bool {
        self.runs_signaling
    }

    /// A joiner's first contact and how long after connecting started it answered.
    pub fn contact(&self) -> Option<(PeerId, Duration)> {
        self.contact
    }

    /// The device frame the next ticks quantize into our input (without an input hook).
    pub fn set_device(&self, d: Option<DeviceFrame>) {
        self.lock().device = d;
    }

    /// The newest published frame (a copy: cheap for small scenes; for large ones prefer
    /// [`with_view`](Self::with_view)).
    pub fn view(&self) -> RollbackView {
        self.lock().view.clone()
    }

    /// Run `f` on the newest published frame (the thread waits for it: keep it short).
    pub fn with_view<R>(&self, f: impl FnOnce(&RollbackView) -> R) -> R {
        f(&self.lock().view)
    }

    /// Events since the last call.
    pub fn drain_events(&self) -> Vec<RollbackEvent> {
        self.lock().events.drain(..).collect()
    }

    /// Why the peer cannot go on (refused, dropped, not welcomed in time), once it stopped.
    pub fn failure(&self) -> Option<String> {
        self.lock().failure.clone()
    }

    /// Whether the thread still runs.
    pub fn running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Leave the room: the thread says goodbye, waits [`LEAVE_GRACE`] and ends (its
    /// `at_end` hook runs). Idempotent.
    pub fn leave(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for RollbackRoom {
    fn drop(&mut self) {
        self.leave();
    }
}

/// The room's thread.
struct Ticker {
    peer: RollbackPeer,
    transport: Box<dyn Transport + Send>,
    clock: Clock,
    scene: Scene,
    share: Option<BlobServer>,
    shared: Arc<Mutex<Shared>>,
    hooks: RollbackHooks,
    up_bytes: u64,
    events: Vec<RollbackEvent>,
}

impl Ticker {
    fn run(&mut self, stop: &AtomicBool) {
        let step = Duration::from_secs_f32(self.shared_dt());
        let mut next = std::time::Instant::now();
        let mut offsets: Vec<Correction> = Vec::new();
        while !stop.load(Ordering::SeqCst) {
            let now = self.clock.now();
            self.network_in(now);
            let device = self.lock().device;
            let input = match self.hooks.input.as_mut() {
                Some(f) => f(&mut self.peer, device.as_ref(), now),
                None => device
                    .as_ref()
                    .map(PlayerInput::from_device)
                    .unwrap_or_default(),
            };
            self.peer.set_input(input);
            self.peer.tick(now);
            self.network_out(now);
            self.events.clear();
            let mut failure = None;
            while let Some(e) = self.peer.poll_event() {
                if let RollbackEvent::Room(softsync_net::Event::Refused { reason }) = &e {
                    failure = Some(format!("refused: {reason}"));
                }
                if let RollbackEvent::Room(softsync_net::Event::Dropped { reason, .. }) = &e {
                    failure = Some(format!("dropped from the room: {reason}"));
                }
                self.events.push(e);
            }
            if let Some(f) = self.hooks.after_tick.as_mut() {
                let info = TickInfo {
                    events: &self.events,
                    now,
                    up_bytes: self.up_bytes,
                };
                f(&self.peer, &info);
            }
            self.publish(&mut offsets, failure);
            if self.lock().failure.is_some() {
                break;
            }
            next += step;
            let wall = std::time::Instant::now();
            if next > wall {
                std::thread::sleep(next - wall);
            } else if wall - next > Duration::from_millis(250) {
                next = wall;
            }
        }
        self.peer.leave(self.clock.now());
        let end = std::time::Instant::now() + LEAVE_GRACE;
        while std::time::Instant::now() < end {
            let now = self.clock.now();
            self.network_out(now);
            std::thread::sleep(Duration::from_millis(5));
        }
        if let Some(f) = self.hooks.at_end.take() {
            f(&self.peer);
        }
    }

    fn shared_dt(&self) -> f32 {
        self.lock().view.dt_s.max(1e-3)
    }

    fn lock(&self) -> MutexGuard<'_, Shared> {
        self.shared.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn network_in(&mut self, now: Instant) {
        while let Some((from, bytes)) = self.transport.recv(now) {
            // the front door: the scene share here, the rest to the rollback peer's (which
            // takes the session's and its own)
            if door::classify(&bytes) == door::Door::Share {
                // a joiner takes the scene from the room's host only: a member names it
                let session = self.peer.session();
                if let (false, true, Some(host)) =
                    (session.is_host(), session.is_connected(), session.host_id())
                {
                    if let Some(t) = softsync_net::share::ask_host(from, &bytes, host) {
                        self.transport.send(now, &t);
                    }
                    continue;
                }
                // a joiner without the scene asks for ours (a state-sync one is then refused
                // at its Hello, told the room syncs by rollback)
                let me = self.peer.me();
                let server = self.share.get_or_insert_with(|| {
                    scene_server(&self.scene, self.peer.session().config(), me)
                });
                let session = self.peer.session();
                let judged =
                    server.handle_judged(now, from, &bytes, |t| session.token_admits(t, from, now));
                if let Some(t) = judged {
                    self.transport.send(now, &t);
                }
                continue;
            }
            self.peer.handle_datagram(now, from, &bytes);
        }
        while let Some(e) = self.transport.poll_peer_event() {
            self.peer.handle_link_event(e);
        }
    }

    fn network_out(&mut self, now: Instant) {
        while let Some(t) = self.peer.poll_transmit(now) {
            self.up_bytes += t.payload.len() as u64;
            self.transport.send(now, &t);
        }
    }

    /// The newest frame for the display, corrections composed into the decaying offsets.
    fn publish(&mut self, offsets: &mut Vec<Correction>, failure: Option<String>) {
        let none = Correction {
            pos: Vec3::ZERO,
            rot: Quat::IDENTITY,
        };
        let dt = self.peer.world().map_or(0.0, |w| w.dt_s());
        let k = (-dt / SMOOTHING_S).exp();
        for o in offsets.iter_mut() {
            o.pos *= k;
            o.rot = Quat::IDENTITY.slerp(o.rot, k);
        }
        if let Some(c) = self.peer.take_corrections() {
            offsets.resize(c.len(), none);
            for (o, c) in offsets.iter_mut().zip(c) {
                o.pos += c.pos;
                o.rot = (c.rot * o.rot).normalize();
            }
        }
        let me = self.peer.me();
        let mut shared = self.shared.lock().unwrap_or_else(|e| e.into_inner());
        let shared = &mut *shared;
        if let Some(f) = failure {
            shared.failure.get_or_insert(f);
        }
        for e in &self.events {
            if shared.events.len() >= EVENT_QUEUE {
                shared.events.pop_front();
            }
            shared.events.push_back(e.clone());
        }
        let v = &mut shared.view;
        let session = self.peer.session();
        v.members = session.members().len();
        v.host = session.host_id();
        v.joined = session.is_host() || session.is_connected();
        let st = self.peer.stats();
        (v.rollbacks, v.resimulated, v.desyncs, v.repairs) =
            (st.rollbacks, st.resimulated, st.desyncs, st.repairs);
        v.up_bytes = self.up_bytes;
        v.confirmed = self.peer.confirmed_frame().unwrap_or(-1);
        v.epoch = self.peer.epoch().map_or(0, |e| e.n);
        let Some(w) = self.peer.world() else {
            return;
        };
        v.frame = w.frame();
        v.dt_s = w.dt_s();
        v.at = Some(std::time::Instant::now());
        let players = w.players();
        let mine = players.iter().position(|p| *p == me);
        v.players.clear();
        for (i, p) in players.iter().enumerate() {
            if let Some(input) = w.player_input(i) {
                v.players.push((*p, input.to_device()));
            }
        }
        let held: Vec<usize> = mine
            .map(|m| (0..2).filter_map(|h| w.held(m, h)).collect())
            .unwrap_or_default();
        v.objects.truncate(w.objects().len());
        for (i, o) in w.objects().iter().enumerate() {
            let (pos, rot) = w.object_pose(i).unwrap_or((Vec3::ZERO, Quat::IDENTITY));
            let (linvel, angvel) = w.object_velocity(i).unwrap_or_default();
            if v.objects.len() <= i {
                v.objects.push(ShownObject {
                    kind: o.kind,
                    pos,
                    rot,
                    linvel,
                    angvel,
                    offset: none,
                    soft: None,
                    held_by_us: false,
                });
            }
            let s = &mut v.objects[i];
            (s.kind, s.pos, s.rot, s.linvel, s.angvel) = (o.kind, pos, rot, linvel, angvel);
            s.offset = offsets.get(i).copied().unwrap_or(none);
            s.held_by_us = held.contains(&i);
            let body = match o.body {
                softsync_peer::LocalBody::Soft(h) => w.soft_bodies().get(h),
                _ => None,
            };
            match body {
                Some(b) => {
                    let m = s.soft.get_or_insert_with(ShownSoft::default);
                    m.positions.clear();
                    m.positions.extend_from_slice(b.render_positions());
                    m.normals.clear();
                    m.normals.extend_from_slice(b.render_normals());
                    let tris = b.render_triangles();
                    if m.triangles.as_slice() != tris {
                        m.triangles.clear();
                        m.triangles.extend_from_slice(tris);
                        m.topology += 1;
                    }
                    m.particles = b.particles().len();
                }
                None => s.soft = None,
            }
        }
    }
}

/// Runs an app's [`RollbackRoom`] in the frame: the device in, events out, an entity per scene
/// object following the drawn frame, leaving on exit (see the module docs).
#[derive(Clone, Debug)]
pub struct RollbackPlugin {
    /// End the app (exit code 3) when the peer cannot go on.
    pub exit_on_failure: bool,
}

impl Default for RollbackPlugin {
    fn default() -> Self {
        RollbackPlugin {
            exit_on_failure: true,
        }
    }
}

#[derive(Resource, Clone, Copy)]
struct RollbackSettings {
    exit_on_failure: bool,
}

/// A scene object's entity in a rollback room (with [`NetObject`], whose id is the index).
#[derive(Component, Clone, Copy, Debug)]
pub struct RollbackObject {
    /// Its index in the scene (and in [`RollbackView::objects`]).
    pub index: usize,
}

impl Plugin for RollbackPlugin {
    fn build(&self, app: &mut App) {
        app.add_message::<RollbackRoomEvent>()
            .add_message::<RoomFailed>()
            .init_resource::<LocalDevice>()
            .insert_resource(RollbackSettings {
                exit_on_failure: self.exit_on_failure,
            })
            .configure_sets(FixedUpdate, SoftsyncSet::Input.before(SoftsyncSet::Step))
            .add_systems(PreUpdate, rollback_events.in_set(SoftsyncSet::NetIn))
            .add_systems(FixedUpdate, rollback_device.in_set(SoftsyncSet::Step))
            .add_systems(Update, rollback_mirror.in_set(SoftsyncSet::Mirror))
            .add_systems(Last, rollback_leave.in_set(SoftsyncSet::Leave));
    }
}

fn rollback_events(
    room: Option<Res<RollbackRoom>>,
    settings: Res<RollbackSettings>,
    mut out: MessageWriter<RollbackRoomEvent>,
    mut failed: MessageWriter<RoomFailed>,
    mut exit: MessageWriter<AppExit>,
    mut told: Local<bool>,
) {
    let Some(room) = room else { return };
    for e in room.drain_events() {
        out.write(RollbackRoomEvent(e));
    }
    if *told {
        return;
    }
    if let Some(reason) = room.failure() {
        *told = true;
        failed.write(RoomFailed { reason });
        if settings.exit_on_failure {
            exit.write(AppExit::from_code(3));
        }
    }
}

/// The device of the frame, for the next ticks.
fn rollback_device(room: Option<Res<RollbackRoom>>, device: Res<LocalDevice>) {
    if let Some(room) = room {
        room.set_device(device.0);
    }
}

fn rollback_mirror(
    mut commands: Commands,
    room: Option<Res<RollbackRoom>>,
    mut q: Query<(
        &RollbackObject,
        &mut Transform,
        &mut NetObject,
        Option<&mut SoftBody>,
    )>,
    mut spawned: Local<usize>,
) {
    let Some(room) = room else { return };
    let scene = room.scene();
    room.with_view(|v| {
        let ahead = v.at.map_or(0.0, |t| t.elapsed().as_secs_f32());
        // a scene's objects are fixed: spawned once, in scene order
        while *spawned < v.objects.len() {
            let i = *spawned;
            let o = &v.objects[i];
            let mut e = commands.spawn((
                RollbackObject { index: i },
                NetObject {
                    id: NetId(i as u32),
                    kind: o.kind,
                    class: scene.name_of(o.kind).to_owned(),
                    owner: None,
                    mine: false,
                    hovered: false,
                },
                Transform::IDENTITY,
            ));
            if let Some(s) = &o.soft {
                e.insert(SoftBody {
                    particles: s.particles,
                    topology: s.topology,
                    level: None,
                    asleep: false,
                });
            }
            *spawned += 1;
        }
        for (r, mut tf, mut net, soft) in &mut q {
            let Some(o) = v.objects.get(r.index) else {
                continue;
            };
            if net.mine != o.held_by_us {
                net.mine = o.held_by_us;
            }
            match (soft, &o.soft) {
                (Some(mut s), Some(m))
                    if s.topology != m.topology || s.particles != m.particles =>
                {
                    s.topology = m.topology;
                    s.particles = m.particles;
                }
                (None, None) => {
                    if let Some((p, q)) = v.shown_pose(r.index, ahead) {
                        *tf =
                            Transform::from_translation(to_bevy(p)).with_rotation(to_bevy_quat(q));
                    }
                }
                _ => {}
            }
        }
    });
}

fn rollback_leave(room: Option<ResMut<RollbackRoom>>, mut exits: MessageReader<AppExit>) {
    if exits.read().next().is_none() {
        return;
    }
    if let Some(mut room) = room {
        room.leave();
    }
}
