//! Who is who on a desktop peer: a label with each other peer's name (`--name`, its
//! `Presence`) floating above its head, in its colour, and its avatar drawn in that colour.
//! The speaking indicator's place is reckoned here too ([`speaking_indicators`]; `view.rs`
//! draws it). The labels are screen-space text placed each frame where the
//! head is seen; a head behind the camera hides its label. (In a headset they do not show:
//! OpenXR draws no bevy UI.)

use std::collections::BTreeMap;

use bevy::camera::Camera;
use bevy::prelude::*;
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
    cams: Query<(&Camera, &GlobalTransform)>,
    mut labels: Query<(Entity, &Label, &mut Node, &mut Visibility, &mut Text)>,
) {
    let peer = &room.peer;
    let me = peer.me();
    let cam = cams.iter().find(|(c, _)| c.is_active);
    // where each named remote peer's head is drawn
    let mut heads: BTreeMap<PeerId, (String, Vec3)> = BTreeMap::new();
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
