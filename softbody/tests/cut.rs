//! Plane cuts (tear paper Algorithm 2, capped): validity of every piece after cuts on each
//! test mesh, volume kept, holes and islands in the section, determinism, refusals.
#![allow(clippy::unwrap_used, missing_docs)]

use glam::Vec3;
use softsync_softbody::cut::{
    cut_mesh, cut_welded, topology_hash, CutError, CutPlane, MeshReport, Side,
};
use softsync_softbody::Mesh;

use softsync_benchkit::SplitMix64 as Rng;

fn bunny() -> Mesh {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj");
    let mut m = Mesh::load(path)
        .expect("assets/bunny.obj loads")
        .fit_size(0.2);
    m.recenter();
    m
}

/// A torus around the z axis: major radius `r`, minor `a`.
fn torus(r: f32, a: f32, rings: u32, sides: u32) -> Mesh {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    for i in 0..rings {
        let u = i as f32 / rings as f32 * std::f32::consts::TAU;
        for j in 0..sides {
            let v = j as f32 / sides as f32 * std::f32::consts::TAU;
            let c = Vec3::new(u.cos(), u.sin(), 0.0);
            let n = c * v.cos() + Vec3::Z * v.sin();
            positions.push(c * r + n * a);
            normals.push(n);
        }
    }
    let mut triangles = Vec::new();
    let id = |i: u32, j: u32| (i % rings) * sides + (j % sides);
    for i in 0..rings {
        for j in 0..sides {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    Mesh {
        positions,
        normals: Some(normals),
        triangles,
    }
}

fn assert_closed_pieces(pieces: &[&Mesh], what: &str) {
    for (i, m) in pieces.iter().enumerate() {
        let r = MeshReport::of(m);
        if !r.is_closed_solid() {
            let w = m.weld(1e-6);
            for (t, tri) in w.triangles.iter().enumerate() {
                let [a, b, c] = tri.map(|k| w.positions[k as usize]);
                let area = (b - a).cross(c - a).length();
                if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] || area == 0.0 {
                    eprintln!(
                        "degenerate tri {t} {tri:?} area {area} render {:?} normals {:?}",
                        m.triangles[t].map(|k| m.positions[k as usize]),
                        m.triangles[t].map(|k| m.normals.as_ref().unwrap()[k as usize])
                    );
                }
            }
        }
        assert!(
            r.is_closed_solid(),
            "{what}: piece {i} is not a closed solid: {r:?}"
        );
    }
}

#[test]
fn a_sphere_cut_in_half_gives_two_closed_halves_of_equal_volume() {
    let m = Mesh::icosphere(0.1, 3);
    let whole = MeshReport::of(&m).volume_m3;
    let cut = cut_mesh(
        &m,
        &CutPlane::new(Vec3::ZERO, Vec3::new(0.3, 1.0, 0.2)).unwrap(),
    )
    .unwrap();
    assert!(cut.capped);
    assert_eq!(cut.pieces.len(), 2);
    assert_eq!(cut.pieces[0].side, Side::Positive);
    assert_eq!(cut.pieces[1].side, Side::Negative);
    assert_closed_pieces(
        &cut.pieces.iter().map(|p| &p.mesh).collect::<Vec<_>>(),
        "sphere",
    );
    let (v0, v1) = (cut.pieces[0].volume_m3, cut.pieces[1].volume_m3);
    assert!(
        ((v0 + v1) / whole - 1.0).abs() < 1e-4,
        "{v0} + {v1} vs {whole}"
    );
    assert!((v0 / v1 - 1.0).abs() < 0.05, "halves {v0} vs {v1}");
    assert!(cut.pieces.iter().all(|p| p.cap_triangles > 0));
    // Every piece lies on its side (up to the plane's tiny shift).
    let plane = CutPlane::new(Vec3::ZERO, Vec3::new(0.3, 1.0, 0.2)).unwrap();
    for p in &cut.pieces {
        let sign = if p.side == Side::Positive { 1.0 } else { -1.0 };
        assert!(p
            .mesh
            .positions
            .iter()
            .all(|&q| sign * plane.distance(q) >= -1e-4));
    }
}

#[test]
fn a_torus_cut_flat_gets_annulus_caps_and_cut_upright_gets_four_discs() {
    let m = torus(0.1, 0.03, 48, 24);
    let whole = MeshReport::of(&m).volume_m3;
    // Through the equator: each half's cap is a ring with a hole.
    let flat = cut_mesh(&m, &CutPlane::new(Vec3::ZERO, Vec3::Z).unwrap()).unwrap();
    assert_eq!(flat.pieces.len(), 2);
    assert_closed_pieces(
        &flat.pieces.iter().map(|p| &p.mesh).collect::<Vec<_>>(),
        "torus flat",
    );
    let cap_area: f32 = annulus_cap_area(&flat.pieces[0].mesh);
    let ring = std::f32::consts::PI * ((0.13f32).powi(2) - (0.07f32).powi(2));
    assert!(
        (cap_area / ring - 1.0).abs() < 0.02,
        "cap {cap_area} vs ring {ring}"
    );
    // Through the axis: two C-shaped pieces, each with two disc caps.
    let upright = cut_mesh(&m, &CutPlane::new(Vec3::ZERO, Vec3::X).unwrap()).unwrap();
    assert_eq!(upright.pieces.len(), 2);
    assert_closed_pieces(
        &upright.pieces.iter().map(|p| &p.mesh).collect::<Vec<_>>(),
        "torus up",
    );
    let sum: f32 = upright.pieces.iter().map(|p| p.volume_m3).sum();
    assert!((sum / whole - 1.0).abs() < 1e-3);
}

/// Area of the triangles whose normal is −z (the positive piece's cap after a cut along +z).
fn annulus_cap_area(m: &Mesh) -> f32 {
    m.triangles
        .iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let n = (b - a).cross(c - a);
            (n.normalize_or_zero().z < -0.999).then_some(n.length() * 0.5)
        })
        .sum()
}

