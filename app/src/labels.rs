//! Who is who on a desktop peer: a label with each other peer's name (`--name`, its
//! `Presence`) floating above its head, in its colour, and its avatar drawn in that colour.
//! The speaking indicator's place is reckoned here too ([`speaking_indicators`]; `view.rs`
//! draws it). On a desktop the labels are screen-space text placed each frame where the
//! head is seen; a head behind the camera hides its label. In a headset (OpenXR draws no
//! screen-space UI) each label is a quad in the world above the head, turned to face the
//! viewer, textured with the name as bevy's UI draws it into an image
//! ([`update_world_labels`]).

use std::collections::BTreeMap;

use bevy::asset::RenderAssetUsages;
use bevy::camera::{Camera, RenderTarget};
use bevy::prelude::*;
use bevy::render::render_resource::TextureFormat;
use bevy::ui::UiTargetCamera;
use softsync_bevy::{NetEntities, Room};
use softsync_net::PeerId;
use softsync_peer::Kind;

/// A peer's label.
#[derive(Component)]
pub struct Label(pub PeerId);

/// How high above a head its label floats, metres.
pub const LABEL_LIFT: f32 = 0.32;

/// The sRGB colour a presence asks for (`[0, 0, 0]`: none, the front end's from the id).
pub fn presence_colour(c: [u8; 3]) -> Option<Color> {
    (c != [0, 0, 0]).then(|| Color::srgb_u8(c[0], c[1], c[2]))
}

/// One label per named remote peer, placed above its head each frame.
pub fn update_labels(
    mut commands: Commands,
    room: NonSend<Room>,
    ents: Res<NetEntities>,
    tfs: Query<&GlobalTransform>,
    cams: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    mut labels: Query<(Entity, &Label, &mut Node, &mut Visibility, &mut Text)>,
) {
    let cam = cams.iter().find(|(c, _)| c.is_active);
    // where each named remote peer's head is drawn
    let mut heads = named_heads(&room, &ents, &tfs);
    for (e, label, mut node, mut vis, mut text) in &mut labels {
        let Some((name, at)) = heads.remove(&label.0) else {
            commands.entity(e).despawn();
            continue;
        };
        let seen = cam.and_then(|(c, gt)| c.world_to_viewport(gt, at + Vec3::Y * LABEL_LIFT).ok());
        match seen {
            Some(s) => {
                node.left = Val::Px(s.x - 4.0 * name.chars().count() as f32);
                node.top = Val::Px(s.y - 10.0);
                *vis = Visibility::Inherited;
            }
            None => *vis = Visibility::Hidden,
        }
        if text.0 != name {
            text.0 = name;
        }
    }
    // new labels
    for (who, (name, _)) in heads {
        let colour = room
            .presences()
            .get(&who)
            .and_then(|p| presence_colour(p.colour))
            .unwrap_or_else(|| crate::view::peer_color(who.0));
        commands.spawn((
            Label(who),
            Text::new(name),
            TextFont::from_font_size(12.0),
            TextColor(colour),
            BackgroundColor(Color::srgba(0.0, 0.0, 0.0, 0.7)),
            Node {
                position_type: PositionType::Absolute,
                padding: UiRect::axes(Val::Px(3.0), Val::Px(1.0)),
                ..default()
            },
            Visibility::Hidden,
        ));
    }
}

/// A peer's name in the world: the quad, and the camera and UI that draw its image.
#[derive(Component)]
pub struct WorldLabel {
    who: PeerId,
    name: String,
    camera: Entity,
    ui: Entity,
    /// Frames its camera has drawn; it is switched off after a few (the image keeps them).
    drawn: u32,
}

/// A world label's image, pixels, and its quad, metres.
const LABEL_PX: (u32, u32) = (256, 48);
const LABEL_M: (f32, f32) = (0.24, 0.045);

/// Where each named remote peer's head is drawn, with its name.
fn named_heads(
    room: &Room,
    ents: &NetEntities,
    tfs: &Query<&GlobalTransform>,
) -> BTreeMap<PeerId, (String, Vec3)> {
    let peer = &room.peer;
    let me = peer.me();
    let mut heads = BTreeMap::new();
    for (id, o) in peer.objects() {
        let Some(who) = o.avatar_of.filter(|p| *p != me && o.kind == Kind::HEAD) else {
            continue;
        };
        let Some(p) = room.presences().get(&who) else {
            continue;
        };
        let Some(at) = ents.get(*id).and_then(|e| tfs.get(e).ok()) else {
            continue;
        };
        heads.insert(who, (p.name.clone(), at.translation()));
    }
    heads
}

