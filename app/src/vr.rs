//! The VR peer (feature `vr`): OpenXR through bevy_mod_openxr 0.6 (the crate once called
//! bevy_oxr). The headset's pose drives the avatar's head, the controllers' grip poses its
//! hands, squeeze grips and trigger triggers. The tracking space's floor (the STAGE reference
//! space) is put at this peer's place around the table, facing it.
//!
//! Bindings are suggested for the common controllers (Khronos simple, Oculus Touch, Valve
//! Index, HTC Vive, Windows Mixed Reality); the simple controller has no squeeze, so its
//! select button grips. A hand's tool button (X/A on Touch, A on Index, the trackpad on Vive,
//! the thumbstick on WMR, menu on the simple controller) switches its trigger between the
//! scalpel (the hand's path tears) and the cutter (a sweep through a body cuts it by the
//! sweep's plane, `peer/cutter.rs`).
//!
//! There is no desktop mirror window: the headset shows the room and the terminal the stats
//! lines. Without a runtime or a headset, [`probe`] says why and the caller opens the desktop
//! peer instead.

use std::time::Duration;

use bevy::app::{PluginGroup, ScheduleRunnerPlugin};
use bevy::prelude::*;
use bevy::window::{ExitCondition, WindowPlugin};
use bevy::winit::WinitPlugin;
use bevy_mod_openxr::action_binding::{OxrSendActionBindings, OxrSuggestActionBinding};
use bevy_mod_openxr::action_set_attaching::OxrAttachActionSet;
use bevy_mod_openxr::action_set_syncing::{OxrActionSetSyncSet, OxrSyncActionSet};
use bevy_mod_openxr::add_xr_plugins;
use bevy_mod_openxr::init::OxrInitPlugin;
use bevy_mod_openxr::openxr_session_running;
use bevy_mod_openxr::resources::OxrInstance;
use bevy_mod_openxr::session::OxrSession;
use bevy_mod_openxr::spaces::OxrSpaceLocationFlags;
use bevy_mod_openxr::types::AppInfo;
use bevy_mod_xr::camera::XrCamera;
use bevy_mod_xr::session::{session_available, XrSessionCreated, XrState, XrTrackingRoot};
use bevy_mod_xr::spaces::{XrSpace, XrSpaceSyncSet};

use softsync_peer::{DeviceFrame, HandTool};

use softsync_bevy::Room;

use crate::driver::Driver;
use softsync_bevy::glue::pose_from_bevy;

/// Is there an OpenXR runtime with a headset? `Err` says what is missing.
#[allow(unsafe_code)]
pub fn probe() -> Result<String, String> {
    // SAFETY: loads the system's OpenXR loader library; nothing else runs in it yet.
    let entry = unsafe { openxr::Entry::load() }.map_err(|e| {
        format!(
            "no OpenXR loader ({e}); install one (Debian: libopenxr-loader1, plus libopenxr-dev \
             for the unversioned libopenxr_loader.so) and a runtime (SteamVR, Monado)"
        )
    })?;
    let app = openxr::ApplicationInfo {
        application_name: "softsync probe",
        application_version: 0,
        engine_name: "bevy",
        engine_version: 0,
        api_version: openxr::Version::new(1, 0, 0),
    };
    let exts = entry
        .enumerate_extensions()
        .map_err(|e| format!("no OpenXR runtime ({e}); is one installed and active?"))?;
    let mut want = openxr::ExtensionSet::default();
    if !exts.khr_vulkan_enable2 {
        return Err("the OpenXR runtime offers no Vulkan (XR_KHR_vulkan_enable2)".into());
    }
    want.khr_vulkan_enable2 = true;
    let instance = entry
        .create_instance(&app, &want, &[])
        .map_err(|e| format!("the OpenXR runtime refused an instance ({e}); is it running?"))?;
    let props = instance
        .properties()
        .map_err(|e| format!("OpenXR runtime properties: {e}"))?;
    let system = instance
        .system(openxr::FormFactor::HEAD_MOUNTED_DISPLAY)
        .map_err(|e| {
            format!(
                "OpenXR runtime {} has no headset ({e}); is it connected?",
                props.runtime_name
            )
        })?;
    let name = instance
        .system_properties(system)
        .map(|p| p.system_name)
        .unwrap_or_default();
    Ok(format!(
        "{} {} with {}",
        props.runtime_name,
        props.runtime_version,
        if name.is_empty() { "a headset" } else { &name }
    ))
}

