//! The frame loop allocates nothing after the first frame: a counting global allocator watches
//! pose writes, updates (refits, rebuilds of meshes and of the top-level tree) and parallel ray
//! batches. Rebuilds go into the existing trees with the engine's one build workspace, which
//! the meshes' first builds sized, so they allocate nothing either. Counting covers every
//! thread (rayon's workers too), so this binary holds a single test.

use dynbvh::engine::{Engine, EngineConfig, Policy, SceneHit, TlasPolicy};
use dynbvh::geom::shapes::{bumpy_sphere, sine_deform};
use dynbvh::report::rays::camera_rays;
use glam::{Affine3A, Quat, Vec3};
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};
use std::alloc::System;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Runs frames of a scene with a large deforming sphere (parallel refit and rebuild), a small
/// one, and rigid instances of a third; returns (allocations, rebuilt?) per frame after the
/// first.
///
/// Everything, building the scene included, runs inside a one-thread pool. On a worker,
/// parallel calls queue their jobs on the worker's own deque; from outside the pool they would
/// go through rayon's global injector, which allocates a block every 63 jobs. And the binned
/// builder keeps spare bins per thread, made by a thread's first build tasks: with one thread,
/// the scene's first builds make them all; with several, a worker that steals its first build
/// task makes its own then, once, at a frame the scheduler picks.
fn run(policy: Policy, tlas: TlasPolicy, frames: usize) -> Vec<(usize, bool)> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    pool.install(|| run_frames(policy, tlas, frames))
}

fn run_frames(policy: Policy, tlas: TlasPolicy, frames: usize) -> Vec<(usize, bool)> {
    let big = bumpy_sphere(200_000);
    let small = bumpy_sphere(500);
    let mut e = Engine::new(EngineConfig {
        policy,
        tlas,
        ..EngineConfig::default()
    });
    let bm = e.add_mesh(big.positions.clone(), big.indices.clone());
    let sm = e.add_mesh(small.positions.clone(), small.indices.clone());
    let rm = e.add_mesh(small.positions.clone(), small.indices.clone());
    e.add_instance(bm, Affine3A::IDENTITY);
    e.add_instance(sm, Affine3A::from_translation(Vec3::new(3.0, 0.0, 0.0)));
    let rigid: Vec<_> = (0..8)
        .map(|k| {
            e.add_instance(
                rm,
                Affine3A::from_translation(Vec3::new(k as f32, 3.0, 0.0)),
            )
        })
        .collect();
    e.update();
    let rays = camera_rays(&e.bounds(), 64, 64);
    let mut hits: Vec<Option<SceneHit>> = vec![None; rays.len()];
    let mut any = vec![false; rays.len()];
    let mut out = Vec::with_capacity(frames);
    for f in 0..frames {
        let phase = f as f32 * 0.2;
        let region = Region::new(GLOBAL);
        sine_deform(&big.positions, e.positions_mut(bm), 0.05, phase);
        sine_deform(&small.positions, e.positions_mut(sm), 0.3, phase);
        for (k, &i) in rigid.iter().enumerate() {
            let r = Quat::from_rotation_y(phase + k as f32);
            e.set_transform(
                i,
                Affine3A::from_rotation_translation(r, Vec3::new(k as f32, 3.0 + phase.sin(), 0.0)),
            );
        }
        let rebuilt = {
            let s = e.update();
            s.rebuilds > 0 || s.tlas_rebuilt
        };
        e.trace_frame(&rays, &mut hits);
        e.trace_any(&rays, &mut any);
        let _ = e.closest_hit(&rays[0]);
        let c = region.change();
        if f > 0 {
            out.push((c.allocations + c.reallocations, rebuilt));
        }
    }
    assert!(hits.iter().any(Option::is_some));
    out
}

/// One test function: the counter is global, so nothing else may run meanwhile.
#[test]
fn frames_after_the_first_allocate_nothing_even_to_rebuild() {
    let frames = run(Policy::Refit, TlasPolicy::Refit, 40);
    for (f, (n, rebuilt)) in frames.iter().enumerate() {
        assert!(!rebuilt);
        assert_eq!(*n, 0, "refit: frame {} allocated {n} times", f + 1);
    }
    for (policy, tlas) in [
        (Policy::Rebuild, TlasPolicy::Rebuild),
        (Policy::Periodic(3), TlasPolicy::Threshold(1.2)),
        (Policy::Threshold(1.05), TlasPolicy::Threshold(1.2)),
        (Policy::Amortized, TlasPolicy::DEFAULT),
    ] {
        let frames = run(policy, tlas, 9);
        for (f, (n, rebuilt)) in frames.iter().enumerate() {
            assert_eq!(
                *n,
                0,
                "{policy}: frame {} allocated {n} times (rebuilt: {rebuilt})",
                f + 1
            );
        }
        if matches!(policy, Policy::Rebuild | Policy::Periodic(3)) {
            assert!(frames.iter().any(|f| f.1), "{policy} never rebuilt");
        }
    }
}
