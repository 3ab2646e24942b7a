//! The desktop and VR views' options: as clap reads them, and as a peer gets them.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;

use super::values::*;

/// Options of the desktop and VR views (each needs --desktop or --vr).
#[derive(Args, Debug)]
#[command(next_help_heading = "Front ends")]
pub(super) struct ViewOpts {
    /// Desktop window size, WIDTHxHEIGHT (64-8192).
    #[arg(long, value_name = "WxH", value_parser = window_size)]
    pub(super) window: Option<(u32, u32)>,
    /// Start the camera close to an object (softbox, bunny, softball, …).
    #[arg(long, value_name = "KIND")]
    pub(super) focus: Option<String>,
    /// Draw soft-body particles and their neighbour links (thesis Fig. 1.1).
    #[arg(long)]
    pub(super) particles: bool,
    /// Draw no avatars.
    #[arg(long)]
    pub(super) hide_avatars: bool,
    /// No HUD.
    #[arg(long)]
    pub(super) no_hud: bool,
    /// Names as cards in the world above each head, as a headset shows them, rather than as
    /// text on the screen.
    #[arg(long)]
    pub(super) world_labels: bool,
    /// Save frame-NNNN.png there every --screenshot-every S and print a line per frame
    /// (soft bodies' deformation and screen boxes), at most --screenshots N.
    #[arg(long, value_name = "DIR")]
    pub(super) screenshot_dir: Option<PathBuf>,
    /// Seconds between screenshots (default 1).
    #[arg(long, value_name = "S", value_parser = positive::<3600>)]
    pub(super) screenshot_every: Option<f64>,
    /// Most screenshots (1-100000, default 60).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub(super) screenshots: Option<u32>,
}

impl ViewOpts {
    /// The first view flag given, if any (they need a front end).
    pub(super) fn first_given(&self) -> Option<&'static str> {
        [
            (self.window.is_some(), "window"),
            (self.focus.is_some(), "focus"),
            (self.particles, "particles"),
            (self.hide_avatars, "hide-avatars"),
            (self.no_hud, "no-hud"),
            (self.world_labels, "world-labels"),
            (self.screenshot_dir.is_some(), "screenshot-dir"),
            (self.screenshot_every.is_some(), "screenshot-every"),
            (self.screenshots.is_some(), "screenshots"),
        ]
        .into_iter()
        .find_map(|(given, name)| given.then_some(name))
    }
}

/// Options of the desktop and VR views.
#[derive(Clone, Debug)]
#[cfg_attr(not(feature = "desktop"), allow(dead_code))]
pub struct ViewArgs {
    /// Window size.
    pub window: (u32, u32),
    /// Start the camera at this kind of object.
    pub focus: Option<String>,
    /// Particle overlay.
    pub particles: bool,
    /// Draw no avatars.
    pub hide_avatars: bool,
    /// No HUD.
    pub no_hud: bool,
    /// Names as cards in the world.
    pub world_labels: bool,
    /// Screenshot folder.
    pub screenshot_dir: Option<PathBuf>,
    /// Screenshot period.
    pub screenshot_every: Duration,
    /// Screenshot count.
    pub screenshots: u32,
}
