//! PLY (ASCII and binary, little or big endian) triangle meshes: `vertex` x/y/z (optional
//! nx/ny/nz) and `face` index lists; polygons are fan-triangulated, other elements skipped.

use std::path::Path;

use glam::Vec3;

use super::{Mesh, MAX_MESH_ELEMENTS};
use crate::SoftBodyError;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Le,
    Be,
}

/// Reads values one at a time from the body, whatever the format.
struct Reader<'a> {
    format: Format,
    bytes: &'a [u8],
    pos: usize,
    tokens: std::str::SplitAsciiWhitespace<'a>,
}

impl Reader<'_> {
    fn read(&mut self, t: Scalar) -> Option<f64> {
        if self.format == Format::Ascii {
            return self.tokens.next()?.parse::<f64>().ok();
        }
        let n = t.size();
        let b = self.bytes.get(self.pos..self.pos + n)?;
        self.pos += n;
        let mut a = [0u8; 8];
        a[..n].copy_from_slice(b);
        if self.format == Format::Be {
            a[..n].reverse();
        }
        Some(match t {
            Scalar::I8 => a[0] as i8 as f64,
            Scalar::U8 => a[0] as f64,
            Scalar::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(a),
        })
    }
}

/// Parses a PLY file's bytes; `source` names the file in errors.
pub(super) fn parse_ply(bytes: &[u8], source: &Path) -> Result<Mesh, SoftBodyError> {
    let bad = |what: String| SoftBodyError::malformed(source, what);
    let header_end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or_else(|| bad("PLY header has no `end_header`".into()))?;
    let mut body_start = header_end + 10;
    while body_start < bytes.len() && bytes[body_start] != b'\n' {
        body_start += 1;
    }
    body_start = (body_start + 1).min(bytes.len());
    let header = std::str::from_utf8(&bytes[..header_end])
        .map_err(|_| bad("PLY header is not text".into()))?;
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err(bad("not a PLY file (first line is not `ply`)".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (n, line) in lines.enumerate() {
        let line_no = n + 2;
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, _] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Le,
                    "binary_big_endian" => Format::Be,
                    other => {
                        return Err(bad(format!("line {line_no}: unknown PLY format `{other}`")))
                    }
                })
            }
            ["element", name, count] => {
                let count: usize = count
                    .parse()
                    .map_err(|_| bad(format!("line {line_no}: bad element count `{count}`")))?;
                if count > MAX_MESH_ELEMENTS {
                    return Err(bad(format!(
                        "line {line_no}: {count} {name} elements is more than {MAX_MESH_ELEMENTS}"
                    )));
                }
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", ct, it, name] => {
                let (ct, it) = (Scalar::parse(ct), Scalar::parse(it));
                let (Some(ct), Some(it), Some(e)) = (ct, it, elements.last_mut()) else {
                    return Err(bad(format!("line {line_no}: bad list property")));
                };
                e.props.push(Property::List(name.to_string(), ct, it));
            }
            ["property", t, name] => {
                let (Some(t), Some(e)) = (Scalar::parse(t), elements.last_mut()) else {
                    return Err(bad(format!("line {line_no}: bad property `{line}`")));
                };
                e.props.push(Property::Scalar(name.to_string(), t));
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            _ => {
                return Err(bad(format!(
                    "line {line_no}: unexpected header line `{line}`"
                )))
            }
        }
    }
    let format = format.ok_or_else(|| bad("PLY header has no `format` line".into()))?;
    let body = &bytes[body_start..];
    let text = if format == Format::Ascii {
        std::str::from_utf8(body).map_err(|_| bad("ASCII PLY body is not text".into()))?
    } else {
        ""
    };
    let mut r = Reader {
        format,
        bytes: body,
        pos: 0,
        tokens: text.split_ascii_whitespace(),
    };
    let mut positions: Vec<Vec3> = Vec::new();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    for e in &elements {
        // A binary element of fixed size must fit in what is left before anything is allocated.
        if format != Format::Ascii && e.props.iter().all(|p| matches!(p, Property::Scalar(..))) {
            let stride: usize = e
                .props
                .iter()
                .map(|p| {
                    if let Property::Scalar(_, t) = p {
                        t.size()
                    } else {
                        0
                    }
                })
                .sum();
            if stride.saturating_mul(e.count) > body.len().saturating_sub(r.pos) {
                return Err(bad(format!(
                    "element `{}` declares {} entries but the file is too short",
                    e.name, e.count
                )));
            }
        }
        let is_vertex = e.name == "vertex";
        let is_face = e.name == "face";
        if is_vertex {
            positions.reserve(e.count.min(body.len()));
        }
        for i in 0..e.count {
            let mut xyz = [f64::NAN; 3];
            let mut nxyz = [f64::NAN; 3];
            for p in &e.props {
                match p {
                    Property::Scalar(name, t) => {
                        let v = r.read(*t).ok_or_else(|| {
                            bad(format!("{} {i}: truncated or not a number", e.name))
                        })?;
                        if is_vertex {
                            match name.as_str() {
                                "x" => xyz[0] = v,
                                "y" => xyz[1] = v,
                                "z" => xyz[2] = v,
                                "nx" => nxyz[0] = v,
                                "ny" => nxyz[1] = v,
                                "nz" => nxyz[2] = v,
                                _ => {}
                            }
                        }
                    }
                    Property::List(name, ct, it) => {
                        let n = r
                            .read(*ct)
                            .ok_or_else(|| bad(format!("{} {i}: truncated list", e.name)))?;
                        if !(0.0..=1024.0).contains(&n) {
                            return Err(bad(format!("{} {i}: list of {n} entries", e.name)));
                        }
                        let mut idx = Vec::with_capacity(n as usize);
                        for _ in 0..n as usize {
                            let v = r.read(*it).ok_or_else(|| {
                                bad(format!("{} {i}: truncated index list", e.name))
                            })?;
                            idx.push(v);
                        }
                        if is_face && (name == "vertex_indices" || name == "vertex_index") {
                            if idx.len() < 3 {
                                return Err(bad(format!(
                                    "face {i} has {} vertices; a face needs at least 3",
                                    idx.len()
                                )));
                            }
                            let nv = positions.len() as f64;
                            if let Some(b) = idx
                                .iter()
                                .find(|&&v| v < 0.0 || v >= nv || v.fract() != 0.0)
                            {
                                return Err(bad(format!(
                                    "face {i}: vertex index {b} out of range (have {nv})"
                                )));
                            }
                            for k in 1..idx.len() - 1 {
                                triangles.push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
                            }
                            if triangles.len() > MAX_MESH_ELEMENTS {
                                return Err(bad("too many triangles".into()));
                            }
                        }
                    }
                }
            }
            if is_vertex {
                if xyz.iter().any(|v| v.is_nan()) {
                    return Err(bad(format!("vertex {i} lacks x, y or z")));
                }
                positions.push(Vec3::new(xyz[0] as f32, xyz[1] as f32, xyz[2] as f32));
                if nxyz.iter().all(|v| !v.is_nan()) {
                    normals.push(
                        Vec3::new(nxyz[0] as f32, nxyz[1] as f32, nxyz[2] as f32)
                            .normalize_or_zero(),
                    );
                }
            }
        }
    }
    if !positions.is_empty() && triangles.is_empty() {
        return Err(bad(format!(
            "mesh has {} vertices but no triangles",
            positions.len()
        )));
    }
    let normals = (normals.len() == positions.len() && !normals.is_empty()).then_some(normals);
    let mesh = Mesh {
        positions,
        normals,
        triangles,
    };
    mesh.validate(source)?;
    Ok(mesh)
}
