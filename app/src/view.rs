//! The room drawn with bevy (feature `desktop`; the VR peer uses it too): the floor and table,
//! rigid props, soft meshes deformed every frame (positions and normals), remote avatars in
//! one colour per peer, a tint for what this peer owns and what its hands hover, an optional
//! overlay of soft-body particles and their neighbour links (thesis Figure 1.1), a HUD, and
//! screenshots on a timer (`--screenshot-dir`).
//!
//! Nothing here changes the simulation: each frame (`Update`, after the fixed steps) copies
//! the room's state into bevy entities.

use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bevy::asset::RenderAssetUsages;
use bevy::camera::Camera;
use bevy::color::palettes::css;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::render_resource::PipelineCache;
use bevy::render::{Render, RenderApp, RenderSystems};
use softsync_net::NetId;

use softsync_peer::{Kind, LocalBody, Peer, Scene, Shape};

use softsync_bevy::glue::to_bevy;
use softsync_bevy::{NetEntities, NetObject, Room, SoftsyncSet};

use crate::driver::Driver;
pub use crate::screenshot::ScreenshotPlan;
use crate::screenshot::{rim_of, save_screenshot, screen_box};

/// What the view shows and records.
#[derive(Clone, Debug, Resource)]
pub struct ViewConfig {
    /// Draw particles and neighbour links over soft bodies (toggle: P).
    pub particles: bool,
    /// Draw no avatars (tests that look at a soft body's own pixels).
    pub hide_avatars: bool,
    /// Draw the HUD (toggle: H).
    pub hud: bool,
    /// Hide our own head (the camera is in it on the desktop and in VR).
    pub hide_own_head: bool,
    /// Names in the world (a headset: OpenXR draws no screen-space UI) rather than on the
    /// screen (the desktop).
    pub world_labels: bool,
    /// Screenshots: folder, period, how many at most.
    pub screenshots: Option<ScreenshotPlan>,
    /// The room is a rollback room ([`softsync_bevy::RollbackRoom`]): drawn by
    /// `rollback_view`.
    pub rollback: bool,
}

/// Draws the room: add to an app that has bevy's renderer, the softsync plugin and a `Driver`.
pub struct ViewPlugin(pub ViewConfig);

impl Plugin for ViewPlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(self.0.clone())
            .init_resource::<ScreenshotState>()
            .insert_resource(ClearColor(Color::srgb(0.62, 0.70, 0.78)))
            .insert_resource(GlobalAmbientLight {
                color: Color::WHITE,
                // Low ambient, a strong key light: dents and bulges show in the shading.
                brightness: 150.0,
                ..default()
            })
            .add_systems(Startup, spawn_static)
            .init_resource::<RenderWarm>();
        if self.0.rollback {
            // a rollback room's view adds its own systems (`rollback_view::add_systems`)
            return;
        }
        app.add_systems(
            Update,
            (
                sync_objects,
                crate::labels::update_labels.run_if(|c: Res<ViewConfig>| !c.world_labels),
                crate::labels::update_world_labels.run_if(|c: Res<ViewConfig>| c.world_labels),
                draw_overlay,
                update_hud,
                take_screenshots,
            )
                .chain()
                .after(SoftsyncSet::Mirror),
        );
    }

    fn finish(&self, app: &mut App) {
        let warm = app.world().resource::<RenderWarm>().clone();
        if let Some(render) = app.get_sub_app_mut(RenderApp) {
            render
                .insert_resource(warm)
                .add_systems(Render, note_render_warm.after(RenderSystems::Render));
        }
    }
}

/// Whether the last rendered frame drew with every render pipeline compiled. Pipelines
/// compile in the background (a synchronous compile would stall the frame loop past the
/// peer timeout on a software renderer); until they are ready, what uses them is not drawn,
/// and the first frames on lavapipe under load are the clear colour alone (measured).
/// Screenshots wait for this.
#[derive(Resource, Clone, Default)]
pub(crate) struct RenderWarm(pub(crate) Arc<AtomicBool>);

fn note_render_warm(cache: Option<Res<PipelineCache>>, warm: Res<RenderWarm>) {
    let ready = cache
        .is_some_and(|c| c.pipelines().next().is_some() && c.waiting_pipelines().next().is_none());
    warm.0.store(ready, Ordering::Relaxed);
}

