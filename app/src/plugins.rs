//! The bevy side of a peer: plugins that call the [`Driver`] (network, simulation, reports) at
//! their places in the frame. The headless peer runs on `MinimalPlugins` with the simulation
//! in `FixedUpdate` at the simulation rate.
//!
//! Frame order (every loop iteration: ~250 Hz headless, the frame rate with a window):
//! 1. `PreUpdate` — [`NetPlugin`]: datagrams in, session timers and events. Desktop/VR front
//!    ends then read their device frame (mouse hands, or OpenXR poses after bevy_mod_xr has
//!    located its spaces), so this frame's fixed steps use it.
//! 2. `FixedUpdate` (0..n times, at `--sim-hz`) — [`SimPlugin`]: the bot and/or the device set
//!    the hands, hands update (authority requests), remote objects are shown, soft bodies and
//!    rapier step, owned objects are published.
//! 3. `Update` — with a window or headset only: the view copies the room into bevy entities
//!    (poses, deformed soft meshes, tints, avatars, HUD).
//! 4. `PostUpdate` — [`NetPlugin`]: datagrams out. Then bevy renders.
//! 5. `Last` — [`ReportPlugin`]: stats line, dump, the end of `--duration`.

use bevy::app::{App, AppExit, FixedUpdate, Last, Plugin, PostUpdate, PreUpdate};
use bevy::ecs::message::{MessageReader, MessageWriter};
use bevy::ecs::schedule::{IntoScheduleConfigs, SystemSet};
use bevy::ecs::system::NonSendMut;

use crate::driver::Driver;

fn net_in(mut driver: NonSendMut<Driver>, mut exit: MessageWriter<AppExit>) {
    if driver.exiting || !driver.ready {
        return;
    }
    if let Err(msg) = driver.network_in() {
        driver.fail(&msg);
        exit.write(AppExit::from_code(3));
    }
}

fn net_out(mut driver: NonSendMut<Driver>) {
    // Not before the front end is ready either: a `Hello` flushed early makes the host count
    // us a member, and time us out while we warm up (seen in CI: an XR session took 5 s).
    if driver.ready {
        driver.flush();
    }
}

fn simulate(mut driver: NonSendMut<Driver>) {
    driver.simulate();
}

fn report(mut driver: NonSendMut<Driver>, mut exit: MessageWriter<AppExit>) {
    if driver.exiting {
        return;
    }
    if driver.report() {
        exit.write(AppExit::Success);
    }
}

/// Whoever asked to exit (`--duration`, Ctrl-C, an error): a last dump and stats line, and a
/// `Leave` to the room so the others act at once (a host is replaced, authority returns).
fn on_exit(mut driver: NonSendMut<Driver>, mut exits: MessageReader<AppExit>) {
    if exits.read().next().is_none() {
        return;
    }
    driver.finish();
}

/// The system set of datagrams in (device front ends run after it).
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct NetIn;

/// Datagrams in and out around the frame.
pub struct NetPlugin;

impl Plugin for NetPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(PreUpdate, net_in.in_set(NetIn))
            .add_systems(PostUpdate, net_out);
    }
}

/// The fixed-rate simulation: bot, hands, soft bodies, rapier, publishing.
pub struct SimPlugin;

impl Plugin for SimPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(FixedUpdate, simulate);
    }
}

/// Stats line, dump, and leaving at the end of `--duration`.
pub struct ReportPlugin;

impl Plugin for ReportPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(Last, (report, on_exit).chain());
    }
}
