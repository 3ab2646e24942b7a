//! The desktop peer (feature `desktop`): a window, an orbit camera, and mouse-driven hands,
//! so people without a headset can join and grab.
//!
//! Controls:
//! - mouse: the right hand follows the cursor, at the reach distance along the cursor's ray;
//! - wheel: reach nearer or farther (0.15–2 m); Shift+wheel: zoom the camera;
//! - left button: grip (hold to keep holding); Ctrl+left: grip with the left hand instead;
//! - E (held): trigger (the scalpel: the hand's path tears a soft body);
//! - X (held): the cutter's trigger: sweep the cursor across a soft body to cut it in two by
//!   the plane of the sweep (the line drawn on screen, along the view);
//! - right button drag: orbit; middle drag or W/A/S/D/Q/Z: move the camera's target;
//! - P: particles and neighbour links; H: the HUD; R: reset the camera.
//!
//! The head of our avatar is the camera; the other peers see it move with the view.

use bevy::diagnostic::FrameCount;
use bevy::input::mouse::{AccumulatedMouseMotion, AccumulatedMouseScroll, MouseScrollUnit};
use bevy::prelude::*;
use bevy::window::PrimaryWindow;

use softsync_peer::scene::TABLE_TOP_Y;
use softsync_peer::{DeviceFrame, HandTool, Kind};

use softsync_bevy::{LocalDevice, RollbackRoom, Room};

use crate::driver::Driver;
use softsync_bevy::glue::{from_bevy, from_bevy_quat, pose_from_bevy, to_bevy, to_bevy_quat};

/// Where the camera looks from and at.
#[derive(Resource, Clone, Copy, Debug)]
pub struct OrbitCamera {
    /// The point it orbits.
    pub target: Vec3,
    /// Rotation about y, radians.
    pub yaw: f32,
    /// Elevation, radians (positive looks down).
    pub pitch: f32,
    /// Distance from the target, metres.
    pub distance_m: f32,
    /// How far along the cursor's ray the hand is, metres.
    pub reach_m: f32,
    /// Focus on an object kind once it exists (`--focus`).
    pub focus: Option<Kind>,
    focused: bool,
    initial: Option<(Vec3, f32, f32, f32)>,
}

impl OrbitCamera {
    /// A camera standing at the peer's place around the table, looking at its middle.
    pub fn at_home(home: (glam::Vec3, glam::Quat), focus: Option<Kind>) -> Self {
        let fwd = to_bevy_quat(home.1) * Vec3::Z;
        let mut c = OrbitCamera {
            target: Vec3::new(0.0, TABLE_TOP_Y, 0.0),
            yaw: fwd.x.atan2(fwd.z),
            pitch: 0.6,
            distance_m: 1.3,
            reach_m: 0.9,
            focus,
            focused: false,
            initial: None,
        };
        c.initial = Some((c.target, c.yaw, c.pitch, c.distance_m));
        c
    }

    /// The camera's transform.
    pub fn transform(&self) -> Transform {
        let dir = Vec3::new(
            self.yaw.sin() * self.pitch.cos(),
            self.pitch.sin(),
            self.yaw.cos() * self.pitch.cos(),
        );
        Transform::from_translation(self.target + dir * self.distance_m)
            .looking_at(self.target, Vec3::Y)
    }
}

/// Marks the desktop camera.
#[derive(Component)]
pub struct DesktopCamera;

/// Camera and mouse hands.
pub struct DesktopPlugin(pub OrbitCamera);

impl Plugin for DesktopPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(self.0)
            .add_systems(Startup, spawn_camera)
            .add_systems(Last, ready_after_first_frames)
            .add_systems(
                PreUpdate,
                desktop_input
                    .after(bevy::input::InputSystems)
                    .after(softsync_bevy::SoftsyncSet::NetIn),
            );
    }
}

/// Frames rendered before the network starts (window and renderer setup stall the first).
const WARMUP_FRAMES: u32 = 5;

fn ready_after_first_frames(room: Option<NonSendMut<Room>>, frames: Res<FrameCount>) {
    // (a rollback room runs on its own thread: no frame holds it up)
    if let (Some(mut room), true) = (room, frames.0 >= WARMUP_FRAMES) {
        Driver::set_ready(&mut room);
    }
}

