//! Refit fails on the exploding and swapping animations: the SAH ratio of an always-refitted
//! tree climbs, and the threshold and amortized policies rebuild. Also the simulator-style API
//! on a generated mesh, and the oracle against the measured schedules' model.

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{Action, EngineConfig, Policy, SceneHit};
use dynbvh::report::rays::camera_rays;
use std::path::PathBuf;

/// Runs `policy` over 30 frames of a shipped animation tracing 64x64 rays a frame; returns the
/// largest SAH ratio and the number of rebuilds.
fn run(file: &str, policy: Policy) -> (f32, u32) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(file);
    let (scene, _) = Scene::load(&path).unwrap();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(30)).unwrap();
    let mut e = src.build(
        0,
        EngineConfig {
            policy,
            ..EngineConfig::default()
        },
    );
    let rays = camera_rays(&e.bounds(), 64, 64);
    let mut hits: Vec<Option<SceneHit>> = vec![None; rays.len()];
    let (mut max_ratio, mut rebuilds) = (1.0f32, 0);
    for f in 1..=src.frames() {
        src.advance(&mut e, f);
        let s = *e.update();
        max_ratio = max_ratio.max(s.max_sah_ratio);
        rebuilds += s.rebuilds;
        assert_eq!(s.action == Action::Rebuild, s.rebuilds > 0);
        e.trace_frame(&rays, &mut hits);
    }
    (max_ratio, rebuilds)
}

#[test]
fn swap_degrades_refit_and_policies_rebuild() {
    let (ratio, rebuilds) = run("swap.glb", Policy::Refit);
    assert_eq!(rebuilds, 0);
    assert!(ratio > 2.0, "swap: refit SAH ratio only reached {ratio}");
    let (ratio, rebuilds) = run("swap.glb", Policy::Threshold(1.3));
    assert!(rebuilds >= 2, "threshold rebuilt {rebuilds} times");
    assert!(ratio <= 1.3 + 1e-6, "threshold kept ratio {ratio}");
    let (_, rebuilds) = run("swap.glb", Policy::Amortized);
    assert!(rebuilds >= 1, "amortized never rebuilt on swap");
}

#[test]
fn explode_degrades_refit_and_policies_rebuild() {
    let (ratio, rebuilds) = run("explode.glb", Policy::Refit);
    assert_eq!(rebuilds, 0);
    assert!(ratio > 1.1, "explode: refit SAH ratio only reached {ratio}");
    let (ratio, rebuilds) = run("explode.glb", Policy::Threshold(1.05));
    assert!(rebuilds >= 2, "threshold rebuilt {rebuilds} times");
    assert!(ratio <= 1.05 + 1e-6);
    let (_, rebuilds) = run("explode.glb", Policy::Amortized);
    assert!(rebuilds >= 1, "amortized never rebuilt on explode");
    let (_, rebuilds) = run("explode.glb", Policy::Periodic(5));
    assert_eq!(rebuilds, 6);
}
