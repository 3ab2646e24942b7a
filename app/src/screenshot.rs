//! Screenshots of the window for the pixel tests (`--screenshot-dir`): the plan, saving a
//! frame with its line of measurements, and the measurements both views print (a screen box
//! of points, a drawn mesh's open rim).

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Duration;

use bevy::camera::Camera;
use bevy::ecs::observer::On;
use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};

/// Screenshots on a timer.
#[derive(Clone, Debug)]
pub struct ScreenshotPlan {
    /// Folder for `frame-NNNN.png`.
    pub dir: PathBuf,
    /// Period.
    pub every: Duration,
    /// Stop after this many.
    pub max: u32,
}

/// ` KEY=x0,y0,x1,y1`: the screen box (pixels) of the points in front of the camera, or
/// nothing if none is.
pub(crate) fn screen_box(
    (c, gt): (&Camera, &GlobalTransform),
    key: &str,
    points: impl Iterator<Item = Vec3>,
) -> String {
    let mut lo = Vec2::splat(f32::MAX);
    let mut hi = Vec2::splat(f32::MIN);
    for p in points {
        if let Ok(s) = c.world_to_viewport(gt, p) {
            lo = lo.min(s);
            hi = hi.max(s);
        }
    }
    if lo.x <= hi.x {
        format!(" {key}={:.0},{:.0},{:.0},{:.0}", lo.x, lo.y, hi.x, hi.y)
    } else {
        String::new()
    }
}

/// A drawn mesh's triangle count, and the corners of its open edges: edges that one triangle
/// alone uses once corners at the same position are one (a closed mesh has none; a torn one
/// has its slit's rim).
pub(crate) fn rim_of(m: &Mesh) -> (usize, Vec<Vec3>) {
    let (Some(bevy::mesh::VertexAttributeValues::Float32x3(pos)), Some(ind)) =
        (m.attribute(Mesh::ATTRIBUTE_POSITION), m.indices())
    else {
        return (0, Vec::new());
    };
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    let ids: Vec<u32> = pos
        .iter()
        .map(|p| {
            let n = weld.len() as u32;
            *weld.entry(p.map(f32::to_bits)).or_insert(n)
        })
        .collect();
    let corners: Vec<usize> = ind.iter().collect();
    let mut edges: HashMap<(u32, u32), (u32, [usize; 2])> = HashMap::new();
    for t in corners.chunks_exact(3) {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let (Some(&ia), Some(&ib)) = (ids.get(a), ids.get(b)) else {
                continue;
            };
            let e = edges.entry((ia.min(ib), ia.max(ib))).or_insert((0, [a, b]));
            e.0 += 1;
        }
    }
    let rim = edges
        .values()
        .filter(|(n, _)| *n == 1)
        .flat_map(|(_, c)| c.map(|i| Vec3::from_array(pos[i])))
        .collect();
    (corners.len() / 3, rim)
}

/// Takes screenshot `n` of the window into `plan`'s folder and prints `fields` with its path
/// once it is saved.
pub(crate) fn save_screenshot(
    commands: &mut Commands,
    plan: &ScreenshotPlan,
    n: u32,
    fields: &str,
) {
    let path = plan.dir.join(format!("frame-{n:04}.png"));
    let line = format!("{fields} path={}", path.display());
    commands
        .spawn(Screenshot::primary_window())
        .observe(move |shot: On<ScreenshotCaptured>| {
            let saved = shot
                .image
                .clone()
                .try_into_dynamic()
                .map_err(|e| e.to_string())
                .and_then(|img| img.to_rgb8().save(&path).map_err(|e| e.to_string()));
            match saved {
                Ok(()) => println!("{line}"),
                Err(e) => eprintln!("screenshot {}: {e}", path.display()),
            }
        });
}
