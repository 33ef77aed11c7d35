//! Property tests: every builder's tree answers every ray exactly as brute force does, before
//! and after several deformations and refits in a row.

mod common;

use common::check_ray;
use common::strategies::{mesh, rays, vec3};
use dynbvh::bvh::{BuildWorkspace, MeshBvh};
use dynbvh::geom::{Ray, TriMesh};
use glam::Vec3;
use proptest::prelude::*;

/// Also rays aimed at the mesh's vertices, the hardest place for the triangle test.
fn aimed(mesh: &TriMesh, from: Vec3) -> impl Iterator<Item = Ray> + '_ {
    mesh.positions
        .iter()
        .take(20)
        .map(move |&p| Ray::new(from, p - from))
        .filter(|r| r.dir().length() > 0.0)
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
    fn every_builder_matches_brute_force(mesh in mesh(80, 8), rays in rays(1..40)) {
        for params in common::builders() {
            let bvh = MeshBvh::build(&mesh, &params);
            check_all(&mesh, &bvh, &rays)?;
        }
    }

    #[test]
    fn refit_after_deformations_matches_brute_force(
        mesh in mesh(80, 8),
        moves in prop::collection::vec((prop::collection::vec(vec3(), 1..8), 0.0f32..3.0), 3),
        rays in rays(1..40),
    ) {
        for params in common::builders() {
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
        meshes in prop::collection::vec(mesh(80, 8), 1..4),
        rays in rays(1..40),
    ) {
        // Meshes of different sizes in a row: the tree and workspace keep stale contents
        // from the previous, possibly larger, build.
        for params in common::builders() {
            let mut ws = BuildWorkspace::default();
            let mut bvh = MeshBvh::default();
            for m in &meshes {
                bvh.rebuild_indexed(&m.positions, &m.indices, &params, &mut ws);
                check_all(m, &bvh, &rays)?;
            }
        }
    }
}
