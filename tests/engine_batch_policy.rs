//! A caller who only casts batches (`Engine::trace_closest`, `trace_any`, the packet batches)
//! drives the default policy: on an animation that degrades a refitted tree, the default
//! configuration rebuilds. Without the trace time (the same rays through the `&self` batch,
//! nothing recorded) the policy has no trace cost to weigh against a rebuild and keeps
//! refitting, so the test separates the two. Costs are priced from work counts
//! (`Timing::Priced`), so the decisions do not depend on the machine's load.

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, FrameSource, Timing};
use dynbvh::report::rays::camera_rays;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Casting {
    Closest,
    Any,
    ClosestPackets,
    Untracked,
}

fn rebuilds(file: &str, casting: Casting) -> u32 {
    let path = format!("{}/animations/{file}", env!("CARGO_MANIFEST_DIR"));
    let (scene, _) = Scene::load(&path).unwrap();
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(24)).unwrap();
    let mut e = src.engine(EngineConfig {
        timing: Timing::Priced,
        ..EngineConfig::default()
    });
    let rays = camera_rays(&e.bounds(), 128, 128);
    let mut hits = vec![None; rays.len()];
    let mut any = vec![false; rays.len()];
    let mut rebuilds = 0;
    for f in 1..=src.frames() {
        src.advance(&mut e, f);
        rebuilds += e.update().rebuilds;
        match casting {
            Casting::Closest => {
                e.trace_closest(&rays, &mut hits);
            }
            Casting::Any => {
                e.trace_any(&rays, &mut any);
            }
            Casting::ClosestPackets => {
                e.trace_closest_packets(&rays, &mut hits);
            }
            Casting::Untracked => e.closest_hit_batch(&rays, &mut hits),
        }
        if casting != Casting::Untracked {
            assert!(
                e.frame_stats().trace_ms > 0.0,
                "{file} frame {f}: trace recorded"
            );
            assert_eq!(e.frame_stats().rays, rays.len() as u64);
        }
    }
    rebuilds
}

#[test]
fn batch_only_callers_get_rebuilds_from_the_default_policy() {
    // On `wave.glb` the any-hit rays stop at the first crest they meet, so the refitted tree
    // costs them about what a fresh one does: whether they rebuild there turns on the sample's
    // noise, not on the batch they come in (`docs/ray_work.md`).
    let closest = [Casting::Closest, Casting::ClosestPackets];
    for (file, castings) in [
        (
            "explode.glb",
            &[Casting::Closest, Casting::Any, Casting::ClosestPackets][..],
        ),
        ("wave.glb", &closest[..]),
    ] {
        let untracked = rebuilds(file, Casting::Untracked);
        for &casting in castings {
            let n = rebuilds(file, casting);
            eprintln!("{file} {casting:?}: {n} rebuilds (untracked: {untracked})");
            assert!(
                n > 0,
                "{file} {casting:?}: the default policy never rebuilt"
            );
            assert!(
                n > untracked,
                "{file} {casting:?}: {n} rebuilds, untracked {untracked}"
            );
        }
    }
}