/// bevy's plugins for a VR peer: OpenXR rendering, no window.
pub fn plugins() -> bevy::app::PluginGroupBuilder {
    add_xr_plugins(
        DefaultPlugins
            .build()
            .disable::<WinitPlugin>()
            // Poses are located right before rendering (bevy_mod_openxr's advice).
            .disable::<bevy::render::pipelined_rendering::PipelinedRenderingPlugin>()
            .set(WindowPlugin {
                primary_window: None,
                exit_condition: ExitCondition::DontExit,
                ..default()
            })
            .add(ScheduleRunnerPlugin::run_loop(Duration::from_millis(1))),
    )
    .set(OxrInitPlugin {
        app_info: AppInfo {
            name: "softsync".into(),
            ..AppInfo::BEVY
        },
        // Asynchronous, as on the desktop: a stalled frame loop misses heartbeats.
        synchronous_pipeline_compilation: false,
        ..default()
    })
}

/// Where the tracking space's floor origin goes in the room, and its heading.
#[derive(Resource, Clone, Copy, Debug)]
pub struct StageOrigin {
    /// Floor point under the peer's home.
    pub pos: Vec3,
    /// Heading.
    pub rot: Quat,
}

/// Controllers, headset, and the tracking root.
pub struct VrPlugin(pub StageOrigin);

impl Plugin for VrPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(self.0)
            .add_systems(Startup, spawn_root)
            .add_systems(Startup, create_actions.run_if(session_available))
            .add_systems(OxrSendActionBindings, suggest_bindings)
            .add_systems(XrSessionCreated, (attach_actions, spawn_hand_spaces))
            .add_systems(
                PreUpdate,
                sync_actions
                    .before(OxrActionSetSyncSet)
                    .run_if(openxr_session_running),
            )
            .add_systems(
                PreUpdate,
                read_device
                    .after(XrSpaceSyncSet)
                    .after(OxrActionSetSyncSet)
                    .after(softsync_bevy::SoftsyncSet::NetIn)
                    .run_if(openxr_session_running),
            )
            .add_systems(Update, report_state)
            .add_systems(Last, ready_when_running);
    }
}

#[derive(Resource)]
struct Actions {
    set: openxr::ActionSet,
    pose: [openxr::Action<openxr::Posef>; 2],
    squeeze: [openxr::Action<f32>; 2],
    trigger: [openxr::Action<f32>; 2],
    /// A press switches the hand's tool between the scalpel and the cutter.
    tool: [openxr::Action<bool>; 2],
    /// Held: push-to-talk (the left hand's second face button, see [`TALK`]).
    talk: openxr::Action<bool>,
}

/// The grip space of a hand (0 left, 1 right).
#[derive(Component)]
struct HandSpace(usize);

fn spawn_root(mut commands: Commands, origin: Res<StageOrigin>) {
    // Where the tracking space sits in the room (tests map room points into it with this).
    let (axis, angle) = origin.rot.to_axis_angle();
    println!(
        "xr stage origin={:.3},{:.3},{:.3} yaw={:.1}",
        origin.pos.x,
        origin.pos.y,
        origin.pos.z,
        (axis.y.signum() * angle).to_degrees()
    );
    commands.spawn((
        XrTrackingRoot,
        Transform::from_translation(origin.pos).with_rotation(origin.rot),
    ));
}

fn create_actions(instance: Res<OxrInstance>, mut commands: Commands) {
    let made = (|| -> openxr::Result<Actions> {
        let set = instance.create_action_set("softsync", "softsync hands", 0)?;
        let mk_pose = |n: &str, l: &str| set.create_action::<openxr::Posef>(n, l, &[]);
        let mk_f = |n: &str, l: &str| set.create_action::<f32>(n, l, &[]);
        Ok(Actions {
            pose: [
                mk_pose("left_grip_pose", "Left grip pose")?,
                mk_pose("right_grip_pose", "Right grip pose")?,
            ],
            squeeze: [
                mk_f("left_squeeze", "Left squeeze")?,
                mk_f("right_squeeze", "Right squeeze")?,
            ],
            trigger: [
                mk_f("left_trigger", "Left trigger")?,
                mk_f("right_trigger", "Right trigger")?,
            ],
            tool: [
                set.create_action::<bool>("left_tool", "Left tool (scalpel or cutter)", &[])?,
                set.create_action::<bool>("right_tool", "Right tool (scalpel or cutter)", &[])?,
            ],
            talk: set.create_action::<bool>("talk", "Push to talk (hold)", &[])?,
            set,
        })
    })();
    match made {
        Ok(a) => commands.insert_resource(a),
        Err(e) => error!("cannot create the controller actions: {e}"),
    }
}

