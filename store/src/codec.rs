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
