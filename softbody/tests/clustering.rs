//! Clustering and particle-map invariants (thesis 3.1, 3.2.1; tear paper Algorithm 3).
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

use glam::Vec3;
use proptest::prelude::*;
use softsync_softbody::{build_particle_map, ClusterMethod, Mesh, ParticleMap};

fn icosphere4() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let m = Mesh::icosphere(0.1, 4);
    let w = m.weld(1e-6);
    (w.positions, w.triangles)
}

/// The particle map of every vertex of `p` (all soft).
fn map_all(p: &[Vec3], t: &[[u32; 3]], method: ClusterMethod, affect_range_m: f32) -> ParticleMap {
    build_particle_map(p, t, &vec![true; p.len()], method, affect_range_m).unwrap()
}

fn methods() -> Vec<ClusterMethod> {
    vec![
        ClusterMethod::ClosestN {
            vertices_per_particle: 3,
        },
        ClusterMethod::Distance { radius_m: 0.01 },
        ClusterMethod::WeightedDistance {
            radius_m: 0.01,
            soft_radius_m: 0.016,
        },
        ClusterMethod::PoissonDisk {
            radius_m: 0.01,
            seed: 7,
        },
    ]
}

fn check_cover(map: &ParticleMap, n: usize) {
    assert_eq!(map.vertex_particles.rows(), n);
    for v in 0..n {
        let (ids, ws) = map.vertex_particles.row(v);
        if map.soft_vertex[v] {
            assert!(!ids.is_empty(), "soft vertex {v} has no particle");
            let s: f32 = ws.iter().sum();
            assert!((s - 1.0).abs() < 1e-4, "vertex {v} weights sum to {s}");
            assert!(
                ws.iter().all(|w| w.is_finite() && *w >= 0.0),
                "vertex {v} weights {ws:?}"
            );
        } else {
            assert!(ids.is_empty(), "rigid vertex {v} has particles");
        }
    }
}

#[test]
fn every_method_covers_every_vertex_with_unit_weights() {
    let (p, t) = icosphere4();
    for m in methods() {
        let map = map_all(&p, &t, m, 0.03);
        check_cover(&map, p.len());
        assert!(
            map.len() > 50 && map.len() < p.len(),
            "{}: {} particles",
            m.name(),
            map.len()
        );
    }
}

#[test]
fn closest_n_gives_n_vertices_per_particle_but_the_last() {
    let (p, t) = icosphere4();
    for n in [1u32, 3, 6, 10] {
        let map = map_all(
            &p,
            &t,
            ClusterMethod::ClosestN {
                vertices_per_particle: n,
            },
            0.0,
        );
        let rows = map.particle_vertices.rows();
        for i in 0..rows - 1 {
            assert_eq!(
                map.particle_vertices.row(i).0.len(),
                n as usize,
                "particle {i} with n={n}"
            );
        }
        assert!(map.particle_vertices.row(rows - 1).0.len() <= n as usize);
        assert_eq!(rows, p.len().div_ceil(n as usize));
    }
}

#[test]
fn distance_clusters_respect_their_radius() {
    let (p, t) = icosphere4();
    let r = 0.012;
    let map = map_all(&p, &t, ClusterMethod::Distance { radius_m: r }, 0.0);
    for i in 0..map.len() {
        let (ids, _) = map.particle_vertices.row(i);
        // All members lie within r of the particle's anchor vertex, so within 2r of each other.
        for &a in ids {
            for &b in ids {
                assert!(p[a as usize].distance(p[b as usize]) <= 2.0 * r + 1e-6);
            }
        }
    }
    // Hard clustering: each vertex belongs to exactly one particle.
    for v in 0..p.len() {
        assert_eq!(map.vertex_particles.row(v).0.len(), 1);
    }
}

#[test]
fn weighted_clusters_share_vertices_and_follow_figure_3_6() {
    let (p, t) = icosphere4();
    let map = map_all(
        &p,
        &t,
        ClusterMethod::WeightedDistance {
            radius_m: 0.01,
            soft_radius_m: 0.018,
        },
        0.0,
    );
    let shared = (0..p.len())
        .filter(|&v| map.vertex_particles.row(v).0.len() > 1)
        .count();
    assert!(shared > p.len() / 2, "only {shared} shared vertices");
    // Closer particles weigh more (inverse-distance weights).
    for v in 0..p.len() {
        let (ids, ws) = map.vertex_particles.row(v);
        for a in 0..ids.len() {
            for b in 0..ids.len() {
                let da = p[v].distance(map.rest_particles[ids[a] as usize]);
                let db = p[v].distance(map.rest_particles[ids[b] as usize]);
                if da + 1e-6 < db {
                    assert!(
                        ws[a] >= ws[b] - 1e-6,
                        "vertex {v}: nearer particle weighs less"
                    );
                }
            }
        }
    }
}

