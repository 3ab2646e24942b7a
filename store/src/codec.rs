//! How values sit in a store's rows, independent of the wire's encoding, so the wire can
//! change without old stores going unreadable.
//!
//! - A topology event is a `kind` text and a JSON object of its fields, in the event format
//!   [`EVENT_FORMAT`]. Kinds are only ever added: an old log reads under a new build; a kind
//!   this build does not know (a newer build's) is an error naming it, never a guess.
//! - Particles are a blob of little-endian `f32` triples.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use softsync_net::wire::TopologyEvent;

use crate::StoreError;

/// The topology-event format this build writes (and the newest it reads).
pub const EVENT_FORMAT: u32 = 1;

#[derive(Serialize, Deserialize)]
struct Tear {
    from: [i32; 3],
    to: [i32; 3],
    blade: [i32; 3],
}

#[derive(Serialize, Deserialize)]
struct Cut {
    point: [i32; 3],
    normal: [i16; 3],
    keep: u8,
}

#[derive(Serialize, Deserialize)]
struct Resolution {
    level: u8,
    particles: u32,
}

/// `e` as a row: its kind and its fields as JSON.
pub fn encode_event(e: &TopologyEvent) -> (&'static str, String) {
    let json = |v: serde_json::Result<String>| v.unwrap_or_else(|_| "{}".into());
    match *e {
        TopologyEvent::Tear { from, to, blade } => (
            "tear",
            json(serde_json::to_string(&Tear { from, to, blade })),
        ),
        TopologyEvent::Lift => ("lift", "{}".into()),
        TopologyEvent::Cut {
            point,
            normal,
            keep,
        } => (
            "cut",
            json(serde_json::to_string(&Cut {
                point,
                normal,
                keep,
            })),
        ),
        TopologyEvent::Resolution { level, particles } => (
            "resolution",
            json(serde_json::to_string(&Resolution { level, particles })),
        ),
    }
}

/// The event of a row of `kind` with fields `json`.
pub fn decode_event(kind: &str, json: &str) -> Result<TopologyEvent, StoreError> {
    let bad = |e: serde_json::Error| StoreError::Row(format!("{kind} event {json:?}: {e}"));
    Ok(match kind {
        "tear" => {
            let t: Tear = serde_json::from_str(json).map_err(bad)?;
            TopologyEvent::Tear {
                from: t.from,
                to: t.to,
                blade: t.blade,
            }
        }
        "lift" => TopologyEvent::Lift,
        "cut" => {
            let c: Cut = serde_json::from_str(json).map_err(bad)?;
            TopologyEvent::Cut {
                point: c.point,
                normal: c.normal,
                keep: c.keep,
            }
        }
        "resolution" => {
            let r: Resolution = serde_json::from_str(json).map_err(bad)?;
            TopologyEvent::Resolution {
                level: r.level,
                particles: r.particles,
            }
        }
        other => {
            return Err(StoreError::Row(format!(
                "topology event kind {other:?} is unknown to this build (written by a newer one?)"
            )))
        }
    })
}