#[test]
fn a_cut_through_both_ears_separates_them() {
    // A plane high on the bunny cuts its ears (and maybe the head) off: several pieces above,
    // one below, all closed.
    let m = bunny();
    let report = MeshReport::of(&m);
    let (lo, hi) = softsync_softbody::mesh::bounds(&m.positions);
    // Find the tallest axis: the ears point along it in the asset.
    let up = if (hi - lo).y >= (hi - lo).z {
        Vec3::Y
    } else {
        Vec3::Z
    };
    let at = lo.dot(up) + 0.8 * (hi - lo).dot(up);
    let cut = cut_mesh(&m, &CutPlane::new(up * at, up).unwrap()).unwrap();
    assert_eq!(cut.capped, report.boundary_edges == 0);
    assert!(cut.pieces.len() >= 2, "{} pieces", cut.pieces.len());
    if cut.capped {
        assert_closed_pieces(
            &cut.pieces.iter().map(|p| &p.mesh).collect::<Vec<_>>(),
            "bunny",
        );
        let sum: f32 = cut.pieces.iter().map(|p| p.volume_m3).sum();
        assert!((sum / report.volume_m3 - 1.0).abs() < 0.01);
    }
}

#[test]
fn ten_random_cuts_keep_every_piece_closed_and_the_volume() {
    let meshes = [
        ("icosphere", Mesh::icosphere(0.1, 3)),
        ("cuboid", Mesh::cuboid(Vec3::new(0.1, 0.06, 0.04), 6)),
        ("torus", torus(0.1, 0.03, 32, 16)),
        ("bunny", bunny()),
    ];
    let mut rng = Rng(0x5eed);
    for (name, m) in meshes {
        let start = MeshReport::of(&m);
        if start.boundary_edges > 0 {
            // Only closed meshes can be capped; an open one is cut uncapped (tested above).
            eprintln!(
                "{name}: open ({} boundary edges), skipped",
                start.boundary_edges
            );
            continue;
        }
        let mut pieces = vec![m];
        let mut cuts = 0;
        while cuts < 10 {
            // Cut the largest piece by a random plane through a point near its centre.
            let (i, _) = pieces
                .iter()
                .enumerate()
                .map(|(i, p)| (i, p.triangles.len()))
                .max_by_key(|&(_, n)| n)
                .unwrap();
            let target = &pieces[i];
            let (lo, hi) = softsync_softbody::mesh::bounds(&target.positions);
            let at = lo
                + (hi - lo) * Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.6
                + (hi - lo) * 0.2;
            let plane = CutPlane::new(at, rng.direction()).unwrap();
            match cut_mesh(target, &plane) {
                Ok(cut) => {
                    assert!(cut.capped, "{name}: cut {cuts} not capped");
                    assert_eq!(cut.cap_conflicts, 0, "{name}: cut {cuts}");
                    let new: Vec<Mesh> = cut.pieces.into_iter().map(|p| p.mesh).collect();
                    assert_closed_pieces(
                        &new.iter().collect::<Vec<_>>(),
                        &format!(
                            "{name} cut {cuts} {plane:?} of {:?}",
                            MeshReport::of(target)
                        ),
                    );
                    pieces.swap_remove(i);
                    pieces.extend(new);
                    cuts += 1;
                }
                Err(CutError::Misses) => continue,
                Err(e) => panic!("{name}: cut {cuts}: {e}"),
            }
        }
        let sum: f32 = pieces.iter().map(|p| MeshReport::of(p).volume_m3).sum();
        assert!(
            (sum / start.volume_m3 - 1.0).abs() < 0.01,
            "{name}: volume {sum} vs {} after 10 cuts",
            start.volume_m3
        );
        assert!(pieces.len() >= 11, "{name}: {} pieces", pieces.len());
    }
}

