//! A rebuild into a warmed-up tree and workspace allocates nothing (binned SAH and median
//! split), and neither does a refit.

use dynbvh::bvh::{BuildParams, BuildWorkspace, MeshBvh};
use dynbvh::geom::shapes::{bumpy_sphere, sine_deform};
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};
use std::alloc::System;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn rebuild_and_refit_allocate_nothing_once_warm() {
    // Big enough for parallel binning of the top nodes and parallel subtrees.
    let mesh = bumpy_sphere(200_000);
    let mut moved = mesh.positions.clone();
    // One thread: the test measures the builder, not how a thread pool schedules tasks.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| {
        for params in [
            BuildParams::BINNED,
            BuildParams::binned(4),
            BuildParams::MEDIAN,
        ] {
            let mut ws = BuildWorkspace::default();
            let mut bvh = MeshBvh::default();
            bvh.rebuild_indexed(&mesh.positions, &mesh.indices, &params, &mut ws);
            for frame in 1..4 {
                sine_deform(&mesh.positions, &mut moved, 0.1, frame as f32);
                let region = Region::new(GLOBAL);
                bvh.refit_indexed(&moved, &mesh.indices);
                bvh.rebuild_indexed(&moved, &mesh.indices, &params, &mut ws);
                let stats = region.change();
                assert_eq!(
                    stats.allocations + stats.reallocations,
                    0,
                    "{} frame {frame}: {stats:?}",
                    params.name()
                );
            }
            let m = dynbvh::geom::TriMesh::new(moved.clone(), mesh.indices.clone());
            bvh.validate(&m).unwrap();
        }
    });
}
