//! Mesh loading, validation, welding and baking; every bad-mesh case gives its error.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

use std::path::PathBuf;

use glam::{Quat, Vec3};
use softsync_softbody::{Mesh, Placement, SoftBodyError};

fn asset(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../assets")
        .join(name)
}

fn tmp(name: &str, content: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("softsync-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, content).unwrap();
    p
}

fn err_of(name: &str, content: &str) -> String {
    let p = tmp(name, content.as_bytes());
    let e = Mesh::load(&p).unwrap_err();
    let s = e.to_string();
    assert!(s.contains(name), "error does not name the file: {s}");
    s
}

#[test]
fn bunny_loads_with_1839_vertices_and_is_closed() {
    let m = Mesh::load(asset("bunny.obj")).unwrap();
    let w = m.weld(1e-7);
    assert_eq!(w.positions.len(), 1839);
    assert_eq!(w.triangles.len(), 3674);
    // Closed, outward: positive volume.
    assert!(w.volume(&w.positions) > 0.0);
}

#[test]
fn icosphere4_has_2562_vertices() {
    let m = Mesh::icosphere(0.1, 4);
    assert_eq!(m.positions.len(), 2562);
    assert_eq!(m.triangles.len(), 5120);
    let w = m.weld(1e-6);
    let v = w.volume(&w.positions);
    let exact = 4.0 / 3.0 * std::f32::consts::PI * 0.001;
    assert!((v / exact - 1.0).abs() < 0.01, "volume {v} vs {exact}");
}

#[test]
fn welding_keeps_seams_closed_and_hard_edges_hard() {
    let uv = Mesh::uv_sphere(1.0, 12, 24);
    let w = uv.weld(1e-5);
    // (rings-1) * segments + 2 poles unique positions.
    assert_eq!(w.positions.len(), 11 * 24 + 2);
    // The UV seam is smooth: both sides of the seam share a normal slot.
    assert!(w.normal_slots < uv.positions.len());
    let cube = Mesh::cuboid(Vec3::splat(0.5), 2);
    let wc = cube.weld(1e-5);
    assert_eq!(wc.positions.len(), 26);
    // Each corner position carries three normal slots (one per face): hard edges stay hard.
    assert_eq!(wc.normal_slots, cube.positions.len());
}

#[test]
fn baking_folds_the_placement_into_the_vertices() {
    let m = Mesh::cuboid(Vec3::splat(0.5), 1);
    let place = Placement {
        translation_m: Vec3::new(1.0, 2.0, 3.0),
        rotation: Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
        scale: Vec3::new(2.0, 1.0, 1.0),
    };
    let baked = m.clone().bake(&place);
    for (a, b) in m.positions.iter().zip(&baked.positions) {
        let expect = place.translation_m + place.rotation * (*a * place.scale);
        assert!(expect.distance(*b) < 1e-5);
    }
    // Mirroring keeps the volume positive (winding flipped back).
    let mirrored = m.bake(&Placement {
        scale: Vec3::new(-1.0, 1.0, 1.0),
        ..Default::default()
    });
    let w = mirrored.weld(1e-6);
    assert!(w.volume(&w.positions) > 0.0);
}

#[test]
fn obj_with_normals_negative_indices_and_quads() {
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf -4//1 -3//1 -2//1 -1//1\n";
    let m = Mesh::from_obj_str(text, "quad.obj").unwrap();
    assert_eq!(m.triangles.len(), 2);
    assert_eq!(m.normals.as_ref().unwrap()[0], Vec3::Z);
}

#[test]
fn gltf_with_data_uri_loads_with_node_transform() {
    // One triangle, positions as a base64 data URI, node translated by (0, 2, 0).
    let json = gltf_with(TRIANGLE_ACCESSOR, r#","translation":[0,2,0]"#);
    let p = tmp("tri.gltf", json.as_bytes());
    let m = Mesh::load(&p).unwrap();
    assert_eq!(m.positions.len(), 3);
    assert_eq!(m.positions[2], Vec3::new(0.0, 3.0, 0.0));
    // The same document with a point primitive is refused.
    let points = json.replace(
        r#""attributes":{"POSITION":0}"#,
        r#""attributes":{"POSITION":0},"mode":0"#,
    );
    let e = Mesh::load(tmp("points.gltf", points.as_bytes()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not triangles"), "{e}");
}

fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[test]
fn every_bad_mesh_gives_its_error() {
    let missing = Mesh::load("/nonexistent/softsync/none.obj").unwrap_err();
    assert!(matches!(missing, SoftBodyError::Io { .. }), "{missing}");
    assert!(missing.to_string().contains("none.obj"));

    assert!(err_of("empty.obj", "").contains("no vertices"));
    assert!(err_of("nofaces.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n").contains("no triangles"));
    assert!(err_of("nan.obj", "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").contains("non-finite"));
    assert!(err_of("word.obj", "v 0 zero 0\n").contains("line 1"));
    assert!(err_of("short.obj", "v 0 0\n").contains("needs 3 numbers"));
    assert!(err_of("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").contains("out of range"));
    assert!(err_of("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n").contains("out of range"));
    assert!(err_of("line.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n").contains("at least 3"));
    assert!(err_of("polyline.obj", "v 0 0 0\nv 1 0 0\nl 1 2\n").contains("not triangles"));
    assert!(err_of("repeat.obj", "v 0 0 0\nv 1 0 0\nf 1 2 2\n").contains("repeats a vertex"));
    let bin = tmp("binary.obj", &[0xff, 0xfe, 0x00, 0x01]);
    assert!(Mesh::load(&bin).unwrap_err().to_string().contains("UTF-8"));
    assert!(err_of("garbage.glb", "not a gltf at all").contains("invalid glTF"));
    assert!(err_of("garbage.gltf", "{\"asset\":").contains("invalid glTF"));
    let e = Mesh::load(tmp("mesh.stl", b"solid")).unwrap_err();
    assert!(matches!(e, SoftBodyError::UnsupportedFormat { .. }), "{e}");
}

#[test]
fn ply_ascii_and_binary_load_the_same_mesh() {
    let ascii = "ply\nformat ascii 1.0\ncomment a quad\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    let a = Mesh::load(tmp("quad.ply", ascii.as_bytes())).unwrap();
    assert_eq!(a.positions.len(), 4);
    assert_eq!(a.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for p in &a.positions {
        for c in p.to_array() {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    bin.push(4);
    for i in [0i32, 1, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let b = Mesh::load(tmp("quad_bin.ply", &bin)).unwrap();
    assert_eq!(a, b);
    // Hostile: a huge vertex count in a short file is refused before any allocation.
    let huge = String::from_utf8_lossy(&bin)
        .replace("element vertex 4", "element vertex 3999999")
        .into_bytes();
    let e = Mesh::load(tmp("huge.ply", &huge)).unwrap_err().to_string();
    assert!(e.contains("too short"), "{e}");
    // Out-of-range face index, truncated body, missing header end.
    assert!(err_of("range.ply", &ascii.replace("4 0 1 2 3", "3 0 1 9")).contains("out of range"));
    assert!(err_of("trunc.ply", &ascii.replace("4 0 1 2 3\n", "4 0 1")).contains("truncated"));
    assert!(err_of("nohdr.ply", "ply\nformat ascii 1.0\n").contains("end_header"));
}

#[test]
fn gltf_buffer_uris_cannot_escape_the_folder() {
    let json =
        r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":4,"uri":"../../etc/passwd"}]}"#;
    let e = Mesh::load(tmp("escape.gltf", json.as_bytes()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("leaves the file's folder"), "{e}");
}

/// The accessor of [`gltf_with`]'s triangle as a valid document declares it.
const TRIANGLE_ACCESSOR: &str =
    r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}"#;

/// A glTF document of one triangle whose positions are a base64 data URI, with `accessor` as
/// its only accessor (`STRIDE4` in it asks for a 4-byte stride) and `extra_nodes` appended to
/// its node.
fn gltf_with(accessor: &str, extra_nodes: &str) -> String {
    let pos: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = pos.iter().flat_map(|f| f.to_le_bytes()).collect();
    let b64 = base64(&bytes);
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"mesh":0{extra_nodes}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "accessors":[{accessor}],
        "bufferViews":[{{"buffer":0,"byteLength":36{stride}}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}]}}"#,
        stride = if accessor.contains("STRIDE4") {
            r#","byteStride":4"#
        } else {
            ""
        }
    )
    .replace("STRIDE4", "")
}

/// Regressions from review: the gltf reader panics on accessors it trusts; every one of these
/// must be a typed error naming the file.
#[test]
fn hostile_gltf_accessors_and_node_graphs_are_errors_not_panics() {
    let ok = TRIANGLE_ACCESSOR;
    assert!(Mesh::load(tmp("ok.gltf", gltf_with(ok, "").as_bytes())).is_ok());
    for (name, acc, nodes, expect) in [
        (
            "stride.gltf",
            r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}STRIDE4"#,
            "",
            "stride",
        ),
        (
            "count0.gltf",
            r#"{"bufferView":0,"componentType":5126,"count":0,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}"#,
            "",
            "no elements",
        ),
        (
            "vec2.gltf",
            r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC2","min":[0,0],"max":[1,1]}"#,
            "",
            "glTF",
        ),
        (
            "u8.gltf",
            r#"{"bufferView":0,"componentType":5121,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}"#,
            "",
            "glTF",
        ),
        (
            "long.gltf",
            r#"{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}"#,
            "",
            "past the end",
        ),
        (
            "cycle.gltf",
            ok,
            &format!(r#","children":[{}]"#, vec!["0"; 2000].join(",")),
            "cyclic",
        ),
    ] {
        let e = Mesh::load(tmp(name, gltf_with(acc, nodes).as_bytes()))
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains(name) && e.contains(expect), "{name}: {e}");
    }
}

#[test]
fn coordinates_beyond_100_km_are_refused() {
    let e = err_of("far.obj", "v 1e13 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    assert!(e.contains("beyond"), "{e}");
}

/// Regression from review: closest-N's kNN grew shells without bound between far-apart parts.
#[test]
fn clustering_a_mesh_with_a_far_away_part_stays_fast() {
    use softsync_softbody::{build_particle_map, ClusterMethod};
    let mut m = Mesh::icosphere(0.05, 3);
    let n = m.positions.len() as u32;
    m.positions.extend([
        Vec3::new(100.0, 0.0, 0.0),
        Vec3::new(100.01, 0.0, 0.0),
        Vec3::new(100.0, 0.01, 0.0),
    ]);
    m.triangles.push([n, n + 1, n + 2]);
    let w = m.weld(1e-6);
    for method in [
        ClusterMethod::ClosestN {
            vertices_per_particle: 8,
        },
        ClusterMethod::Distance { radius_m: 0.01 },
    ] {
        // Before the fix this took hours; it must now finish like any other mesh.
        let map = build_particle_map(
            &w.positions,
            &w.triangles,
            &vec![true; w.positions.len()],
            method,
            0.03,
        )
        .unwrap();
        assert!(map.len() > 10);
    }
}

#[test]
fn only_regular_files_of_bounded_size_are_read_and_the_kind_is_known_first() {
    let dir = std::env::temp_dir().join(format!("softsync-mesh-special-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // a device behind a mesh's name: /dev/zero never ends
    let zero = dir.join("zero.obj");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let e = Mesh::load(&zero).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    // a FIFO nobody writes: opening it would block for ever
    let fifo = dir.join("pipe.ply");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let e = Mesh::load(&fifo).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    // a folder
    let folder = dir.join("folder.glb");
    std::fs::create_dir_all(&folder).unwrap();
    let e = Mesh::load(&folder).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    // a file past the cap (sparse: nothing is written)
    let big = dir.join("big.obj");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(softsync_softbody::mesh::MAX_MESH_FILE_BYTES + 1)
        .unwrap();
    let e = Mesh::load(&big).unwrap_err().to_string();
    assert!(e.contains("more than the"), "{e}");
    // an unknown kind is refused before the file is opened: /dev/zero again
    let e = Mesh::load("/dev/zero").unwrap_err();
    assert!(matches!(e, SoftBodyError::UnsupportedFormat { .. }), "{e}");
    // a glTF whose buffer is a device
    std::os::unix::fs::symlink("/dev/zero", dir.join("buf.bin")).unwrap();
    let gltf = dir.join("dev.gltf");
    std::fs::write(
        &gltf,
        r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"buf.bin","byteLength":12}]}"#,
    )
    .unwrap();
    let e = Mesh::load(&gltf).unwrap_err().to_string();
    assert!(e.contains("not a regular file"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
