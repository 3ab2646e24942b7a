//! The dump: a JSON-lines record of the state a peer shows (`softsync join --dump FILE`), one
//! [`DumpLine`] per dump period and one at exit. The live benches and tests read it
//! ([`read_dump`]) to compare what every peer showed against the owners' own states.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use serde::{Deserialize, Serialize};
use softsync_net::Instant;

use crate::Peer;

/// One object in a dump line.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DumpObject {
    /// Network id.
    pub id: u32,
    /// Kind name.
    pub kind: String,
    /// Owner's peer id.
    pub owner: u64,
    /// Center position.
    pub pos: [f32; 3],
    /// Center rotation (x, y, z, w).
    pub rot: [f32; 4],
    /// Particles in world space (soft bodies).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub particles: Vec<[f32; 3]>,
    /// For objects we do not own: the time (s) the shown state stands for, on the clock of the
    /// peer it came from ([`DumpObject::src_from`]: the owner, or the host relaying it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub src: Option<f64>,
    /// The peer whose clock `src` is on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub src_from: Option<u64>,
    /// Soft bodies: entries of the object's topology log (tears, cuts) applied.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log: Option<u32>,
    /// Soft bodies: hash of the rest mesh's triangles and quantised vertices
    /// (`softbody::cut::topology_hash`, 10 µm): equal on two peers when they hold the
    /// identical torn or cut mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology: Option<String>,
    /// Who holds it (its owner's word): `[peer, hand, particle]` per hand, sorted
    /// (`particle` `u32::MAX`: the center or a rigid body).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub holders: Vec<[u64; 3]>,
}

/// One of this peer's hands holding a particle of a soft body, in a dump line.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DumpHand {
    /// 0 left, 1 right.
    pub hand: u8,
    /// The object it holds.
    pub object: u32,
    /// The particle it holds.
    pub particle: u32,
    /// A remote hand (the body is simulated by another peer).
    pub remote: bool,
    /// Where the hand is.
    pub pos: [f32; 3],
    /// Where this peer draws the held particle (for a remote hand: the replicated body plus
    /// the local correction).
    pub drawn: [f32; 3],
}

/// One dump line.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DumpLine {
    /// This peer's clock (s since it started; the session's clock).
    pub t: f64,
    /// The time (same clock) of the last simulation step: the time the states of the objects
    /// this peer owns stand for (the shown states of others carry their own `src`).
    pub state_t: f64,
    /// Wall clock, ms since the Unix epoch.
    pub wall_ms: u64,
    /// The room time (s; `Session::room_time`): the host's clock, which every peer of the
    /// room reads alike. None until this peer has heard it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub room_s: Option<f64>,
    /// This peer's id.
    pub peer: u64,
    /// The peer it follows as host.
    pub host: Option<u64>,
    /// Room term.
    pub term: u32,
    /// Members of the room as this peer knows them.
    pub members: Vec<u64>,
    /// Bytes of datagrams this peer's session has sent so far.
    pub up_bytes: u64,
    /// Bytes of datagrams it has received so far.
    pub down_bytes: u64,
    /// Objects.
    pub objects: Vec<DumpObject>,
    /// Our hands holding particles of soft bodies.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hands: Vec<DumpHand>,
}

/// Take a dump line of what `peer` shows at `now`; `wall_ms` is the wall clock (ms since the
/// Unix epoch: the peer reads no clock, its driver does).
pub fn snapshot(now: Instant, wall_ms: u64, peer: &mut Peer) -> DumpLine {
    let ids: Vec<_> = peer.objects().keys().copied().collect();
    let me = peer.me();
    let mut objects = Vec::with_capacity(ids.len());
    for id in ids {
        let Some(kind) = peer.objects().get(&id).map(|o| o.kind) else {
            continue;
        };
        let owner = peer.session().owner(id);
        let mine = owner == Some(me);
        let (state, src) = if mine {
            (peer.shown_state(now, id), None)
        } else {
            match peer.displayed_state(now, id) {
                Some(d) => (Some(d.state), Some(d.source_time.as_secs_f64())),
                None => (peer.session().latest_state(id), None),
            }
        };
        let src_from = src.and(peer.session().state_source(id)).map(|p| p.0);
        let Some(mut s) = state else {
            continue;
        };
        // A centre-only soft body (thesis §5.4.1) travels without its particles: this peer
        // shows its own body's, simulated around the centre it receives.
        if !mine && s.particles.is_empty() {
            if let Some(local) = peer.local_state(id).filter(|l| !l.particles.is_empty()) {
                s.particles = local.particles;
            }
        }
        objects.push(DumpObject {
            id: id.0,
            kind: peer.scene().name_of(kind).to_owned(),
            owner: owner.map_or(0, |p| p.0),
            pos: s.pos.to_array(),
            rot: s.rot.to_array(),
            particles: s.particles.iter().map(|p| p.to_array()).collect(),
            src,
            src_from,
            log: peer
                .objects()
                .get(&id)
                .filter(|o| matches!(o.body, crate::LocalBody::Soft(_)))
                .map(|o| o.topology),
            topology: peer.topology_hash(id).map(|h| format!("{h:016x}")),
            holders: peer
                .holders(id)
                .iter()
                .map(|h| [h.peer.0, u64::from(h.hand), u64::from(h.particle)])
                .collect(),
        });
    }
    let mut hands = Vec::new();
    for h in 0..2 {
        let (Some((id, softsync_interaction::Target::SoftParticle(_, particle))), Some(pos)) =
            (peer.held(h), peer.hand_position(h))
        else {
            continue;
        };
        let Some(drawn) = peer
            .local_state(id)
            .and_then(|s| s.particles.get(particle as usize).copied())
        else {
            continue;
        };
        hands.push(DumpHand {
            hand: h as u8,
            object: id.0,
            particle,
            remote: peer.holds_remotely(h),
            pos: pos.to_array(),
            drawn: drawn.to_array(),
        });
    }
    let session = peer.session();
    DumpLine {
        t: now.as_secs_f64(),
        state_t: peer.last_step_at().as_secs_f64(),
        wall_ms,
        room_s: session.room_time(now).map(|d| d.as_secs_f64()),
        peer: me.0,
        host: session.host_id().map(|h| h.0),
        term: session.term().0,
        members: session.members().keys().map(|p| p.0).collect(),
        up_bytes: session.stats().up.bytes,
        down_bytes: session.stats().down.bytes,
        objects,
        hands,
    }
}

/// A dump file, flushed after every line (a killed peer leaves whole lines).
pub struct Dump {
    out: BufWriter<File>,
}

impl Dump {
    /// Create (truncate) `path`.
    pub fn create(path: &Path) -> std::io::Result<Dump> {
        Ok(Dump {
            out: BufWriter::new(File::create(path)?),
        })
    }

    /// Append a line.
    pub fn write(&mut self, line: &DumpLine) -> std::io::Result<()> {
        serde_json::to_writer(&mut self.out, line)?;
        self.out.write_all(b"\n")?;
        self.out.flush()
    }
}

/// Read a dump file (lines that do not parse, such as a torn last line, are skipped).
pub fn read_dump(path: &Path) -> std::io::Result<Vec<DumpLine>> {
    let text = std::fs::read_to_string(path)?;
    Ok(text
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect())
}
