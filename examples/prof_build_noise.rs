//! How much a tree's ray work depends on the build alone: a clip that returns to its first
//! pose (its last frame within float rounding of frame 0) gives two builds of one pose, the
//! first frame's tree refitted through the clip and a tree built at the last frame. Prints the
//! largest vertex difference between the two poses, whether the two trees order the triangles
//! alike, and the work (nodes and triangle tests a ray, closest hit through the engine's
//! default traversal) of each on the same camera rays:
//!
//! `cargo run --release --example prof_build_noise FILE.glb [frames] [size]`
use dynbvh::anim::Scene;
use dynbvh::bvh::TraversalStats;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{Engine, EngineConfig, FrameSource, Policy};
use dynbvh::geom::Ray;
use dynbvh::report::rays::camera_rays;

fn work(e: &Engine, rays: &[Ray]) -> TraversalStats {
    let mut s = TraversalStats::default();
    for r in rays {
        let _ = e.closest_hit_counted(r, &mut s);
    }
    s
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (scene, _) = Scene::load(&args[0]).unwrap();
    let frames: usize = args.get(1).map_or(30, |s| s.parse().unwrap());
    let size: usize = args.get(2).map_or(128, |s| s.parse().unwrap());
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(frames)).unwrap();
    let config = |policy| EngineConfig {
        policy,
        ..EngineConfig::default()
    };
    let mut first = src.engine(config(Policy::Refit));
    let mut last = src.engine(config(Policy::Rebuild));
    let rays = camera_rays(&first.bounds(), size, size);
    let m = src.deforming()[0];
    let p0 = first.positions(m).to_vec();
    for f in 1..=frames {
        src.advance(&mut first, f);
        first.update();
        src.advance(&mut last, f);
        last.update();
    }
    let moved = p0
        .iter()
        .zip(last.positions(m))
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);
    let same = first.mesh_bvh(m).bvh().prim_indices() == last.mesh_bvh(m).bvh().prim_indices();
    let (a, b) = (work(&first, &rays), work(&last, &rays));
    let per = |s: TraversalStats| {
        (
            s.nodes as f64 / rays.len() as f64,
            s.prims as f64 / rays.len() as f64,
        )
    };
    let ((an, ap), (bn, bp)) = (per(a), per(b));
    println!(
        "{}: frame {frames} vs frame 0, largest vertex difference {moved:e}; same triangle order: {same}",
        args[0]
    );
    println!(
        "frame-0 tree refitted: {an:.2} nodes, {ap:.2} triangles a ray; built at frame {frames}: {bn:.2}, {bp:.2}; work ratio {:.3}",
        (an + ap) / (bn + bp)
    );
}