#[test]
fn poisson_anchors_keep_their_distance() {
    let (p, t) = icosphere4();
    let r = 0.015;
    let map = map_all(
        &p,
        &t,
        ClusterMethod::PoissonDisk {
            radius_m: r,
            seed: 3,
        },
        0.0,
    );
    for i in 0..map.len() {
        for j in 0..i {
            assert!(map.rest_particles[i].distance(map.rest_particles[j]) >= r - 1e-6);
        }
    }
}

#[test]
fn clustering_is_deterministic() {
    let (p, t) = icosphere4();
    for m in methods() {
        let a = map_all(&p, &t, m, 0.03);
        let b = map_all(&p, &t, m, 0.03);
        assert_eq!(a.rest_particles, b.rest_particles, "{}", m.name());
        assert_eq!(a.vertex_particles, b.vertex_particles, "{}", m.name());
        assert_eq!(a.neighbours, b.neighbours, "{}", m.name());
    }
}

#[test]
fn neighbour_weights_are_clamped_and_symmetric() {
    let (p, t) = icosphere4();
    let delta = 0.03;
    let map = map_all(&p, &t, ClusterMethod::Distance { radius_m: 0.01 }, delta);
    for i in 0..map.len() {
        let (ids, ws) = map.neighbours.row(i);
        for (&j, &w) in ids.iter().zip(ws) {
            assert_ne!(j as usize, i);
            let d = map.rest_particles[i].distance(map.rest_particles[j as usize]);
            assert!((w - (1.0 - d / delta)).abs() < 1e-5 && w > 0.0 && w <= 1.0);
            let (back, bw) = map.neighbours.row(j as usize);
            let k = back
                .iter()
                .position(|&x| x as usize == i)
                .expect("symmetric");
            assert!((bw[k] - w).abs() < 1e-6);
        }
    }
}

#[test]
fn restricted_region_excludes_outside_vertices() {
    let (p, t) = icosphere4();
    let soft: Vec<bool> = p.iter().map(|v| v.x > 0.03).collect();
    let map = build_particle_map(
        &p,
        &t,
        &soft,
        ClusterMethod::Distance { radius_m: 0.01 },
        0.03,
    )
    .unwrap();
    check_cover(&map, p.len());
    assert!(map.rest_particles.iter().all(|q| q.x > 0.02));
}

#[test]
fn bad_parameters_are_config_errors() {
    let (p, t) = icosphere4();
    let all = vec![true; p.len()];
    for m in [
        ClusterMethod::ClosestN {
            vertices_per_particle: 0,
        },
        ClusterMethod::Distance { radius_m: f32::NAN },
        ClusterMethod::Distance { radius_m: -1.0 },
        ClusterMethod::WeightedDistance {
            radius_m: 0.02,
            soft_radius_m: 0.01,
        },
        ClusterMethod::PoissonDisk {
            radius_m: 0.0,
            seed: 0,
        },
    ] {
        let e = build_particle_map(&p, &t, &all, m, 0.0).unwrap_err();
        assert!(
            e.to_string().contains(m.name()) || e.to_string().contains("radius"),
            "{e}"
        );
    }
    assert!(build_particle_map(
        &p,
        &t,
        &vec![false; p.len()],
        ClusterMethod::Distance { radius_m: 0.01 },
        0.0
    )
    .is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn random_clouds_are_covered(
        pts in prop::collection::vec((-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0), 3..300),
        n in 1u32..12, r in 0.05f32..0.6, method in 0usize..4, seed in any::<u64>())
    {
        let p: Vec<Vec3> = pts.iter().map(|&(x, y, z)| Vec3::new(x, y, z)).collect();
        let t: Vec<[u32; 3]> = (0..p.len() as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
        let m = match method {
            0 => ClusterMethod::ClosestN { vertices_per_particle: n },
            1 => ClusterMethod::Distance { radius_m: r },
            2 => ClusterMethod::WeightedDistance { radius_m: r, soft_radius_m: r * 1.5 },
            _ => ClusterMethod::PoissonDisk { radius_m: r, seed },
        };
        let map = map_all(&p, &t, m, r * 2.0);
        check_cover(&map, p.len());
        prop_assert!(map.particle_extent_m.iter().all(|e| e.is_finite() && *e > 0.0));
    }
}
