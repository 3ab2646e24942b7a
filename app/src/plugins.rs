//! The binary's systems around `softsync-bevy`'s [`SoftsyncPlugin`], which runs the room
//! (network in and out, fixed steps, object entities, leaving on exit) as in any user's app.
//! The headless peer runs on `MinimalPlugins` with the simulation in `FixedUpdate` at the
//! simulation rate.
//!
//! Frame order (every loop iteration: ~250 Hz headless, the frame rate with a window):
//! 1. `PreUpdate` — the plugin's [`SoftsyncSet::NetIn`]: datagrams in, session timers and
//!    events; then [`ReportPlugin`] logs the events and stops on a failure. Desktop/VR front
//!    ends then read their device frame (mouse hands, or OpenXR poses after bevy_mod_xr has
//!    located its spaces), so this frame's fixed steps use it.
//! 2. `FixedUpdate` (0..n times, at `--sim-hz`) — [`SoftsyncSet::Input`]: the bot and/or the
//!    device set the hands; then the plugin's step: hands update (authority requests), remote
//!    objects are shown, soft bodies and rapier step, owned objects are published.
//! 3. `Update` — the plugin's entities follow the room; with a window or headset the view
//!    draws them (poses, deformed soft meshes, tints, avatars, HUD).
//! 4. `PostUpdate` — the plugin's [`SoftsyncSet::NetOut`]: datagrams out. Then bevy renders.
//! 5. `Last` — [`ReportPlugin`]: stats line, dump, the end of `--duration`; then the plugin's
//!    [`SoftsyncSet::Leave`] sends the `Leave` on exit.

use bevy::app::{App, AppExit, FixedUpdate, Last, Plugin, PreUpdate};
use bevy::ecs::message::{MessageReader, MessageWriter};
use bevy::ecs::schedule::IntoScheduleConfigs;
use bevy::ecs::system::NonSendMut;
use bevy::ecs::system::ResMut;
use softsync_bevy::{LocalDevice, Room, RoomEvent, RoomFailed, SoftsyncSet};

use crate::driver::Driver;

fn log_events(
    mut room: NonSendMut<Room>,
    mut driver: NonSendMut<Driver>,
    mut events: MessageReader<RoomEvent>,
) {
    for RoomEvent(e) in events.read() {
        driver.log_event(&room, e);
    }
    driver.log_voice(&mut room);
}

fn on_failure(
    mut room: NonSendMut<Room>,
    mut driver: NonSendMut<Driver>,
    mut failed: MessageReader<RoomFailed>,
) {
    if let Some(f) = failed.read().next() {
        if !driver.exiting {
            driver.fail(&mut room, &f.reason);
        }
    }
}

/// The front end's device (desktop or VR) goes to the driver, which composes it with a bot
/// (taken: the plugin's step does not apply it again).
fn drive_hands(
    mut room: NonSendMut<Room>,
    mut driver: NonSendMut<Driver>,
    mut device: ResMut<LocalDevice>,
) {
    if let Some(d) = device.0.take() {
        driver.device = Some(d);
    }
    driver.drive_hands(&mut room);
}

fn report(
    mut room: NonSendMut<Room>,
    mut driver: NonSendMut<Driver>,
    mut exit: MessageWriter<AppExit>,
) {
    if driver.exiting {
        return;
    }
    if driver.report(&mut room) {
        exit.write(AppExit::Success);
    }
}

/// Whoever asked to exit (`--duration`, Ctrl-C, an error): a last dump and stats line, before
/// the plugin sends the `Leave`.
fn on_exit(
    mut room: NonSendMut<Room>,
    mut driver: NonSendMut<Driver>,
    mut exits: MessageReader<AppExit>,
) {
    if exits.read().next().is_none() {
        return;
    }
    driver.finish(&mut room);
}

/// Event log lines, failures, the bot's hands, the stats line and dump, the end of the run.
pub struct ReportPlugin;

impl Plugin for ReportPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(
            PreUpdate,
            (log_events, on_failure).chain().after(SoftsyncSet::NetIn),
        )
        .add_systems(FixedUpdate, drive_hands.in_set(SoftsyncSet::Input))
        .add_systems(Last, (report, on_exit).chain().before(SoftsyncSet::Leave));
    }
}