fn spawn_camera(mut commands: Commands, orbit: Res<OrbitCamera>) {
    commands.spawn((Camera3d::default(), DesktopCamera, orbit.transform()));
}

#[allow(clippy::too_many_arguments)]
fn desktop_input(
    mut room: Option<NonSendMut<Room>>,
    driver: Option<NonSend<Driver>>,
    rollback: Option<Res<RollbackRoom>>,
    mut device: ResMut<LocalDevice>,
    mut orbit: ResMut<OrbitCamera>,
    mut cam: Query<(&Camera, &GlobalTransform, &mut Transform), With<DesktopCamera>>,
    windows: Query<&Window, With<PrimaryWindow>>,
    buttons: Res<ButtonInput<MouseButton>>,
    keys: Res<ButtonInput<KeyCode>>,
    motion: Res<AccumulatedMouseMotion>,
    scroll: Res<AccumulatedMouseScroll>,
    time: Res<Time>,
) {
    let dt = time.delta_secs().min(0.1);
    // Focus on an object once it is in the room.
    if let (Some(kind), false) = (orbit.focus, orbit.focused) {
        let at = match (&mut room, &rollback) {
            (Some(room), _) => {
                let now = room.now();
                let found = room
                    .peer
                    .objects()
                    .iter()
                    .find(|(_, o)| o.kind == kind)
                    .map(|(id, _)| *id);
                found
                    .and_then(|id| room.peer.shown_state(now, id))
                    .map(|s| s.pos)
            }
            (None, Some(rb)) => {
                rb.with_view(|v| v.objects.iter().find(|o| o.kind == kind).map(|o| o.pos))
            }
            (None, None) => None,
        };
        if let Some(pos) = at {
            // A fixed view of it, from the room's +z side and above, whoever we are: the
            // same picture on every run (the pixel test relies on it).
            orbit.target = to_bevy(pos);
            orbit.yaw = 0.0;
            orbit.pitch = 0.5;
            orbit.distance_m = 0.4;
            orbit.reach_m = 0.3;
            orbit.focused = true;
        }
    }
    // Camera: orbit, pan, zoom, reset.
    let shift = keys.pressed(KeyCode::ShiftLeft) || keys.pressed(KeyCode::ShiftRight);
    if buttons.pressed(MouseButton::Right) {
        orbit.yaw -= motion.delta.x * 0.005;
        orbit.pitch = (orbit.pitch + motion.delta.y * 0.005).clamp(-0.2, 1.5);
    }
    let (right, fwd) = {
        let tf = orbit.transform();
        let f = tf.forward().as_vec3();
        (
            tf.right().as_vec3(),
            Vec3::new(f.x, 0.0, f.z).normalize_or_zero(),
        )
    };
    if buttons.pressed(MouseButton::Middle) {
        let k = orbit.distance_m * 0.0015;
        orbit.target += (-right * motion.delta.x + Vec3::Y * motion.delta.y) * k;
    }
    let mut pan = Vec3::ZERO;
    for (key, d) in [
        (KeyCode::KeyW, fwd),
        (KeyCode::KeyS, -fwd),
        (KeyCode::KeyD, right),
        (KeyCode::KeyA, -right),
        (KeyCode::KeyQ, Vec3::Y),
        (KeyCode::KeyZ, -Vec3::Y),
    ] {
        if keys.pressed(key) {
            pan += d;
        }
    }
    orbit.target += pan * dt * 0.8;
    let wheel = match scroll.unit {
        MouseScrollUnit::Line => scroll.delta.y,
        MouseScrollUnit::Pixel => scroll.delta.y / 40.0,
    };
    if shift {
        orbit.distance_m = (orbit.distance_m * (1.0 - wheel * 0.1)).clamp(0.15, 6.0);
    } else {
        orbit.reach_m = (orbit.reach_m + wheel * 0.05).clamp(0.15, 2.0);
    }
    if keys.just_pressed(KeyCode::KeyR) {
        if let Some((t, y, p, d)) = orbit.initial {
            (orbit.target, orbit.yaw, orbit.pitch, orbit.distance_m) = (t, y, p, d);
        }
    }
    if let (Some(room), Some(driver)) = (room.as_mut(), driver.as_ref()) {
        replay_keys(room, driver, &keys);
    }
    let Ok((camera, gt, mut tf)) = cam.single_mut() else {
        return;
    };
    *tf = orbit.transform();
    // a played-back recording seen from one of its people (`softsync replay --as PEER`):
    // the view is that peer's head
    if let (Some(room), Some(driver)) = (room.as_mut(), driver.as_ref()) {
        let follow = driver.replay_clock.as_ref().and_then(|(c, _)| c.follow);
        let now = room.now();
        if let Some(s) = follow.and_then(|id| room.peer.shown_state(now, id)) {
            tf.translation = to_bevy(s.pos);
            tf.rotation = to_bevy_quat(s.rot);
        }
    }
    // Hands: the active one on the cursor's ray, the other resting below the view.
    let head = pose_from_bevy(&tf);
    let rest = |side: f32| {
        (
            from_bevy(tf.translation + tf.rotation * Vec3::new(0.2 * side, -0.3, -0.35)),
            from_bevy_quat(tf.rotation),
        )
    };
    let ray = windows
        .single()
        .ok()
        .and_then(|w| w.cursor_position())
        .and_then(|c| camera.viewport_to_world(gt, c).ok());
    let ctrl = keys.pressed(KeyCode::ControlLeft) || keys.pressed(KeyCode::ControlRight);
    let active = if ctrl { 0 } else { 1 };
    let mut hands = [Some(rest(-1.0)), Some(rest(1.0))];
    if let Some(r) = ray {
        hands[active] = Some((
            from_bevy(r.origin + r.direction.as_vec3() * orbit.reach_m),
            from_bevy_quat(tf.rotation),
        ));
    }
    let mut grip = [0.0; 2];
    if buttons.pressed(MouseButton::Left) {
        grip[active] = 1.0;
    }
    let mut trigger = [0.0; 2];
    let mut tool = [HandTool::Scalpel; 2];
    if keys.pressed(KeyCode::KeyE) {
        trigger[active] = 1.0;
    }
    if keys.pressed(KeyCode::KeyX) {
        // the cutter: its blade points into the screen, so the plane of the sweep holds the
        // view ray: the line the cursor draws across the body
        trigger[active] = 1.0;
        tool[active] = HandTool::Cutter;
        if let Some((_, rot)) = hands[active].as_mut() {
            *rot =
                from_bevy_quat(tf.rotation * Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2));
        }
    }
    device.0 = Some(DeviceFrame {
        head: Some(head),
        hands,
        grip,
        trigger,
        tool,
        // V: push-to-talk (used only with --push-to-talk)
        talk: keys.pressed(KeyCode::KeyV),
    });
}

