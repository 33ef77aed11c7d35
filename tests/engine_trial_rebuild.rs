//! Under the ray-work measure the default policy's rebuilds are trials: the previous frame's
//! sampled rays are replayed on the refitted tree and the new one, and a new tree that does
//! worse is dropped in the same frame. What must hold when that happens: the mesh keeps
//! exactly the refitted trees (binary and wide, bit for bit), the replay did read worse, every
//! hit stays right, and the update allocates nothing (the spares were reserved when the mesh
//! was added). When a kept trial's probation goes back to the tree it replaced, the mesh holds
//! exactly that tree, refitted. Costs are priced from work counts (`Timing::Priced`), so the decisions are the
//! same on every run. The frames run in a one-thread pool, as in `engine_alloc.rs` (from
//! outside a pool rayon's queue allocates), and this binary holds one test (the allocation
//! counter is global).

use dynbvh::anim::Scene;
use dynbvh::bvh::{MeshBvh, MeshBvh8};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{Action, Engine, EngineConfig, FrameSource, MeshId, Policy, Timing};
use dynbvh::report::rays::camera_rays;
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};
use std::alloc::System;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Runs `file` under the default configuration beside an always-refit engine; returns the
/// rebuilds, the rejected trials and the returns to a replaced tree.
fn run(file: &str) -> (u32, u32, u32) {
    let path = format!("{}/animations/{file}", env!("CARGO_MANIFEST_DIR"));
    let (scene, _) = Scene::load(&path).unwrap();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(30)).unwrap();
    let config = |policy| EngineConfig {
        policy,
        timing: Timing::Priced,
        ..EngineConfig::default()
    };
    let mut e = src.engine(config(Policy::DEFAULT));
    let mut refit = src.engine(config(Policy::Refit));
    e.plan_frames(Some(src.frames() as u64));
    // At 200x200 rays, explode and swap make rebuilds the replay finds worse.
    let rays = camera_rays(&e.bounds(), 200, 200);
    let mut hits = vec![None; rays.len()];
    let (mut rebuilds, mut rejected, mut backs) = (0, 0, 0);
    // Per deforming mesh, the tree the last kept rebuild replaced: what going back must bring.
    let mut replaced: Vec<Option<_>> = vec![None; src.deforming().len()];
    for f in 1..=src.frames() {
        // The trees as they stand, refitted here to the new pose: what a rejected trial
        // must leave.
        let before: Vec<_> = src
            .deforming()
            .iter()
            .map(|&m| (e.mesh_bvh(m).clone(), e.mesh_bvh8(m).cloned()))
            .collect();
        src.advance(&mut e, f);
        src.advance(&mut refit, f);
        let region = Region::new(GLOBAL);
        let s = *e.update();
        let c = region.change();
        assert!(
            f == 1 || c.allocations + c.reallocations == 0,
            "{file} frame {f}: the update allocated"
        );
        refit.update();
        rebuilds += s.rebuilds;
        for (k, (&m, (bvh, wide))) in src.deforming().iter().zip(before).enumerate() {
            let ms = e.mesh_stats(m);
            if ms.action == Action::Back {
                // The replaced tree, refitted to this pose, binary and wide; the one left
                // becomes the spare.
                backs += 1;
                let old = replaced[k].take().expect("a replaced tree to go back to");
                assert_holds(&e, m, old, &format!("{file} frame {f}, back"));
                replaced[k] = Some((bvh, wide));
                continue;
            }
            // One deforming mesh a file: the frame's reverts are its own.
            if ms.action == Action::Rebuild && s.reverts == 0 {
                replaced[k] = Some((bvh, wide));
                continue;
            }
            if !(ms.action == Action::Rebuild && s.reverts > 0) {
                continue;
            }
            rejected += 1;
            assert!(
                ms.measured_work_ratio > 0.0 && ms.measured_work_ratio < 1.0,
                "{file} frame {f}: rejected at replay ratio {}",
                ms.measured_work_ratio
            );
            assert_holds(&e, m, (bvh, wide), &format!("{file} frame {f}, rejected"));
        }
        e.trace_closest(&rays, &mut hits);
        for (r, h) in rays.iter().zip(&hits).step_by(7) {
            let want = refit.closest_hit(r);
            assert_eq!(h.map(|h| h.t), want.map(|h| h.t), "{file} frame {f}");
        }
    }
    (rebuilds, rejected, backs)
}

/// Asserts that mesh `m` holds `trees` (binary and wide), refitted to its pose.
fn assert_holds(e: &Engine, m: MeshId, (mut bvh, mut wide): (MeshBvh, Option<MeshBvh8>), at: &str) {
    bvh.refit_indexed(e.positions(m), e.indices(m));
    assert_eq!(e.mesh_bvh(m).bvh().nodes(), bvh.bvh().nodes(), "{at}");
    assert_eq!(
        e.mesh_bvh(m).bvh().prim_indices(),
        bvh.bvh().prim_indices(),
        "{at}"
    );
    if let Some(w) = &mut wide {
        w.refit_indexed(e.positions(m), e.indices(m));
        let got = e.mesh_bvh8(m).expect("wide tree");
        assert_eq!(got.nodes(), w.nodes(), "{at}: wide nodes");
        assert_eq!(got.blocks().len(), w.blocks().len(), "{at}: blocks");
    }
}

#[test]
fn a_rejected_trial_rebuild_leaves_the_refitted_trees() {
    // The whole run inside a one-thread pool (see `engine_alloc.rs`): from outside a pool,
    // rayon's injector allocates a block every 63 jobs, which a frame would be charged with.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    pool.install(all_files);
}

fn all_files() {
    let (mut total, mut backs) = (0, 0);
    for file in [
        "explode.glb",
        "lidar_cloth.glb",
        "swap.glb",
        "tube.glb",
        "wave.glb",
    ] {
        let (rebuilds, rejected, back) = run(file);
        eprintln!("{file}: {rebuilds} rebuilds, {rejected} rejected, {back} back");
        total += rejected;
        backs += back;
    }
    assert!(total >= 2, "{total} trials rejected: too little checked");
    assert!(
        backs >= 1,
        "{backs} returns to a replaced tree: too little checked"
    );
}