/// Names in a headset: one quad per named remote peer above its head, facing the viewer
/// (the mean of the active 3D cameras: both eyes). Its image is drawn by bevy's UI through a
/// camera of its own, for a few frames when the label is made or renamed, then that camera
/// sleeps.
#[allow(clippy::too_many_arguments)]
pub fn update_world_labels(
    mut commands: Commands,
    room: NonSend<Room>,
    ents: Res<NetEntities>,
    tfs: Query<&GlobalTransform>,
    eyes: Query<(&Camera, &GlobalTransform), With<Camera3d>>,
    mut labels: Query<(Entity, &mut WorldLabel, &mut Transform)>,
    mut cams: Query<&mut Camera, Without<Camera3d>>,
    mut texts: Query<&mut Text>,
    mut images: ResMut<Assets<Image>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    let mut heads = named_heads(&room, &ents, &tfs);
    let seen: Vec<Vec3> = eyes
        .iter()
        .filter(|(c, _)| c.is_active)
        .map(|(_, t)| t.translation())
        .collect();
    let viewer = (!seen.is_empty()).then(|| seen.iter().sum::<Vec3>() / seen.len() as f32);
    for (e, mut label, mut tf) in &mut labels {
        let Some((name, at)) = heads.remove(&label.who) else {
            commands.entity(label.camera).despawn();
            commands.entity(label.ui).despawn();
            commands.entity(e).despawn();
            continue;
        };
        let pos = at + Vec3::Y * LABEL_LIFT;
        tf.translation = pos;
        if let Some(v) = viewer {
            // the quad's front (+z) toward the viewer, upright
            let to = Vec3::new(v.x - pos.x, 0.0, v.z - pos.z);
            if to.length_squared() > 1e-6 {
                tf.rotation = Quat::from_rotation_arc(Vec3::Z, to.normalize());
            }
        }
        if label.name != name {
            if let Ok(mut t) = texts.get_mut(label.ui) {
                t.0 = name.clone();
            }
            label.name = name;
            label.drawn = 0;
        }
        if let Ok(mut c) = cams.get_mut(label.camera) {
            label.drawn += 1;
            let active = label.drawn <= 4;
            if c.is_active != active {
                c.is_active = active;
            }
        }
    }
    for (who, (name, at)) in heads {
        let colour = room
            .presences()
            .get(&who)
            .and_then(|p| presence_colour(p.colour))
            .unwrap_or_else(|| crate::view::peer_color(who.0));
        let image = images.add(Image::new_target_texture(
            LABEL_PX.0,
            LABEL_PX.1,
            TextureFormat::Rgba8UnormSrgb,
            None,
        ));
        let camera = commands
            .spawn((
                Camera2d,
                Camera {
                    order: -10,
                    clear_color: ClearColorConfig::Custom(Color::srgba(0.0, 0.0, 0.0, 0.75)),
                    ..default()
                },
                RenderTarget::Image(image.clone().into()),
            ))
            .id();
        let ui = commands
            .spawn((
                Text::new(name.clone()),
                TextFont::from_font_size(34.0),
                TextColor(colour),
                TextLayout::justify(Justify::Center),
                Node {
                    width: Val::Percent(100.0),
                    top: Val::Px(2.0),
                    ..default()
                },
                UiTargetCamera(camera),
            ))
            .id();
        let mut mesh = Mesh::from(Rectangle::new(LABEL_M.0, LABEL_M.1));
        mesh.asset_usage = RenderAssetUsages::default();
        commands.spawn((
            WorldLabel {
                who,
                name,
                camera,
                ui,
                drawn: 0,
            },
            Mesh3d(meshes.add(mesh)),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color_texture: Some(image),
                unlit: true,
                alpha_mode: AlphaMode::Blend,
                double_sided: true,
                cull_mode: None,
                ..default()
            })),
            Transform::from_translation(at + Vec3::Y * LABEL_LIFT),
        ));
        println!("view label peer={} world=true", who.0);
    }
}

/// How high above a speaker's head its speaking indicator floats, metres.
const INDICATOR_LIFT: f32 = 0.2;

/// Each peer heard speaking now: where its indicator is drawn (above its head as shown) and
/// its radius (larger when louder).
pub fn speaking_indicators(
    room: &Room,
    ents: &NetEntities,
    tfs: &Query<&GlobalTransform>,
) -> Vec<(u64, Vec3, f32)> {
    let Some(voice) = room.voice_view() else {
        return Vec::new();
    };
    let peer = &room.peer;
    voice
        .speaking()
        .into_iter()
        .filter_map(|(who, db)| {
            let (id, _) = peer
                .objects()
                .iter()
                .find(|(_, o)| o.kind == Kind::HEAD && o.avatar_of == Some(who))?;
            let at = tfs.get(ents.get(*id)?).ok()?.translation();
            let loud = ((db + 70.0) / 70.0).clamp(0.0, 1.0);
            Some((who.0, at + Vec3::Y * INDICATOR_LIFT, 0.03 + 0.04 * loud))
        })
        .collect()
}
