//! Closest-point distance from a fixed probe to a skinned character over its clip: the scene is
//! posed at evenly spaced times with `GltfSource::set_time` (any time, not only a frame grid),
//! the engine refits or rebuilds the deformed mesh, and `Engine::closest_point` gives the
//! nearest surface point, its distance and triangle. The default file is the shipped skinned
//! tube (`animations/tube.glb`); any skinned glTF works (e.g. a character from the glTF
//! sample models).
//!
//! `cargo run --release --example proximity -- [--file animations/tube.glb] [--steps 20]`

use anyhow::Result;
use clap::Parser;
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, ScenePoint};
use dynbvh::glam::Vec3;
use std::path::PathBuf;

/// Distance from a probe to an animated (skinned) glTF scene over its clip.
#[derive(Parser, Debug, Clone)]
pub struct Args {
    /// The glTF scene (its first animation is played).
    #[arg(long, default_value = "animations/tube.glb")]
    pub file: PathBuf,
    /// Times sampled over the clip.
    #[arg(long, default_value_t = 20)]
    pub steps: usize,
}

/// Per sampled time: the time and the nearest point.
#[derive(Debug, Default)]
pub struct Summary {
    /// The probe.
    pub probe: Vec3,
    /// `(t, nearest point)` at each sampled time.
    pub samples: Vec<(f32, ScenePoint)>,
}

/// Runs the clip.
pub fn run(args: &Args) -> Result<Summary> {
    let (scene, _) = Scene::load(&args.file)?;
    let anim = (!scene.animations.is_empty()).then_some(0);
    let duration = anim.map_or(0.0, |a| scene.animations[a].duration);
    let mut src = GltfSource::new(&scene, anim, FrameTimes::Count(1))?;
    let mut engine = src.engine(EngineConfig::default());
    let b = engine.bounds();
    // Beside the rest pose's box, a tenth of its diagonal off its +x face, mid-height.
    let probe = Vec3::new(
        b.max.x + 0.1 * b.extent().length(),
        b.center().y,
        b.center().z,
    );
    let mut summary = Summary {
        probe,
        samples: Vec::new(),
    };
    for k in 0..args.steps.max(1) {
        let t = duration * k as f32 / args.steps.max(1) as f32;
        src.set_time(&mut engine, t)?;
        engine.update();
        if let Some(p) = engine.closest_point(probe, f32::INFINITY) {
            summary.samples.push((t, p));
        }
    }
    Ok(summary)
}

#[allow(dead_code)]
fn main() -> Result<()> {
    let args = Args::parse();
    let s = run(&args)?;
    println!(
        "{:>8} {:>10} {:>9} {:>9}",
        "t (s)", "distance", "instance", "triangle"
    );
    for (t, p) in &s.samples {
        println!(
            "{t:8.3} {:10.4} {:9} {:9}",
            p.distance, p.instance.0, p.prim
        );
    }
    if let Some((t, p)) = s
        .samples
        .iter()
        .min_by(|a, b| a.1.distance.total_cmp(&b.1.distance))
    {
        println!(
            "nearest at t = {t:.3} s: {:.4} (point {})",
            p.distance, p.point
        );
    }
    Ok(())
}
