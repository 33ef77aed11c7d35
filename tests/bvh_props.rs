//! Property tests: every builder's tree answers every ray exactly as brute force does, before
//! and after several deformations and refits in a row.

mod common;

use common::check_ray;
use dynbvh::bvh::{BuildParams, BuildWorkspace, MeshBvh};
use dynbvh::geom::{Ray, TriMesh};
use glam::Vec3;
use proptest::prelude::*;

fn builders() -> Vec<BuildParams> {
    let widest = BuildParams {
        all_axes: false,
        ..BuildParams::binned(8)
    };
    let tiny_leaves = BuildParams {
        max_leaf_size: 1,
        ..BuildParams::binned(4)
    };
    // A low threshold so that small inputs also take the parallel paths.
    let parallel = BuildParams {
        parallel_threshold: 2,
        ..BuildParams::binned(32)
    };
    let parallel_sweep = BuildParams {
        parallel_threshold: 2,
        ..BuildParams::SWEEP
    };
    vec![
        BuildParams::binned(4),
        BuildParams::BINNED,
        widest,
        tiny_leaves,
        parallel,
        BuildParams::SWEEP,
        parallel_sweep,
        BuildParams::MEDIAN,
    ]
}

fn coord() -> impl Strategy<Value = f32> {
    -10.0f32..10.0
}

fn vec3() -> impl Strategy<Value = Vec3> {
    (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A triangle soup: unshared vertices anywhere in the cube.
fn soup() -> impl Strategy<Value = TriMesh> {
    prop::collection::vec([vec3(), vec3(), vec3()], 1..80).prop_map(|t| TriMesh::from_soup(&t))
}

/// A connected height-field mesh on a grid (shared vertices and edges).
fn grid() -> impl Strategy<Value = TriMesh> {
    (2usize..8, 2usize..8)
        .prop_flat_map(|(w, h)| (Just((w, h)), prop::collection::vec(-3.0f32..3.0, w * h)))
        .prop_map(|((w, h), heights)| {
            let positions = (0..w * h)
                .map(|i| Vec3::new((i % w) as f32, heights[i], (i / w) as f32))
                .collect();
            let mut indices = Vec::new();
            for y in 0..h - 1 {
                for x in 0..w - 1 {
                    let i = (y * w + x) as u32;
                    let (r, d) = (i + 1, i + w as u32);
                    indices.push([i, r, d + 1]);
                    indices.push([i, d + 1, d]);
                }
            }
            TriMesh::new(positions, indices)
        })
}

fn mesh() -> impl Strategy<Value = TriMesh> {
    prop_oneof![soup(), grid()]
}

/// A direction: random, or with one or two zero components (axis-parallel rays).
fn direction() -> impl Strategy<Value = Vec3> {
    prop_oneof![
        vec3().prop_filter("non-zero", |d| d.length() > 1e-3),
        (0usize..3, any::<bool>()).prop_map(|(a, neg)| {
            let mut d = Vec3::ZERO;
            d[a] = if neg { -1.0 } else { 1.0 };
            d
        }),
        (0usize..3, coord(), coord()).prop_filter_map("non-zero", |(a, u, v)| {
            let mut d = Vec3::new(u, v, u - v);
            d[a] = 0.0;
            (d.length() > 1e-3).then_some(d)
        }),
    ]
}

/// Rays: origins anywhere (inside the mesh's box too), some ending early, some starting late.
fn rays() -> impl Strategy<Value = Vec<Ray>> {
    prop::collection::vec(
        (
            vec3(),
            direction(),
            prop_oneof![Just(f32::INFINITY), 0.5f32..20.0],
            prop_oneof![Just(0.0f32), 0.0f32..2.0],
        ),
        1..40,
    )
    .prop_map(|v| {
        v.into_iter()
            .map(|(o, d, tmax, tmin)| Ray::with_range(o, d, tmin, tmax))
            .collect()
    })
}

/// Also rays aimed at the mesh's vertices, the hardest place for the triangle test.
fn aimed(mesh: &TriMesh, from: Vec3) -> impl Iterator<Item = Ray> + '_ {
    mesh.positions
        .iter()
        .take(20)
        .map(move |&p| Ray::new(from, p - from))
        .filter(|r| r.dir.length() > 0.0)
}

fn check_all(mesh: &TriMesh, bvh: &MeshBvh, rays: &[Ray]) -> Result<(), TestCaseError> {
    bvh.validate(mesh).map_err(TestCaseError::fail)?;
    for ray in rays
        .iter()
        .copied()
        .chain(aimed(mesh, Vec3::new(0.3, 11.0, -0.7)))
    {
        check_ray(mesh, bvh, &ray).map_err(TestCaseError::fail)?;
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn every_builder_matches_brute_force(mesh in mesh(), rays in rays()) {
        for params in builders() {
            let bvh = MeshBvh::build(&mesh, &params);
            check_all(&mesh, &bvh, &rays)?;
        }
    }

    #[test]
    fn refit_after_deformations_matches_brute_force(
        mesh in mesh(),
        moves in prop::collection::vec((prop::collection::vec(vec3(), 1..8), 0.0f32..3.0), 3),
        rays in rays(),
    ) {
        for params in builders() {
            let mut m = mesh.clone();
            let mut bvh = MeshBvh::build(&m, &params);
            // Several deformations in a row, each refitted from the previous tree.
            for (offsets, scale) in &moves {
                for (i, p) in m.positions.iter_mut().enumerate() {
                    *p += offsets[i % offsets.len()] * *scale * (1.0 + (i % 3) as f32);
                }
                bvh.refit(&m);
                check_all(&m, &bvh, &rays)?;
            }
        }
    }

    #[test]
    fn rebuilds_into_a_reused_tree_match_brute_force(
        meshes in prop::collection::vec(mesh(), 1..4),
        rays in rays(),
    ) {
        // Meshes of different sizes in a row: the tree and workspace keep stale contents
        // from the previous, possibly larger, build.
        for params in builders() {
            let mut ws = BuildWorkspace::default();
            let mut bvh = MeshBvh::default();
            for m in &meshes {
                bvh.rebuild_indexed(&m.positions, &m.indices, &params, &mut ws);
                check_all(m, &bvh, &rays)?;
            }
        }
    }
}
