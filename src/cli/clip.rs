//! `dynbvh clip`: the clip-aware tree against the plain one, both refitted through an
//! animation, on its largest deforming mesh.

use super::args::{self, Limits, Size};
use anyhow::{Context, Result};
use clap::Args;
use dynbvh::bvh::build::clip::MAX_POSES;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::report::clip::{self, Options};
use std::path::PathBuf;

/// Arguments of `dynbvh clip`.
#[derive(Args)]
pub struct ClipArgs {
    /// The animated glTF file.
    pub file: PathBuf,
    /// Animation (index or name; default the first).
    #[arg(short, long)]
    pub animation: Option<String>,
    /// Frames spread over one loop of the animation (the trees are built at frame 0).
    #[arg(long, allow_negative_numbers = true, default_value_t = 30, value_parser = clap::value_parser!(u64).range(2..=args::MAX_TIMELINE))]
    pub frames: u64,
    /// Poses of the clip the clip-aware tree is built from, evenly spread over the frames.
    #[arg(long, allow_negative_numbers = true, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=MAX_POSES as u64))]
    pub poses: u64,
    /// Camera rays counted for the ray work, WxH.
    #[arg(long, default_value = "128x128")]
    pub size: Size,
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
pub fn run(a: ClipArgs) -> Result<()> {
    args::init_threads(a.threads)?;
    a.limits.check_memory(
        &format!("--size {}x{}", a.size.w, a.size.h),
        a.size.pixels().saturating_mul(64),
    )?;
    a.limits
        .check_frames(&format!("--frames {}", a.frames), a.frames as f64)?;
    let scene = super::load_scene(&a.file, None)?;
    let anim = args::animation_or_first(&scene, &a.file, a.animation.as_deref())?
        .with_context(|| format!("{}: no animation: nothing deforms", a.file.display()))?;
    let mut src = GltfSource::new(&scene, Some(anim), FrameTimes::Count(a.frames as usize))?;
    let opts = Options {
        poses: a.poses as usize,
        rays: (a.size.w as usize, a.size.h as usize),
    };
    let r = clip::run(&mut src, &opts)?;
    print!("{}", clip::table(&r));
    if let Some(p) = &a.json {
        let s = serde_json::to_string_pretty(&r)?;
        std::fs::write(p, s).map_err(|e| dynbvh::Error::io(p, e))?;
    }
    Ok(())
}
