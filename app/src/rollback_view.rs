//! A rollback room drawn with bevy (feature `desktop`; the VR peer uses it too): the scene's
//! objects from the room's newest predicted frame (`softsync_bevy::RollbackView`), extrapolated
//! to the display's time and with rollback corrections glided out (the rule is in
//! `softsync_bevy::rollback`'s docs), everyone's hands and heads from their inputs, a tint on
//! what our hands hold, a HUD, and screenshots on a timer with the measurements the pixel tests
//! read.
//!
//! Nothing here changes the simulation: the room's thread owns it; this reads the frame it
//! published.

use std::collections::HashMap;
use std::sync::atomic::Ordering;

use bevy::asset::RenderAssetUsages;
use bevy::camera::Camera;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use softsync_bevy::glue::{to_bevy, to_bevy_quat};
use softsync_bevy::{RollbackObject, RollbackRoom, RollbackView, SoftsyncSet};
use softsync_net::PeerId;
use softsync_peer::Kind;

use crate::screenshot::{save_screenshot, screen_box};
use crate::view::{
    kind_color, peer_color, rigid_mesh, short, to_arrays, Hud, RenderWarm, ScreenshotState,
    ViewConfig,
};

/// The view's systems for a rollback room.
pub fn add_systems(app: &mut App) {
    app.init_resource::<FrameCosts>().add_systems(
        Update,
        (draw_objects, draw_avatars, update_hud, take_screenshots)
            .chain()
            .after(SoftsyncSet::Mirror),
    );
}

/// The drawing of one scene object.
#[derive(Component)]
struct RbDrawn {
    material: Handle<StandardMaterial>,
    base: Color,
    soft_mesh: Option<Handle<Mesh>>,
    topology: u32,
    held: bool,
}

/// One part (head 0, hands 1 and 2) of a player's avatar.
#[derive(Component)]
struct RbAvatar {
    of: PeerId,
    part: usize,
}

/// What drawing the newest frame costs here (the soft meshes' offsets and uploads), µs.
#[derive(Resource, Default)]
struct FrameCosts {
    draw_us: Vec<f32>,
}

impl FrameCosts {
    /// The median of the last 300 frames' costs, µs.
    fn recent_p50(&self) -> f32 {
        let mut v: Vec<f32> = self.draw_us.iter().rev().take(300).copied().collect();
        v.sort_by(f32::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    }
}

/// Seconds since the frame was published (the display extrapolates by this).
fn ahead(v: &RollbackView) -> f32 {
    v.at.map_or(0.0, |t| t.elapsed().as_secs_f32())
}

fn soft_mesh(positions: Vec<[f32; 3]>, normals: Vec<[f32; 3]>, triangles: &[[u32; 3]]) -> Mesh {
    let mut m = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
    );
    m.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    m.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
    m.insert_indices(Indices::U32(triangles.iter().flatten().copied().collect()));
    m
}

/// Vertex data as bevy's mesh takes it.
type Points = Vec<[f32; 3]>;

/// The shown positions and normals of soft object `i` (the tick's mesh moved as the object's
/// shown pose is: extrapolation and correction).
fn shown_soft(v: &RollbackView, i: usize, ahead_s: f32) -> Option<(Points, Points)> {
    let s = v.objects.get(i)?.soft.as_ref()?;
    let map = v.shown_map(i, ahead_s)?;
    let turn = v.objects[i].offset.rot;
    let pos = s.positions.iter().map(|p| map(*p).to_array()).collect();
    let nrm = if turn == glam::Quat::IDENTITY {
        to_arrays(&s.normals)
    } else {
        s.normals.iter().map(|n| (turn * *n).to_array()).collect()
    };
    Some((pos, nrm))
}