#[test]
fn the_same_cut_gives_bit_identical_pieces() {
    let m = bunny();
    let plane = CutPlane::through(
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(0.05, 0.1, 0.02),
        Vec3::new(-0.03, 0.02, 0.1),
    )
    .unwrap();
    let a = cut_mesh(&m, &plane).unwrap();
    let b = cut_mesh(&m.clone(), &plane).unwrap();
    assert_eq!(a.pieces.len(), b.pieces.len());
    for (p, q) in a.pieces.iter().zip(&b.pieces) {
        assert_eq!(p.mesh, q.mesh);
        assert_eq!(topology_hash(&p.mesh, 1e-5), topology_hash(&q.mesh, 1e-5));
    }
}

#[test]
fn a_cut_of_the_welded_form_is_the_cut_and_a_welded_form_that_does_not_match_is_refused() {
    let m = bunny();
    let w = m.weld(1e-6);
    let plane = CutPlane::new(Vec3::new(0.0, 0.03, 0.0), Vec3::new(0.2, 1.0, 0.1)).unwrap();
    let a = cut_mesh(&m, &plane).unwrap();
    let b = cut_welded(&m, &w.positions, &w.triangles, &plane).unwrap();
    assert_eq!(a.pieces.len(), b.pieces.len());
    assert_eq!(a.intersection_points, b.intersection_points);
    for (p, q) in a.pieces.iter().zip(&b.pieces) {
        assert_eq!(p.mesh, q.mesh);
    }
    // A vertex moved, a triangle missing, an index out of range, a NaN: refused.
    let mut moved = w.positions.clone();
    moved[w.triangles[7][1] as usize].x += 1e-3;
    let short = &w.triangles[1..];
    let mut wild = w.triangles.clone();
    wild[3][2] = u32::MAX;
    let mut nan = w.positions.clone();
    nan[0] = Vec3::NAN;
    for (pos, tris) in [
        (&moved[..], &w.triangles[..]),
        (&w.positions[..], short),
        (&w.positions[..], &wild[..]),
        (&nan[..], &w.triangles[..]),
    ] {
        assert!(matches!(
            cut_welded(&m, pos, tris, &plane),
            Err(CutError::Mesh(_))
        ));
    }
}

#[test]
fn refused_cuts_say_why() {
    let m = Mesh::icosphere(0.1, 2);
    assert_eq!(
        cut_mesh(
            &m,
            &CutPlane::new(Vec3::new(0.0, 0.5, 0.0), Vec3::Y).unwrap()
        )
        .unwrap_err(),
        CutError::Misses
    );
    let nan = CutPlane {
        normal: Vec3::new(f32::NAN, 0.0, 0.0),
        offset_m: 0.0,
    };
    assert!(matches!(cut_mesh(&m, &nan), Err(CutError::NonFinite(_))));
    let mut broken = m.clone();
    broken.triangles[0][1] = 1_000_000;
    assert!(matches!(
        cut_mesh(&broken, &CutPlane::new(Vec3::ZERO, Vec3::Y).unwrap()),
        Err(CutError::Mesh(_))
    ));
}

#[test]
fn an_open_mesh_is_cut_but_not_capped() {
    let mut m = Mesh::icosphere(0.1, 2);
    m.triangles.remove(0);
    let cut = cut_mesh(&m, &CutPlane::new(Vec3::ZERO, Vec3::Y).unwrap()).unwrap();
    assert!(!cut.capped);
    assert!(cut.pieces.iter().all(|p| p.cap_triangles == 0));
    for p in &cut.pieces {
        assert!(MeshReport::of(&p.mesh).is_sound());
    }
}

