//! A tree does not depend on the number of threads that built it: the same nodes, the same
//! triangle order and the same 8-wide tree from pools of one to four threads, for every builder
//! and for inputs large enough to take the binned builder's parallel partition (whose sides come
//! out in another order than the serial partition's), and for a warm rebuild into a grown tree.
//! This is what makes the engine's modelled totals the same on machines with other core counts.

mod common;

use common::Rng;
use dynbvh::bvh::{BuildWorkspace, MeshBvh, MeshBvh8};
use dynbvh::geom::{TriMesh, shapes};
use glam::Vec3;

/// Everything a build decides, as text (NaN lanes compare equal there).
fn fingerprint(m: &MeshBvh) -> String {
    let w = MeshBvh8::from_mesh_bvh(m);
    format!(
        "{:?}\n{:?}\n{:?}\n{:?}",
        m.bvh().nodes(),
        m.bvh().prim_indices(),
        w.nodes(),
        w.blocks()
    )
}

/// A soup of `n` small triangles, and `n` triangles around one centroid (binning cannot
/// separate them: the builders cut them by count).
fn inputs(n: usize) -> Vec<(&'static str, TriMesh)> {
    let mut rng = Rng(7);
    let soup = TriMesh::from_soup(&rng.soup(n, 0.01));
    let centred: Vec<[Vec3; 3]> = (0..n)
        .map(|_| {
            let (a, b) = (rng.unit_vector(), rng.unit_vector());
            [a, b, -(a + b)]
        })
        .collect();
    vec![
        ("icosphere", shapes::icosphere(6)),
        ("soup", soup),
        ("one centroid", TriMesh::from_soup(&centred)),
    ]
}

#[test]
fn every_builder_makes_the_same_tree_on_any_number_of_threads() {
    let pools: Vec<_> = (1..=4).map(common::pool).collect();
    for (name, mesh) in inputs(40_000) {
        for params in common::builders() {
            let want = pools[0].install(|| fingerprint(&MeshBvh::build(&mesh, &params)));
            for (t, p) in pools.iter().enumerate().skip(1) {
                let got = p.install(|| fingerprint(&MeshBvh::build(&mesh, &params)));
                assert!(
                    got == want,
                    "{name}, {}: the tree built on {} threads differs from one thread's",
                    params.name(),
                    t + 1
                );
            }
            // A warm rebuild into a tree of another mesh gives the cold build's tree.
            let mut m = MeshBvh::build(&shapes::icosphere(2), &params);
            let mut ws = BuildWorkspace::default();
            pools[1]
                .install(|| m.rebuild_indexed(&mesh.positions, &mesh.indices, &params, &mut ws));
            assert!(
                fingerprint(&m) == want,
                "{name}, {}: a rebuild differs from a cold build",
                params.name()
            );
        }
    }
}
