//! Rays with NaN or infinite origins, directions or ranges: every traversal (binary trees of
//! every builder, BVH4, BVH8, and packets over each, and the course's other structures)
//! returns what brute force returns and never panics; and the simulator's queries (closest
//! point, overlap, all hits) on such inputs. Such rays reach a library from simulators whose state has gone bad; they must
//! not crash the caller.

use dynbvh::bvh::{
    BuildParams, MeshBvh, MeshBvh4, MeshBvh8, PacketMode, WideBvh, brute_force_all_hits,
    brute_force_any, brute_force_closest, brute_force_closest_point, brute_force_overlap_box,
    brute_force_overlap_sphere,
};
use dynbvh::geom::{Aabb, Ray, TriMesh};
use glam::Vec3;

mod common;
use common::{builders, rays_around, same_closest, soup_with_nan_and_inf};

/// Rays around the unit cube with one component of the origin, the direction or the range
/// replaced by NaN, +inf or -inf, a few of each kind in one packet.
fn bad_rays() -> Vec<Ray> {
    let base = rays_around(Vec3::ZERO, 1.0, 40, 7);
    let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
    let mut rays = Vec::new();
    for (i, r) in base.iter().enumerate() {
        let v = bad[i % 3];
        let a = i % 3;
        let mut o = r.origin().to_array();
        let mut d = r.dir().to_array();
        match (i / 3) % 5 {
            0 => o[a] = v,
            1 => d[a] = v,
            2 => {
                o = [v; 3];
            }
            3 => {
                d = [v; 3];
            }
            _ => {
                rays.push(Ray::with_range(r.origin(), r.dir(), v, f32::INFINITY));
                rays.push(Ray::with_range(r.origin(), r.dir(), 0.0, v));
                continue;
            }
        }
        rays.push(Ray::new(Vec3::from(o), Vec3::from(d)));
    }
    // Also whole packets of one kind, so that no finite ray leads them.
    for v in bad {
        for r in base.iter().take(20) {
            rays.push(Ray::new(Vec3::new(v, r.origin().y, r.origin().z), r.dir()));
        }
    }
    rays
}

/// A point in the cube and the same with one or every coordinate NaN, +inf or -inf.
fn bad_points() -> Vec<Vec3> {
    let base = [0.2, -0.3, 0.1];
    let mut points = vec![Vec3::from(base)];
    for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for a in 0..3 {
            let mut p = base;
            p[a] = v;
            points.push(Vec3::from(p));
        }
        points.push(Vec3::splat(v));
    }
    points
}

/// A box in the cube and the same with one bound of one axis NaN, +inf or -inf.
fn bad_boxes() -> Vec<Aabb> {
    let mut boxes = vec![Aabb::new(Vec3::splat(-0.3), Vec3::splat(0.3))];
    for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        for a in 0..3 {
            let (mut lo, mut hi) = ([-0.3f32; 3], [0.3f32; 3]);
            lo[a] = v;
            boxes.push(Aabb::new(Vec3::from(lo), Vec3::splat(0.3)));
            hi[a] = v;
            boxes.push(Aabb::new(Vec3::splat(-0.3), Vec3::from(hi)));
        }
    }
    boxes
}

/// 500 small finite triangles in the unit cube.
fn cube_soup() -> TriMesh {
    let mut rng = common::Rng(3);
    let tris: Vec<[Vec3; 3]> = (0..500)
        .map(|_| {
            let p = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            [p, p + rng.unit_vector() * 0.3, p + rng.unit_vector() * 0.3]
        })
        .collect();
    TriMesh::from_soup(&tris)
}

fn check_wide<const K: usize>(
    mesh: &TriMesh,
    wide: &WideBvh<K>,
    rays: &[Ray],
    what: &str,
) -> Result<(), String> {
    for mode in [PacketMode::Always, PacketMode::Auto] {
        let mut hits = vec![None; rays.len()];
        wide.closest_hit_packet_mode(rays, &mut hits, mode);
        let mut any = vec![false; rays.len()];
        wide.any_hit_packet_mode(rays, &mut any, mode);
        for (i, r) in rays.iter().enumerate() {
            let want = brute_force_closest(mesh, r);
            let single = wide.closest_hit(r);
            if !same_closest(mesh, r, want, single) {
                return Err(format!(
                    "{what} single {r:?}: want {want:?}, got {single:?}"
                ));
            }
            if !same_closest(mesh, r, want, hits[i]) {
                return Err(format!(
                    "{what} {mode:?} packet {r:?}: want {want:?}, got {:?}",
                    hits[i]
                ));
            }
            let want_any = brute_force_any(mesh, r);
            if wide.any_hit(r) != want_any || any[i] != want_any {
                return Err(format!("{what} {mode:?} any hit {r:?}: want {want_any}"));
            }
        }
    }
    Ok(())
}