#[test]
fn a_plane_through_vertices_is_nudged_off_them() {
    // The cuboid has whole rows of vertices on z = 0: the plane moves a hair so no edge is
    // cut at its end (which would leave zero-area triangles).
    let m = Mesh::cuboid(Vec3::splat(0.05), 4);
    let cut = cut_mesh(&m, &CutPlane::new(Vec3::ZERO, Vec3::Z).unwrap()).unwrap();
    assert!(cut.plane_shift_m != 0.0 && cut.plane_shift_m.abs() < 3e-4);
    assert_closed_pieces(
        &cut.pieces.iter().map(|p| &p.mesh).collect::<Vec<_>>(),
        "cuboid",
    );
}

// ---- tears ----

use softsync_softbody::cut::{TearMesh, TearSegment};

/// A stroke of `n` segments over the surface of `m`: starts at a random vertex, moves along a
/// random tangent, the blade standing along the outward normal, the tip `depth` inside.
fn stroke(m: &Mesh, rng: &mut Rng, n: usize, step: f32, depth: f32) -> Vec<TearSegment> {
    let v = (rng.next_u64() % m.positions.len() as u64) as usize;
    let normal = m
        .normals
        .as_ref()
        .map(|ns| ns[v])
        .unwrap_or(m.positions[v].normalize());
    let mut dir = rng.direction();
    dir = (dir - normal * dir.dot(normal)).normalize_or_zero();
    if dir == Vec3::ZERO {
        dir = normal.any_orthonormal_vector();
    }
    let mut at = m.positions[v] - normal * depth;
    let mut out = Vec::new();
    for _ in 0..n {
        // Wander a little.
        let turn = (rng.direction() - normal * rng.direction().dot(normal)) * 0.3;
        dir = (dir + turn).normalize_or_zero();
        if dir == Vec3::ZERO {
            dir = normal.any_orthonormal_vector();
        }
        let next = at + dir * step;
        out.push(TearSegment {
            from: at,
            to: next,
            blade: normal * (depth + 0.02),
        });
        at = next;
    }
    out
}

fn assert_sound_torn(m: &Mesh, what: &str) {
    let r = MeshReport::of(m);
    if !r.is_sound() || r.non_manifold_edges > 0 {
        let w = m.weld(1e-6);
        for tri in &w.triangles {
            let [a, b, c] = tri.map(|k| w.positions[k as usize]);
            if tri[0] == tri[1]
                || tri[1] == tri[2]
                || tri[0] == tri[2]
                || (b - a).cross(c - a) == Vec3::ZERO
            {
                eprintln!("degenerate {tri:?} {a} {b} {c}");
            }
        }
        let mut uses: std::collections::HashMap<(u32, u32), Vec<usize>> = Default::default();
        for (t, tri) in w.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                uses.entry((a.min(b), a.max(b))).or_default().push(t);
            }
        }
        for (e, ts) in uses.iter().filter(|(_, ts)| ts.len() > 2) {
            eprintln!(
                "edge {e:?} {} {} used by",
                w.positions[e.0 as usize], w.positions[e.1 as usize]
            );
            for &t in ts {
                eprintln!(
                    "   {:?} {:?}",
                    w.triangles[t],
                    w.triangles[t].map(|k| w.positions[k as usize])
                );
            }
        }
    }
    assert!(r.is_sound(), "{what}: {r:?}");
    assert_eq!(r.non_manifold_edges, 0, "{what}: {r:?}");
}