#[allow(clippy::too_many_arguments)]
fn draw_objects(
    mut commands: Commands,
    room: Res<RollbackRoom>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    new: Query<(Entity, &RollbackObject), Without<RbDrawn>>,
    mut drawn: Query<(&RollbackObject, &mut RbDrawn, &mut Visibility)>,
    mut costs: ResMut<FrameCosts>,
) {
    let t0 = std::time::Instant::now();
    let scene = room.scene();
    room.with_view(|v| {
        let ahead = ahead(v);
        for (e, r) in &new {
            let Some(o) = v.objects.get(r.index) else {
                continue;
            };
            let base = kind_color(scene, o.kind);
            let material = materials.add(StandardMaterial {
                base_color: base,
                perceptual_roughness: 0.6,
                ..default()
            });
            let (mesh, soft) = match (&o.soft, shown_soft(v, r.index, ahead)) {
                (Some(s), Some((p, n))) => {
                    let h = meshes.add(soft_mesh(p, n, &s.triangles));
                    (h.clone(), Some(h))
                }
                _ => (meshes.add(rigid_mesh(scene, o.kind)), None),
            };
            commands.entity(e).insert((
                Mesh3d(mesh),
                MeshMaterial3d(material.clone()),
                Visibility::Inherited,
                RbDrawn {
                    material,
                    base,
                    soft_mesh: soft,
                    topology: o.soft.as_ref().map_or(0, |s| s.topology),
                    held: false,
                },
            ));
        }
        for (r, mut d, mut vis) in &mut drawn {
            let Some(o) = v.objects.get(r.index) else {
                if *vis != Visibility::Hidden {
                    *vis = Visibility::Hidden;
                }
                continue;
            };
            if let (Some(s), Some(h)) = (&o.soft, &d.soft_mesh) {
                if let (Some((p, n)), Some(mut m)) =
                    (shown_soft(v, r.index, ahead), meshes.get_mut(h))
                {
                    m.insert_attribute(Mesh::ATTRIBUTE_POSITION, p);
                    m.insert_attribute(Mesh::ATTRIBUTE_NORMAL, n);
                    if d.topology != s.topology {
                        m.insert_indices(Indices::U32(
                            s.triangles.iter().flatten().copied().collect(),
                        ));
                        d.topology = s.topology;
                    }
                }
            }
            if d.held != o.held_by_us {
                d.held = o.held_by_us;
                if let Some(mut m) = materials.get_mut(&d.material) {
                    m.emissive = if d.held {
                        LinearRgba::rgb(0.04, 0.35, 0.10)
                    } else {
                        LinearRgba::BLACK
                    };
                    m.base_color = d.base;
                }
            }
        }
    });
    let us = t0.elapsed().as_secs_f32() * 1e6;
    if costs.draw_us.len() >= 36_000 {
        costs.draw_us.drain(..18_000);
    }
    costs.draw_us.push(us);
}

/// Heads and hands of the epoch's players, where their last inputs put them (ours: the hands
/// only; the camera is our head).
#[allow(clippy::too_many_arguments)]
fn draw_avatars(
    mut commands: Commands,
    room: Res<RollbackRoom>,
    cfg: Res<ViewConfig>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut parts: Query<(Entity, &RbAvatar, &mut Transform, &mut Visibility)>,
    mut shapes: Local<Option<[Handle<Mesh>; 2]>>,
) {
    let me = room.me();
    let scene = room.scene();
    let shapes = shapes.get_or_insert_with(|| {
        [
            meshes.add(rigid_mesh(scene, Kind::HEAD)),
            meshes.add(rigid_mesh(scene, Kind::HAND)),
        ]
    });
    room.with_view(|v| {
        let mut seen: HashMap<(PeerId, usize), bool> = HashMap::new();
        for (who, d) in &v.players {
            let poses = [d.head, d.hands[0], d.hands[1]];
            for (part, pose) in poses.iter().enumerate() {
                let hidden = cfg.hide_avatars
                    || (part == 0 && *who == me && cfg.hide_own_head)
                    || pose.is_none();
                seen.insert((*who, part), hidden);
            }
        }
        for (e, a, mut tf, mut vis) in &mut parts {
            let Some(hidden) = seen.remove(&(a.of, a.part)) else {
                commands.entity(e).despawn();
                continue;
            };
            let d = v.players.iter().find(|(p, _)| *p == a.of).map(|(_, d)| d);
            let pose = d.and_then(|d| [d.head, d.hands[0], d.hands[1]][a.part]);
            if let Some((p, q)) = pose {
                *tf = Transform::from_translation(to_bevy(p)).with_rotation(to_bevy_quat(q));
            }
            let want = if hidden {
                Visibility::Hidden
            } else {
                Visibility::Inherited
            };
            if *vis != want {
                *vis = want;
            }
        }
        for ((who, part), hidden) in seen {
            let material = materials.add(StandardMaterial {
                base_color: peer_color(who.0),
                perceptual_roughness: 0.6,
                ..default()
            });
            commands.spawn((
                RbAvatar { of: who, part },
                Mesh3d(shapes[usize::from(part > 0)].clone()),
                MeshMaterial3d(material),
                Transform::from_translation(Vec3::splat(-100.0)),
                if hidden {
                    Visibility::Hidden
                } else {
                    Visibility::Inherited
                },
            ));
        }
    });
}