#[test]
fn non_finite_rays_match_brute_force_in_every_traversal() {
    let rays = bad_rays();
    let meshes = [
        ("cube soup", cube_soup()),
        ("NaN/inf soup", soup_with_nan_and_inf()),
    ];
    for (name, mesh) in &meshes {
        for params in builders() {
            let bin = MeshBvh::build(mesh, &params);
            for mode in [PacketMode::Always, PacketMode::Auto] {
                let mut hits = vec![None; rays.len()];
                bin.closest_hit_packet_mode(&rays, &mut hits, mode);
                let mut any = vec![false; rays.len()];
                bin.any_hit_packet_mode(&rays, &mut any, mode);
                for (i, r) in rays.iter().enumerate() {
                    let want = brute_force_closest(mesh, r);
                    let got = bin.closest_hit(r);
                    assert!(
                        same_closest(mesh, r, want, got),
                        "{name} {params:?} binary {r:?}: want {want:?}, got {got:?}"
                    );
                    assert!(
                        same_closest(mesh, r, want, hits[i]),
                        "{name} {params:?} {mode:?} binary packet {r:?}: want {want:?}, got {:?}",
                        hits[i]
                    );
                    let want_any = brute_force_any(mesh, r);
                    assert_eq!(bin.any_hit(r), want_any, "{name} {params:?} any {r:?}");
                    assert_eq!(
                        any[i], want_any,
                        "{name} {params:?} {mode:?} packet any {r:?}"
                    );
                }
            }
            let w8 = MeshBvh8::from_mesh_bvh(&bin);
            check_wide(mesh, &w8, &rays, &format!("{name} {params:?} BVH8")).unwrap();
            let w4 = MeshBvh4::from_mesh_bvh(&bin);
            check_wide(mesh, &w4, &rays, &format!("{name} {params:?} BVH4")).unwrap();
        }
    }
}

/// The kd-tree, BIH, grid and octree on the same rays.
#[test]
fn non_finite_rays_match_brute_force_in_the_other_structures() {
    use dynbvh::accel::AccelKind;
    let rays = bad_rays();
    for (name, mesh) in [
        ("cube soup", cube_soup()),
        ("NaN/inf soup", soup_with_nan_and_inf()),
    ] {
        for kind in AccelKind::ALL {
            let a = kind.build(&mesh);
            for r in &rays {
                let want = brute_force_closest(&mesh, r);
                let got = a.closest_hit(r);
                assert!(
                    same_closest(&mesh, r, want, got),
                    "{name} {kind:?} {r:?}: want {want:?}, got {got:?}"
                );
                assert_eq!(
                    a.any_hit(r),
                    brute_force_any(&mesh, r),
                    "{name} {kind:?} any {r:?}"
                );
            }
        }
    }
}

/// The simulator's queries on non-finite inputs: closest points from NaN and infinite points
/// and with NaN, infinite, zero and negative reaches; boxes and spheres holding NaN or infinite
/// values; all hits of the bad rays. The binary tree and the BVH8 answer as brute force does.
#[test]
fn non_finite_query_inputs_match_brute_force() {
    let (points, boxes) = (bad_points(), bad_boxes());
    let bits = |d: Option<f32>| d.map(f32::to_bits);
    let (mut got, mut hits) = (Vec::new(), Vec::new());
    for (name, mesh) in [
        ("cube soup", cube_soup()),
        ("NaN/inf soup", soup_with_nan_and_inf()),
    ] {
        let bin = MeshBvh::build(&mesh, &BuildParams::BINNED);
        let w8 = MeshBvh8::from_mesh_bvh(&bin);
        for &p in &points {
            for reach in [f32::INFINITY, 0.5, 0.0, -1.0, f32::NAN] {
                let want = bits(brute_force_closest_point(&mesh, p, reach).map(|h| h.distance));
                let b = bits(bin.closest_point(p, reach).map(|h| h.distance));
                assert_eq!(
                    b, want,
                    "{name}: binary closest point of {p} within {reach}"
                );
                let w = bits(w8.closest_point(p, reach).map(|h| h.distance));
                assert_eq!(w, want, "{name}: BVH8 closest point of {p} within {reach}");
            }
            for r in [0.3, 0.0, -1.0, f32::INFINITY, f32::NAN] {
                bin.overlap_sphere(p, r, &mut got);
                let want = brute_force_overlap_sphere(&mesh, p, r);
                assert_eq!(got, want, "{name}: sphere {p} {r}");
            }
        }
        for q in &boxes {
            bin.overlap_box(*q, &mut got);
            assert_eq!(got, brute_force_overlap_box(&mesh, *q), "{name}: box {q:?}");
        }
        for r in &bad_rays() {
            let want = brute_force_all_hits(&mesh, r);
            bin.all_hits(r, usize::MAX, &mut hits);
            assert_eq!(hits, want, "{name}: binary all hits of {r:?}");
            w8.all_hits(r, usize::MAX, &mut hits);
            assert_eq!(hits, want, "{name}: BVH8 all hits of {r:?}");
        }
    }
}

