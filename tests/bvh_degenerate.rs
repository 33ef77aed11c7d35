//! Inputs where builders and traversal tend to fail: empty and single-triangle meshes,
//! coinciding centroids, identical and zero-area triangles, NaN and infinite vertices, extreme
//! scales, and inputs that would make an SAH tree arbitrarily deep. Every builder must produce a
//! valid tree that answers rays exactly as brute force does.

mod common;

use common::{Rng, check_ray};
use dynbvh::bvh::{BuildParams, Bvh, MAX_DEPTH, MeshBvh};
use dynbvh::geom::{Aabb, Ray, TriMesh};
use glam::Vec3;

/// The common builders, and the widest axis with the default bin count.
fn builders() -> Vec<BuildParams> {
    let mut b = common::builders();
    b.push(BuildParams {
        all_axes: false,
        ..BuildParams::BINNED
    });
    b
}

/// Builds with every builder, validates, and compares every ray with brute force; then
/// refits once with the same positions and checks again.
fn check_everything(mesh: &TriMesh, rays: &[Ray]) {
    for params in builders() {
        let mut bvh = MeshBvh::build(mesh, &params);
        for round in 0..2 {
            bvh.validate(mesh)
                .unwrap_or_else(|e| panic!("{} round {round}: {e}", params.name()));
            assert!(bvh.bvh().depth() <= MAX_DEPTH);
            for ray in rays {
                check_ray(mesh, &bvh, ray).unwrap_or_else(|e| panic!("{}: {e}", params.name()));
            }
            bvh.refit(mesh);
        }
    }
}

#[test]
fn empty_input_builds_an_empty_tree() {
    let mesh = TriMesh::default();
    for params in builders() {
        let mut bvh = MeshBvh::build(&mesh, &params);
        bvh.validate(&mesh).unwrap();
        assert!(bvh.bvh().nodes().is_empty());
        assert_eq!(bvh.bvh().sah_cost(), 0.0);
        assert!(bvh.closest_hit(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
        assert!(!bvh.any_hit(&Ray::new(Vec3::ZERO, Vec3::X)));
        bvh.refit(&mesh);
    }
    assert!(Bvh::build(&[], &BuildParams::BINNED).validate().is_ok());
}

#[test]
fn single_triangle() {
    let mesh = TriMesh::from_soup(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]);
    let rays = common::rays_around(Vec3::new(0.3, 0.3, 0.0), 1.0, 200, 1);
    check_everything(&mesh, &rays);
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    assert_eq!(bvh.bvh().nodes().len(), 1);
    assert_eq!(bvh.bvh().sah_cost(), 1.0);
}

#[test]
fn all_centroids_in_one_point() {
    // 3000 different triangles, all with their centroid at (1, 2, 3): no split by position exists.
    let c = Vec3::new(1.0, 2.0, 3.0);
    let mut rng = Rng(7);
    let tris: Vec<[Vec3; 3]> = (0..3000)
        .map(|_| {
            let a = rng.unit_vector() * rng.range(0.1, 1.0);
            let b = rng.unit_vector() * rng.range(0.1, 1.0);
            // The box centre is what builders see: keep it at c by mirroring.
            [c + a, c - a, c + b * 0.0]
        })
        .collect();
    let mesh = TriMesh::from_soup(&tris);
    for i in 0..mesh.len() {
        assert_eq!(mesh.triangle_bounds(i).center(), c);
    }
    check_everything(&mesh, &common::rays_around(c, 1.0, 300, 2));
}

#[test]
fn triangles_that_are_one_point_get_a_balanced_tree() {
    // Every box is the same point, so every split costs the same (nothing): the builders must
    // still halve the list, not peel one triangle off per level (which made the full sweep
    // over millions of such triangles run for minutes).
    let n = 20_000;
    let mesh = TriMesh {
        positions: vec![Vec3::new(0.5, -2.0, 7.0)],
        indices: vec![[0, 0, 0]; n],
    };
    let balanced = (n as f32).log2().ceil() as usize + 2;
    for params in builders() {
        let bvh = MeshBvh::build(&mesh, &params);
        bvh.validate(&mesh).unwrap();
        assert!(
            bvh.bvh().depth() <= balanced,
            "{}: depth {} over {n} point triangles",
            params.name(),
            bvh.bvh().depth()
        );
    }
}

#[test]
fn identical_triangles() {
    let t = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];
    let mesh = TriMesh::from_soup(&vec![t; 20_000]);
    let rays = common::rays_around(Vec3::ZERO, 1.0, 50, 3);
    check_everything(&mesh, &rays);
    // Every leaf respects the size limit although no split separates anything.
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    assert!(
        bvh.bvh()
            .nodes()
            .iter()
            .all(|n| n.count <= BuildParams::BINNED.max_leaf_size)
    );
}