#[test]
fn a_tear_across_a_sphere_opens_a_slot_and_keeps_the_mesh_sound() {
    let m = Mesh::icosphere(0.1, 4);
    let mut t = TearMesh::new(&m, 0.004).unwrap();
    let before = t.face_count();
    // Across the top, the blade standing up, tip 1 cm deep.
    let segs = [
        (Vec3::new(-0.04, 0.09, 0.0), Vec3::new(-0.01, 0.09, 0.005)),
        (Vec3::new(-0.01, 0.09, 0.005), Vec3::new(0.02, 0.09, 0.0)),
        (Vec3::new(0.02, 0.09, 0.0), Vec3::new(0.04, 0.09, -0.01)),
    ];
    let mut added = 0;
    for (from, to) in segs {
        let s = t
            .tear(&TearSegment {
                from,
                to,
                blade: Vec3::Y * 0.05,
            })
            .unwrap();
        assert!(s.faces_clipped > 0);
        assert!(
            s.faces_searched < before / 2,
            "sections searched {}",
            s.faces_searched
        );
        added += s.faces_added;
    }
    assert!(added > 0);
    let torn = t.to_mesh();
    assert_sound_torn(&torn, "sphere");
    let r = MeshReport::of(&torn);
    assert!(r.boundary_edges > 20, "a slot has a rim: {r:?}");
    // Nothing is left inside the slot: no vertex within the tear's half width of the line
    // (tip region), away from the ends.
    for p in &torn.positions {
        // The middle segment runs from (-0.01, 0.005) to (0.02, 0.0) in (x, z).
        if p.y > 0.0905 && p.x > -0.005 && p.x < 0.015 {
            let z_line = 0.005 - (p.x + 0.01) / 0.03 * 0.005;
            let across = (p.z - z_line).abs() * (1.0f32 / (1.0 + 1.0 / 36.0)).sqrt();
            assert!(
                across >= 0.0019,
                "vertex {p} inside the slot ({across} from its middle)"
            );
        }
    }
}

#[test]
fn a_small_tear_inside_one_face_cuts_a_hole_in_it() {
    // Two big triangles on each side of the box: the tear box lies inside one of them, clear
    // of both diagonals (z = ±x; at z = 0.012 a corner of the box sat on one, and the box
    // moved off it, across the diagonal).
    let m = Mesh::cuboid(Vec3::splat(0.05), 1);
    let faces = m.triangles.len();
    let mut t = TearMesh::new(&m, 0.004).unwrap();
    let s = t
        .tear(&TearSegment {
            from: Vec3::new(-0.01, 0.05 - 0.003, 0.02),
            to: Vec3::new(0.01, 0.05 - 0.003, 0.02),
            blade: Vec3::Y * 0.02,
        })
        .unwrap();
    assert!(s.faces_clipped >= 1);
    let torn = t.to_mesh();
    assert!(torn.triangles.len() > faces);
    assert_sound_torn(&torn, "cuboid hole");
    let r = MeshReport::of(&torn);
    assert_eq!(r.boundary_edges, 4, "a rectangular hole: {r:?}");
}

#[test]
fn a_hundred_random_tears_keep_every_mesh_sound() {
    let meshes = [
        ("icosphere", Mesh::icosphere(0.1, 3)),
        ("cuboid", Mesh::cuboid(Vec3::new(0.1, 0.06, 0.04), 6)),
        ("bunny", bunny()),
    ];
    let mut rng = Rng(0x7ea5);
    for (name, m) in meshes {
        let mut t = TearMesh::new(&m, 0.003).unwrap();
        let mut done = 0;
        while done < 100 {
            for seg in stroke(&m, &mut rng, 5, 0.01, 0.005) {
                if done == 100 {
                    break;
                }
                t.tear(&seg).unwrap();
                done += 1;
            }
            t.lift();
        }
        assert_sound_torn(&t.to_mesh(), name);
    }
}

/// Regression, the soak's seed 30: the torn cuboid ended with a triangle 0.4 µm wide (one
/// degenerate triangle and one non-manifold edge once welded). After eight tries at moving the
/// box's planes clear of every vertex the clip went ahead anyway, and cut an edge 0.4 µm from
/// its end.
#[test]
fn seed_30_cuboid_tears_leave_no_sliver() {
    let icosphere = Mesh::icosphere(0.1, 3);
    let m = Mesh::cuboid(Vec3::new(0.1, 0.06, 0.04), 6);
    let mut rng = Rng(30);
    // The soak draws the icosphere's strokes first.
    for _ in 0..20 {
        stroke(&icosphere, &mut rng, 5, 0.01, 0.005);
    }
    let mut t = TearMesh::new(&m, 0.003).unwrap();
    for _ in 0..20 {
        for seg in stroke(&m, &mut rng, 5, 0.01, 0.005) {
            t.tear(&seg).unwrap();
        }
        t.lift();
    }
    assert_sound_torn(&t.to_mesh(), "seed 30 cuboid");
}

