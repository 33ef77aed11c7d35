//! Line of sight among moving instances, with visibility masks: in an animated scene of many
//! rigid instances (by default the 166 spinning and hopping cubes of `animations/orbit.glb`),
//! every instance is an agent or an obstacle (its mask). Each frame every agent looks at every
//! other agent along the segment between their centres: the view is blocked when the segment
//! hits something other than the two of them. The query passes through the viewer (exclusion)
//! and sees obstacles and agents (masks); a second pass with the obstacle mask only shows
//! what the agents alone hide.
//!
//! `cargo run --release --example visibility -- [--file animations/orbit.glb] [--frames 8]
//! [--agents 24]`

use anyhow::Result;
use clap::Parser;
use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{EngineConfig, FrameSource, InstanceId, QueryFilter};
use dynbvh::geom::{Aabb, Ray};
use dynbvh::glam::Vec3;
use std::path::PathBuf;

/// Mask bit of the agents.
const AGENT: u32 = 1;
/// Mask bit of the obstacles.
const OBSTACLE: u32 = 2;

/// Line of sight among the moving instances of a glTF scene.
#[derive(Parser, Debug, Clone)]
pub struct Args {
    /// The glTF scene (its first animation is played).
    #[arg(long, default_value = "animations/orbit.glb")]
    pub file: PathBuf,
    /// Frames over one loop of the animation.
    #[arg(long, default_value_t = 8)]
    pub frames: usize,
    /// Agents (every k-th instance; the rest are obstacles).
    #[arg(long, default_value_t = 24)]
    pub agents: usize,
}

/// Per frame: visible agent pairs with every instance blocking, and with obstacles only.
#[derive(Debug, Default)]
pub struct Summary {
    /// Ordered pairs (viewer, target) in view, every instance blocking.
    pub visible: Vec<usize>,
    /// The same with only obstacles blocking (agents see through each other).
    pub visible_past_agents: Vec<usize>,
    /// Pairs looked at per frame.
    pub pairs: usize,
}

/// Runs the frames.
pub fn run(args: &Args) -> Result<Summary> {
    let (scene, _) = Scene::load(&args.file)?;
    let anim = (!scene.animations.is_empty()).then_some(0);
    let mut src = GltfSource::new(&scene, anim, FrameTimes::Count(args.frames.max(1)))?;
    let mut engine = src.engine(EngineConfig::default());
    let n = engine.instance_count();
    let step = (n / args.agents.max(1)).max(1);
    let agents: Vec<InstanceId> = (0..n as u32).step_by(step).map(InstanceId).collect();
    for k in 0..n as u32 {
        let mask = if (k as usize).is_multiple_of(step) {
            AGENT
        } else {
            OBSTACLE
        };
        engine.set_instance_mask(InstanceId(k), mask);
    }
    let mut summary = Summary {
        pairs: agents.len() * agents.len().saturating_sub(1),
        ..Summary::default()
    };
    let mut queries = Vec::new();
    let mut blocked = Vec::new();
    for f in 0..src.frames() {
        src.advance(&mut engine, f);
        engine.update();
        let centre = |i: InstanceId| {
            let m = engine.instance_mesh(i);
            let c = Aabb::from_points(engine.positions(m)).center();
            engine.transform(i).transform_point3(c)
        };
        let centres: Vec<Vec3> = agents.iter().map(|&i| centre(i)).collect();
        // Every instance blocks: the first surface on the segment must be the target's.
        let mut visible = 0;
        for (a, &viewer) in agents.iter().enumerate() {
            for (b, &target) in agents.iter().enumerate() {
                if a == b {
                    continue;
                }
                let ray = Ray::segment(centres[a], centres[b]);
                let seen = QueryFilter::mask(AGENT | OBSTACLE).excluding(viewer);
                let first = engine.closest_hit_filtered(&ray, &seen);
                visible += usize::from(first.is_none_or(|h| h.instance == target));
            }
        }
        summary.visible.push(visible);
        // Obstacles only, as one batch of any-hit queries (recorded for the policy).
        queries.clear();
        for a in 0..agents.len() {
            for b in 0..agents.len() {
                if a != b {
                    let ray = Ray::segment(centres[a], centres[b]);
                    queries.push((ray, QueryFilter::mask(OBSTACLE)));
                }
            }
        }
        blocked.resize(queries.len(), false);
        engine.trace_any_filtered(&queries, &mut blocked);
        summary
            .visible_past_agents
            .push(blocked.iter().filter(|b| !**b).count());
    }
    Ok(summary)
}

#[allow(dead_code)]
fn main() -> Result<()> {
    let args = Args::parse();
    let s = run(&args)?;
    for (f, (v, o)) in s.visible.iter().zip(&s.visible_past_agents).enumerate() {
        println!(
            "frame {f:3}: {v:5} of {} pairs in view ({o} with agents see-through)",
            s.pairs
        );
    }
    Ok(())
}
