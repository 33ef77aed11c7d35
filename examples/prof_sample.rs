//! The ray-work sample's cost in a frame loop: each frame traces the same camera rays through
//! the sampled pass (`Engine::trace_closest`) and the plain one (`closest_hit_batch`), the two
//! alternated on one thread, and prints the medians of their CPU times, their ratio, and the
//! share of the frame's first pass its own clock gave the sampling (`FrameStats::sample_ms`
//! over the pass's wall time):
//!
//! `cargo run --release --example prof_sample FILE.glb [frames] [passes]` (`SIDE`: the camera
//! image's side, default 128)
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, FrameSource, Timing};
use dynbvh::report::rays::camera_rays;

#[path = "common/cpu.rs"]
mod cpu;
use cpu::{cpu_s, median, one_thread};
use std::time::Instant;

fn main() {
    one_thread();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (scene, _) = Scene::load(&args[0]).unwrap();
    let frames: usize = args.get(1).map_or(30, |s| s.parse().unwrap());
    let passes: usize = args.get(2).map_or(20, |s| s.parse().unwrap());
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(frames)).unwrap();
    let mut e = src.engine(EngineConfig {
        timing: Timing::Priced,
        ..EngineConfig::default()
    });
    let side: usize = std::env::var("SIDE").map_or(128, |s| s.parse().unwrap());
    let rays = camera_rays(&e.bounds(), side, side);
    let mut hits = vec![None; rays.len()];
    let (mut sampled, mut plain, mut shares) = (Vec::new(), Vec::new(), Vec::new());
    for f in 1..=src.frames() {
        src.advance(&mut e, f);
        e.update();
        let (mut s, mut p) = (0.0, 0.0);
        // The frame's first pass takes its sample; the share is what that pass measured.
        let t = Instant::now();
        e.trace_closest(&rays, &mut hits);
        let pass_ms = t.elapsed().as_secs_f64() * 1e3;
        shares.push(e.frame_stats().sample_ms / pass_ms);
        for _ in 0..passes {
            let t = cpu_s();
            e.trace_closest(&rays, &mut hits);
            s += cpu_s() - t;
            let t = cpu_s();
            e.closest_hit_batch(&rays, &mut hits);
            p += cpu_s() - t;
        }
        sampled.push(s);
        plain.push(p);
    }
    let ratios: Vec<f64> = sampled.iter().zip(&plain).map(|(s, p)| s / p).collect();
    println!(
        "{}: sampled / plain pass, median over {} frames: {:.4} (sampled {:.3} ms, plain {:.3} ms a pass); share the pass measured: median {:.4}",
        args[0],
        frames,
        median(ratios),
        median(sampled) * 1e3 / passes as f64,
        median(plain) * 1e3 / passes as f64,
        median(shares),
    );
}
