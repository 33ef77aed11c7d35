//! Refit of trees large enough to be refitted as several subtrees (and in parallel on two
//! threads): every box must come out exactly as bounding the moved triangles bottom-up gives
//! it, and a refit back to the built positions must give the built tree back.

mod common;

use dynbvh::bvh::MeshBvh;
use dynbvh::geom::{Aabb, TriMesh, shapes};
use glam::Vec3;

/// A bumpy sphere of about 40,000 triangles (more than 16,384 nodes for every builder, so that the refit splits it) with
/// the NaN and infinite soup appended.
fn large_mesh() -> TriMesh {
    let mut m = shapes::bumpy_sphere(40_000);
    let soup = common::soup_with_nan_and_inf();
    let base = m.positions.len() as u32;
    m.positions.extend(&soup.positions);
    m.indices
        .extend(soup.indices.iter().map(|t| t.map(|v| v + base)));
    m
}

/// Every node's box computed bottom-up from the mesh's triangles.
fn reference_boxes(bvh: &MeshBvh, mesh: &TriMesh) -> Vec<Aabb> {
    let nodes = bvh.bvh().nodes();
    let prims = bvh.bvh().prim_indices();
    let mut boxes = vec![Aabb::EMPTY; nodes.len()];
    for (i, n) in nodes.iter().enumerate().rev() {
        boxes[i] = if n.is_leaf() {
            prims[n.first as usize..(n.first + n.count) as usize]
                .iter()
                .fold(Aabb::EMPTY, |b, &p| {
                    b.union(Aabb::of_triangle(&mesh.triangle(p as usize)))
                })
        } else {
            boxes[n.first as usize].union(boxes[n.first as usize + 1])
        };
    }
    boxes
}

fn refit_on(threads: usize, bvh: &mut MeshBvh, mesh: &TriMesh) {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| bvh.refit(mesh));
}

#[test]
fn large_refits_are_exact_on_one_and_two_threads() {
    let rest = large_mesh();
    let mut moved = rest.clone();
    shapes::sine_deform(&rest.positions, &mut moved.positions, 0.1, 0.7);
    for params in common::builders() {
        let built = MeshBvh::build(&rest, &params);
        assert!(built.bvh().nodes().len() > 1 << 14, "{}", params.name());
        for threads in [1, 2] {
            let mut bvh = built.clone();
            for (mesh, what) in [(&moved, "moved"), (&rest, "back"), (&moved, "moved again")] {
                refit_on(threads, &mut bvh, mesh);
                let name = format!("{}, {threads} threads, {what}", params.name());
                bvh.validate(mesh).unwrap_or_else(|e| panic!("{name}: {e}"));
                let want = reference_boxes(&bvh, mesh);
                for (i, (n, w)) in bvh.bvh().nodes().iter().zip(&want).enumerate() {
                    assert_eq!(n.bounds(), *w, "{name}: node {i}");
                }
                if what == "back" {
                    assert_eq!(bvh.bvh(), built.bvh(), "{name}");
                }
            }
            for ray in common::rays_around(Vec3::ZERO, 1.2, 200, 3) {
                common::check_ray(&moved, &bvh, &ray).unwrap_or_else(|e| panic!("{e}"));
            }
        }
    }
}