#[test]
fn zero_area_triangles() {
    let mut rng = Rng(11);
    let mut tris = Vec::new();
    for _ in 0..500 {
        let p = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        let q = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        tris.push([p, p, p]); // a point
        tris.push([p, q, (p + q) * 0.5]); // a segment
        tris.push([p, q, q]); // a segment with a repeated vertex
    }
    // And some proper triangles so that there is something to hit.
    for _ in 0..200 {
        let p = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        tris.push([p, p + rng.unit_vector() * 0.2, p + rng.unit_vector() * 0.2]);
    }
    let mesh = TriMesh::from_soup(&tris);
    check_everything(&mesh, &common::rays_around(Vec3::ZERO, 1.0, 400, 4));
}

#[test]
fn nan_and_infinite_vertices_do_not_break_the_tree() {
    let mesh = common::soup_with_nan_and_inf();
    for params in builders() {
        let bvh = MeshBvh::build(&mesh, &params);
        // Structure holds (each primitive once, leaves in range, children after parents).
        bvh.bvh()
            .validate()
            .unwrap_or_else(|e| panic!("{}: {e}", params.name()));
        // Triangles with a NaN vertex are never hit; the others are found as brute force finds
        // them.
        for ray in common::rays_around(Vec3::ZERO, 1.0, 300, 5) {
            check_ray(&mesh, &bvh, &ray).unwrap_or_else(|e| panic!("{}: {e}", params.name()));
        }
        // A refit to the same positions bounds every leaf exactly as the build did (NaN
        // coordinates skipped, infinities clamped), so every box comes back unchanged.
        let mut refitted = bvh.clone();
        refitted.refit(&mesh);
        assert_eq!(refitted.bvh(), bvh.bvh(), "{}", params.name());
    }
}

fn scaled_sphere(scale: f32) -> TriMesh {
    let mut m = dynbvh::geom::shapes::icosphere(3);
    for p in &mut m.positions {
        *p *= scale;
    }
    m
}

#[test]
fn tiny_scale() {
    let s = 1e-20;
    check_everything(
        &scaled_sphere(s),
        &common::rays_around(Vec3::ZERO, s, 300, 6),
    );
}

#[test]
fn huge_scale() {
    let s = 1e20;
    let mesh = scaled_sphere(s);
    check_everything(&mesh, &common::rays_around(Vec3::ZERO, s, 300, 7));
    // Areas of 1e40 overflow f32: the SAH must still separate the triangles sensibly.
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let unit = MeshBvh::build(&scaled_sphere(1.0), &BuildParams::BINNED);
    assert!(
        bvh.bvh().depth() <= 2 * unit.bvh().depth(),
        "depth {} vs {}",
        bvh.bvh().depth(),
        unit.bvh().depth()
    );
}

#[test]
fn exponentially_spaced_boxes_stay_within_the_depth_limit() {
    // Boxes at 2^i: an SAH split peels off one box at a time, which would make a tree as deep
    // as the input is long. The builders must cap the depth.
    let boxes: Vec<Aabb> = (0..2000)
        .map(|i| {
            let x = 2f32.powf((i % 250) as f32 * 0.5 - 60.0) * if i % 2 == 0 { 1.0 } else { -1.0 };
            let p = Vec3::new(x, (i / 250) as f32, 0.0);
            Aabb::new(p, p + Vec3::splat(x.abs() * 1e-3))
        })
        .collect();
    for params in builders() {
        let bvh = Bvh::build(&boxes, &params);
        bvh.validate()
            .unwrap_or_else(|e| panic!("{}: {e}", params.name()));
        assert!(bvh.depth() <= MAX_DEPTH);
    }
}

/// Quality, not only correctness: binned SAH stays within 2% of the full sweep's SAH cost, and
/// the median split is worse than both, on a smooth mesh and on a random soup.
#[test]
fn binned_sah_is_within_two_percent_of_full_sweep() {
    let mut rng = Rng(21);
    let soup = rng.soup(20_000, 0.01);
    let meshes = [
        ("sphere", dynbvh::geom::shapes::bumpy_sphere(30_000)),
        ("soup", TriMesh::from_soup(&soup)),
    ];
    for (name, mesh) in &meshes {
        let sah = |p: &BuildParams| MeshBvh::build(mesh, p).bvh().sah_cost();
        let sweep = sah(&BuildParams::SWEEP);
        let median = sah(&BuildParams::MEDIAN);
        for k in [8, 16, 32] {
            let binned = sah(&BuildParams::binned(k));
            assert!(
                binned <= sweep * 1.02,
                "{name}: binned{k} {binned} vs sweep {sweep}"
            );
            assert!(
                binned < median,
                "{name}: binned{k} {binned} vs median {median}"
            );
        }
    }
}