/// In a played-back recording's room: space pauses and plays, left and right seek 5 s, up
/// and down double and halve the speed (a `ReplayControl` to its host).
fn replay_keys(room: &mut Room, driver: &Driver, keys: &ButtonInput<KeyCode>) {
    use softsync_peer::messages::ReplayControl;
    let Some(clock) = &driver.replay_clock else {
        return;
    };
    let (c, _) = clock;
    let t = crate::driver::replay_position(clock, room.now());
    let mut ask = ReplayControl {
        pause: None,
        seek_s: None,
        speed: None,
    };
    if keys.just_pressed(KeyCode::Space) {
        ask.pause = Some(!c.paused);
    }
    if keys.just_pressed(KeyCode::ArrowLeft) {
        ask.seek_s = Some((t - 5.0).max(0.0));
    }
    if keys.just_pressed(KeyCode::ArrowRight) {
        ask.seek_s = Some(t + 5.0);
    }
    if keys.just_pressed(KeyCode::ArrowUp) {
        ask.speed = Some(c.speed * 2.0);
    }
    if keys.just_pressed(KeyCode::ArrowDown) {
        ask.speed = Some(c.speed / 2.0);
    }
    if ask.pause.is_none() && ask.seek_s.is_none() && ask.speed.is_none() {
        return;
    }
    let to = softsync_net::MessageTarget::Host;
    if let Err(e) = room.send(to, softsync_net::Delivery::Reliable, &ask) {
        eprintln!("replay control not sent: {e}");
    }
}