/// Suggested bindings per interaction profile: (profile, squeeze path, trigger path, the
/// tool button's path on the left and on the right hand).
type Profile = (
    &'static str,
    &'static str,
    Option<&'static str>,
    [&'static str; 2],
);
const PROFILES: [Profile; 5] = [
    (
        "/interaction_profiles/khr/simple_controller",
        "input/select/click",
        None,
        ["input/menu/click", "input/menu/click"],
    ),
    (
        "/interaction_profiles/oculus/touch_controller",
        "input/squeeze/value",
        Some("input/trigger/value"),
        ["input/x/click", "input/a/click"],
    ),
    (
        "/interaction_profiles/valve/index_controller",
        "input/squeeze/value",
        Some("input/trigger/value"),
        ["input/a/click", "input/a/click"],
    ),
    (
        "/interaction_profiles/htc/vive_controller",
        "input/squeeze/click",
        Some("input/trigger/value"),
        ["input/trackpad/click", "input/trackpad/click"],
    ),
    (
        "/interaction_profiles/microsoft/motion_controller",
        "input/squeeze/click",
        Some("input/trigger/value"),
        ["input/thumbstick/click", "input/thumbstick/click"],
    ),
];

/// Push-to-talk's binding per interaction profile (the left hand), where the profile has a
/// button left over (the simple controller has two, both taken).
const TALK: [(&str, &str); 4] = [
    (
        "/interaction_profiles/oculus/touch_controller",
        "input/y/click",
    ),
    (
        "/interaction_profiles/valve/index_controller",
        "input/b/click",
    ),
    (
        "/interaction_profiles/htc/vive_controller",
        "input/menu/click",
    ),
    (
        "/interaction_profiles/microsoft/motion_controller",
        "input/menu/click",
    ),
];

fn suggest_bindings(
    actions: Option<Res<Actions>>,
    mut out: MessageWriter<OxrSuggestActionBinding>,
) {
    let Some(a) = actions else { return };
    for (profile, button) in TALK {
        out.write(OxrSuggestActionBinding {
            action: a.talk.as_raw(),
            interaction_profile: profile.into(),
            bindings: vec![format!("/user/hand/left/{button}").into()],
        });
    }
    for (profile, squeeze, trigger, tool) in PROFILES {
        for (h, side) in [(0, "left"), (1, "right")] {
            let hand = |p: &str| format!("/user/hand/{side}/{p}");
            out.write(OxrSuggestActionBinding {
                action: a.pose[h].as_raw(),
                interaction_profile: profile.into(),
                bindings: vec![hand("input/grip/pose").into()],
            });
            out.write(OxrSuggestActionBinding {
                action: a.squeeze[h].as_raw(),
                interaction_profile: profile.into(),
                bindings: vec![hand(squeeze).into()],
            });
            if let Some(t) = trigger {
                out.write(OxrSuggestActionBinding {
                    action: a.trigger[h].as_raw(),
                    interaction_profile: profile.into(),
                    bindings: vec![hand(t).into()],
                });
            }
            out.write(OxrSuggestActionBinding {
                action: a.tool[h].as_raw(),
                interaction_profile: profile.into(),
                bindings: vec![hand(tool[h]).into()],
            });
        }
    }
}

fn attach_actions(actions: Option<Res<Actions>>, mut attach: MessageWriter<OxrAttachActionSet>) {
    if let Some(a) = actions {
        attach.write(OxrAttachActionSet(a.set.clone()));
    }
}

fn sync_actions(actions: Option<Res<Actions>>, mut sync: MessageWriter<OxrSyncActionSet>) {
    if let Some(a) = actions {
        sync.write(OxrSyncActionSet(a.set.clone()));
    }
}

fn spawn_hand_spaces(
    actions: Option<Res<Actions>>,
    session: Res<OxrSession>,
    mut commands: Commands,
) {
    let Some(a) = actions else { return };
    for h in 0..2 {
        match session.create_action_space(&a.pose[h], openxr::Path::NULL, Isometry3d::IDENTITY) {
            Ok(space) => {
                commands.spawn((space, HandSpace(h), bevy_mod_xr::session::XrTracker));
            }
            Err(e) => error!("cannot create the grip space of hand {h}: {e}"),
        }
    }
}

fn float_state(session: &OxrSession, a: &openxr::Action<f32>) -> f32 {
    a.state(session, openxr::Path::NULL)
        .map(|s| if s.is_active { s.current_state } else { 0.0 })
        .unwrap_or(0.0)
}

/// What [`read_device`] has printed: the tracked poses once, the button states per hand.
#[derive(Default)]
struct Seen {
    announced: bool,
    /// [squeeze, trigger] held, per hand.
    pressed: [[bool; 2]; 2],
    /// The tool button held, and each hand's tool (a press switches it).
    tool_pressed: [bool; 2],
    tools: [HandTool; 2],
}

/// Headset and controllers → the device frame, in room coordinates.
fn read_device(
    mut device: ResMut<softsync_bevy::LocalDevice>,
    origin: Res<StageOrigin>,
    session: Res<OxrSession>,
    actions: Option<Res<Actions>>,
    views: Query<&Transform, With<XrCamera>>,
    hands: Query<(&Transform, &HandSpace, &OxrSpaceLocationFlags), With<XrSpace>>,
    mut seen: Local<Seen>,
) {
    let root = Transform::from_translation(origin.pos).with_rotation(origin.rot);
    let to_room = |t: &Transform| {
        pose_from_bevy(
            &Transform::from_translation(root.transform_point(t.translation))
                .with_rotation(root.rotation * t.rotation),
        )
    };
    let mut frame = DeviceFrame::default();
    // The head: between the eyes.
    let eyes: Vec<&Transform> = views.iter().collect();
    if let Some(first) = eyes.first() {
        let mid = eyes.iter().map(|t| t.translation).sum::<Vec3>() / eyes.len() as f32;
        frame.head = Some(to_room(
            &Transform::from_translation(mid).with_rotation(first.rotation),
        ));
    }
    for (t, h, flags) in &hands {
        if flags.pos_valid() && flags.rot_valid() {
            frame.hands[h.0] = Some(to_room(t));
        }
    }
    if let Some(a) = actions {
        frame.talk = a
            .talk
            .state(&session, openxr::Path::NULL)
            .is_ok_and(|s| s.is_active && s.current_state);
        for h in 0..2 {
            frame.grip[h] = float_state(&session, &a.squeeze[h]);
            frame.trigger[h] = float_state(&session, &a.trigger[h]);
            let tool = a.tool[h]
                .state(&session, openxr::Path::NULL)
                .is_ok_and(|s| s.is_active && s.current_state);
            if tool && !seen.tool_pressed[h] {
                seen.tools[h] = match seen.tools[h] {
                    HandTool::Scalpel => HandTool::Cutter,
                    HandTool::Cutter => HandTool::Scalpel,
                };
                println!(
                    "xr tool hand={} tool={:?}",
                    ["left", "right"][h],
                    seen.tools[h]
                );
            }
            seen.tool_pressed[h] = tool;
            frame.tool[h] = seen.tools[h];
            // Button edges, for people checking their bindings (and the tests).
            let now = [frame.grip[h] > 0.5, frame.trigger[h] > 0.5];
            if now != seen.pressed[h] {
                seen.pressed[h] = now;
                println!(
                    "xr input hand={} squeeze={:.2} trigger={:.2}",
                    ["left", "right"][h],
                    frame.grip[h],
                    frame.trigger[h]
                );
            }
        }
    }
    if !seen.announced && frame.head.is_some() && frame.hands.iter().all(Option::is_some) {
        // Once: where the tracked parts are in the room (the smoke test compares the host's
        // view of our avatar with this).
        seen.announced = true;
        let f = |p: Option<(glam::Vec3, glam::Quat)>| {
            p.map_or("-".into(), |(v, _)| {
                format!("{:.3},{:.3},{:.3}", v.x, v.y, v.z)
            })
        };
        println!(
            "xr tracked head={} left={} right={}",
            f(frame.head),
            f(frame.hands[0]),
            f(frame.hands[1])
        );
    }
    device.0 = Some(frame);
}

/// Frames the XR session renders before the network starts (session start stalls the loop).
const WARMUP_FRAMES: u32 = 30;

fn ready_when_running(
    room: Option<NonSendMut<Room>>,
    state: Option<Res<XrState>>,
    mut running: Local<u32>,
) {
    // (a rollback room runs on its own thread: no frame holds it up)
    let Some(mut room) = room else { return };
    if state.is_some_and(|s| *s == XrState::Running) {
        *running += 1;
        if *running >= WARMUP_FRAMES {
            Driver::set_ready(&mut room);
        }
    }
}

/// Print session state changes (the smoke test waits for FOCUSED-equivalent `Running`).
fn report_state(state: Option<Res<XrState>>, mut last: Local<Option<XrState>>) {
    let Some(s) = state else { return };
    if *last != Some(*s) {
        println!("xr state={:?}", *s);
        *last = Some(*s);
    }
}