/// The HUD's text in a rollback room.
fn hud_text(room: &RollbackRoom, v: &RollbackView, costs: &FrameCosts) -> String {
    let p50 = costs.recent_p50();
    let held: Vec<String> = v
        .objects
        .iter()
        .filter(|o| o.held_by_us)
        .map(|o| room.scene().name_of(o.kind).to_owned())
        .collect();
    format!(
        "rollback room | me {}{}\nepoch {} | players {} | peers {}\nframe {} confirmed {} (ahead {})\nrollbacks {} resimulated {} | desyncs {} repaired {}\ndraw {:.0} µs{}\n",
        short(room.me().0),
        if v.host == Some(room.me()) { " (host)" } else { "" },
        v.epoch,
        v.players.len(),
        v.members,
        v.frame,
        v.confirmed,
        v.frame - v.confirmed,
        v.rollbacks,
        v.resimulated,
        v.desyncs,
        v.repairs,
        p50,
        if held.is_empty() {
            String::new()
        } else {
            format!("\nholding {}", held.join(", "))
        }
    )
}

fn update_hud(
    room: Res<RollbackRoom>,
    cfg: Res<ViewConfig>,
    costs: Res<FrameCosts>,
    mut q: Query<&mut Text, With<Hud>>,
) {
    if !cfg.hud {
        return;
    }
    let Ok(mut text) = q.single_mut() else {
        return;
    };
    let new = room.with_view(|v| hud_text(&room, v, &costs));
    if text.0 != new {
        text.0 = new;
    }
}

/// Screenshots on the timer, each with a line: `screenshot n=… frame=… players=…` and per
/// soft class `NAME_px=` (its screen box), `NAME_count=`, `NAME_tris=`; `held=` what our hands
/// hold; `draw_us_p50=` this view's cost per frame.
#[allow(clippy::too_many_arguments)]
fn take_screenshots(
    mut commands: Commands,
    room: Res<RollbackRoom>,
    mut state: ResMut<ScreenshotState>,
    cfg: Res<ViewConfig>,
    cams: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    warm: Res<RenderWarm>,
    costs: Res<FrameCosts>,
    time: Res<Time<Real>>,
) {
    let Some(plan) = &cfg.screenshots else {
        return;
    };
    let t = time.elapsed();
    let joined = room.with_view(|v| v.joined && v.at.is_some());
    if state.taken >= plan.max || t < state.next || !joined || !warm.0.load(Ordering::Relaxed) {
        return;
    }
    state.next = t + plan.every;
    let n = state.taken;
    state.taken += 1;
    let cam = cams.iter().find(|(c, _)| c.is_active);
    let scene = room.scene();
    let fields = room.with_view(|v| {
        let ahead = ahead(v);
        let mut fields = format!(
            "screenshot n={n} t={:.2} frame={} players={}",
            t.as_secs_f64(),
            v.frame,
            v.players.len()
        );
        let mut classes: std::collections::BTreeMap<String, (usize, Vec<Vec3>, usize)> =
            Default::default();
        let mut held = Vec::new();
        for (i, o) in v.objects.iter().enumerate() {
            let name = scene.name_of(o.kind).to_owned();
            if o.held_by_us {
                held.push(name.clone());
            }
            let (Some(s), Some(map)) = (&o.soft, v.shown_map(i, ahead)) else {
                continue;
            };
            let c = classes.entry(name).or_default();
            c.0 += 1;
            c.1.extend(s.positions.iter().map(|p| to_bevy(map(*p))));
            c.2 += s.triangles.len();
        }
        for (name, (count, points, tris)) in classes {
            fields.push_str(&format!(" {name}_count={count} {name}_tris={tris}"));
            if let Some(cam) = cam {
                fields.push_str(&screen_box(cam, &format!("{name}_px"), points.into_iter()));
            }
        }
        if !held.is_empty() {
            fields.push_str(&format!(" held={}", held.join(",")));
        }
        fields
    });
    let fields = format!("{fields} draw_us_p50={:.0}", costs.recent_p50());
    save_screenshot(&mut commands, plan, n, &fields);
}
