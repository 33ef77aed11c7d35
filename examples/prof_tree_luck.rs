//! Fresh trees of the same pose from four builders (binned SAH with 16, 32 and 8 bins, and
//! the full sweep), rebuilt at every frame of a glTF animation: each one's SAH cost and its
//! work (nodes visited plus triangles tested) on a fixed camera's rays, over binned16's, per
//! frame, then the spread of the work ratios. Trees of nearly equal SAH can cost a given
//! camera's rays quite different amounts; an oracle that rebuilds in hindsight picks the
//! frames whose trees suit the rays (`docs/ray_work.md`, "Trees of equal SAH").
//!
//! `cargo run --release --example prof_tree_luck FILE.glb [animation] [side]` (`side`: the
//! camera image's side, default 128; 30 frames)
use dynbvh::anim::Scene;
use dynbvh::bvh::{BuildParams, TraversalStats};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, FrameSource, MeshId, Policy, Timing};
use dynbvh::report::rays::camera_rays;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (scene, _) = Scene::load(&args[0]).unwrap();
    let anim: Option<usize> = args.get(1).map(|s| s.parse().unwrap());
    let side: usize = args.get(2).map_or(128, |s| s.parse().unwrap());
    let frames = 30;
    let builds = [
        BuildParams::BINNED,
        BuildParams::binned(32),
        BuildParams::binned(8),
        BuildParams::SWEEP,
    ];
    let mut srcs = Vec::new();
    let mut engines = Vec::new();
    for b in builds {
        let mut src = GltfSource::new(&scene, anim.or(Some(0)), FrameTimes::Count(frames)).unwrap();
        let e = src.engine(EngineConfig {
            timing: Timing::Priced,
            policy: Policy::Rebuild,
            build: b,
            ..EngineConfig::default()
        });
        srcs.push(src);
        engines.push(e);
    }
    let rays = camera_rays(&engines[0].bounds(), side, side);
    println!(
        "frame: per builder (binned16, binned32, binned8, sweep): SAH / binned16's, work / binned16's"
    );
    let mut spread = Vec::new();
    let mut sahs = Vec::new();
    for f in 1..=frames {
        let mut row = Vec::new();
        for (s, e) in srcs.iter_mut().zip(engines.iter_mut()) {
            s.advance(e, f);
            e.update();
            let mut w = TraversalStats::default();
            for r in &rays {
                let _ = e.closest_hit_counted(r, &mut w);
            }
            // Summed over the meshes (one in most of the samples).
            let sah: f32 = (0..e.mesh_count())
                .map(|m| e.mesh_stats(MeshId(m as u32)).sah)
                .sum();
            row.push((sah, (w.nodes + w.prims) as f64));
        }
        let (s0, w0) = row[0];
        let cells: Vec<String> = row
            .iter()
            .map(|(s, w)| format!("{:.3}/{:.3}", s / s0, w / w0))
            .collect();
        for (s, w) in &row[1..] {
            spread.push(w / w0);
            sahs.push(f64::from(s / s0));
        }
        println!("{f}: {}", cells.join("  "));
    }
    spread.sort_by(f64::total_cmp);
    sahs.sort_by(f64::total_cmp);
    print!(
        "SAH ratios to binned16: {:.3}-{:.3}; ",
        sahs[0],
        sahs[sahs.len() - 1]
    );
    let out = spread.iter().filter(|&&r| (r - 1.0).abs() > 0.05).count();
    println!(
        "work ratios to binned16: min {:.3} median {:.3} max {:.3}; {} of {} beyond 5%",
        spread[0],
        spread[spread.len() / 2],
        spread[spread.len() - 1],
        out,
        spread.len()
    );
}
