//! What `dynbvh` does with no arguments: the whole story on one shipped animation. It renders
//! the frames and a GIF, renders the traversal-work heat maps of always-refit against
//! always-rebuild side by side, runs the policy benchmark (as `dynbvh bench` does), writes the
//! report and charts, and prints where everything went with a short summary.

use super::render::{RenderArgs, RenderSummary, execute};
use anyhow::{Context, Result};
use clap::Parser;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::report::frame_bench::{self, Options, RaySpec};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The animation the default job shows: a sphere whose triangles fly apart and come back,
/// the worst case for refitting.
const DEFAULT_ANIMATION: &str = "animations/explode.glb";

/// Frames of the animation (2 s at 30 fps).
const FRAMES: usize = 60;

#[derive(Parser)]
#[command(name = "render")]
struct RenderCli {
    #[command(flatten)]
    args: RenderArgs,
}

/// The folder holding `animations/`: the current one when it has them, else the crate's.
fn base_dir() -> PathBuf {
    if Path::new(DEFAULT_ANIMATION).is_file() {
        PathBuf::new()
    } else {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
    }
}

fn render(args: &[&str]) -> Result<RenderSummary> {
    let cli = RenderCli::try_parse_from(std::iter::once("render").chain(args.iter().copied()))
        .context("default job: render arguments")?;
    execute(&cli.args)
}

/// Runs the default job.
pub fn run() -> Result<()> {
    let t0 = Instant::now();
    let base = base_dir();
    let file = base.join(DEFAULT_ANIMATION);
    let out = base.join("out");
    let file_s = file.to_string_lossy().into_owned();
    let frames_dir = out.join("frames");
    let heat_dir = out.join("heatmap");
    let bench_dir = out.join("bench");
    let frames = FRAMES.to_string();
    println!(
        "dynbvh default job on {} ({FRAMES} frames): frames, heat maps, policy benchmark",
        file.display()
    );

    eprintln!("rendering the frames ...");
    let shaded = render(&[
        &file_s,
        "--frames",
        &frames,
        "--size",
        "480x360",
        "--shadows",
        "--gif",
        "--out",
        &frames_dir.to_string_lossy(),
    ])?;
    eprintln!("rendering the heat maps of refit against rebuild ...");
    let heat = render(&[
        &file_s,
        "--frames",
        &frames,
        "--size",
        "320x240",
        "--heatmap",
        "--compare",
        "refit,rebuild",
        "--gif",
        "--out",
        &heat_dir.to_string_lossy(),
    ])?;

    eprintln!("benchmarking the policies ...");
    let scene = super::load_scene(&file, None)?;
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(FRAMES))?;
    let opts = Options {
        rays: RaySpec::Size(256, 192),
        trace_repeats: 2,
        ..Options::default()
    };
    let report = frame_bench::run(&mut src, &opts, |m| eprintln!("  {m} ..."));
    std::fs::create_dir_all(&bench_dir)
        .with_context(|| format!("creating {}", bench_dir.display()))?;
    let table = frame_bench::summary_table(&report);
    std::fs::write(bench_dir.join("summary.txt"), &table)?;
    std::fs::write(
        bench_dir.join("frames.csv"),
        frame_bench::to_csv(&report.per_frame),
    )?;
    std::fs::write(
        bench_dir.join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    let mut charts = Vec::new();
    for (stem, chart) in frame_bench::charts(&report) {
        let path = bench_dir.join(stem);
        chart
            .save(&path, 960, 540)
            .with_context(|| format!("writing chart {stem}"))?;
        charts.push(stem);
    }

    // Where everything went.
    println!();
    println!("{table}");
    println!("written:");
    println!(
        "  {:<44} {} shaded frames (480x360, shadow rays) and {}",
        format!("{}/", frames_dir.display()),
        shaded.pngs.len(),
        shaded
            .gif
            .as_ref()
            .and_then(|g| g.file_name())
            .map_or(String::new(), |g| g.to_string_lossy().into_owned())
    );
    println!(
        "  {:<44} {} heat maps, refit (left) against rebuild (right), and {}",
        format!("{}/", heat_dir.display()),
        heat.pngs.len(),
        heat.gif
            .as_ref()
            .and_then(|g| g.file_name())
            .map_or(String::new(), |g| g.to_string_lossy().into_owned())
    );
    println!(
        "  {:<44} summary.txt, report.json, frames.csv, charts {} (.svg and .png)",
        format!("{}/", bench_dir.display()),
        charts.join(", ")
    );

    // The short story.
    println!();
    println!("summary:");
    let (refit, rebuild) = (&heat.timings[0].1, &heat.timings[1].1);
    if let Some((k, worst)) = refit.iter().enumerate().max_by(|a, b| {
        a.1.counts
            .work_per_pixel()
            .total_cmp(&b.1.counts.work_per_pixel())
    }) && let Some(fresh) = rebuild.get(k)
    {
        println!(
            "  heat maps: at frame {} the refitted tree costs {:.1} nodes + triangles per covered \
             pixel against {:.1} rebuilt ({:.2}x; SAH ratio {:.2}); see {}",
            worst.frame,
            worst.counts.work_per_pixel(),
            fresh.counts.work_per_pixel(),
            worst.counts.work_per_pixel() / fresh.counts.work_per_pixel().max(1e-9),
            worst.sah_ratio,
            heat_dir
                .join(format!("compare_{:04}.png", worst.frame))
                .display()
        );
    }
    let find = |name: &str| report.policies.iter().find(|p| p.policy == name);
    if let (Some(r), Some(b)) = (find("refit"), find("rebuild")) {
        println!(
            "  benchmark: always refit {:.0} ms, always rebuild {:.0} ms over {} frames of {} rays",
            r.total_ms, b.total_ms, report.frames, report.rays_per_frame
        );
    }
    if let Some(best) = report
        .policies
        .iter()
        .min_by(|a, b| a.total_ms.total_cmp(&b.total_ms))
    {
        let oracle = if report.oracle.total_ms > 0.0 {
            format!(
                ", {:.2}x the best schedule in hindsight ({} rebuilds)",
                best.oracle_ratio, report.oracle.rebuilds
            )
        } else {
            String::new()
        };
        println!(
            "  fastest policy: {} ({:.0} ms, {} rebuilds{oracle})",
            best.policy, best.total_ms, best.rebuilds
        );
    }
    if let Some(d) = report.policies.iter().find(|p| p.default) {
        println!(
            "  default policy {}: {:.0} ms, {} rebuilds, {:.2}x the oracle",
            d.policy, d.total_ms, d.rebuilds, d.oracle_ratio
        );
    }
    println!(
        "  rendering: {:.0} fps at 480x360 with shadow rays (pose, update, normals and tracing; \
         {} triangles)",
        shaded.fps(0),
        shaded.triangles
    );
    println!("done in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}