#[test]
fn the_same_tears_give_the_same_mesh() {
    let m = bunny();
    let mut rng = Rng(42);
    let segs = stroke(&m, &mut rng, 20, 0.008, 0.004);
    let run = || {
        let mut t = TearMesh::new(&m, 0.002).unwrap();
        for s in &segs {
            t.tear(s).unwrap();
        }
        t.to_mesh()
    };
    let (a, b) = (run(), run());
    assert_eq!(a, b);
    assert_eq!(topology_hash(&a, 1e-5), topology_hash(&b, 1e-5));
    assert_ne!(topology_hash(&a, 1e-5), topology_hash(&m, 1e-5));
}

#[test]
fn hostile_tears_are_refused_and_change_nothing() {
    let m = Mesh::icosphere(0.1, 2);
    assert!(TearMesh::new(&m, f32::NAN).is_err());
    assert!(TearMesh::new(&m, 0.0).is_err());
    assert!(TearMesh::new(&m, 1.0).is_err());
    let mut t = TearMesh::new(&m, 0.003).unwrap();
    let h0 = topology_hash(&t.to_mesh(), 1e-5);
    let bad = [
        TearSegment {
            from: Vec3::NAN,
            to: Vec3::ZERO,
            blade: Vec3::Y,
        },
        TearSegment {
            from: Vec3::ZERO,
            to: Vec3::ZERO,
            blade: Vec3::Y * 0.1,
        },
        TearSegment {
            from: Vec3::ZERO,
            to: Vec3::X * 100.0,
            blade: Vec3::Y * 0.1,
        },
        TearSegment {
            from: Vec3::ZERO,
            to: Vec3::X * 0.01,
            blade: Vec3::X * 0.1,
        },
        TearSegment {
            from: Vec3::ZERO,
            to: Vec3::X * 0.01,
            blade: Vec3::new(0.0, f32::INFINITY, 0.0),
        },
    ];
    for s in &bad {
        assert!(t.tear(s).is_err(), "{s:?}");
    }
    // Far outside the object: accepted, changes nothing.
    let s = t
        .tear(&TearSegment {
            from: Vec3::splat(0.5),
            to: Vec3::splat(0.51),
            blade: Vec3::Y * 0.05,
        })
        .unwrap();
    assert_eq!(s.faces_clipped, 0);
    assert_eq!(topology_hash(&t.to_mesh(), 1e-5), h0);
}

/// The random tears and cuts above over 40 seeds (20 strokes of 5 segments and 10 cuts per
/// mesh each): `cargo test --release -p softsync-softbody --test cut -- --ignored`. It found
/// seed 30's torn cuboid with a triangle the weld collapses: the box was used although its
/// planes were still within the clearance of a vertex (see `TearMesh::clear_box`).
#[test]
#[ignore = "a soak: 40 seeds, ~2 s in release"]
fn stress_many_seeds() {
    let meshes = [
        ("icosphere", Mesh::icosphere(0.1, 3)),
        ("cuboid", Mesh::cuboid(Vec3::new(0.1, 0.06, 0.04), 6)),
        ("bunny", bunny()),
    ];
    let mut bad = 0;
    for seed in 0..40u64 {
        let mut rng = Rng(seed);
        for (name, m) in &meshes {
            let mut t = TearMesh::new(m, 0.003).unwrap();
            for _ in 0..20 {
                for seg in stroke(m, &mut rng, 5, 0.01, 0.005) {
                    t.tear(&seg).unwrap();
                }
                t.lift();
            }
            let r = MeshReport::of(&t.to_mesh());
            if !r.is_sound() || r.non_manifold_edges > 0 {
                bad += 1;
                eprintln!("seed {seed} {name}: {r:?}");
            }
        }
        // cuts
        for (name, m) in &meshes {
            let mut pieces = vec![m.clone()];
            for _ in 0..10 {
                let i = (0..pieces.len())
                    .max_by_key(|&i| pieces[i].triangles.len())
                    .unwrap();
                let (lo, hi) = softsync_softbody::mesh::bounds(&pieces[i].positions);
                let at = lo
                    + (hi - lo)
                        * (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.6 + Vec3::splat(0.2));
                if let Ok(c) = cut_mesh(&pieces[i], &CutPlane::new(at, rng.direction()).unwrap()) {
                    pieces.swap_remove(i);
                    for p in c.pieces {
                        let r = MeshReport::of(&p.mesh);
                        if !r.is_closed_solid() {
                            bad += 1;
                            eprintln!("seed {seed} cut {name}: {r:?}");
                        }
                        pieces.push(p.mesh);
                    }
                }
            }
        }
    }
    assert_eq!(bad, 0);
}