/// The engine's queries on the same non-finite inputs, over two instances (one moved): what
/// brute force finds over the world-space triangles of both.
#[test]
fn non_finite_query_inputs_through_the_engine() {
    use dynbvh::engine::{Engine, EngineConfig};
    use glam::Affine3A;
    let mesh = cube_soup();
    let shift = Vec3::new(0.5, 0.0, 0.0);
    let placed = |t: Vec3| TriMesh {
        positions: mesh.positions.iter().map(|&p| p + t).collect(),
        indices: mesh.indices.clone(),
    };
    let worlds = [placed(Vec3::ZERO), placed(shift)];
    let mut e = Engine::new(EngineConfig::default());
    let id = e.add_mesh(mesh.positions.clone(), mesh.indices.clone());
    let ids = [
        e.add_instance(id, Affine3A::IDENTITY),
        e.add_instance(id, Affine3A::from_translation(shift)),
    ];
    e.update();
    let nearest = |p: Vec3, reach: f32| {
        worlds
            .iter()
            .filter_map(|w| brute_force_closest_point(w, p, reach).map(|h| h.distance))
            .min_by(f32::total_cmp)
    };
    let union = |per: &dyn Fn(&TriMesh) -> Vec<u32>| {
        let mut all: Vec<_> = ids
            .iter()
            .zip(&worlds)
            .flat_map(|(&i, w)| per(w).into_iter().map(move |k| (i, k)))
            .collect();
        all.sort_unstable();
        all
    };
    let mut got = Vec::new();
    for p in bad_points() {
        for reach in [f32::INFINITY, 0.5, 0.0, -1.0, f32::NAN] {
            let have = e.closest_point(p, reach).map(|h| h.distance.to_bits());
            let want = nearest(p, reach).map(f32::to_bits);
            assert_eq!(have, want, "closest point of {p} within {reach}");
        }
        for r in [0.3, 0.0, -1.0, f32::INFINITY, f32::NAN] {
            e.overlap_sphere(p, r, &mut got);
            let want = union(&|w| brute_force_overlap_sphere(w, p, r));
            assert_eq!(got, want, "sphere {p} {r}");
        }
    }
    for q in bad_boxes() {
        e.overlap_box(q, &mut got);
        assert_eq!(got, union(&|w| brute_force_overlap_box(w, q)), "box {q:?}");
    }
    for r in &bad_rays() {
        let want: usize = worlds
            .iter()
            .map(|w| brute_force_all_hits(w, r).len())
            .sum();
        assert_eq!(e.count_hits(r) as usize, want, "hits of {r:?}");
    }
}

/// The engine (two levels, rays moved into each instance's space) with the same rays: single
/// rays and packets agree with each other, any hit agrees with closest hit, and nothing panics.
#[test]
fn non_finite_rays_through_the_engine() {
    use dynbvh::engine::{Engine, EngineConfig};
    use glam::Affine3A;
    let mesh = cube_soup();
    let mut e = Engine::new(EngineConfig::default());
    let id = e.add_mesh(mesh.positions.clone(), mesh.indices.clone());
    e.add_instance(id, Affine3A::IDENTITY);
    e.add_instance(id, Affine3A::from_translation(Vec3::new(0.5, 0.0, 0.0)));
    e.update();
    let rays = bad_rays();
    for mode in [PacketMode::Always, PacketMode::Auto] {
        let mut hits = vec![None; rays.len()];
        e.closest_hit_packet_mode(&rays, &mut hits, mode);
        let mut any = vec![false; rays.len()];
        e.any_hit_packet_mode(&rays, &mut any, mode);
        for (i, r) in rays.iter().enumerate() {
            let single = e.closest_hit(r);
            let key = |h: Option<dynbvh::engine::SceneHit>| h.map(|h| (h.t, h.prim, h.instance));
            assert_eq!(key(single), key(hits[i]), "{mode:?} {r:?}");
            assert_eq!(e.any_hit(r), single.is_some(), "{r:?}");
            assert_eq!(any[i], single.is_some(), "{mode:?} {r:?}");
            if let Some(h) = single {
                assert!(
                    h.t.is_finite() && h.t >= r.tmin && h.t < r.tmax,
                    "{r:?}: {h:?}"
                );
            }
        }
    }
}