/// Particles as a blob.
pub fn encode_particles(p: &[Vec3]) -> Vec<u8> {
    let mut out = Vec::with_capacity(p.len() * 12);
    for v in p {
        for c in v.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    out
}

/// A blob back to particles: its length must be a whole number of triples and every value
/// finite.
pub fn decode_particles(b: &[u8]) -> Result<Vec<Vec3>, StoreError> {
    if b.len() % 12 != 0 {
        return Err(StoreError::Row(format!(
            "particle blob of {} bytes is not whole triples",
            b.len()
        )));
    }
    let f = |i: usize| {
        let mut a = [0u8; 4];
        a.copy_from_slice(&b[i..i + 4]);
        f32::from_le_bytes(a)
    };
    let out: Vec<Vec3> = (0..b.len() / 12)
        .map(|k| Vec3::new(f(k * 12), f(k * 12 + 4), f(k * 12 + 8)))
        .collect();
    if out.iter().any(|v| !v.is_finite()) {
        return Err(StoreError::Row("a particle is not finite".into()));
    }
    Ok(out)
}

/// `b` as lowercase hex.
pub fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// Hex back to bytes.
pub fn unhex(s: &str) -> Result<Vec<u8>, StoreError> {
    if s.len() % 2 != 0 || !s.is_ascii() {
        return Err(StoreError::Row(format!("{} hex digits", s.len())));
    }
    (0..s.len() / 2)
        .map(|i| {
            u8::from_str_radix(&s[2 * i..2 * i + 2], 16)
                .map_err(|_| StoreError::Row(format!("not hex: {:?}", &s[2 * i..2 * i + 2])))
        })
        .collect()
}

/// A room image as JSON (a recording's start): objects with their logs in the event row
/// form, retained messages with hex payloads.
pub fn image_to_json(image: &softsync_net::RoomImage) -> String {
    use serde_json::json;
    let objects: Vec<serde_json::Value> = image
        .objects
        .iter()
        .map(|o| {
            let log: Vec<serde_json::Value> = o
                .topology
                .iter()
                .map(|e| {
                    let (k, j) = encode_event(e);
                    json!([k, j])
                })
                .collect();
            json!({
                "id": o.id.0, "class": o.class.0,
                "pos": o.state.pos.to_array(), "rot": o.state.rot.to_array(),
                "particles": hex(&encode_particles(&o.state.particles)),
                "log": log,
            })
        })
        .collect();
    let retained: Vec<serde_json::Value> = image
        .retained
        .iter()
        .map(|m| {
            json!({
                "kind": m.kind.0, "object": crate::rows::retained_object(m), "origin": m.origin.0,
                "seq": m.seq, "delivery": crate::rows::delivery_text(m.delivery),
                "payload": hex(&m.payload),
            })
        })
        .collect();
    json!({"room_us": image.room_time.as_micros() as u64, "objects": objects, "retained": retained})
        .to_string()
}

/// [`image_to_json`] back.
pub fn image_from_json(text: &str) -> Result<softsync_net::RoomImage, StoreError> {
    use softsync_net::{ClassId, KeptObject, NetId, ObjectState};
    let bad = |what: &str| StoreError::Row(format!("recording image: {what}"));
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| bad(&e.to_string()))?;
    let num = |v: &serde_json::Value, k: &str| v[k].as_u64().ok_or_else(|| bad(k));
    let floats = |v: &serde_json::Value, k: &str, n: usize| -> Result<Vec<f32>, StoreError> {
        let a = v[k].as_array().ok_or_else(|| bad(k))?;
        let f: Vec<f32> = a
            .iter()
            .filter_map(|x| x.as_f64())
            .map(|x| x as f32)
            .collect();
        if f.len() != n || f.iter().any(|x| !x.is_finite()) {
            return Err(bad(k));
        }
        Ok(f)
    };
    let mut objects = Vec::new();
    for o in v["objects"].as_array().ok_or_else(|| bad("objects"))? {
        let p = floats(o, "pos", 3)?;
        let q = floats(o, "rot", 4)?;
        let mut topology = Vec::new();
        for e in o["log"].as_array().ok_or_else(|| bad("log"))? {
            let (Some(k), Some(j)) = (e[0].as_str(), e[1].as_str()) else {
                return Err(bad("log entry"));
            };
            topology.push(decode_event(k, j)?);
        }
        objects.push(KeptObject {
            id: NetId(u32::try_from(num(o, "id")?).map_err(|_| bad("id"))?),
            class: ClassId(u16::try_from(num(o, "class")?).map_err(|_| bad("class"))?),
            state: ObjectState {
                pos: Vec3::new(p[0], p[1], p[2]),
                rot: glam::Quat::from_xyzw(q[0], q[1], q[2], q[3]),
                particles: decode_particles(&unhex(
                    o["particles"].as_str().ok_or_else(|| bad("particles"))?,
                )?)?,
            },
            topology,
        });
    }
    let mut retained = Vec::new();
    for m in v["retained"].as_array().ok_or_else(|| bad("retained"))? {
        retained.push(crate::rows::retained(
            m["kind"].as_i64().ok_or_else(|| bad("kind"))?,
            m["object"].as_i64().ok_or_else(|| bad("object"))?,
            m["origin"].as_u64().ok_or_else(|| bad("origin"))? as i64,
            m["seq"].as_i64().ok_or_else(|| bad("seq"))?,
            m["delivery"].as_str().ok_or_else(|| bad("delivery"))?,
            unhex(m["payload"].as_str().ok_or_else(|| bad("payload"))?)?,
        )?);
    }
    Ok(softsync_net::RoomImage {
        room_time: std::time::Duration::from_micros(num(&v, "room_us")?),
        objects,
        retained,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn every_event_kind_round_trips_and_an_unknown_kind_is_named() {
        let events = [
            TopologyEvent::Tear {
                from: [1, -2, 3],
                to: [4, 5, -6],
                blade: [0, 4000, 0],
            },
            TopologyEvent::Lift,
            TopologyEvent::Cut {
                point: [10, 20, 30],
                normal: [0, 32767, 0],
                keep: 2,
            },
            TopologyEvent::Resolution {
                level: 3,
                particles: 400,
            },
        ];
        for e in events {
            let (k, j) = encode_event(&e);
            assert_eq!(decode_event(k, &j).unwrap(), e);
        }
        let err = decode_event("graft", "{}").unwrap_err().to_string();
        assert!(err.contains("graft"), "{err}");
        assert!(decode_event("tear", "{\"from\":1}").is_err());
    }

    #[test]
    fn particles_round_trip_and_bad_blobs_are_refused() {
        let p = vec![Vec3::new(0.1, -2.0, 3.5), Vec3::splat(1e-7)];
        assert_eq!(decode_particles(&encode_particles(&p)).unwrap(), p);
        assert!(decode_particles(&[0; 13]).is_err());
        assert!(decode_particles(&encode_particles(&[Vec3::new(f32::NAN, 0.0, 0.0)])).is_err());
    }
}
