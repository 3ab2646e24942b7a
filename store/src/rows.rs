//! Rows back to values, the same for every back end: each column's range checked, so a
//! store edited by hand or damaged gives an error naming the row, never a panic or a NaN.

use glam::{Quat, Vec3};
use softsync_net::wire::{AppMessage, Delivery, MessageKind, MessageTarget};
use softsync_net::{ClassId, KeptObject, NetId, ObjectState, PeerId};

use crate::codec::{decode_event, decode_particles};
use crate::StoreError;

/// An `objects` row.
pub(crate) fn object(
    id: i64,
    class: i64,
    p: [f64; 3],
    q: [f64; 4],
    particles: &[u8],
) -> Result<KeptObject, StoreError> {
    let id = u32::try_from(id).map_err(|_| StoreError::Row(format!("object id {id}")))?;
    let class = u16::try_from(class).map_err(|_| StoreError::Row(format!("class {class}")))?;
    let pos = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
    let rot = Quat::from_xyzw(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32);
    if !pos.is_finite() || !rot.is_finite() {
        return Err(StoreError::Row(format!("object {id}: pose not finite")));
    }
    Ok(KeptObject {
        id: NetId(id),
        class: ClassId(class),
        state: ObjectState {
            pos,
            rot,
            particles: decode_particles(particles)?,
        },
        topology: Vec::new(),
    })
}

/// A `topology` row, appended to its object's log (rows come ordered by object and seq).
pub(crate) fn push_event(
    objects: &mut [KeptObject],
    object: i64,
    seq: i64,
    kind: &str,
    json: &str,
) -> Result<(), StoreError> {
    let Some(o) = objects.iter_mut().find(|o| i64::from(o.id.0) == object) else {
        return Err(StoreError::Row(format!(
            "topology of object {object}, which is not kept"
        )));
    };
    if seq != o.topology.len() as i64 {
        return Err(StoreError::Row(format!(
            "object {object}'s log skips from {} to {seq}",
            o.topology.len()
        )));
    }
    o.topology.push(decode_event(kind, json)?);
    Ok(())
}

/// A `retained` row.
pub(crate) fn retained(
    kind: i64,
    object: i64,
    origin: i64,
    seq: i64,
    delivery: &str,
    payload: Vec<u8>,
) -> Result<AppMessage, StoreError> {
    let kind = u16::try_from(kind).map_err(|_| StoreError::Row(format!("message kind {kind}")))?;
    let seq = u32::try_from(seq).map_err(|_| StoreError::Row(format!("message seq {seq}")))?;
    let delivery = match (delivery, u32::try_from(object)) {
        ("retained", _) => Delivery::Retained,
        ("per-object", Ok(o)) => Delivery::ObjectState(NetId(o)),
        (d, _) => return Err(StoreError::Row(format!("retained message delivery {d:?}"))),
    };
    Ok(AppMessage {
        origin: PeerId(origin as u64),
        seq,
        kind: MessageKind(kind),
        to: MessageTarget::Everyone,
        delivery,
        payload,
    })
}

/// How a retained message's delivery is written.
pub(crate) fn delivery_text(d: Delivery) -> &'static str {
    match d {
        Delivery::Retained => "retained",
        Delivery::ObjectState(_) => "per-object",
        Delivery::Reliable => "reliable",
        Delivery::Unreliable => "unreliable",
    }
}

/// The `object` column of a retained message: its object, or -1 for a room-wide one.
pub(crate) fn retained_object(m: &AppMessage) -> i64 {
    match m.delivery {
        Delivery::ObjectState(o) => i64::from(o.0),
        _ => -1,
    }
}
