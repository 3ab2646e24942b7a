//! Every mesh loader on hostile bytes (issue 32): random bytes, and valid files (the bunny's
//! OBJ, an ASCII and a binary PLY, a glTF with its buffer inline) with bytes flipped,
//! overwritten, cut or repeated. A loader gives a mesh or an error, never a panic, and a mesh
//! it gives is one `validate` can judge. Seeded, so a failure names its input.
#![allow(clippy::unwrap_used, missing_docs)]

use std::path::PathBuf;

use softsync_softbody::Mesh;

/// SplitMix64: the inputs' source, seeded.
struct SeededRng(u64);

impl SeededRng {
    fn new(seed: u64) -> Self {
        SeededRng(seed)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

fn scratch() -> PathBuf {
    let d = std::env::temp_dir().join(format!("softsync-hostile-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn quad_gltf() -> Vec<u8> {
    // four vertices and two triangles in one base64 buffer
    let mut buf = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
        for c in p {
            buf.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        buf.extend_from_slice(&i.to_le_bytes());
    }
    let b64 = base64(&buf);
    format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{b64}"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":12}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},{{"bufferView":1,"componentType":5123,"count":6,"type":"SCALAR"}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],"nodes":[{{"mesh":0}}],"scenes":[{{"nodes":[0]}}],"scene":0}}"#,
        buf.len()
    )
    .into_bytes()
}

fn base64(b: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in b.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn mutate(rng: &mut SeededRng, valid: &[u8]) -> Vec<u8> {
    let mut d = valid.to_vec();
    let at = |rng: &mut SeededRng, d: &Vec<u8>| (rng.next_u64() as usize) % d.len().max(1);
    match rng.next_u64() % 5 {
        0 => {
            for _ in 0..1 + rng.next_u64() % 8 {
                let i = at(rng, &d);
                if let Some(b) = d.get_mut(i) {
                    *b ^= 1 << (rng.next_u64() % 8);
                }
            }
        }
        1 => {
            let i = at(rng, &d);
            d.truncate(i);
        }
        2 => {
            let i = at(rng, &d);
            let n = (rng.next_u64() % 64) as usize;
            for k in i..(i + n).min(d.len()) {
                d[k] = rng.next_u64() as u8;
            }
        }
        3 => {
            let (i, j) = (at(rng, &d), at(rng, &d));
            let a = i.min(j);
            let b = i.max(j).min(a + 4096);
            let piece = d[a..b].to_vec();
            d.splice(b..b, piece);
        }
        _ => {
            // digits for digits: counts and indices out of range
            let i = at(rng, &d);
            if let Some(b) = d.get_mut(i) {
                if b.is_ascii_digit() {
                    *b = b'9';
                }
            }
            d.extend_from_slice(b" 4294967295 99999999999 -1 nan inf\n");
        }
    }
    d
}

#[test]
fn every_mesh_loader_survives_hostile_bytes() {
    let dir = scratch();
    let bunny = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj")).unwrap();
    let ply = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n".to_vec();
    let mut ply_bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
        for c in p {
            ply_bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    ply_bin.push(4);
    for i in [0i32, 1, 2, 3] {
        ply_bin.extend_from_slice(&i.to_le_bytes());
    }
    let gltf = quad_gltf();
    let valid: [(&str, &[u8], usize); 4] = [
        ("obj", &bunny, 40),
        ("ply", &ply, 300),
        ("ply", &ply_bin, 300),
        ("gltf", &gltf, 300),
    ];
    // the valid ones load
    for (ext, bytes, _) in &valid {
        let p = dir.join(format!("valid.{ext}"));
        std::fs::write(&p, bytes).unwrap();
        let m = Mesh::load(&p).unwrap_or_else(|e| panic!("{ext}: {e}"));
        m.validate(&p).unwrap();
    }
    let mut rng = SeededRng::new(20261128);
    let (mut loaded, mut refused) = (0, 0);
    for (ext, bytes, n) in valid {
        for k in 0..n {
            let d = if k % 4 == 3 {
                (0..rng.next_u64() % 2048)
                    .map(|_| rng.next_u64() as u8)
                    .collect()
            } else {
                mutate(&mut rng, bytes)
            };
            let p = dir.join(format!("hostile-{k}.{ext}"));
            std::fs::write(&p, &d).unwrap();
            let got = std::panic::catch_unwind(|| Mesh::load(&p).map(|m| m.validate(&p)));
            match got {
                Err(_) => panic!("{ext} input {k} panicked the loader: {d:?}"),
                Ok(Ok(_)) => loaded += 1,
                Ok(Err(_)) => refused += 1,
            }
            // as a .glb too (the binary container's parser)
            if ext == "gltf" {
                let g = dir.join(format!("hostile-{k}.glb"));
                std::fs::write(&g, &d).unwrap();
                assert!(
                    std::panic::catch_unwind(|| Mesh::load(&g).map(|m| m.validate(&g))).is_ok(),
                    "glb input {k} panicked the loader"
                );
            }
        }
    }
    println!("hostile meshes: {loaded} loaded (or judged by validate), {refused} refused");
    assert!(
        refused > 100,
        "the mutations should break most files: {refused}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