/// Per-peer colour: evenly spread hues, none near the soft bodies' warm colours (so a test can
/// tell an avatar from a soft body by hue).
pub fn peer_color(peer: u64) -> Color {
    // Hues 150..330: greens, blues, purples.
    let h = 150.0 + ((peer.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) % 180) as f32;
    Color::hsl(h, 0.65, 0.5)
}

/// The colour a class is drawn in, as its scene says (avatars use their peer's colour).
pub fn kind_color(scene: &Scene, kind: Kind) -> Color {
    let [r, g, b] = scene.class(kind).map_or([0.8, 0.8, 0.8], |c| c.colour);
    Color::srgb(r, g, b)
}

/// How an object is drawn this frame (a change rewrites its material).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Tint {
    Plain,
    Hovered,
    Owned,
    Held,
}

/// The drawing of one networked object (on the plugin's entity of it).
#[derive(Component)]
struct ObjView {
    base: Color,
    material: Handle<StandardMaterial>,
    /// Soft bodies: the mesh rewritten every frame.
    soft_mesh: Option<Handle<Mesh>>,
    /// Topology log entries the mesh's triangles reflect.
    topology: u32,
    tint: Tint,
}

#[derive(Component)]
pub(crate) struct Hud;

#[derive(Resource, Default)]
pub(crate) struct ScreenshotState {
    pub(crate) next: Duration,
    pub(crate) taken: u32,
}

