//! `dynbvh rungs`: the rungs between refit and rebuild (optimise, partial rebuild, rebuild) on
//! the largest deforming mesh of an animation: time and recovered quality of each.

use super::args::{self, Limits, Size};
use anyhow::{Context, Result};
use clap::Args;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::report::rungs::{self, Options, Rung};
use std::path::PathBuf;

/// Arguments of `dynbvh rungs`.
#[derive(Args)]
pub struct RungsArgs {
    /// The animated glTF file.
    pub file: PathBuf,
    /// Animation (index or name; default the first).
    #[arg(short, long)]
    pub animation: Option<String>,
    /// Frames spread over one loop of the animation (numbered from 0, the animation's start,
    /// as in every command's output; the tree is built at frame 0).
    #[arg(long, allow_negative_numbers = true, default_value_t = 30, value_parser = clap::value_parser!(u64).range(2..=args::MAX_TIMELINE))]
    pub frames: u64,
    /// Measure every N-th frame.
    #[arg(long, allow_negative_numbers = true, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub step: u64,
    /// Timed repeats of each rung per measured frame (the median is reported).
    #[arg(long, allow_negative_numbers = true, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=args::MAX_REPEATS))]
    pub repeats: u64,
    /// Camera rays counted for the ray work, WxH.
    #[arg(long, default_value = "128x128")]
    pub size: Size,
    /// Rungs, comma separated: optimize:SHARE[xPASSES], partial:SHARE, rebuild.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "optimize:0.01,optimize:0.05,partial:0.1,partial:0.25,rebuild"
    )]
    pub rungs: Vec<Rung>,
    /// Worker threads (default: all cores).
    #[arg(long, allow_negative_numbers = true, value_parser = args::thread_count)]
    pub threads: Option<usize>,
    /// Also write the report as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub limits: Limits,
}

/// Runs it.
pub fn run(a: RungsArgs) -> Result<()> {
    args::init_threads(a.threads)?;
    a.limits.check_memory(
        &format!("--size {}x{}", a.size.w, a.size.h),
        a.size.pixels().saturating_mul(64),
    )?;
    let scene = super::load_scene(&a.file, None)?;
    let anim = args::animation_or_first(&scene, &a.file, a.animation.as_deref())?
        .with_context(|| format!("{}: no animation: nothing deforms", a.file.display()))?;
    let mut src = GltfSource::new(&scene, Some(anim), FrameTimes::Count(a.frames as usize))?;
    let opts = Options {
        rungs: a.rungs,
        step: a.step as usize,
        repeats: a.repeats as usize,
        rays: (a.size.w as usize, a.size.h as usize),
    };
    a.limits
        .check_frames(&format!("--frames {}", a.frames), a.frames as f64)?;
    let r = rungs::run(&mut src, &opts)?;
    print!("{}", rungs::table(&r));
    if let Some(p) = &a.json {
        let s = serde_json::to_string_pretty(&r)?;
        std::fs::write(p, s).map_err(|e| dynbvh::Error::io(p, e))?;
    }
    Ok(())
}