fn spawn_static(
    mut commands: Commands,
    room: Option<NonSend<Room>>,
    rollback: Option<Res<softsync_bevy::RollbackRoom>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    cfg: Res<ViewConfig>,
) {
    let scene = match (&room, &rollback) {
        (Some(r), _) => r.peer.scene(),
        (None, Some(r)) => r.scene(),
        (None, None) => return,
    };
    // The scene's fixed boxes (the floor, the table), as the peer's world has them.
    for b in &scene.fixed {
        let [r, g, bl] = b.colour;
        let material = materials.add(StandardMaterial {
            base_color: Color::srgb(r, g, bl),
            perceptual_roughness: 0.8,
            ..default()
        });
        let size = 2.0 * to_bevy(b.half_extents_m).abs();
        commands.spawn((
            Mesh3d(meshes.add(Cuboid::new(size.x, size.y, size.z))),
            MeshMaterial3d(material),
            Transform::from_translation(to_bevy(b.at)),
        ));
    }
    commands.spawn((
        DirectionalLight {
            illuminance: 9000.0,
            ..default()
        },
        Transform::from_xyz(1.5, 4.0, 2.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    commands.spawn((
        Hud,
        Text::new(""),
        TextFont::from_font_size(13.0),
        TextColor(Color::WHITE),
        BackgroundColor(Color::srgba(0.0, 0.0, 0.0, 0.55)),
        Node {
            position_type: PositionType::Absolute,
            top: Val::Px(6.0),
            left: Val::Px(6.0),
            padding: UiRect::all(Val::Px(4.0)),
            ..default()
        },
        if cfg.hud {
            Visibility::Inherited
        } else {
            Visibility::Hidden
        },
    ));
}

/// A mesh for a soft body from its current render data (world space).
fn soft_mesh(peer: &Peer, h: softsync_softbody::SoftBodyHandle) -> Option<Mesh> {
    let b = peer.soft_bodies().get(h)?;
    let mut m = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
    );
    m.insert_attribute(Mesh::ATTRIBUTE_POSITION, to_arrays(b.render_positions()));
    m.insert_attribute(Mesh::ATTRIBUTE_NORMAL, to_arrays(b.render_normals()));
    m.insert_indices(Indices::U32(
        b.render_triangles().iter().flatten().copied().collect(),
    ));
    Some(m)
}

pub(crate) fn to_arrays(v: &[glam::Vec3]) -> Vec<[f32; 3]> {
    v.iter().map(|p| p.to_array()).collect()
}

/// A rigid or avatar class's mesh, from its shape in the scene.
pub(crate) fn rigid_mesh(scene: &Scene, kind: Kind) -> Mesh {
    let Some(class) = scene.class(kind) else {
        return Sphere::new(0.05).into();
    };
    match &class.shape {
        Shape::Ball { radius_m, .. } => Sphere::new(*radius_m).mesh().uv(24, 16),
        Shape::Cuboid { half_extents_m, .. } => {
            let s = 2.0 * to_bevy(*half_extents_m).abs();
            Cuboid::new(s.x, s.y, s.z).into()
        }
        Shape::Cylinder {
            half_height_m,
            radius_m,
        } => Cylinder::new(*radius_m, 2.0 * half_height_m).into(),
        // A rigid mesh class: drawn as its file's mesh (it collides as the hull).
        Shape::Mesh { size_m, .. } => match class.mesh() {
            Some(m) => {
                let mut out = Mesh::new(
                    PrimitiveTopology::TriangleList,
                    RenderAssetUsages::MAIN_WORLD | RenderAssetUsages::RENDER_WORLD,
                );
                out.insert_attribute(Mesh::ATTRIBUTE_POSITION, to_arrays(&m.positions));
                out.insert_indices(Indices::U32(
                    m.triangles.iter().flatten().copied().collect(),
                ));
                out.compute_smooth_normals();
                out
            }
            None => Sphere::new(0.5 * size_m).mesh().uv(24, 16),
        },
    }
}

/// Gives the plugin's object entities (`NetObject`, its `Transform` following the room) their
/// meshes and materials, and each frame rewrites soft meshes, visibility and tints.
#[allow(clippy::too_many_arguments)]
fn sync_objects(
    mut commands: Commands,
    room: NonSend<Room>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    new: Query<(Entity, &NetObject), Without<ObjView>>,
    mut q: Query<(&NetObject, &mut ObjView, &mut Visibility)>,
    cfg: Res<ViewConfig>,
) {
    let peer = &room.peer;
    let me = peer.me();
    for (e, obj) in &new {
        let Some(o) = peer.objects().get(&obj.id) else {
            continue;
        };
        let base = match o.avatar_of {
            Some(p) => peer_color(p.0),
            None => kind_color(peer.scene(), o.kind),
        };
        let material = materials.add(StandardMaterial {
            base_color: base,
            perceptual_roughness: 0.6,
            ..default()
        });
        let (mesh, soft) = match o.body {
            LocalBody::Soft(h) => match soft_mesh(peer, h) {
                Some(m) => {
                    let handle = meshes.add(m);
                    (handle.clone(), Some(handle))
                }
                None => continue,
            },
            // being built off the frame: its mesh once it lands
            LocalBody::Building => continue,
            _ => (meshes.add(rigid_mesh(peer.scene(), o.kind)), None),
        };
        commands.entity(e).insert((
            Mesh3d(mesh),
            MeshMaterial3d(material.clone()),
            Visibility::Hidden,
            ObjView {
                base,
                material,
                soft_mesh: soft,
                topology: o.topology,
                tint: Tint::Plain,
            },
        ));
    }
    let hovered = peer.hovered_ids();
    let held: HashSet<NetId> = (0..2).filter_map(|h| peer.held(h).map(|x| x.0)).collect();
    for (obj, mut view, mut vis) in &mut q {
        let id = obj.id;
        let Some(o) = peer.objects().get(&id) else {
            continue;
        };
        // an avatar in the colour its peer chose (`--colour`), once its presence arrives
        if let Some(c) = o
            .avatar_of
            .and_then(|p| room.presences().get(&p))
            .and_then(|p| crate::labels::presence_colour(p.colour))
        {
            if view.base != c {
                view.base = c;
                if let Some(mut m) = materials.get_mut(&view.material) {
                    m.base_color = c;
                }
            }
        }
        let hidden = (o.kind.is_avatar() && cfg.hide_avatars)
            || (o.kind == Kind::HEAD && cfg.hide_own_head && o.avatar_of == Some(me));
        // Soft bodies: rewrite positions and normals (world space, identity transform), and
        // the triangles too after a tear or cut changed them.
        if let (LocalBody::Soft(h), Some(handle)) = (o.body, &view.soft_mesh) {
            if let (Some(b), Some(mut m)) = (peer.soft_bodies().get(h), meshes.get_mut(handle)) {
                m.insert_attribute(Mesh::ATTRIBUTE_POSITION, to_arrays(b.render_positions()));
                m.insert_attribute(Mesh::ATTRIBUTE_NORMAL, to_arrays(b.render_normals()));
                let indices = m.indices().map_or(0, |i| i.len());
                if view.topology != o.topology || indices != b.render_triangles().len() * 3 {
                    m.insert_indices(Indices::U32(
                        b.render_triangles().iter().flatten().copied().collect(),
                    ));
                }
            }
            view.topology = o.topology;
        }
        let want_vis = if hidden {
            Visibility::Hidden
        } else {
            Visibility::Inherited
        };
        if *vis != want_vis {
            *vis = want_vis;
        }
        let tint = if held.contains(&id) {
            Tint::Held
        } else if obj.mine && !o.kind.is_avatar() {
            Tint::Owned
        } else if hovered.contains(&id) {
            Tint::Hovered
        } else {
            Tint::Plain
        };
        if tint != view.tint {
            view.tint = tint;
            if let Some(mut m) = materials.get_mut(&view.material) {
                let glow = match tint {
                    Tint::Plain => LinearRgba::BLACK,
                    Tint::Hovered => LinearRgba::rgb(0.25, 0.25, 0.25),
                    Tint::Owned => LinearRgba::rgb(0.0, 0.07, 0.02),
                    Tint::Held => LinearRgba::rgb(0.04, 0.35, 0.10),
                };
                m.emissive = glow;
                m.base_color = view.base;
            }
        }
    }
}

/// Particles and neighbour links (thesis Figure 1.1), when switched on (P).
#[allow(clippy::too_many_arguments)]
fn draw_overlay(
    mut room: NonSendMut<Room>,
    mut gizmos: Gizmos,
    mut cfg: ResMut<ViewConfig>,
    keys: Option<Res<ButtonInput<KeyCode>>>,
    mut hud: Query<&mut Visibility, With<Hud>>,
    ents: Res<NetEntities>,
    tfs: Query<&GlobalTransform>,
) {
    // who is speaking: lime-green rings above the speaker's head, larger when louder
    for (_, at, r) in crate::labels::speaking_indicators(&room, &ents, &tfs) {
        for k in 0..4 {
            let rr = r * (1.0 - 0.2 * k as f32);
            gizmos.sphere(Isometry3d::from_translation(at), rr, css::LIME);
        }
    }
    if let Some(k) = &keys {
        if k.just_pressed(KeyCode::KeyP) {
            cfg.particles = !cfg.particles;
        }
        // M mutes and unmutes our microphone
        if k.just_pressed(KeyCode::KeyM) {
            if let Some(v) = room.voice() {
                let muted = !v.muted();
                v.chat().set_muted(muted);
            }
        }
        if k.just_pressed(KeyCode::KeyH) {
            cfg.hud = !cfg.hud;
            for mut v in &mut hud {
                *v = if cfg.hud {
                    Visibility::Inherited
                } else {
                    Visibility::Hidden
                };
            }
        }
    }
    if !cfg.particles {
        return;
    }
    let peer = &room.peer;
    for o in peer.objects().values() {
        let LocalBody::Soft(h) = o.body else { continue };
        let Some(b) = peer.soft_bodies().get(h) else {
            continue;
        };
        let ps = b.particle_positions(peer.world());
        let map = b.particle_map();
        for (i, p) in ps.iter().enumerate() {
            gizmos.sphere(Isometry3d::from_translation(to_bevy(*p)), 0.004, css::AQUA);
            let (nbrs, _) = map.neighbours.row(i);
            for &j in nbrs {
                let j = j as usize;
                if j > i {
                    if let Some(q) = ps.get(j) {
                        gizmos.line(to_bevy(*p), to_bevy(*q), css::WHITE.with_alpha(0.6));
                    }
                }
            }
        }
    }
}

fn update_hud(
    room: NonSend<Room>,
    driver: NonSend<Driver>,
    cfg: Res<ViewConfig>,
    mut q: Query<&mut Text, With<Hud>>,
) {
    if !cfg.hud {
        return;
    }
    let Ok(mut text) = q.single_mut() else {
        return;
    };
    let new = hud_text(&room, &driver);
    if text.0 != new {
        text.0 = new;
    }
}

/// A peer id, short enough for the HUD (its low 24 bits in hex; the log has the full id).
pub(crate) fn short(id: u64) -> String {
    format!("{:06x}", id & 0xff_ffff)
}

/// The HUD's text: room, peers, host, RTT, bytes/s, objects owned, the hands, the last events.
pub fn hud_text(room: &Room, driver: &Driver) -> String {
    let peer = &room.peer;
    let session = peer.session();
    let rtt = crate::report::mean_rtt_ms(peer).map_or("-".to_owned(), |r| format!("{r:.0} ms"));
    let host = session.host_id();
    let mut s = format!(
        "room {} | me {}{}\nhost {} term {} | peers {}\nrtt {rtt} | up {:.0} B/s down {:.0} B/s\nowned {}/{}\n",
        room.name(),
        short(peer.me().0),
        if session.is_host() { " (host)" } else { "" },
        host.map_or("-".into(), |h| short(h.0)),
        session.term().0,
        session.members().len(),
        driver.last_rates.up,
        driver.last_rates.down,
        peer.owned_count(),
        peer.objects().len(),
    );
    for (h, name) in [(0, "left"), (1, "right")] {
        if let Some((id, _)) = peer.held(h) {
            // co-manipulation: every hand on it, ours or not; a remote hand (the body is
            // another peer's) says so
            let hands = peer.holders(id).len().max(1);
            s.push_str(&format!(
                "{name} hand holds {}{} | {hands} hand{} on it\n",
                object_name(peer, id),
                if peer.holds_remotely(h) {
                    " (remote)"
                } else {
                    ""
                },
                if hands == 1 { "" } else { "s" },
            ));
        }
        if peer.hand_tool(h) == softsync_peer::HandTool::Cutter {
            let state = if peer.is_sweeping(h) {
                "sweeping"
            } else {
                "ready"
            };
            s.push_str(&format!("{name} hand: cutter {state}\n"));
        }
    }
    let building = peer
        .objects()
        .values()
        .filter(|o| o.body == LocalBody::Building)
        .count();
    if building > 0 {
        s.push_str(&format!("building {building} pieces off the frame\n"));
    }
    // voice: muted or not, and who is speaking (with their level)
    if let Some(v) = room.voice_view() {
        let talking: Vec<String> = v
            .speaking()
            .iter()
            .map(|(p, db)| format!("{} {db:.0} dB", short(p.0)))
            .collect();
        s.push_str(&format!(
            "voice{}{}\n",
            if v.muted() { " (muted)" } else { "" },
            if talking.is_empty() {
                String::new()
            } else {
                format!(" | speaking: {}", talking.join(", "))
            }
        ));
    }
    // Torn and cut soft bodies: how many log entries each has, and the pieces of a cut.
    let torn: Vec<String> = peer
        .objects()
        .iter()
        .filter(|(_, o)| o.topology > 0)
        .map(|(id, o)| format!("{} ({} cuts/tears)", object_name(peer, *id), o.topology))
        .collect();
    if !torn.is_empty() {
        s.push_str(&format!("torn: {}\n", torn.join(", ")));
    }
    if let Some(clock) = &driver.replay_clock {
        // a played-back recording: its timeline, and the keys that steer it
        let (c, _) = clock;
        let t = crate::driver::replay_position(clock, room.now());
        let filled = if c.length_s > 0.0 {
            ((t / c.length_s).clamp(0.0, 1.0) * 30.0).round() as usize
        } else {
            0
        };
        s.push_str(&format!(
            "replay {t:.1} / {:.1} s {} {}x [{}{}]\nspace pause | left/right 5 s | up/down speed\n",
            c.length_s,
            if c.paused { "paused" } else { "playing" },
            c.speed,
            "=".repeat(filled),
            "-".repeat(30 - filled),
        ));
    }
    for e in driver.recent_events.iter() {
        s.push_str(e);
        s.push('\n');
    }
    s
}

fn object_name(peer: &Peer, id: NetId) -> String {
    peer.objects().get(&id).map_or(format!("#{}", id.0), |o| {
        format!("{} #{}", peer.scene().name_of(o.kind), id.0)
    })
}

/// Shape change of a soft body: the largest distance of a vertex from where the rest shape,
/// moved rigidly with the center, puts it (metres).
pub fn deformation_m(peer: &Peer, h: softsync_softbody::SoftBodyHandle) -> Option<f32> {
    let b = peer.soft_bodies().get(h)?;
    let (c, r) = b.center_pose(peer.world());
    Some(
        b.vertices()
            .iter()
            .zip(b.rest_vertices())
            .map(|(v, rest)| v.distance(c + r * *rest))
            .fold(0.0, f32::max),
    )
}

/// What a screenshot's line reads of the drawn scene: entities, their views and meshes, and
/// where things are.
type Drawn<'w, 's, 'a, 'b> = (
    Res<'w, NetEntities>,
    Query<'w, 's, &'a ObjView>,
    Res<'w, Assets<Mesh>>,
    Query<'w, 's, &'b GlobalTransform>,
);

fn take_screenshots(
    mut commands: Commands,
    room: NonSend<Room>,
    mut state: ResMut<ScreenshotState>,
    cfg: Res<ViewConfig>,
    cams: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    warm: Res<RenderWarm>,
    (ents, objs, meshes, tfs): Drawn,
) {
    let Some(plan) = &cfg.screenshots else {
        return;
    };
    let peer = &room.peer;
    let t = Duration::from_micros(room.now().as_micros());
    if state.taken >= plan.max
        || t < state.next
        || !peer.joined()
        || !warm.0.load(Ordering::Relaxed)
    {
        return;
    }
    state.next = t + plan.every;
    let n = state.taken;
    state.taken += 1;
    // What the frame shows, measured now: per soft body its deformation and screen box.
    let mut fields = format!(
        "screenshot n={n} t={:.2} peers={}",
        t.as_secs_f64(),
        peer.session().members().len()
    );
    let cam = cams.iter().find(|(c, _)| c.is_active);
    // per class: how many soft bodies (a cut makes pieces of one class) and all their points
    let mut classes: std::collections::BTreeMap<String, (usize, Vec<Vec3>)> = Default::default();
    for (id, o) in peer.objects() {
        let LocalBody::Soft(h) = o.body else { continue };
        let name = peer.scene().name_of(o.kind);
        if let Some(b) = peer.soft_bodies().get(h) {
            let c = classes.entry(name.to_string()).or_default();
            c.0 += 1;
            c.1.extend(b.render_positions().iter().map(|p| to_bevy(*p)));
        }
        if let Some(d) = deformation_m(peer, h) {
            fields.push_str(&format!(" {name}_deform_mm={:.2}", d * 1e3));
        }
        if let (Some(cam), Some(b)) = (cam, peer.soft_bodies().get(h)) {
            let points = b.render_positions().iter().map(|p| to_bevy(*p));
            fields.push_str(&screen_box(cam, &format!("{name}_px"), points));
        }
        // What is drawn, read back from the mesh asset the renderer uses: its triangles,
        // and the screen box of its open rim (the edges of a tear's slit).
        let drawn = (ents.get(*id))
            .and_then(|e| objs.get(e).ok())
            .and_then(|v| v.soft_mesh.as_ref())
            .and_then(|h| meshes.get(h));
        if let Some(m) = drawn {
            let (tris, rim) = rim_of(m);
            fields.push_str(&format!(" {name}_tris={tris}"));
            if let Some(cam) = cam {
                fields.push_str(&screen_box(cam, &format!("{name}_rim_px"), rim.into_iter()));
            }
        }
    }
    // names: who, and where the label is anchored on screen
    if let Some((c, gt)) = cam {
        for (id, o) in peer.objects() {
            let Some(who) = o
                .avatar_of
                .filter(|p| *p != peer.me() && o.kind == Kind::HEAD)
            else {
                continue;
            };
            if !room.presences().contains_key(&who) {
                continue;
            }
            let Some(at) = ents.get(*id).and_then(|e| tfs.get(e).ok()) else {
                continue;
            };
            if let Ok(s) =
                c.world_to_viewport(gt, at.translation() + Vec3::Y * crate::labels::LABEL_LIFT)
            {
                fields.push_str(&format!(" label={} label_at={:.0},{:.0}", who.0, s.x, s.y));
            }
        }
    }
    // speaking indicators: who, and the screen box of the indicator
    if let Some(cam) = cam {
        for (who, at, r) in crate::labels::speaking_indicators(&room, &ents, &tfs) {
            fields.push_str(&format!(" speaking={who}"));
            let pts = [-1.0f32, 1.0]
                .into_iter()
                .flat_map(|x| [-1.0f32, 1.0].map(|y| (x, y)))
                .flat_map(|(x, y)| [-1.0f32, 1.0].map(|z| at + Vec3::new(x, y, z) * r));
            fields.push_str(&screen_box(cam, "speaking_px", pts));
        }
    }
    for (name, (count, points)) in classes {
        fields.push_str(&format!(" {name}_count={count}"));
        if let Some(cam) = cam {
            fields.push_str(&screen_box(
                cam,
                &format!("{name}_all_px"),
                points.into_iter(),
            ));
        }
    }
    save_screenshot(&mut commands, plan, n, &fields);
}
